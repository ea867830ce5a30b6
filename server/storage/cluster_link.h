// What storage knows of a world shared by several servers (PostgreSQL,
// STORE_POSTGRESQL.md): the leases that fence the chunk store's writes,
// the forwarded edits and claims Storage passes on, and ClusterLink, the
// cluster room (server/cluster/) as Storage reaches it. The types live
// here, below both rooms, so that storage never includes cluster/.
//
// Threading: plain data; a ClusterLink's methods may be called from any
// thread (see each).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/world/coarse_image.h"
#include "protocol/messages.h"
#include "server/storage/notices.h"
#include "server/storage/pg_connection.h"

namespace terrane {

// How a claim treats a free region (STORE_POSTGRESQL.md, "Regions and leases").
enum class ClaimRule : std::uint8_t {
  kAny,               // take it (tools, forwarded edits, rollbacks)
  kPreferNeighbours,  // leave it to a server writing a neighbour unless the claimant writes one itself
                      // (a server's clients' own edits)
};

// A region's lease as its holder knows it. epoch grows by one each time the
// region changes hands, so a stale holder's writes are told apart.
struct RegionLease {
  Vec3i region;
  std::uint32_t owner = 0;  // the server id
  std::uint64_t epoch = 0;
  friend bool operator==(const RegionLease&, const RegionLease&) = default;
};

// Edits forwarded between servers (STORE_POSTGRESQL.md, "Forwarded
// edits"): a server sends an edit in a region another server holds to that
// server's inbox (a row with a deadline by the database's clock, and a
// notice on terrane_inbox naming the server); the owner takes it (only
// before its deadline), applies it in a tick and answers in the tick's
// commit (the row deleted, and a notice on terrane_answers naming the
// sender). A sender whose wait ran out takes back the row not taken.
inline constexpr const char* kInboxChannel = "terrane_inbox";
inline constexpr const char* kAnswersChannel = "terrane_answers";
struct InboxEdit {
  std::int64_t id = 0;
  std::uint32_t from = 0;  // the server that forwarded it
  std::string player;
  std::vector<std::uint8_t> edit;  // an EditRequest frame, as a client sent it (forwarded_edit.h)
  // Until then (this server's steady clock) the row's deadline has surely
  // not passed by the database's clock: the time the take was sent plus
  // what the database said was left (its clock read after the take left
  // here). The taker applies the edit only before it.
  std::chrono::steady_clock::time_point current_until{};
};

// The news between servers (STORE_POSTGRESQL.md, "Notices"): every fenced
// write notifies channel terrane_changes, in its transaction, of each chunk
// it wrote and the chunk's new revision, and of each region it wrote and
// the region's new sequence number (+1 per write of it). Payloads are
// text: entries "x,y,z,revision" or "x,y,z,revision,tick,UNITS" (a chunk)
// and "r,x,y,z,seq" (a region) separated by one space, at most
// kMaxChangeNoticeBytes each (more entries: more notices). UNITS is the
// base64 (RFC 4648, padded) of the update batch of the 4^3 units that
// changed from revision - 1 to revision in the writer's world tick `tick`
// (ChunkWrite::units and tick), when the write knows them and they take at
// most kMaxNoticeUnitsBytes of base64; a reader holding revision - 1
// applies them instead of reading the chunk.
inline constexpr const char* kChangesChannel = "terrane_changes";

// Server ids (terrane-server --server-id) are below 2^31: PostgreSQL's integer.
inline constexpr std::uint32_t kMaxServerId = 2147483647;

// Where a server's writes get their leases: the leases of the regions given
// (a LeaseKeeper's ensure), or kOwned naming the holder of one of them.
using LeaseSource = std::function<StoreResult<std::vector<RegionLease>>(std::span<const Vec3i> regions)>;

// The region (8 x 8 x 8 chunks, the coarse images' regions) a chunk
// belongs to: the unit of a lease.
inline Vec3i lease_region_of(Vec3i chunk_pos) { return coarse_region_of(chunk_pos); }
// Whether two non-empty regions have chunks in a lease region in common.
// (The regions a box's chunks fall in form a box of region coordinates:
// two of those meet where the boxes share one.)
inline bool lease_regions_meet(const Region& a, const Region& b) {
  const auto regions = [](const Region& r) {
    return Region{lease_region_of(chunk_of(r.min)), lease_region_of(chunk_of(r.max - Vec3i{1, 1, 1})) + Vec3i{1, 1, 1}};
  };
  return !a.empty() && !b.empty() && !intersect(regions(a), regions(b)).empty();
}

// A claim's outcome (ClusterLink::claim). Once held, the region's stored
// chunks are listed with their revisions, read after the claim: another
// server may have written them while it held the region, and whatever
// this server holds of them older than that must be read again before it
// writes there. why names the holder when another server has the region.
struct RegionClaim {
  bool held = false;
  bool unreachable = false;  // not held because the database could not be reached (try again)
  bool left = false;         // free, but left to holder, which writes its neighbours (ClaimRule)
  std::string why;
  std::optional<std::uint32_t> holder;                  // the server holding it instead
  std::vector<std::pair<Vec3i, std::uint64_t>> stored;  // chunk, revision
};

// The cluster room's operations that Storage passes on for the world
// owner (server/cluster/cluster_control.h implements them on its control
// thread). Each asynchronous one runs there, in the order asked, and calls
// done on that thread.
class ClusterLink {
 public:
  virtual ~ClusterLink() = default;
  // This server's id.
  virtual std::uint32_t server_id() const = 0;
  // Whether this server holds region's lease now (any thread).
  virtual bool holds(Vec3i region) const = 0;
  // Claims region for this server if it does not hold it, then lists its
  // stored chunks (RegionClaim).
  virtual void claim(Vec3i region, ClaimRule rule, std::function<void(RegionClaim)> done) = 0;
  // Sends an edit to server to's inbox (done gets the inbox row's id; the
  // row holds encode_forwarded_edit(edit)), releasing hand_over first
  // (regions of this server's the edit also writes: nothing of them in
  // flight), so that server can take them.
  // deadline (this server's steady clock): when the sender's wait runs
  // out; the row's deadline is a lower bound of the database's clock at
  // that time, so it has passed there once it has here. Not sent (an
  // error: nothing written) without a recent reading of the database's
  // clock or once deadline has passed; kUnknown: the commit's answer was
  // lost (the row may be there).
  virtual void forward(std::uint32_t to, std::string player, EditRequestMsg edit, std::vector<Vec3i> hand_over,
                       std::chrono::steady_clock::time_point deadline,
                       std::function<void(StoreResult<std::int64_t>)> done) = 0;
  // Takes back this server's forwarded edit (inbox row): done gets true if
  // it was deleted untaken (never applied), false if its addressee took it
  // (or answered it).
  virtual void take_back(std::int64_t row, std::function<void(StoreResult<bool>)> done) = 0;
  // Passes this server's inbox row on to server to, releasing hand_over
  // first as forward does.
  virtual void relay(std::int64_t row, std::uint32_t to, std::vector<Vec3i> hand_over,
                     std::function<void(StoreResult<Ok>)> done) = 0;
  // Takes this server's inbox past after (rows not taken, before their
  // deadline), at most limit, oldest first.
  virtual void read_inbox(std::int64_t after, std::size_t limit,
                          std::function<void(StoreResult<std::vector<InboxEdit>>)> done) = 0;
  // Answers edits refused without a commit (a failure is logged).
  virtual void answer(std::vector<ForwardAnswer> answers) = 0;
};

}  // namespace terrane
