// The server's counters: atomics every room adds to and any thread reads
// (the metrics endpoint, the stats log, tests). Nothing here knows a room;
// each room includes this and bumps its own.
#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <span>

namespace terrane {

// A steady-clock time as the counters keep it (last_tick_at_ns,
// lease_renewed_at_ns): nanoseconds since the clock's epoch, 0 for never.
inline std::int64_t steady_ns(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

// A fixed-bucket histogram of durations, lock-free (Prometheus' histogram
// type: cumulative buckets "le", a _sum and a _count, made when rendered).
class DurationHistogram {
 public:
  static constexpr std::size_t kBuckets = 12;
  // Upper bounds in seconds; the last bucket is +Inf.
  static constexpr std::array<double, kBuckets - 1> kBounds = {0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025,
                                                                0.05,   0.1,   0.25,   0.5,   1.0};

  void observe(std::chrono::nanoseconds d) {
    const double s = std::chrono::duration<double>(d).count();
    const auto i = static_cast<std::size_t>(std::lower_bound(kBounds.begin(), kBounds.end(), s) - kBounds.begin());
    counts_[i].fetch_add(1, std::memory_order_relaxed);
    sum_ns_.fetch_add(static_cast<std::uint64_t>(std::max<std::int64_t>(0, d.count())), std::memory_order_relaxed);
  }
  // Observations in bucket i alone (not cumulative).
  std::uint64_t bucket(std::size_t i) const { return counts_[i].load(std::memory_order_relaxed); }
  std::uint64_t count() const {
    std::uint64_t n = 0;
    for (const auto& c : counts_) n += c.load(std::memory_order_relaxed);
    return n;
  }
  double sum_seconds() const { return static_cast<double>(sum_ns_.load(std::memory_order_relaxed)) * 1e-9; }

 private:
  std::array<std::atomic<std::uint64_t>, kBuckets> counts_{};
  std::atomic<std::uint64_t> sum_ns_{0};
};

// Why a session ended: one label each on terrane_disconnects_total. The
// text sent to the client (Disconnect.reason) says more.
enum class CloseReason : std::uint8_t {
  kPeerClosed,        // the client closed the socket (FIN, or a reset when it
                      // left with our data unread)
  kClientBye,         // the client sent Disconnect
  kSocketError,
  kHandshakeTimeout,
  kIdleTimeout,
  kFrameTimeout,      // a frame begun and not finished in time
  kTooSlow,           // a write made no progress
  kTooFarBehind,      // the send queue reached its cap
  kInboundRate,
  kProtocolError,
  kVersionMismatch,
  kAuthFailed,
  kMovingTooFast,
  kEditRate,
  kRequestRate,       // chunk hash requests beyond their budget
  kServerFull,
  kShutdown,
  kStorageFailure,
  kKicked,            // by an operator (terrane-admin kick)
  kBanned,            // refused at the handshake, or ended by a ban
  kNotWhitelisted,    // refused at the handshake
  kReplaced,          // the same player joined again: the newer session wins
  kCount
};
const char* close_reason_label(CloseReason r);

// Why an edit was refused: one label each on terrane_edits_rejected_total.
enum class RejectReason : std::uint8_t {
  kInvalid,            // meaningless on the wire (bad kind, inverted box, ...)
  kUnknownMaterial,
  kTooLarge,
  kOutsideWorld,
  kOutsideFullRes,     // not where the client holds the world at full resolution
  kQueueFull,
  kHistory,            // nothing to undo/redo, or the step is out of reach
  kShutdown,
  kStorageFailure,
  kNotOwner,           // a region another server of a shared world holds
  kOutcomeUnknown,     // the server cannot tell whether it was applied (a forward or commit whose answer was lost)
  kCount
};
const char* reject_reason_label(RejectReason r);

// The server's memory by part, as each part's owner estimates it from
// its sizes and counts (terrane_memory_bytes{part=...}): the parts that
// grow with the clients, to tell what a client costs. Each owner adds the
// change of its own estimate (any thread; readers see a sum).
enum class MemoryPart : std::uint8_t {
  kChunkSlots,  // every replicator's ChunkSlots (session strands)
  kInterest,    // the interest index: who holds which chunk (world strand)
  kResidency,   // the chunk versions the world holds and its entry per chunk (world strand)
  kCount
};
const char* memory_part_label(MemoryPart p);

struct MemoryCounters {
  std::array<std::atomic<std::int64_t>, static_cast<std::size_t>(MemoryPart::kCount)> bytes{};
  std::atomic<std::int64_t>& operator[](MemoryPart p) { return bytes[static_cast<std::size_t>(p)]; }
  std::int64_t load(MemoryPart p) const { return bytes[static_cast<std::size_t>(p)].load(std::memory_order_relaxed); }
};

// Per message type (the Body union's index), shared by every session; plus
// what the sessions hold queued in all and why they ended.
struct NetCounters {
  static constexpr std::size_t kTypes = 32;
  std::array<std::atomic<std::uint64_t>, kTypes> sent_bytes{}, sent_frames{}, received_bytes{}, received_frames{};
  std::atomic<std::int64_t> queued_bytes{0};  // every session's send queue
  std::atomic<std::uint64_t> writes{0};       // gathered socket writes started (each one or more system calls)
  std::array<std::atomic<std::uint64_t>, static_cast<std::size_t>(CloseReason::kCount)> disconnects{};
  void disconnected(CloseReason r) { disconnects[static_cast<std::size_t>(r)].fetch_add(1, std::memory_order_relaxed); }
  std::uint64_t sessions_closed() const {
    std::uint64_t n = 0;
    for (const auto& d : disconnects) n += d.load(std::memory_order_relaxed);
    return n;
  }
};

// A shared PostgreSQL world's links to its database, as the threads using
// them last found them; /health and /metrics read them (SQLite worlds leave
// them at zero). Each is written by one thread, named beside it.
struct DatabaseCounters {
  // Writer thread: commits being tried again now (the database went away)
  // and the attempts that failed and were tried again.
  std::atomic<std::uint64_t> commits_retrying{0};
  std::atomic<std::uint64_t> commit_retries{0};
  // Lease keeper's thread (steady clock, ns): when the last renewal round
  // that reached the database started (its leases renewed, its address
  // told); the keeper's opening counts as one. 0: not a shared world.
  std::atomic<std::int64_t> lease_renewed_at_ns{0};
  // Listener's thread: 1 while its connection is broken (the other
  // servers' notices and the inbox's news are not heard).
  std::atomic<std::uint64_t> listener_down{0};
  // Control thread: 1 while the last read of the inbox failed.
  std::atomic<std::uint64_t> inbox_failing{0};
};

// One commit's retries as DatabaseCounters count them: in commits_retrying
// from its first failed attempt (start()) until it ends (stored or failed),
// every failed attempt in commit_retries. counters may be null.
class CommitRetries {
 public:
  explicit CommitRetries(DatabaseCounters* counters) : counters_(counters) {}
  CommitRetries(const CommitRetries&) = delete;
  CommitRetries& operator=(const CommitRetries&) = delete;
  ~CommitRetries() {
    if (on_) counters_->commits_retrying.fetch_sub(1, std::memory_order_relaxed);
  }
  void start() {
    if (counters_ == nullptr) return;
    counters_->commit_retries.fetch_add(1, std::memory_order_relaxed);
    if (!on_) counters_->commits_retrying.fetch_add(1, std::memory_order_relaxed);
    on_ = true;
  }

 private:
  DatabaseCounters* const counters_;
  bool on_ = false;
};

struct ServerCounters {
  std::atomic<std::uint64_t> sessions_accepted{0};
  std::atomic<std::uint64_t> joins{0};           // handshakes accepted (Welcome sent)
  std::atomic<std::uint64_t> clients{0};         // players welcomed and connected now
  std::atomic<std::uint64_t> admin_sessions{0};  // operators' sessions (terrane-admin) connected now
  std::atomic<std::uint64_t> ticks{0};
  std::atomic<std::uint64_t> edits_applied{0};
  std::array<std::atomic<std::uint64_t>, static_cast<std::size_t>(RejectReason::kCount)> edits_rejected_by{};
  std::atomic<std::uint64_t> chunks_sent{0};     // full-resolution chunks (8 units each)
  std::atomic<std::uint64_t> mips_sent{0};
  std::atomic<std::uint64_t> estimates_sent{0};  // Estimate records (a coarsest mip estimated)
  std::atomic<std::uint64_t> horizons_sent{0};   // Horizon records (a region's image, to one client)
  std::atomic<std::uint64_t> empties_sent{0};
  std::atomic<std::uint64_t> mip_refreshes{0};   // mips sent again because their bytes changed
  std::atomic<std::uint64_t> mip_patches{0};     // of them: sent as a Mip patch (the changed sub-units)
  std::atomic<std::uint64_t> refreshes_skipped{0};  // changes whose held level's bytes did not
  std::atomic<std::uint64_t> update_batches_sent{0};
  std::atomic<std::uint64_t> update_units_sent{0};
  std::atomic<std::uint64_t> updates_dropped_by_fault{0};
  std::atomic<std::uint64_t> updates_corrupted_by_fault{0};
  std::atomic<std::uint64_t> stream_bytes{0};    // StreamBatch bytes queued
  std::atomic<std::uint64_t> presence_sent{0};
  std::atomic<std::uint64_t> hashes_pushed{0};
  std::atomic<std::uint64_t> chunks_asked{0};   // chunks replicators asked the world for (streaming)
  std::atomic<std::uint64_t> stream_yields{0};  // pumps that found the stream gate closed (one per pause and client)
  std::atomic<std::uint64_t> mip_refresh_yields{0};  // refreshes of mips put off: the stream gate was closed
  std::atomic<std::uint64_t> chunks_loaded{0};   // resident now
  std::atomic<std::uint64_t> chunks_unloaded{0};
  std::atomic<std::uint64_t> limit_violations{0};
  std::atomic<std::uint64_t> auth_failures{0};
  std::atomic<std::uint64_t> chunks_resumed{0};  // claimed by a resuming client, still current, not resent
  // Estimated chunks generated for real (world strand): each replaced its
  // estimate; corrected: the exact mip differed, so holders were sent it.
  std::atomic<std::uint64_t> estimates_replaced{0};
  std::atomic<std::uint64_t> estimates_corrected{0};
  // A shared world: chunks held here that another server's notice said were
  // stored newer, so they were read again, or, when no client here held
  // them, forgotten, or brought up to date from the notice's units (world
  // strand).
  std::atomic<std::uint64_t> chunks_changed_elsewhere{0};
  std::atomic<std::uint64_t> chunks_forgotten_elsewhere{0};
  std::atomic<std::uint64_t> chunks_updated_elsewhere{0};
  // Edits in regions another server holds sent to its inbox, and edits
  // other servers sent to this one's.
  std::atomic<std::uint64_t> edits_forwarded{0};
  std::atomic<std::uint64_t> forwarded_edits_received{0};
  std::atomic<std::uint64_t> redirects_sent{0};      // clients told to go on at another server
  std::atomic<std::uint64_t> redirects_received{0};  // clients that came with a Redirect's token
  std::atomic<std::uint64_t> regions_handed_over{0};  // released to the server an edit across a border went to
  // Per-tick cost split (world strand): applying edits and publishing
  // versions (the tick), and fanning committed changes out to their
  // holders. Commit time is the storage's (StorageCounters).
  DurationHistogram tick_duration;
  DurationHistogram fanout_duration;
  // A client's edit from its session handing it to the world to its ack
  // being queued on that session: the wait for the tick, the tick, the
  // commit and the fan-out (the network and the client's side excluded).
  DurationHistogram edit_ack_duration;
  std::atomic<std::uint64_t> tick_lag_ns{0};     // how late the last tick started
  std::atomic<std::int64_t> last_tick_at_ns{0};  // steady clock, when the last tick ended
  std::atomic<std::uint64_t> deliveries{0};      // (changed chunk, holder) pairs fanned out
  std::atomic<std::uint64_t> tick_frames{0};     // frames the replicators sent for ticks' news
  std::atomic<std::uint64_t> ticks_late{0};      // ticks that started more than a period late
  NetCounters net;
  DatabaseCounters database;
  MemoryCounters memory;

  void rejected(RejectReason r, std::uint64_t n = 1) {
    edits_rejected_by[static_cast<std::size_t>(r)].fetch_add(n, std::memory_order_relaxed);
  }
  std::uint64_t edits_rejected() const {
    std::uint64_t n = 0;
    for (const auto& c : edits_rejected_by) n += c.load(std::memory_order_relaxed);
    return n;
  }
};

}  // namespace terrane
