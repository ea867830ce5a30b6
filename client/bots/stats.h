// Measurements shared by all bots of a run: latency summaries, the edit
// fan-out tracker (joins each edit's ack tick with the UpdateBatches other
// bots received for that tick), and the mismatch log.
//
// Thread-safety: FanoutTracker and MismatchLog are called from the io pool
// (client callbacks) and the driver thread; each guards its state with one
// mutex because those threads share it and nothing else orders them.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "client/bots/histogram.h"
#include "client/client.h"

namespace terrane::bots {

using Clock = std::chrono::steady_clock;

// A latency distribution as the report gives it: the percentiles people
// read, and the histogram they were read from (which the JSON report keeps
// so that the reports of several processes merge).
struct LatencySummary {
  double p50 = 0, p95 = 0, p99 = 0;
  std::size_t count = 0;
  double max = 0;
  LatencyHistogram histogram;
};
// The percentiles of h (within LatencyHistogram::kRelativePrecision).
LatencySummary summarize(const LatencyHistogram& h);
// Exact nearest-rank percentiles of a few samples (sorts a copy): the live
// progress line's.
LatencySummary summarize(std::vector<float> samples_ms);

double ms_between(Clock::time_point a, Clock::time_point b);
// A server's reason for refusing an edit with its particulars taken out
// (each run of digits is N, a lease's expiry time is cut), so refusals of
// one kind count together: "region (N,N,-N) is leased to server N (epoch N)".
std::string reason_class(std::string_view reason);

// Records a sample in by_second[the whole seconds from run_start to t]
// (second 0 for t before run_start), growing it as needed.
void add_per_second(std::vector<LatencyHistogram>& by_second, Clock::time_point run_start, Clock::time_point t,
                    double ms);

// Fan-out of an edit to one receiver: from the author calling fill_* to the
// receiver's UpdateBatch of the edit's tick that covers one of the edit's
// chunks (the last such batch when the edit spans several chunks). Bots
// share a process, hence a clock. Edits sent before measure_from are
// tracked (receivers) but give no latency samples.
class FanoutTracker {
 public:
  // servers: how many servers the bots spread over (bot i on server
  // i % servers); ticks are matched per server, and a receiver on another
  // server than the editor's is measured by the first change of the edited
  // chunks it receives after the edit was sent (within 3 s): a chunk
  // arriving again whole (chunk_arrived: a server resends what another
  // server changed) or an update at the edit's revision or later. Only
  // receivers holding the chunk at full resolution when the edit was sent
  // are measured (one that gets it whole later saw the edit in it), and an
  // edit that changed nothing the editor holds is measured nowhere.
  FanoutTracker(Clock::time_point run_start, Clock::time_point measure_from, int servers = 1);
  // Moves the start of measurement (a run that waits for every bot's join
  // measures from then on).
  void set_measure_from(Clock::time_point t) {
    std::lock_guard lock(mutex_);
    measure_from_ = t;
  }

  // Records the send time, calls send() (which returns the edit id, 0 when
  // the client refused), and registers the edit under that id. Holding the
  // lock across send() means the ack cannot be seen first.
  std::uint32_t send_edit(int bot, const Region& bounds, double edited_voxels,
                          const std::function<std::uint32_t()>& send);
  void edit_result(int bot, std::uint32_t edit_id, const EditOutcome& outcome, Clock::time_point t);
  void update_received(int bot, std::uint64_t tick, const std::vector<ChunkRevisionMsg>& revisions,
                       Clock::time_point t);
  // A chunk arrived whole at full resolution, or was released (several
  // servers only). Only a chunk arriving again at a bot that held it
  // counts: a first arrival is the bot's view reaching it, not an edit.
  void chunk_arrived(int bot, Vec3i chunk, Clock::time_point t);
  void chunk_released(int bot, Vec3i chunk);
  // A batch of a bot's holding changes at t, under one lock: a chunk now
  // held at full resolution arrived, any other was released (held coarser
  // now, or not at all).
  void holdings_changed(int bot, std::span<const HoldingChange> changes, Clock::time_point t);
  // The bot was welcomed by this server (its Welcome's server_id): a bot
  // not yet welcomed counts as on its entry server.
  void bot_on_server(int bot, std::uint32_t server_id);
  // Joins edits and updates of ticks first seen before now - horizon (every
  // tick when horizon is zero) and forgets them.
  void settle(Clock::time_point now, Clock::duration horizon);

  struct Totals {
    std::uint64_t edits_sent = 0, edits_acked = 0, edits_rejected = 0;
    std::uint64_t edits_measured = 0;        // acked, sent after measure_from, settled
    std::uint64_t receiver_pairs = 0;        // (edit, receiver) over measured edits
    double edited_voxel_receivers = 0;       // sum of edited voxels x receivers, measured edits
    std::map<std::string, std::uint64_t> reject_reasons;  // by reason_class
  };
  Totals totals() const;
  LatencyHistogram ack_ms() const;
  LatencyHistogram fanout_ms() const;
  // Receivers on another server than the editor's (several servers only).
  LatencyHistogram fanout_other_server_ms() const;
  // Per second of the run (by send time): samples for the timeline.
  std::vector<LatencyHistogram> fanout_by_second() const;
  std::vector<LatencyHistogram> ack_by_second() const;
  // Live: p99 of fan-out samples settled in the last few seconds.
  double recent_fanout_p99() const;

 private:
  // chunk_arrived and chunk_released under mutex_.
  void arrived_locked(int bot, Vec3i chunk, Clock::time_point t);
  void released_locked(int bot, Vec3i chunk);
  struct Edit {
    int bot = 0;
    Clock::time_point sent;
    Clock::time_point acked;  // once acknowledged
    std::vector<Vec3i> chunks;
    // Several servers: per chunk of `chunks`, the bots holding it at full
    // resolution when the edit was sent.
    std::vector<std::vector<int>> held_by;
    double voxels = 0;
  };
  struct Update {
    int bot;
    Vec3i chunk;
    Clock::time_point t;
    std::uint64_t revision;
  };
  // A chunk's change reaching a bot: an update (its new revision) or the
  // chunk arriving again whole (revision 0: not told).
  struct Arrival {
    int bot;
    Clock::time_point t;
    std::uint64_t revision;
  };
  struct Tick {
    Clock::time_point first_seen;
    std::vector<Edit> edits;
    std::vector<Update> updates;
  };
  static std::uint64_t key(int bot, std::uint32_t id) { return (std::uint64_t(std::uint32_t(bot)) << 32) | id; }
  // Under mutex_: the server a bot is on (its entry server's index, above
  // every server id, before its first Welcome).
  std::uint64_t server_of(int bot) const {
    auto it = server_of_bot_.find(bot);
    return it != server_of_bot_.end() ? it->second : (std::uint64_t{1} << 32) + static_cast<std::uint64_t>(bot % servers_);
  }
  // A server's tick, told apart from another server's same tick number
  // (server ids modulo 2^16).
  std::uint64_t tick_key(int bot, std::uint64_t tick) const {
    return ((server_of(bot) & 0xffff) << 48) | (tick & ((std::uint64_t{1} << 48) - 1));
  }
  // Under mutex_: the chunks of e's box (indices into e.chunks) its tick
  // (or, forwarded, its owner) changed, each with the revision it made (0:
  // not told); none when the editor held a chunk of the box and saw none
  // change (the edit changed nothing), all of them when the editor held none.
  std::vector<std::pair<std::size_t, std::uint64_t>> changed_by(const Edit& e, const Tick& tk) const;

  mutable std::mutex mutex_;
  Clock::time_point run_start_, measure_from_;
  std::unordered_map<std::uint64_t, Edit> in_flight_;
  std::map<std::uint64_t, Tick> ticks_;
  Totals totals_;
  LatencyHistogram ack_ms_, fanout_ms_, fanout_other_ms_;
  const int servers_;
  std::unordered_map<int, std::uint64_t> server_of_bot_;
  // Several servers: changes reaching the bots, by chunk, kept a while past
  // the settle horizon.
  std::unordered_map<Vec3i, std::vector<Arrival>, Vec3iHash> arrivals_;
  std::unordered_map<Vec3i, std::unordered_set<int>, Vec3iHash> held_full_;  // chunk -> bots holding it whole
  std::vector<LatencyHistogram> fanout_by_second_, ack_by_second_;
  std::vector<float> recent_;  // fan-out samples of the last settle rounds
};

struct Mismatch {
  int bot = 0;
  Vec3i chunk;
  std::uint64_t replica_revision = 0, server_revision = 0;
  std::string reason;
  bool final_check = false;
};

// Latency samples over the measured part of the run and per second of it
// (by the time each was taken). Two logs: keepalive round trips of every
// bot (Ping to Pong, ClientCounters::last_round_trip_ms; where one is long,
// bytes wait in a queue on one side or the other, whatever the world does)
// and the bots' own io lag (how late a 10 ms timer on their io threads
// fires: the bots process behind, which every figure it takes includes).
class LatencyLog {
 public:
  LatencyLog(Clock::time_point run_start, Clock::time_point measure_from)
      : run_start_(run_start), measure_from_(measure_from) {}
  void set_measure_from(Clock::time_point t) {
    std::lock_guard lock(mutex_);
    measure_from_ = t;
  }
  void add(Clock::time_point t, double ms);
  LatencyHistogram all() const;
  std::vector<LatencyHistogram> by_second() const;

 private:
  mutable std::mutex mutex_;
  Clock::time_point run_start_, measure_from_;
  LatencyHistogram all_;
  std::vector<LatencyHistogram> by_second_;
};

class MismatchLog {
 public:
  void add(const Mismatch& m);
  std::vector<Mismatch> all() const;
  std::size_t count() const;

 private:
  mutable std::mutex mutex_;
  std::vector<Mismatch> list_;
};

}  // namespace terrane::bots
