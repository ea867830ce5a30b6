// What the servers of a shared world tell each other in PostgreSQL's
// notices (STORE_POSTGRESQL.md, "Notices"): the chunks and regions a commit
// wrote, and the answers to forwarded edits, as payload text and back.
// Payloads come from the database: parsing checks every field.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/world/world_store.h"

namespace terrane {

// A region's write sequence: +1 with each commit that writes it (kept
// across changes of hands), so a reader that missed a notice finds out.
struct RegionSeq {
  Vec3i region;
  std::uint64_t seq = 0;
  friend bool operator==(const RegionSeq&, const RegionSeq&) = default;
};

// The answer of a region's server to an edit forwarded to it (InboxEdit).
struct ForwardAnswer {
  std::int64_t id = 0;     // the inbox row
  std::uint32_t from = 0;  // the server that forwarded it (the notice's addressee)
  bool accepted = false;
  std::uint64_t tick = 0;  // the owner's tick that applied it
  std::string reason;      // why not, if not
  friend bool operator==(const ForwardAnswer&, const ForwardAnswer&) = default;
};
// terrane_answers payload: "from id accepted(0|1) tick reason..." (the
// reason, up to 256 bytes, last).
std::string answer_notice(const ForwardAnswer& a);
std::optional<ForwardAnswer> parse_answer_notice(std::string_view payload);

// A commit's change notices: each at most kMaxChangeNoticeBytes, a chunk's
// units (base64) only up to kMaxNoticeUnitsBytes.
inline constexpr std::size_t kMaxChangeNoticeBytes = 7000;
inline constexpr std::size_t kMaxNoticeUnitsBytes = 4000;
struct ChunkChange {
  Vec3i pos;
  std::uint64_t revision = 0;
  std::vector<std::uint8_t> units = {};  // decoded from UNITS; empty without
  std::uint64_t tick = 0;                // the writer's tick that made them
  friend bool operator==(const ChunkChange&, const ChunkChange&) = default;
};
struct ChangeNotice {
  std::vector<ChunkChange> chunks;
  std::vector<RegionSeq> regions;
  // Chunks whose UNITS did not read (not base64, or over the cap): kept
  // without units, so they are read again.
  std::size_t units_unread = 0;
};
std::vector<std::string> change_notices(std::span<const ChunkWrite> chunks, std::span<const RegionSeq> regions = {});
// nullopt if the payload is not one (another program's notice, damage);
// a chunk's UNITS that do not read only lose the chunk its units.
std::optional<ChangeNotice> parse_change_notice(std::string_view payload);

}  // namespace terrane
