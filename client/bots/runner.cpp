#include "client/bots/runner.h"

#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <future>
#include <limits>
#include <random>
#include <thread>

#include "client/bots/bot.h"

namespace terrane::bots {

namespace {

constexpr auto kStep = std::chrono::milliseconds(100);
constexpr auto kLagProbe = std::chrono::milliseconds(10);
// Bots step in this many groups spread over each step, as a crowd of real
// players acts at times of its own: when every bot stepped at once, the
// edits of all of them reached the server in one burst every 100 ms, at a
// phase to its ticks that changed from run to run (and with it every
// latency measured).
constexpr int kStepPhases = 10;
constexpr auto kPhaseStep = kStep / kStepPhases;
// Fan-out is joined once a tick is this old: every receiver has had time
// to hear of it (a later batch would still be a valid sample, but rare).
constexpr auto kSettleHorizon = std::chrono::seconds(3);
constexpr auto kDrainTimeout = std::chrono::seconds(15);
constexpr auto kFinalCheckTimeout = std::chrono::seconds(30);

// One open file per bot plus the runtime's own.
void raise_open_file_limit(int bots) {
  rlimit lim{};
  if (getrlimit(RLIMIT_NOFILE, &lim) != 0) return;
  const rlim_t want = static_cast<rlim_t>(bots) + 256;
  if (lim.rlim_cur >= want) return;
  lim.rlim_cur = lim.rlim_max == RLIM_INFINITY ? want : std::min(want, lim.rlim_max);
  setrlimit(RLIMIT_NOFILE, &lim);
}

std::uint64_t splitmix(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

class IoPool {
 public:
  explicit IoPool(int threads) : work_(asio::make_work_guard(io_)) {
    for (int i = 0; i < threads; ++i) threads_.emplace_back([this] { io_.run(); });
  }
  ~IoPool() {
    work_.reset();
    for (auto& t : threads_) t.join();
  }
  asio::io_context& io() { return io_; }

 private:
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_;
  std::vector<std::thread> threads_;
};

}  // namespace

std::vector<BotPlan> plan_bots(const BotsOptions& o, Vec3f spawn) {
  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::vector<BotPlan> out;
  const float half = static_cast<float>(o.spread) / 2.0f;
  for (int i = 0; i < o.bots; ++i) {
    BotPlan p;
    p.id = i;
    p.start = Vec3f{spawn.x + (unit(rng) * 2.0f - 1.0f) * half, spawn.y, spawn.z + (unit(rng) * 2.0f - 1.0f) * half};
    switch (o.behavior) {
      case Behavior::kIdle: break;
      case Behavior::kWalk: p.gait = Gait::kWalk; break;
      case Behavior::kFly: p.gait = Gait::kFly; break;
      case Behavior::kDig: p.edits = EditMode::kDig; break;
      case Behavior::kBuild: p.edits = EditMode::kBuild; break;
      case Behavior::kTeleport:
        p.gait = Gait::kTeleport;
        p.edits = EditMode::kBoth;
        break;
      case Behavior::kHotspot:
        p.gait = Gait::kHotspot;
        p.edits = EditMode::kBoth;
        break;
      case Behavior::kMixed: {
        const float u = unit(rng);
        p.gait = u < 0.6f ? Gait::kWalk : (u < 0.9f ? Gait::kIdle : Gait::kFly);
        p.edits = EditMode::kBoth;
        break;
      }
    }
    p.seed = splitmix(o.seed * 1000003u + static_cast<std::uint64_t>(i));
    if (in_shard(o, i)) out.push_back(p);
  }
  return out;
}

bool run_bots(const BotsOptions& o, const std::function<void(const Progress&)>& progress, BotsReport* report,
              std::string* error) {
  raise_open_file_limit(o.bots);
  IoPool pool(io_threads(o));

  // A probe learns the spawn, the bounds and the server's caps. It joins
  // as the shard's first bot, before that bot does (bot_login).
  WelcomeMsg welcome;
  {
    ClientOptions po;
    po.host = o.host;
    po.port = o.port;
    BotLogin login = bot_login(o, o.shard_index);
    po.name = std::move(login.name);
    po.auth_token = std::move(login.token);
    po.io_context = &pool.io();
    po.state = ClientStateMsg{{0, 0, 0}, 32, 32};
    Client probe(po);
    std::string err;
    if (!probe.connect(&err)) {
      *error = err;
      return false;
    }
    probe.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, std::chrono::seconds(10));
    const auto w = probe.welcome();
    if (!w) {
      *error = "no Welcome from " + o.host + ":" + std::to_string(o.port) + ": " +
               (probe.closed() ? probe.disconnect_reason() : std::string("timed out"));
      return false;
    }
    welcome = *w;
    probe.disconnect();
  }
  // The server's figures cover the whole run, joins included.
  std::unique_ptr<ServerWatch> watch;
  if (o.metrics_port != 0) {
    watch = std::make_unique<ServerWatch>(o.metrics_host, o.metrics_port);
    if (std::string err; !watch->start(&err)) {
      *error = "--server-metrics: " + err;
      return false;
    }
  }

  RunContext ctx;
  ctx.options = &o;
  ctx.welcome = welcome;
  // The distances the server applies (client/view_coverage.h).
  const StreamedView asked = streamed_view(ClientStateMsg{{}, o.view_distance, o.full_res_radius}, welcome);
  ctx.view_distance = asked.view_distance;
  ctx.full_res_radius = asked.full_res_radius;
  ctx.spawn = o.spawn_set ? Vec3f{static_cast<float>(o.spawn.x) + 0.5f, static_cast<float>(o.spawn.y),
                                  static_cast<float>(o.spawn.z) + 0.5f}
                          : welcome.spawn;
  ctx.io = &pool.io();
  const auto t0 = Clock::now();
  const auto ramp = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.ramp_up_s));
  // Figures count from the end of the ramp-up, from the first connection
  // (--measure-from start) or, with a join wait, from the moment every bot
  // has joined (set below): until then nothing is measured, not even an
  // edit sent after the ramp-up and answered before the last join.
  auto measure_from = o.join_timeout_s > 0 ? Clock::time_point::max() : o.measure_from_start ? t0 : t0 + ramp;
  FanoutTracker fanout(t0, measure_from, std::max<int>(1, static_cast<int>(o.servers.size())));
  MismatchLog mismatches;
  LatencyLog round_trips(t0, measure_from);
  ctx.fanout = &fanout;
  ctx.round_trips = &round_trips;
  // The bots' own io lag: a timer every kLagProbe on their io threads (on
  // a strand of its own), sampled for how late it fires.
  LatencyLog io_lag(t0, measure_from);
  struct LagProbe {
    asio::strand<asio::io_context::executor_type> strand;
    asio::steady_timer timer;
    LatencyLog& log;
    bool stopped = false;  // on the strand
    void arm() {
      timer.async_wait([this](const asio::error_code& ec) {
        if (ec || stopped) return;
        const auto now = Clock::now();
        log.add(now, std::chrono::duration<double, std::milli>(now - timer.expiry()).count());
        timer.expires_at(std::max(timer.expiry() + kLagProbe, now));
        arm();
      });
    }
    // On the strand: no wait pending, no handler left to run, after it.
    void stop() {
      for (int round = 0; round < 2; ++round) {  // the second waits for the aborted wait's handler
        std::promise<void> done;
        asio::post(strand, [this, &done] {
          stopped = true;
          timer.cancel();
          done.set_value();
        });
        done.get_future().wait();
      }
    }
  };
  auto lag_strand = asio::make_strand(pool.io());
  LagProbe lag_probe{lag_strand, asio::steady_timer(lag_strand, kLagProbe), io_lag};
  asio::post(lag_strand, [&lag_probe] { lag_probe.arm(); });
  ctx.mismatches = &mismatches;
  if (const std::size_t shared = shared_chunks_for(o); shared > 0)
    ctx.shared_chunks = std::make_shared<DecodedChunks>(shared);
  if (!o.chunk_cache_dir.empty()) {
    auto cache = ChunkCache::open(o.chunk_cache_dir, std::uint64_t(o.chunk_cache_mb) << 20);
    if (!cache) {
      *error = "--chunk-cache: " + cache.error().message;
      return false;
    }
    ctx.chunk_cache = std::move(*cache);
  }
  ctx.run_start = t0;

  std::vector<std::unique_ptr<Bot>> bots;
  for (const BotPlan& p : plan_bots(o, ctx.spawn))
    bots.push_back(std::make_unique<Bot>(p.id, ctx, p.start, p.gait, p.edits, p.seed));
  // Bot i connects at i / bots of the ramp-up and steps in phase i mod
  // kStepPhases, whichever shard runs it.
  std::vector<std::vector<Bot*>> by_phase(kStepPhases);
  for (auto& b : bots) by_phase[static_cast<std::size_t>(b->index() % kStepPhases)].push_back(b.get());

  BotsReport& r = *report;
  r = BotsReport{};
  r.options = o;
  r.edits_expected = behavior_edits(o.behavior);
  r.bots = static_cast<int>(bots.size());
  std::size_t next_bot = 0;
  std::uint64_t prev_in = 0, prev_out = 0, prev_acked = 0, update_bytes_at_measure = 0;
  std::array<std::uint64_t, kMessageTypeCount> prev_in_by_type{};
  std::vector<char> seen_joined(bots.size(), 0);  // by position in bots: its join was counted in a second
  bool measured_snapshot = ramp.count() == 0 || o.measure_from_start;
  auto next_second = t0 + std::chrono::seconds(1);
  auto sum_counters = [&](std::uint64_t* in, std::uint64_t* out, std::uint64_t* updates, int* live,
                          std::array<std::uint64_t, kMessageTypeCount>* in_by_type, int* joins) {
    *in = *out = *updates = 0;
    *live = *joins = 0;
    in_by_type->fill(0);
    for (std::size_t i = 0; i < bots.size(); ++i) {
      const auto& b = bots[i];
      if (!b->connected()) continue;
      const ClientCounters k = b->counters();
      *in += k.bytes_in;
      *out += k.bytes_out;
      *updates += k.by_message_type[static_cast<std::size_t>(wire::Body::UpdateBatch)].bytes_in;
      for (std::size_t t = 0; t < kMessageTypeCount; ++t) (*in_by_type)[t] += k.by_message_type[t].bytes_in;
      if (!b->closed()) ++*live;
      if (!seen_joined[i] && b->joined()) {
        seen_joined[i] = 1;
        ++*joins;
      }
    }
  };
  auto once_a_second = [&](Clock::time_point now) {
    if (now < next_second) return;
    next_second += std::chrono::seconds(1);
    std::uint64_t in = 0, out = 0, updates = 0;
    std::array<std::uint64_t, kMessageTypeCount> in_by_type{};
    int live = 0, joins = 0;
    sum_counters(&in, &out, &updates, &live, &in_by_type, &joins);
    if (!measured_snapshot && now >= measure_from) {
      update_bytes_at_measure = updates;
      measured_snapshot = true;
    }
    fanout.settle(now, kSettleHorizon);
    const auto totals = fanout.totals();
    TimelinePoint p;
    p.t_s = std::chrono::duration<double>(now - t0).count();
    p.bots_connected = live;
    p.mb_per_s_in = static_cast<double>(in - prev_in) / 1e6;
    p.mb_per_s_out = static_cast<double>(out - prev_out) / 1e6;
    p.edits_acked_per_s = static_cast<double>(totals.edits_acked - prev_acked);
    p.joins = joins;
    // A bot that left takes its bytes out of the sums: such a second counts
    // no bytes of a type rather than a negative amount.
    for (std::size_t t = 0; t < kMessageTypeCount; ++t)
      p.bytes_in_by_type[t] = in_by_type[t] > prev_in_by_type[t] ? in_by_type[t] - prev_in_by_type[t] : 0;
    prev_in_by_type = in_by_type;
    if (watch) p.server = watch->next_interval();
    prev_in = in;
    prev_out = out;
    prev_acked = totals.edits_acked;
    r.timeline.push_back(p);
    if (progress)
      progress(Progress{p.t_s, live, static_cast<int>(bots.size()), p.mb_per_s_in, p.mb_per_s_out, p.edits_acked_per_s,
                        fanout.recent_fanout_p99(), mismatches.count()});
  };

  // Active phase: connect over the ramp-up, step every bot every 100 ms
  // (bot i in phase i mod kStepPhases, one phase every 10 ms).
  // With a join wait, the duration starts once every bot has joined.
  const auto duration = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.duration_s));
  auto end_active = t0 + duration;
  bool joins_done = o.join_timeout_s <= 0;
  const auto join_deadline =
      t0 + ramp + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.join_timeout_s));
  auto next_step = t0;
  std::size_t phase = 0;
  bool joins_marked = false;
  for (auto now = Clock::now(); !joins_done || now < end_active; now = Clock::now()) {
    while (next_bot < bots.size() &&
           now >= t0 + ramp * static_cast<Clock::rep>(bots[next_bot]->index()) / static_cast<Clock::rep>(o.bots)) {
      Bot& b = *bots[next_bot++];
      if (!b.connect()) {
        ++r.connect_failures;
        if (r.first_connect_error.empty()) r.first_connect_error = b.result().connect_error;
      }
    }
    for (Bot* b : by_phase[phase]) b->step(now, true);
    phase = (phase + 1) % static_cast<std::size_t>(kStepPhases);
    once_a_second(now);
    if (watch && !joins_marked && next_bot == bots.size() && phase == 0 &&
        std::all_of(bots.begin(), bots.end(), [](const auto& b) { return b->join_settled(); })) {
      joins_marked = true;  // the server's cost of the joins ends here (JoinCost)
      watch->mark_joined();
    }
    if (!joins_done && next_bot == bots.size() && phase == 0) {
      // A bot whose connect failed is settled too: waiting for it held a
      // run up for the whole --wait-joined.
      const bool all = std::all_of(bots.begin(), bots.end(), [](const auto& b) { return b->join_settled(); });
      if (all || now >= join_deadline) {
        joins_done = true;
        r.joined_s = std::chrono::duration<double>(now - t0).count();
        end_active = now + duration;
        // Latency and steady-state figures count from here: joins under way
        // are the ramp-up, reported as joined_s.
        fanout.set_measure_from(now);
        round_trips.set_measure_from(now);
        io_lag.set_measure_from(now);
        measure_from = now;
        measured_snapshot = false;
      }
    }
    next_step = std::max<Clock::time_point>(next_step + kPhaseStep, Clock::now());
    std::this_thread::sleep_until(next_step);
  }
  // Bots not connected by now (a ramp-up as long as the run) connect late.
  for (; next_bot < bots.size(); ++next_bot)
    if (!bots[next_bot]->connect()) ++r.connect_failures;

  // Drain: every edit acknowledged (or rejected), then a quiet period.
  auto wait_phase = [&](Clock::duration limit, const std::function<bool()>& done) {
    const auto until = Clock::now() + limit;
    for (auto now = Clock::now(); now < until && !done(); now = Clock::now()) {
      for (auto& b : bots) b->step(now, false);
      once_a_second(now);
      std::this_thread::sleep_for(kStep);
    }
  };
  wait_phase(kDrainTimeout, [&] {
    return std::all_of(bots.begin(), bots.end(),
                       [](const auto& b) { return b->closed() || b->outstanding_edits() == 0; });
  });
  wait_phase(std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.quiet_s)),
             [] { return false; });
  // Final check: each bot's whole full-resolution region.
  for (auto& b : bots) b->start_final_check();
  wait_phase(kFinalCheckTimeout, [&] {
    const auto now = Clock::now();
    bool any = false;
    for (auto& b : bots) any = b->checks_pending(now) || any;
    return !any;
  });
  fanout.settle(Clock::now(), Clock::duration::zero());
  lag_probe.stop();
  std::uint64_t ub_end = 0;
  {
    std::uint64_t in = 0, out = 0;
    std::array<std::uint64_t, kMessageTypeCount> in_by_type{};
    int live = 0, joins = 0;
    sum_counters(&in, &out, &ub_end, &live, &in_by_type, &joins);
  }
  r.duration_s = std::chrono::duration<double>(Clock::now() - t0).count();
  if (watch) {
    watch->stop();
    r.server = watch->figures();
  }
  for (auto& b : bots)
    if (b->connected()) r.replica_memory += b->replica_memory();
  for (auto& b : bots) b->finish();

  // --- the report ----------------------------------------------------------
  LatencyHistogram coarse, full;
  double bpv_sum = 0;
  int bpv_n = 0;
  r.min_checks_during_run = std::numeric_limits<std::uint64_t>::max();
  for (std::size_t i = 0; i < bots.size(); ++i) {
    const BotResult& br = bots[i]->result();
    if (!br.connected) continue;
    const ClientCounters& k = br.counters;
    r.redirects += k.redirects;
    ++r.bots_per_server[br.server_id];
    r.bytes_received += k.bytes_in;
    r.bytes_sent += k.bytes_out;
    r.cache_chunks_loaded += k.cache_chunks_loaded;
    r.cache_chunks_saved += k.cache_chunks_saved;
    for (std::size_t t = 0; t < kMessageTypeCount; ++t) {
      r.by_message_type[t].frames_in += k.by_message_type[t].frames_in;
      r.by_message_type[t].bytes_in += k.by_message_type[t].bytes_in;
      r.by_message_type[t].frames_out += k.by_message_type[t].frames_out;
      r.by_message_type[t].bytes_out += k.by_message_type[t].bytes_out;
    }
    if (br.join_coarse_ms) {
      coarse.record(*br.join_coarse_ms);
      r.join_coarse_bytes += br.join_coarse_bytes;
    }
    if (br.join_full_ms) {
      full.record(*br.join_full_ms);
      r.join_bytes_received += br.join_bytes;
      for (std::size_t c = 0; c < kByteCauseCount; ++c)
        r.steady_bytes_by_cause[c] += k.bytes_in_by_cause[c] - std::min(k.bytes_in_by_cause[c], br.join_bytes_by_cause[c]);
      r.steady_bot_s += br.steady_s;
      if (br.join_non_empty_voxels > 0) {
        bpv_sum += static_cast<double>(br.join_bytes) / static_cast<double>(br.join_non_empty_voxels);
        ++bpv_n;
      }
    } else {
      ++r.joins_incomplete;
    }
    r.replica_regions_checked += br.hash_checked;
    r.hash_unanswered += br.hash_unanswered;
    r.walk_steps += br.walk_steps;
    r.teleports += br.teleports;
    r.edits_held_back += br.edits_held_back;
    r.bots_at_hotspot += br.at_hotspot ? 1 : 0;
    for (std::size_t w = 0; w < r.walk_blocked.size(); ++w) r.walk_blocked[w] += br.walk_blocked[w];
    r.min_checks_during_run = std::min<std::uint64_t>(r.min_checks_during_run, static_cast<std::uint64_t>(br.checks_during_run));
    if (br.unexpected_disconnect) {
      ++r.unexpected_disconnects;
      r.disconnects.emplace_back(bots[i]->index(), br.disconnect_reason);
    }
  }
  if (r.min_checks_during_run == std::numeric_limits<std::uint64_t>::max()) r.min_checks_during_run = 0;
  r.steady_bytes_received = r.bytes_received - std::min(r.bytes_received, r.join_bytes_received);
  r.bytes_per_non_empty_voxel = bpv_n > 0 ? bpv_sum / bpv_n : 0;
  r.join_coarse_ms = summarize(coarse);
  r.join_full_ms = summarize(full);
  r.edit_ack_ms = summarize(fanout.ack_ms());
  r.edit_fanout_ms = summarize(fanout.fanout_ms());
  r.edit_fanout_other_server_ms = summarize(fanout.fanout_other_server_ms());
  r.round_trip_ms = summarize(round_trips.all());
  r.bots_io_lag_ms = summarize(io_lag.all());
  if (ctx.chunk_cache) {
    const ChunkCacheCounters c = ctx.chunk_cache->counters();
    r.cache_regions_loaded = c.regions_loaded;
    r.cache_regions_damaged = c.regions_damaged;
    r.cache_regions_saved = c.regions_saved;
  }
  if (ctx.shared_chunks) {
    const DecodedChunks::Stats s = ctx.shared_chunks->stats();
    r.shared_chunk_hits = s.hits;
    r.shared_chunk_misses = s.misses;
    r.shared_chunk_bytes += s.bytes;
    const DecodedMips::Stats m = ctx.shared_chunks->mips().stats();
    r.shared_mips_known = m.known_units;
    r.shared_mips_decoded = m.units_kept;
    const SharedUpdates::Stats u = ctx.shared_chunks->updates().stats();
    r.shared_update_hits = u.hits;
    r.shared_update_misses = u.misses;
    r.shared_update_twins = u.twins;
    r.shared_chunk_bytes += u.bytes;
  }
  const auto totals = fanout.totals();
  r.edits_sent = totals.edits_sent;
  r.edits_acked = totals.edits_acked;
  r.edits_rejected = totals.edits_rejected;
  r.edits_measured = totals.edits_measured;
  r.reject_reasons = totals.reject_reasons;
  r.receivers_per_edit =
      totals.edits_measured > 0 ? static_cast<double>(totals.receiver_pairs) / static_cast<double>(totals.edits_measured) : 0;
  r.update_batch_bytes_steady = ub_end - std::min(ub_end, update_bytes_at_measure);
  r.update_bytes_per_edited_voxel_per_receiver =
      totals.edited_voxel_receivers > 0 ? static_cast<double>(r.update_batch_bytes_steady) / totals.edited_voxel_receivers
                                        : 0;
  r.mismatches = mismatches.all();
  const auto fan_s = fanout.fanout_by_second(), ack_s = fanout.ack_by_second(), rtt_s = round_trips.by_second();
  for (std::size_t s = 0; s < r.timeline.size(); ++s) {
    if (s < fan_s.size()) r.timeline[s].fanout_ms = summarize(fan_s[s]);
    if (s < ack_s.size()) r.timeline[s].ack_ms = summarize(ack_s[s]);
    if (s < rtt_s.size()) r.timeline[s].round_trip_ms = summarize(rtt_s[s]);
  }
  r.thresholds = r.evaluate_own_thresholds();
  return true;
}

std::vector<std::string> BotsReport::broken_thresholds() const {
  std::vector<std::string> out;
  for (const ThresholdResult& t : thresholds) {
    if (t.passed) continue;
    char value[64];
    std::snprintf(value, sizeof value, "%.6g", t.value);
    if (!t.threshold.per_second) {
      out.push_back("threshold " + t.threshold.expression + " broken: " + t.threshold.metric + " = " + value);
      continue;
    }
    char when[96];
    std::snprintf(when, sizeof when, " in %zu of %zu seconds, the worst ending at %.0f s", t.seconds_broken, t.seconds,
                  t.worst_t_s);
    out.push_back("threshold " + t.threshold.expression + " broken: " + t.threshold.metric + " = " + value + when);
  }
  return out;
}

int BotsReport::exit_status() const {
  if (!failures().empty()) return kExitFailed;
  return broken_thresholds().empty() ? kExitPassed : kExitThresholds;
}

std::map<std::string, double> BotsReport::threshold_values() const {
  const auto pct = [](std::uint64_t part, std::uint64_t whole) {
    return whole > 0 ? 100.0 * static_cast<double>(part) / static_cast<double>(whole) : 0.0;
  };
  const double bot_seconds = static_cast<double>(bots) * duration_s;
  return {
      {"fanout_p50", edit_fanout_ms.p50},
      {"fanout_p95", edit_fanout_ms.p95},
      {"fanout_p99", edit_fanout_ms.p99},
      {"fanout_max", edit_fanout_ms.max},
      {"fanout_other_server_p99", edit_fanout_other_server_ms.p99},
      {"ack_p50", edit_ack_ms.p50},
      {"ack_p95", edit_ack_ms.p95},
      {"ack_p99", edit_ack_ms.p99},
      {"ack_max", edit_ack_ms.max},
      {"join_coarse_p50", join_coarse_ms.p50},
      {"join_coarse_p95", join_coarse_ms.p95},
      {"join_coarse_p99", join_coarse_ms.p99},
      {"join_full_p50", join_full_ms.p50},
      {"join_full_p95", join_full_ms.p95},
      {"join_full_p99", join_full_ms.p99},
      {"round_trip_p99", round_trip_ms.p99},
      {"io_lag_p99", bots_io_lag_ms.p99},
      {"mismatches", static_cast<double>(mismatches.size())},
      {"disconnects", static_cast<double>(unexpected_disconnects)},
      {"connect_failures", static_cast<double>(connect_failures)},
      {"joins_incomplete", static_cast<double>(joins_incomplete)},
      {"edits_acked", static_cast<double>(edits_acked)},
      {"rejected_pct", pct(edits_rejected, edits_sent)},
      {"bytes_per_bot_s", bot_seconds > 0 ? static_cast<double>(bytes_received) / bot_seconds : 0.0},
      {"steady_bytes_per_bot_s", steady_bytes_per_bot_s()},
      {"hash_unanswered", static_cast<double>(hash_unanswered)},
  };
}

std::vector<SecondValues> BotsReport::per_second_threshold_values() const {
  std::vector<SecondValues> out;
  for (const TimelinePoint& p : timeline) {
    if (p.t_s - 1.0 < joined_s) continue;  // (a second that began before the measurement)
    SecondValues s;
    s.t_s = p.t_s;
    if (p.fanout_ms.count > 0) {
      s.values["fanout_p50"] = p.fanout_ms.p50;
      s.values["fanout_p95"] = p.fanout_ms.p95;
      s.values["fanout_p99"] = p.fanout_ms.p99;
      s.values["fanout_max"] = p.fanout_ms.max;
    }
    if (p.ack_ms.count > 0) {
      s.values["ack_p50"] = p.ack_ms.p50;
      s.values["ack_p95"] = p.ack_ms.p95;
      s.values["ack_p99"] = p.ack_ms.p99;
      s.values["ack_max"] = p.ack_ms.max;
    }
    if (p.round_trip_ms.count > 0) s.values["round_trip_p99"] = p.round_trip_ms.p99;
    if (p.bots_connected > 0) s.values["bytes_per_bot_s"] = p.mb_per_s_in * 1e6 / p.bots_connected;
    out.push_back(std::move(s));
  }
  return out;
}

double BotsReport::steady_bytes_per_bot_s() const {
  if (steady_bot_s <= 0) return 0;
  std::uint64_t all = 0;
  for (const std::uint64_t b : steady_bytes_by_cause) all += b;
  return static_cast<double>(all) / steady_bot_s;
}

std::vector<std::string> BotsReport::failures() const {
  std::vector<std::string> out;
  if (!mismatches.empty()) out.push_back(std::to_string(mismatches.size()) + " replica mismatches");
  if (unexpected_disconnects > 0)
    out.push_back(std::to_string(unexpected_disconnects) + " bots were disconnected unexpectedly");
  if (connect_failures > 0)
    out.push_back(std::to_string(connect_failures) + " bots could not connect: " + first_connect_error);
  if (joins_incomplete > 0)
    out.push_back(std::to_string(joins_incomplete) + " of " + std::to_string(bots) +
                  " bots never completed their join (coarse view and full-resolution region)");
  if (edits_expected && edits_acked == 0)
    out.push_back("the bots were to edit, but no edit was acknowledged (" + std::to_string(edits_sent) + " sent, " +
                  std::to_string(edits_rejected) + " rejected)");
  return out;
}

}  // namespace terrane::bots
