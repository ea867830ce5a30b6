// A bots run: connects a probe to learn the server's spawn and caps, starts
// the bots over the ramp-up on a shared io_context (a small thread pool),
// drives their behaviours from one driver thread every 100 ms, then drains
// edits, waits a quiet period, verifies every bot's whole full-resolution
// region against the server's hashes and builds the report.
// Thread-safety: run_bots is called from one thread and blocks for the run.
#pragma once

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "client/bots/bot.h"
#include "client/bots/options.h"
#include "client/bots/server_watch.h"
#include "client/bots/stats.h"

namespace terrane::bots {

struct TimelinePoint {
  double t_s = 0;  // end of the second, since the first connection
  int bots_connected = 0;
  double mb_per_s_in = 0, mb_per_s_out = 0;
  double edits_acked_per_s = 0;
  int joins = 0;  // bots whose full-resolution join completed in that second
  // Bytes the bots received in that second by message type (wire::Body),
  // all bots together.
  std::array<std::uint64_t, kMessageTypeCount> bytes_in_by_type{};
  LatencySummary fanout_ms, ack_ms;  // of edits sent in that second
  LatencySummary round_trip_ms;      // keepalive round trips answered in that second
  // With --server-metrics: the server since the previous point (its
  // scrapes, up to a second behind).
  std::optional<ServerInterval> server;
};

struct BotsReport {
  BotsOptions options;
  int bots = 0;
  double duration_s = 0;  // wall time from the first connection to the end of the final check
  std::uint64_t bytes_received = 0, bytes_sent = 0;
  std::uint64_t join_bytes_received = 0, steady_bytes_received = 0;
  std::uint64_t join_coarse_bytes = 0;  // summed over the bots whose coarse view completed
  // --chunk-cache: chunks the bots joined from and saved at the end, and the
  // cache's region files read back, damaged (removed) and written.
  std::uint64_t cache_chunks_loaded = 0, cache_chunks_saved = 0;
  std::uint64_t cache_regions_loaded = 0, cache_regions_damaged = 0, cache_regions_saved = 0;
  // The byte budget: what the bots that joined received after their join,
  // by cause (ByteCause), and their seconds connected since (BotResult's
  // steady_s, summed), so a cause's bytes per bot per second is its bytes
  // over steady_bot_s.
  std::array<std::uint64_t, kByteCauseCount> steady_bytes_by_cause{};
  double steady_bot_s = 0;
  // Steady bytes per bot per second, all causes (0 when no bot joined).
  double steady_bytes_per_bot_s() const;
  double bytes_per_non_empty_voxel = 0;  // mean over bots that completed their join
  LatencySummary join_coarse_ms, join_full_ms, edit_ack_ms, edit_fanout_ms;
  // Several servers: receivers on another server than the editor's (each
  // edited chunk arriving again there, whole).
  LatencySummary edit_fanout_other_server_ms;
  // Keepalive round trips (each bot's Ping every 5 s) answered while measured.
  LatencySummary round_trip_ms;
  // How late a 10 ms timer on the bots' io threads fired while measured:
  // the bots process behind (every latency above includes it).
  LatencySummary bots_io_lag_ms;
  std::uint64_t edits_sent = 0, edits_acked = 0, edits_rejected = 0, edits_measured = 0;
  std::map<std::string, std::uint64_t> reject_reasons;
  double receivers_per_edit = 0;
  std::uint64_t update_batch_bytes_steady = 0;
  double update_bytes_per_edited_voxel_per_receiver = 0;
  std::uint64_t replica_regions_checked = 0;
  std::vector<Mismatch> mismatches;
  std::uint64_t hash_unanswered = 0;
  std::uint64_t min_checks_during_run = 0;
  int unexpected_disconnects = 0;
  // Several servers: Redirects the bots followed, and how many bots each
  // server had at the end (by server id).
  std::uint64_t redirects = 0;
  // Full records' chunks taken from the bots' shared cache / packed anew
  // (--shared-chunks; both 0 when off).
  std::uint64_t shared_chunk_hits = 0, shared_chunk_misses = 0;
  // Mip and Estimate records found in the shared cache before they were
  // decoded / decoded and kept (DecodedMips::known_unit, intern_unit).
  std::uint64_t shared_mips_known = 0, shared_mips_decoded = 0;
  // Updates of shared chunks taken made by another bot / made by a bot
  // (client/shared_updates.h).
  std::uint64_t shared_update_hits = 0, shared_update_misses = 0;
  std::uint64_t shared_update_twins = 0;  // of the hits and adoptions: through a twin (SharedUpdates::Stats::twins)
  // The bots' replicas by part, summed over the bots at the end of the run
  // (before they leave; shared voxels count once in all), and the heap
  // bytes of the process's shared caches then.
  ReplicaMemory replica_memory;
  std::size_t shared_chunk_bytes = 0;
  std::map<std::uint32_t, int> bots_per_server;
  std::vector<std::pair<int, std::string>> disconnects;  // bot, reason
  int connect_failures = 0;
  std::string first_connect_error;
  int joins_incomplete = 0;
  std::uint64_t walk_steps = 0;
  std::array<std::uint64_t, 4> walk_blocked{};  // BotResult::walk_blocked, summed
  std::uint64_t teleports = 0;  // jumps of teleporting bots
  std::uint64_t edits_held_back = 0;  // due while 8 were unanswered, not sent (BotResult)
  int bots_at_hotspot = 0;      // hotspot bots that landed there
  std::array<MessageTypeCounters, kMessageTypeCount> by_message_type{};
  std::vector<TimelinePoint> timeline;
  // The server's own figures over the run (--server-metrics), else none.
  std::optional<ServerFigures> server;

  // Seconds from the first connection until every bot had joined (or the
  // join wait gave up); 0 when the run did not wait (--wait-joined 0).
  double joined_s = 0;
  bool edits_expected = false;  // the behaviour edits

  // The run's thresholds (options.thresholds) against its figures.
  std::vector<ThresholdResult> thresholds;

  // Why the run failed, one line each; empty when it ran soundly. A run
  // fails on a replica mismatch, an unexpected disconnect, a failed
  // connection, a bot that never completed its join, and a run whose bots
  // were to edit but none of whose edits was acknowledged.
  std::vector<std::string> failures() const;
  // Each broken threshold with its value: "fanout_p99<100 broken: 153.2".
  std::vector<std::string> broken_thresholds() const;
  bool passed() const { return failures().empty() && broken_thresholds().empty(); }
  // kExitFailed when the run failed, else kExitThresholds when a threshold
  // broke, else kExitPassed (thresholds.h).
  int exit_status() const;
  // Every metric a threshold can name (threshold_metrics()) -> its value
  // in this report.
  std::map<std::string, double> threshold_values() const;
  // The per-second metrics (threshold_metrics()'s per_second ones) of each
  // measured second of the timeline: those that start once the measurement
  // did (joined_s; every second when the run did not wait for joins), a
  // latency only in a second that had a sample, bytes per bot only while
  // bots were connected.
  std::vector<SecondValues> per_second_threshold_values() const;
  // The options' thresholds against this report's figures.
  std::vector<ThresholdResult> evaluate_own_thresholds() const {
    return evaluate_thresholds(options.thresholds, threshold_values(), per_second_threshold_values());
  }
};

// How a bot starts: where, walking or flying, editing or not, its seed.
struct BotPlan {
  int id = 0;  // of all o.bots, whatever the shard
  Vec3f start;
  Gait gait = Gait::kIdle;
  EditMode edits = EditMode::kNone;
  std::uint64_t seed = 0;
};
// The bots of o's shard (in_shard), in id order, each planned as when one
// process runs every bot: one random stream (o.seed) draws every bot's
// start and role in id order, and shards keep their own.
std::vector<BotPlan> plan_bots(const BotsOptions& o, Vec3f spawn);

struct Progress {
  double t_s = 0;
  int bots_connected = 0, bots_total = 0;
  double mb_per_s_in = 0, mb_per_s_out = 0, edits_per_s = 0, fanout_p99_ms = 0;
  std::size_t mismatches = 0;
};

// Returns false with *error when the server cannot be reached at all (the
// probe fails); everything else ends up in the report.
bool run_bots(const BotsOptions& options, const std::function<void(const Progress&)>& progress, BotsReport* report,
              std::string* error);

}  // namespace terrane::bots
