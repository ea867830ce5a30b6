// Presence records (PROTOCOL.md, "Presence records"): what changed in a
// client's presence list since the last message, as bytes, for a client
// that set kFeaturePresenceRecords. Positions are in eighths of a voxel
// (presence_eighths), so a client's list holds exactly the positions the
// server told (a far entry's may be up to 8 turns old).
//
// encode_presence_records and decode_presence_records are the format;
// PresenceList is the list a client keeps and applies them to (the checks
// that need the list: an entry moved or left must be in it, one entering
// must not, at most 64).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/vec3.h"
#include "protocol/messages.h"

namespace terrane {

// Records in one message: every entry of a full list leaving and as many
// entering, and moves of the entries that stay.
inline constexpr std::size_t kMaxPresenceRecords = 3 * kMaxPresenceEntries;

enum class PresenceRecordKind : std::uint8_t { kMoved = 0, kEntered = 1, kLeft = 2 };

struct PresenceRecord {
  PresenceRecordKind kind = PresenceRecordKind::kMoved;
  std::uint32_t client_id = 0;
  Vec3i eighths;      // kEntered: the position; kMoved: the change; kLeft: unused
  std::string name;   // kEntered only
  friend bool operator==(const PresenceRecord&, const PresenceRecord&) = default;
};

// A position in eighths of a voxel, rounded half away from zero. Positions
// on the wire are within kMaxWireCoordinate, so the result fits.
Vec3i presence_eighths(Vec3f position);
Vec3f presence_position(Vec3i eighths);

void encode_presence_records(std::span<const PresenceRecord> records, std::vector<std::uint8_t>& out);
// Every record well formed: a known kind, no client twice, names as in
// Hello, positions and changes within range, nothing left over.
Result<std::vector<PresenceRecord>> decode_presence_records(std::span<const std::uint8_t> bytes);

// The presence list as its client keeps it: the server's rounded positions.
class PresenceList {
 public:
  struct Entry {
    std::uint32_t client_id = 0;
    Vec3i eighths;
    std::string name;
  };
  // Applies one message's records (all or none); the list may not exceed
  // 64 entries once all are applied. An error's offset is the index of the
  // record that does not fit the list (or the count, for too many).
  Status apply(std::span<const PresenceRecord> records);
  const std::vector<Entry>& entries() const { return entries_; }
  // The entry of this client, or null.
  const Entry* find(std::uint32_t client_id) const;
  void clear() { entries_.clear(); }
  // The entries nearest `from` first (ties by id), as messages carry them.
  std::vector<PresenceEntryMsg> nearest_first(Vec3f from) const;

 private:
  std::vector<Entry> entries_;  // by client_id
};

}  // namespace terrane
