#include "client/bots/merge.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <map>
#include <set>

#include "client/bots/report.h"

namespace terrane::bots {

namespace {

using Flat = std::map<std::string, std::string>;

// Reads typed values from a flattened report; the first error sticks and
// names its key.
class FlatReader {
 public:
  explicit FlatReader(const Flat& flat) : f_(flat) {}
  const std::string& error() const { return err_; }
  bool has(const std::string& key) const { return f_.count(key) != 0; }

  double number(const std::string& key) { return parsed<double>(key, "a number"); }
  std::uint64_t whole(const std::string& key) { return parsed<std::uint64_t>(key, "a whole number"); }
  int integer(const std::string& key) { return parsed<int>(key, "an integer"); }
  // An integer in [lo, hi]: a count of bots or a bot's id, which the
  // merge adds up or lists (a file is input).
  int integer(const std::string& key, int lo, int hi) {
    const int v = integer(key);
    if (v < lo || v > hi)
      return fail(key, std::to_string(v) + " is not in " + std::to_string(lo) + ".." + std::to_string(hi)), 0;
    return v;
  }
  std::string text(const std::string& key, const std::string& otherwise = "") {
    const auto it = f_.find(key);
    return it == f_.end() ? otherwise : it->second;
  }
  bool flag(const std::string& key) { return text(key) == "true"; }
  // null (or absent) -> none; "+Inf" -> infinity (json_opt in report.cpp).
  std::optional<double> optional(const std::string& key) {
    const std::string v = text(key, "null");
    if (v == "null") return std::nullopt;
    if (v == "+Inf") return std::numeric_limits<double>::infinity();
    return number(key);
  }
  // {p50, p95, p99, max, count, histogram}: the summary of its histogram.
  LatencySummary latency(const std::string& key) {
    LatencyHistogram h;
    if (has(key + ".histogram.sub_buckets")) {
      if (auto e = histogram_from_flat(f_, key + ".histogram", &h); !e.empty() && err_.empty()) err_ = e;
    } else if (whole(key + ".count") != 0) {
      fail(key, "has no histogram (written by a terrane-bots older than mergeable reports)");
    }
    if (err_.empty() && h.count() != whole(key + ".count"))
      fail(key + ".count", "differs from its histogram's (" + std::to_string(h.count()) + ")");
    return summarize(h);
  }
  // The keys under prefix + "." (one level), in order.
  std::vector<std::string> children(const std::string& prefix) const {
    std::vector<std::string> out;
    const std::string p = prefix + ".";
    for (auto it = f_.lower_bound(p); it != f_.end() && it->first.compare(0, p.size(), p) == 0; ++it) {
      const std::string rest = it->first.substr(p.size());
      const std::string child = rest.substr(0, rest.find('.'));
      if (out.empty() || out.back() != child) out.push_back(child);
    }
    return out;
  }
  // The length of the array at prefix whose elements hold field.
  std::size_t length(const std::string& prefix, const std::string& field) const {
    std::size_t n = 0;
    while (has(prefix + "." + std::to_string(n) + (field.empty() ? "" : "." + field))) ++n;
    return n;
  }
  void fail(const std::string& key, const std::string& what) {
    if (err_.empty()) err_ = key + ": " + what;
  }

 private:
  // The value at key as a T (the whole text, std::from_chars); 0 and the
  // error when it is missing or not one.
  template <typename T>
  T parsed(const std::string& key, const char* what) {
    const auto it = f_.find(key);
    if (it == f_.end()) return fail(key, "missing"), T{};
    T v{};
    auto [p, ec] = std::from_chars(it->second.data(), it->second.data() + it->second.size(), v);
    if (ec != std::errc() || p != it->second.data() + it->second.size())
      return fail(key, "'" + it->second + "' is not " + what), T{};
    return v;
  }

  const Flat& f_;
  std::string err_;
};

std::string read_options(FlatReader& in, BotsOptions* o) {
  OptionValues v;
  auto put = [&](const char* option, const std::string& key) {
    if (in.has("scenario." + key)) v.emplace(option, std::make_pair(in.text("scenario." + key), "scenario." + key));
  };
  put("connect", "connect");
  put("bots", "bots");
  put("duration", "duration");
  put("behavior", "behavior");
  if (in.has("scenario.spawn.0"))
    v.emplace("spawn", std::make_pair(in.text("scenario.spawn.0") + "," + in.text("scenario.spawn.1") + "," +
                                          in.text("scenario.spawn.2"),
                                      std::string("scenario.spawn")));
  put("spread", "spread");
  put("view-distance", "view_distance");
  put("full-res-radius", "full_res_radius");
  put("ramp-up", "ramp_up");
  put("seed", "seed");
  put("edit-interval", "edit_interval");
  put("edit-radius", "edit_radius");
  put("latency-ms", "latency_ms");
  put("bandwidth-kbps", "bandwidth_kbps");
  put("hash-checks", "hash_checks");
  put("threads", "threads");
  put("wait-joined", "wait_joined");
  put("measure-from", "measure_from");
  put("shard", "shard");
  put("preset", "preset");
  put("edit-shape", "edit_shape");
  put("teleport-interval", "teleport_interval");
  put("teleport-distance", "teleport_distance");
  for (std::size_t i = 0; i < in.length("thresholds", "expression"); ++i) {
    const std::string key = "thresholds." + std::to_string(i) + ".expression";
    v.emplace("threshold", std::make_pair(in.text(key), key));
  }
  return apply_option_values(v, o);
}

ServerInterval read_interval(FlatReader& in, const std::string& k) {
  ServerInterval s;
  s.cpu_share = in.number(k + ".cpu_share");
  s.edits_applied = in.whole(k + ".edits_applied");
  s.tick_ms_mean = in.optional(k + ".tick_ms_mean");
  s.commit_ms_mean = in.optional(k + ".commit_ms_mean");
  s.edit_ack_ms_mean = in.optional(k + ".edit_ack_ms_mean");
  s.edit_ack_p99_ms = in.optional(k + ".edit_ack_p99_ms_bound");
  s.tick_ms_max = in.optional(k + ".tick_ms_max_bound");
  s.commit_ms_max = in.optional(k + ".commit_ms_max_bound");
  s.fanout_ms_max = in.optional(k + ".fanout_ms_max_bound");
  s.ticks_late = in.whole(k + ".ticks_late");
  // Added later: absent from older reports (none).
  s.tick_p99_ms = in.optional(k + ".tick_p99_ms_bound");
  if (in.text(k + ".rss_bytes", "null") != "null") s.rss_bytes = in.whole(k + ".rss_bytes");
  if (in.text(k + ".send_queue_bytes", "null") != "null") s.send_queue_bytes = in.whole(k + ".send_queue_bytes");
  return s;
}

ServerFigures read_server(FlatReader& in) {
  const std::string k = "server_counters";
  ServerFigures f;
  f.wall_s = in.number(k + ".wall_s");
  f.cpu_s = in.number(k + ".cpu_s");
  f.rss_peak = in.whole(k + ".rss_peak_bytes");
  f.edits_applied = in.whole(k + ".edits_applied");
  f.edits_rejected = in.whole(k + ".edits_rejected");
  f.ticks = in.whole(k + ".ticks");
  f.ticks_late = in.whole(k + ".ticks_late");
  f.disconnects = in.whole(k + ".disconnects");
  f.tick_p99_ms = in.optional(k + ".tick_p99_ms_bound");
  f.commit_p99_ms = in.optional(k + ".commit_p99_ms_bound");
  f.fanout_p99_ms = in.optional(k + ".fanout_p99_ms_bound");
  f.edit_ack_mean_ms = in.optional(k + ".edit_ack_mean_ms");
  f.edit_ack_p99_ms = in.optional(k + ".edit_ack_p99_ms_bound");
  f.stream_gate_closings = in.whole(k + ".stream_gate_closings");
  f.stream_gate_closed_s = in.number(k + ".stream_gate_closed_s");
  f.scrapes = in.integer(k + ".scrapes");
  f.scrape_errors = in.integer(k + ".scrape_errors");
  if (in.has(k + ".joins.cpu_s")) {
    JoinCost c;
    c.wall_s = in.number(k + ".joins.wall_s");
    c.cpu_s = in.number(k + ".joins.cpu_s");
    c.records = in.whole(k + ".joins.records");
    c.stream_bytes = in.whole(k + ".joins.stream_bytes");
    f.joins = c;
  }
  for (const std::string& type : in.children(k + ".sent_by_type"))
    f.sent_by_type[type] = {in.whole(k + ".sent_by_type." + type + ".frames"),
                            in.whole(k + ".sent_by_type." + type + ".bytes")};
  return f;
}

}  // namespace

std::string report_from_json(const std::string& text, BotsReport* out) {
  Flat flat;
  if (auto e = flatten_json(text, &flat); !e.empty()) return e;
  FlatReader in(flat);
  if (!in.has("bots") || !in.has("edit_fanout_ms.count")) return "not a terrane-bots report (no bots / edit_fanout_ms)";
  BotsReport r;
  if (auto e = read_options(in, &r.options); !e.empty()) return e;
  const BotsOptions& o = r.options;
  r.edits_expected = behavior_edits(o.behavior);
  r.joined_s = in.number("joined_s");
  // Every count of bots within the part's own: their sums stay within o.bots.
  r.bots = in.integer("bots", 0, shard_bots(o));
  r.duration_s = in.number("duration_s");
  r.bytes_received = in.whole("bytes_received");
  r.bytes_sent = in.whole("bytes_sent");
  r.join_bytes_received = in.whole("join_bytes_received");
  r.join_coarse_bytes = in.whole("join_coarse_bytes");
  r.steady_bytes_received = in.whole("steady_bytes_received");
  // The byte budget was added later: absent from older reports (zeros).
  if (in.has("steady_bot_s")) {
    r.steady_bot_s = in.number("steady_bot_s");
    if (!(r.steady_bot_s >= 0 && r.steady_bot_s < 1e12)) in.fail("steady_bot_s", "is not a count of seconds");
    for (std::size_t c = 0; c < kByteCauseCount; ++c)
      r.steady_bytes_by_cause[c] = in.whole(std::string("steady_bytes_by_cause.") + byte_cause_name(c));
  }
  r.bytes_per_non_empty_voxel = in.number("bytes_per_non_empty_voxel");
  r.join_coarse_ms = in.latency("join_coarse_ms");
  r.join_full_ms = in.latency("join_full_ms");
  r.joins_incomplete = in.integer("joins_incomplete", 0, r.bots);
  r.edit_ack_ms = in.latency("edit_ack_ms");
  r.edit_fanout_ms = in.latency("edit_fanout_ms");
  r.edit_fanout_other_server_ms = in.latency("edit_fanout_other_server_ms");
  r.round_trip_ms = in.latency("round_trip_ms");
  r.bots_io_lag_ms = in.latency("bots_io_lag_ms");
  r.redirects = in.whole("redirects");
  r.shared_chunk_hits = in.whole("shared_chunk_hits");
  r.shared_chunk_misses = in.whole("shared_chunk_misses");
  r.shared_mips_known = in.whole("shared_mips_known");
  r.shared_mips_decoded = in.whole("shared_mips_decoded");
  r.shared_update_hits = in.whole("shared_update_hits");
  r.shared_update_misses = in.whole("shared_update_misses");
  r.shared_update_twins = in.whole("shared_update_twins");
  for (const std::string& id : in.children("bots_per_server")) {
    std::uint32_t server = 0;
    auto [p, ec] = std::from_chars(id.data(), id.data() + id.size(), server);
    if (ec != std::errc() || p != id.data() + id.size()) in.fail("bots_per_server." + id, "not a server id");
    r.bots_per_server[server] = in.integer("bots_per_server." + id, 0, r.bots);
  }
  r.edits_sent = in.whole("edits_sent");
  r.edits_acked = in.whole("edits_acked");
  r.edits_rejected = in.whole("edits_rejected");
  for (const std::string& reason : in.children("reject_reasons"))
    r.reject_reasons[reason] = in.whole("reject_reasons." + reason);
  r.edits_measured = in.whole("edits_measured");
  r.receivers_per_edit = in.number("receivers_per_edit");
  r.update_batch_bytes_steady = in.whole("update_batch_bytes_steady");
  r.update_bytes_per_edited_voxel_per_receiver = in.number("update_bytes_per_edited_voxel_per_receiver");
  r.replica_regions_checked = in.whole("replica_regions_checked");
  for (std::size_t i = 0; i < in.length("mismatches", "bot"); ++i) {
    const std::string k = "mismatches." + std::to_string(i);
    Mismatch m;
    m.bot = in.integer(k + ".bot", 0, o.bots - 1);
    m.chunk = {in.integer(k + ".chunk.0"), in.integer(k + ".chunk.1"), in.integer(k + ".chunk.2")};
    m.replica_revision = in.whole(k + ".replica_revision");
    m.server_revision = in.whole(k + ".server_revision");
    m.final_check = in.flag(k + ".final_check");
    m.reason = in.text(k + ".reason");
    r.mismatches.push_back(m);
  }
  if (in.error().empty() && in.whole("replica_mismatches") != r.mismatches.size())
    in.fail("replica_mismatches", "differs from the mismatches listed");
  r.hash_unanswered = in.whole("hash_unanswered");
  r.min_checks_during_run = in.whole("min_hash_checks_during_run");
  r.unexpected_disconnects = in.integer("unexpected_disconnects", 0, r.bots);
  for (std::size_t i = 0; i < in.length("disconnects", "bot"); ++i) {
    const std::string k = "disconnects." + std::to_string(i);
    r.disconnects.emplace_back(in.integer(k + ".bot", 0, o.bots - 1), in.text(k + ".reason"));
  }
  r.connect_failures = in.integer("connect_failures", 0, r.bots);
  r.first_connect_error = in.text("first_connect_error");
  r.walk_steps = in.whole("walk_steps");
  r.teleports = in.whole("teleports");
  r.edits_held_back = in.whole("edits_held_back");
  r.bots_at_hotspot = in.integer("bots_at_hotspot", 0, r.bots);
  const char* const refused[] = {"outside_area", "not_full_resolution", "too_steep", "obstacle"};
  for (std::size_t w = 0; w < r.walk_blocked.size(); ++w)
    r.walk_blocked[w] = in.whole(std::string("walk_refused.") + refused[w]);
  if (in.text("server_counters", "") != "null") r.server = read_server(in);
  for (std::size_t t = 0; t < kMessageTypeCount; ++t) {
    const std::string k = std::string("by_message_type.") + message_type_name(t);
    if (!in.has(k + ".frames_in")) continue;
    r.by_message_type[t] = {in.whole(k + ".frames_in"), in.whole(k + ".bytes_in"), in.whole(k + ".frames_out"),
                            in.whole(k + ".bytes_out")};
  }
  for (std::size_t i = 0; i < in.length("timeline", "t_s"); ++i) {
    const std::string k = "timeline." + std::to_string(i);
    TimelinePoint p;
    p.t_s = in.number(k + ".t_s");
    p.bots_connected = in.integer(k + ".bots", 0, r.bots);
    p.mb_per_s_in = in.number(k + ".mb_per_s_in");
    p.mb_per_s_out = in.number(k + ".mb_per_s_out");
    p.edits_acked_per_s = in.number(k + ".edits_acked_per_s");
    // joins and bytes_in_by_type were added later: absent from older reports.
    if (in.has(k + ".joins")) p.joins = in.integer(k + ".joins", 0, r.bots);
    for (const std::string& type : in.children(k + ".bytes_in_by_type")) {
      std::size_t t = 0;
      while (t < kMessageTypeCount && type != message_type_name(t)) ++t;
      if (t == kMessageTypeCount) {
        in.fail(k + ".bytes_in_by_type." + type, "not a message type");
        break;
      }
      p.bytes_in_by_type[t] = in.whole(k + ".bytes_in_by_type." + type);
    }
    p.fanout_ms = in.latency(k + ".fanout_ms");
    p.ack_ms = in.latency(k + ".ack_ms");
    p.round_trip_ms = in.latency(k + ".round_trip_ms");
    if (in.has(k + ".server.cpu_share")) p.server = read_interval(in, k + ".server");
    r.timeline.push_back(p);
  }
  if (!in.error().empty()) return in.error();
  r.thresholds = r.evaluate_own_thresholds();
  *out = std::move(r);
  return "";
}

namespace {

void add(LatencySummary& into, const LatencySummary& part) {
  LatencyHistogram h = into.histogram;
  h.merge(part.histogram);
  into = summarize(h);
}

}  // namespace

std::string merge_reports(const std::vector<BotsReport>& parts, BotsReport* out) {
  if (parts.empty()) return "no reports to merge";
  const BotsOptions& first = parts.front().options;
  const int n = first.shard_count;
  std::set<int> seen;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const BotsOptions& o = parts[i].options;
    const std::string which = "part " + std::to_string(i + 1) + " (shard " + std::to_string(o.shard_index) + "/" +
                              std::to_string(o.shard_count) + ")";
    if (o.shard_count != n) return which + ": another number of shards than part 1's " + std::to_string(n);
    BotsOptions a = o, b = first;
    a.shard_index = b.shard_index = 0;
    if (scenario_text(a) != scenario_text(b)) return which + ": another scenario than part 1's";
    if (!seen.insert(o.shard_index).second) return which + ": that shard is given twice";
  }
  if (static_cast<int>(seen.size()) != n) {
    std::string missing;
    for (int i = 0; i < n; ++i)
      if (seen.count(i) == 0) missing += (missing.empty() ? "" : ", ") + std::to_string(i);
    return "shards missing: " + missing + " of " + std::to_string(n);
  }

  BotsReport r;
  r.options = first;
  r.options.shard_index = 0;
  r.options.shard_count = 1;
  r.edits_expected = parts.front().edits_expected;
  r.min_checks_during_run = std::numeric_limits<std::uint64_t>::max();
  double bpv_weighted = 0, receivers_weighted = 0, edited_voxel_receivers = 0;
  std::uint64_t bpv_bots = 0;
  for (const BotsReport& p : parts) {
    r.bots += p.bots;
    r.duration_s = std::max(r.duration_s, p.duration_s);
    r.joined_s = std::max(r.joined_s, p.joined_s);
    r.bytes_received += p.bytes_received;
    r.bytes_sent += p.bytes_sent;
    r.join_bytes_received += p.join_bytes_received;
    r.steady_bytes_received += p.steady_bytes_received;
    r.steady_bot_s += p.steady_bot_s;
    for (std::size_t c = 0; c < kByteCauseCount; ++c) r.steady_bytes_by_cause[c] += p.steady_bytes_by_cause[c];
    r.join_coarse_bytes += p.join_coarse_bytes;
    // A mean over the bots that completed their join.
    bpv_weighted += p.bytes_per_non_empty_voxel * static_cast<double>(p.join_full_ms.count);
    bpv_bots += p.join_full_ms.count;
    add(r.join_coarse_ms, p.join_coarse_ms);
    add(r.join_full_ms, p.join_full_ms);
    add(r.edit_ack_ms, p.edit_ack_ms);
    add(r.edit_fanout_ms, p.edit_fanout_ms);
    add(r.edit_fanout_other_server_ms, p.edit_fanout_other_server_ms);
    add(r.round_trip_ms, p.round_trip_ms);
    add(r.bots_io_lag_ms, p.bots_io_lag_ms);
    r.edits_sent += p.edits_sent;
    r.edits_acked += p.edits_acked;
    r.edits_rejected += p.edits_rejected;
    r.edits_measured += p.edits_measured;
    for (const auto& [reason, count] : p.reject_reasons) r.reject_reasons[reason] += count;
    // A mean per measured edit; a ratio of bytes to edited voxels x receivers.
    receivers_weighted += p.receivers_per_edit * static_cast<double>(p.edits_measured);
    r.update_batch_bytes_steady += p.update_batch_bytes_steady;
    if (p.update_bytes_per_edited_voxel_per_receiver > 0)
      edited_voxel_receivers +=
          static_cast<double>(p.update_batch_bytes_steady) / p.update_bytes_per_edited_voxel_per_receiver;
    r.replica_regions_checked += p.replica_regions_checked;
    r.mismatches.insert(r.mismatches.end(), p.mismatches.begin(), p.mismatches.end());
    r.hash_unanswered += p.hash_unanswered;
    r.min_checks_during_run = std::min(r.min_checks_during_run, p.min_checks_during_run);
    r.unexpected_disconnects += p.unexpected_disconnects;
    r.disconnects.insert(r.disconnects.end(), p.disconnects.begin(), p.disconnects.end());
    r.connect_failures += p.connect_failures;
    if (r.first_connect_error.empty()) r.first_connect_error = p.first_connect_error;
    r.joins_incomplete += p.joins_incomplete;
    r.redirects += p.redirects;
    r.shared_chunk_hits += p.shared_chunk_hits;
    r.shared_chunk_misses += p.shared_chunk_misses;
    r.shared_mips_known += p.shared_mips_known;
    r.shared_mips_decoded += p.shared_mips_decoded;
    r.shared_update_hits += p.shared_update_hits;
    r.shared_update_misses += p.shared_update_misses;
    r.shared_update_twins += p.shared_update_twins;
    for (const auto& [server, count] : p.bots_per_server) r.bots_per_server[server] += count;
    r.walk_steps += p.walk_steps;
    r.teleports += p.teleports;
    r.edits_held_back += p.edits_held_back;
    r.bots_at_hotspot += p.bots_at_hotspot;
    for (std::size_t w = 0; w < r.walk_blocked.size(); ++w) r.walk_blocked[w] += p.walk_blocked[w];
    for (std::size_t t = 0; t < kMessageTypeCount; ++t) {
      r.by_message_type[t].frames_in += p.by_message_type[t].frames_in;
      r.by_message_type[t].bytes_in += p.by_message_type[t].bytes_in;
      r.by_message_type[t].frames_out += p.by_message_type[t].frames_out;
      r.by_message_type[t].bytes_out += p.by_message_type[t].bytes_out;
    }
    if (!r.server && p.server) r.server = p.server;
    // Second by second: each part's second s since its first connection.
    if (r.timeline.size() < p.timeline.size()) r.timeline.resize(p.timeline.size());
    for (std::size_t s = 0; s < p.timeline.size(); ++s) {
      TimelinePoint& into = r.timeline[s];
      const TimelinePoint& q = p.timeline[s];
      into.t_s = std::max(into.t_s, q.t_s);
      into.bots_connected += q.bots_connected;
      into.mb_per_s_in += q.mb_per_s_in;
      into.mb_per_s_out += q.mb_per_s_out;
      into.edits_acked_per_s += q.edits_acked_per_s;
      into.joins += q.joins;
      for (std::size_t t = 0; t < kMessageTypeCount; ++t) into.bytes_in_by_type[t] += q.bytes_in_by_type[t];
      add(into.fanout_ms, q.fanout_ms);
      add(into.ack_ms, q.ack_ms);
      add(into.round_trip_ms, q.round_trip_ms);
      if (!into.server && q.server) into.server = q.server;
    }
  }
  if (r.min_checks_during_run == std::numeric_limits<std::uint64_t>::max()) r.min_checks_during_run = 0;
  r.bytes_per_non_empty_voxel = bpv_bots > 0 ? bpv_weighted / static_cast<double>(bpv_bots) : 0;
  r.receivers_per_edit = r.edits_measured > 0 ? receivers_weighted / static_cast<double>(r.edits_measured) : 0;
  r.update_bytes_per_edited_voxel_per_receiver =
      edited_voxel_receivers > 0 ? static_cast<double>(r.update_batch_bytes_steady) / edited_voxel_receivers : 0;
  std::stable_sort(r.mismatches.begin(), r.mismatches.end(), [](const Mismatch& a, const Mismatch& b) { return a.bot < b.bot; });
  std::sort(r.disconnects.begin(), r.disconnects.end());
  r.thresholds = r.evaluate_own_thresholds();
  *out = std::move(r);
  return "";
}

}  // namespace terrane::bots
