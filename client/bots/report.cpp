#include "client/bots/report.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "common/cli/json.h"

namespace terrane::bots {

namespace {

std::string esc(const std::string& s) { return json_escape(s); }

std::string num(double v) {
  if (!std::isfinite(v)) return "0";
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}


// A histogram's bucket bound (server figures): "<= 5 ms", "> 1000 ms".
std::string bound_ms(const std::optional<double>& ms) {
  if (!ms) return "-";
  if (!std::isfinite(*ms)) return "> 1000 ms";
  return "<= " + num(*ms) + " ms";
}

std::string json_opt(const std::optional<double>& v) {
  if (!v) return "null";
  if (!std::isfinite(*v)) return "\"+Inf\"";
  return num(*v);
}

std::string json_whole(const std::optional<std::uint64_t>& v) { return v ? std::to_string(*v) : "null"; }

std::string server_json(const ServerFigures& f) {
  std::ostringstream j;
  j << "{\"wall_s\": " << num(f.wall_s) << ", \"cpu_s\": " << num(f.cpu_s)
    << ", \"cpu_share\": " << num(f.wall_s > 0 ? f.cpu_s / f.wall_s : 0) << ", \"rss_peak_bytes\": " << f.rss_peak
    << ", \"edits_applied\": " << f.edits_applied << ", \"edits_rejected\": " << f.edits_rejected
    << ", \"ticks\": " << f.ticks << ", \"ticks_late\": " << f.ticks_late << ", \"disconnects\": " << f.disconnects
    << ", \"tick_p99_ms_bound\": " << json_opt(f.tick_p99_ms) << ", \"commit_p99_ms_bound\": " << json_opt(f.commit_p99_ms)
    << ", \"fanout_p99_ms_bound\": " << json_opt(f.fanout_p99_ms)
    << ", \"edit_ack_mean_ms\": " << json_opt(f.edit_ack_mean_ms)
    << ", \"edit_ack_p99_ms_bound\": " << json_opt(f.edit_ack_p99_ms)
    << ", \"stream_gate_closings\": " << f.stream_gate_closings
    << ", \"stream_gate_closed_s\": " << num(f.stream_gate_closed_s) << ", \"scrapes\": " << f.scrapes
    << ", \"scrape_errors\": " << f.scrape_errors << ", \"joins\": ";
  if (f.joins)
    j << "{\"wall_s\": " << num(f.joins->wall_s) << ", \"cpu_s\": " << num(f.joins->cpu_s)
      << ", \"records\": " << f.joins->records << ", \"stream_bytes\": " << f.joins->stream_bytes << "}";
  else
    j << "null";
  j << ", \"sent_by_type\": {";
  bool first = true;
  for (const auto& [type, fb] : f.sent_by_type) {
    j << (first ? "" : ", ") << "\"" << esc(type) << "\": {\"frames\": " << fb.first << ", \"bytes\": " << fb.second << "}";
    first = false;
  }
  j << "}}";
  return j.str();
}

// A distribution: its percentiles and, when it counted anything, the
// histogram they came from (what `merge` adds up).
std::string lat(const LatencySummary& l) {
  return "{\"p50\": " + num(l.p50) + ", \"p95\": " + num(l.p95) + ", \"p99\": " + num(l.p99) +
         ", \"max\": " + num(l.max) + ", \"count\": " + std::to_string(l.count) +
         (l.histogram.empty() ? std::string() : ", \"histogram\": " + histogram_json(l.histogram)) + "}";
}

std::string region_name(Vec3i cp) {
  const Vec3i o = chunk_origin(cp);
  std::ostringstream s;
  s << "chunk (" << cp.x << "," << cp.y << "," << cp.z << ") voxels [" << o.x << "," << o.y << "," << o.z << " .. "
    << o.x + kChunkSize << "," << o.y + kChunkSize << "," << o.z + kChunkSize << ")";
  return s.str();
}

}  // namespace

std::string fixed(double v, int d) {
  if (!std::isfinite(v)) return "-";
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", d, v);
  return b;
}

std::string per_second_detail(const ThresholdResult& t) {
  if (!t.threshold.per_second) return "";
  return " in the worst second (ending at " + fixed(t.worst_t_s, 0) + " s), " + std::to_string(t.seconds_broken) +
         " of " + std::to_string(t.seconds) + " seconds broken";
}

std::string report_json(const BotsReport& r) {
  std::ostringstream j;
  const BotsOptions& o = r.options;
  j << "{\n";
  std::string connect = o.host + ":" + std::to_string(o.port);
  if (o.servers.size() > 1) {
    connect.clear();
    for (const auto& [host, port] : o.servers) connect += (connect.empty() ? "" : ",") + host + ":" + std::to_string(port);
  }
  j << "  \"scenario\": {\"connect\": \"" << esc(connect) << "\", \"servers\": " << std::max<std::size_t>(1, o.servers.size())
    << ", \"bots\": " << o.bots
    << ", \"duration\": " << num(o.duration_s) << ", \"behavior\": \"" << behavior_name(o.behavior) << "\", ";
  if (o.spawn_set) j << "\"spawn\": [" << o.spawn.x << ", " << o.spawn.y << ", " << o.spawn.z << "], ";
  j << "\"spread\": " << o.spread << ", \"view_distance\": " << o.view_distance
    << ", \"full_res_radius\": " << o.full_res_radius << ", \"ramp_up\": " << num(o.ramp_up_s)
    << ", \"seed\": " << o.seed << ", \"edit_interval\": " << num(o.edit_interval_s)
    << ", \"edit_radius\": " << num(o.edit_radius) << ", \"latency_ms\": " << o.latency_ms
    << ", \"bandwidth_kbps\": " << o.bandwidth_kbps << ", \"hash_checks\": " << o.hash_checks
    << ", \"threads\": " << o.threads << ", \"wait_joined\": " << num(o.join_timeout_s)
    << ", \"measure_from\": \"" << (o.measure_from_start ? "start" : "ramp-up") << "\""
    << ", \"shard\": \"" << o.shard_index << "/" << o.shard_count << "\""
    << ", \"edit_shape\": \"" << edit_shape_name(o.edit_shape) << "\""
    << ", \"teleport_interval\": " << num(o.teleport_interval_s) << ", \"teleport_distance\": " << o.teleport_distance;
  if (!o.preset.empty()) j << ", \"preset\": \"" << esc(o.preset) << "\"";
  j << "},\n";
  j << "  \"passed\": " << (r.passed() ? "true" : "false") << ",\n";
  j << "  \"failures\": [";
  {
    auto why = r.failures();
    for (std::string& broken : r.broken_thresholds()) why.push_back(std::move(broken));
    for (std::size_t i = 0; i < why.size(); ++i) j << (i ? ", " : "") << "\"" << esc(why[i]) << "\"";
  }
  j << "],\n";
  j << "  \"exit_status\": " << r.exit_status() << ",\n";
  j << "  \"thresholds\": [";
  for (std::size_t i = 0; i < r.thresholds.size(); ++i) {
    const ThresholdResult& t = r.thresholds[i];
    j << (i ? ",\n    " : "\n    ") << "{\"expression\": \"" << esc(t.threshold.expression) << "\", \"metric\": \""
      << esc(t.threshold.metric) << "\", \"op\": \"" << threshold_op_text(t.threshold.op)
      << "\", \"limit\": " << num(t.threshold.limit) << ", \"value\": " << (std::isfinite(t.value) ? num(t.value) : "null")
      << ", \"passed\": " << (t.passed ? "true" : "false");
    if (t.threshold.per_second)
      j << ", \"per_second\": {\"seconds\": " << t.seconds << ", \"seconds_broken\": " << t.seconds_broken
        << ", \"worst_t_s\": " << num(t.worst_t_s) << "}";
    j << "}";
  }
  j << (r.thresholds.empty() ? "],\n" : "\n  ],\n");
  j << "  \"joined_s\": " << num(r.joined_s) << ",\n";
  j << "  \"bots\": " << r.bots << ",\n";
  j << "  \"duration_s\": " << num(r.duration_s) << ",\n";
  j << "  \"bytes_received\": " << r.bytes_received << ",\n";
  j << "  \"bytes_sent\": " << r.bytes_sent << ",\n";
  j << "  \"join_bytes_received\": " << r.join_bytes_received << ",\n";
  j << "  \"join_coarse_bytes\": " << r.join_coarse_bytes << ",\n";
  j << "  \"steady_bytes_received\": " << r.steady_bytes_received << ",\n";
  j << "  \"steady_bot_s\": " << num(r.steady_bot_s) << ",\n";
  j << "  \"steady_bytes_per_bot_s\": " << num(r.steady_bytes_per_bot_s()) << ",\n";
  j << "  \"steady_bytes_by_cause\": {";
  for (std::size_t c = 0; c < kByteCauseCount; ++c)
    j << (c ? ", " : "") << "\"" << byte_cause_name(c) << "\": " << r.steady_bytes_by_cause[c];
  j << "},\n";
  j << "  \"bytes_per_non_empty_voxel\": " << num(r.bytes_per_non_empty_voxel) << ",\n";
  j << "  \"join_coarse_ms\": " << lat(r.join_coarse_ms) << ",\n";
  j << "  \"join_full_ms\": " << lat(r.join_full_ms) << ",\n";
  j << "  \"joins_incomplete\": " << r.joins_incomplete << ",\n";
  j << "  \"edit_ack_ms\": " << lat(r.edit_ack_ms) << ",\n";
  j << "  \"edit_fanout_ms\": " << lat(r.edit_fanout_ms) << ",\n";
  j << "  \"edit_fanout_other_server_ms\": " << lat(r.edit_fanout_other_server_ms) << ",\n";
  j << "  \"round_trip_ms\": " << lat(r.round_trip_ms) << ",\n";
  j << "  \"bots_io_lag_ms\": " << lat(r.bots_io_lag_ms) << ",\n";
  j << "  \"redirects\": " << r.redirects << ",\n";
  j << "  \"cache_chunks_loaded\": " << r.cache_chunks_loaded << ",\n";
  j << "  \"cache_chunks_saved\": " << r.cache_chunks_saved << ",\n";
  j << "  \"cache_regions_loaded\": " << r.cache_regions_loaded << ",\n";
  j << "  \"cache_regions_damaged\": " << r.cache_regions_damaged << ",\n";
  j << "  \"cache_regions_saved\": " << r.cache_regions_saved << ",\n";
  j << "  \"shared_chunk_hits\": " << r.shared_chunk_hits << ",\n";
  j << "  \"shared_chunk_misses\": " << r.shared_chunk_misses << ",\n";
  j << "  \"shared_mips_known\": " << r.shared_mips_known << ",\n";
  j << "  \"shared_mips_decoded\": " << r.shared_mips_decoded << ",\n";
  j << "  \"shared_update_hits\": " << r.shared_update_hits << ",\n";
  j << "  \"shared_update_misses\": " << r.shared_update_misses << ",\n";
  j << "  \"shared_update_twins\": " << r.shared_update_twins << ",\n";
  j << "  \"bots_per_server\": {";
  for (auto it = r.bots_per_server.begin(); it != r.bots_per_server.end(); ++it)
    j << (it == r.bots_per_server.begin() ? "" : ", ") << "\"" << it->first << "\": " << it->second;
  j << "},\n";
  j << "  \"edits_sent\": " << r.edits_sent << ",\n";
  j << "  \"edits_acked\": " << r.edits_acked << ",\n";
  j << "  \"edits_rejected\": " << r.edits_rejected << ",\n";
  j << "  \"reject_reasons\": {";
  bool first = true;
  for (const auto& [reason, n] : r.reject_reasons) {
    j << (first ? "" : ", ") << "\"" << esc(reason) << "\": " << n;
    first = false;
  }
  j << "},\n";
  j << "  \"edits_measured\": " << r.edits_measured << ",\n";
  j << "  \"receivers_per_edit\": " << num(r.receivers_per_edit) << ",\n";
  j << "  \"update_batch_bytes_steady\": " << r.update_batch_bytes_steady << ",\n";
  j << "  \"update_bytes_per_edited_voxel_per_receiver\": " << num(r.update_bytes_per_edited_voxel_per_receiver)
    << ",\n";
  j << "  \"replica_regions_checked\": " << r.replica_regions_checked << ",\n";
  j << "  \"replica_mismatches\": " << r.mismatches.size() << ",\n";
  j << "  \"mismatches\": [";
  for (std::size_t i = 0; i < r.mismatches.size(); ++i) {
    const Mismatch& m = r.mismatches[i];
    const Vec3i c = m.chunk, v = chunk_origin(m.chunk);
    j << (i ? ",\n    " : "\n    ") << "{\"bot\": " << m.bot << ", \"chunk\": [" << c.x << ", " << c.y << ", " << c.z
      << "], \"voxels\": [" << v.x << ", " << v.y << ", " << v.z << ", " << v.x + kChunkSize << ", "
      << v.y + kChunkSize << ", " << v.z + kChunkSize << "], \"replica_revision\": " << m.replica_revision
      << ", \"server_revision\": " << m.server_revision << ", \"final_check\": " << (m.final_check ? "true" : "false")
      << ", \"reason\": \"" << esc(m.reason) << "\"}";
  }
  j << (r.mismatches.empty() ? "],\n" : "\n  ],\n");
  j << "  \"hash_unanswered\": " << r.hash_unanswered << ",\n";
  j << "  \"min_hash_checks_during_run\": " << r.min_checks_during_run << ",\n";
  j << "  \"unexpected_disconnects\": " << r.unexpected_disconnects << ",\n";
  j << "  \"disconnects\": [";
  for (std::size_t i = 0; i < r.disconnects.size(); ++i)
    j << (i ? ", " : "") << "{\"bot\": " << r.disconnects[i].first << ", \"reason\": \"" << esc(r.disconnects[i].second)
      << "\"}";
  j << "],\n";
  j << "  \"connect_failures\": " << r.connect_failures << ",\n";
  j << "  \"first_connect_error\": \"" << esc(r.first_connect_error) << "\",\n";
  j << "  \"walk_steps\": " << r.walk_steps << ",\n";
  j << "  \"teleports\": " << r.teleports << ",\n";
  j << "  \"edits_held_back\": " << r.edits_held_back << ",\n";
  j << "  \"bots_at_hotspot\": " << r.bots_at_hotspot << ",\n";
  j << "  \"walk_refused\": {\"outside_area\": " << r.walk_blocked[0] << ", \"not_full_resolution\": " << r.walk_blocked[1]
    << ", \"too_steep\": " << r.walk_blocked[2] << ", \"obstacle\": " << r.walk_blocked[3] << "},\n";
  j << "  \"server_counters\": " << (r.server ? server_json(*r.server) : std::string("null")) << ",\n";
  j << "  \"by_message_type\": {";
  first = true;
  for (std::size_t t = 0; t < kMessageTypeCount; ++t) {
    const auto& m = r.by_message_type[t];
    if (m.frames_in == 0 && m.frames_out == 0) continue;
    j << (first ? "\n    " : ",\n    ") << "\"" << message_type_name(t) << "\": {\"frames_in\": " << m.frames_in
      << ", \"bytes_in\": " << m.bytes_in << ", \"frames_out\": " << m.frames_out << ", \"bytes_out\": " << m.bytes_out
      << "}";
    first = false;
  }
  j << "\n  },\n";
  j << "  \"timeline\": [";
  for (std::size_t i = 0; i < r.timeline.size(); ++i) {
    const TimelinePoint& p = r.timeline[i];
    j << (i ? ",\n    " : "\n    ") << "{\"t_s\": " << num(p.t_s) << ", \"bots\": " << p.bots_connected
      << ", \"mb_per_s_in\": " << num(p.mb_per_s_in) << ", \"mb_per_s_out\": " << num(p.mb_per_s_out)
      << ", \"edits_acked_per_s\": " << num(p.edits_acked_per_s) << ", \"joins\": " << p.joins
      << ", \"bytes_in_by_type\": {";
    bool first_type = true;
    for (std::size_t t = 0; t < kMessageTypeCount; ++t) {
      if (p.bytes_in_by_type[t] == 0) continue;
      j << (first_type ? "" : ", ") << "\"" << message_type_name(t) << "\": " << p.bytes_in_by_type[t];
      first_type = false;
    }
    j << "}, \"fanout_ms\": " << lat(p.fanout_ms)
      << ", \"ack_ms\": " << lat(p.ack_ms) << ", \"round_trip_ms\": " << lat(p.round_trip_ms);
    if (p.server)
      j << ", \"server\": {\"cpu_share\": " << num(p.server->cpu_share)
        << ", \"edits_applied\": " << p.server->edits_applied << ", \"tick_ms_mean\": " << json_opt(p.server->tick_ms_mean)
        << ", \"commit_ms_mean\": " << json_opt(p.server->commit_ms_mean)
        << ", \"edit_ack_ms_mean\": " << json_opt(p.server->edit_ack_ms_mean)
        << ", \"edit_ack_p99_ms_bound\": " << json_opt(p.server->edit_ack_p99_ms)
        << ", \"tick_ms_max_bound\": " << json_opt(p.server->tick_ms_max)
        << ", \"commit_ms_max_bound\": " << json_opt(p.server->commit_ms_max)
        << ", \"fanout_ms_max_bound\": " << json_opt(p.server->fanout_ms_max)
        << ", \"ticks_late\": " << p.server->ticks_late
        << ", \"tick_p99_ms_bound\": " << json_opt(p.server->tick_p99_ms)
        << ", \"rss_bytes\": " << json_whole(p.server->rss_bytes)
        << ", \"send_queue_bytes\": " << json_whole(p.server->send_queue_bytes) << "}";
    j << "}";
  }
  j << "\n  ]\n}\n";
  return j.str();
}

std::string report_table(const BotsReport& r) {
  std::ostringstream t;
  char line[256];
  auto row = [&](const char* name, const std::string& value) {
    std::snprintf(line, sizeof line, "  %-44s %s\n", name, value.c_str());
    t << line;
  };
  auto l = [](const LatencySummary& s) {
    char b[128];
    std::snprintf(b, sizeof b, "p50 %.1f  p95 %.1f  p99 %.1f  (%zu samples)", s.p50, s.p95, s.p99, s.count);
    return std::string(b);
  };
  auto mb = [](std::uint64_t b) { return fixed(static_cast<double>(b) / 1e6, 2) + " MB"; };
  t << "terrane-bots: " << r.bots << " bots, " << behavior_name(r.options.behavior) << ", "
    << (r.options.preset.empty() ? "" : "preset " + r.options.preset + ", ")
    << fixed(r.duration_s, 1) << " s — " << (r.passed() ? "PASSED" : "FAILED") << "\n";
  for (const std::string& why : r.failures()) t << "  FAILED: " << why << "\n";
  for (const std::string& why : r.broken_thresholds()) t << "  FAILED: " << why << "\n";
  if (!r.thresholds.empty()) {
    t << "  thresholds:\n";
    for (const ThresholdResult& th : r.thresholds) {
      const std::string value = th.threshold.metric + " = " + num(th.value) + per_second_detail(th);
      std::snprintf(line, sizeof line, "    %-4s %-40s %s\n", th.passed ? "ok" : "FAIL", th.threshold.expression.c_str(),
                    value.c_str());
      t << line;
    }
  }
  if (r.joined_s > 0) row("all bots joined after", fixed(r.joined_s, 1) + " s");
  row("bytes received (all / join / steady)",
      mb(r.bytes_received) + " / " + mb(r.join_bytes_received) + " / " + mb(r.steady_bytes_received));
  row("bytes sent", mb(r.bytes_sent));
  row("bytes per non-empty voxel (join, mean)", fixed(r.bytes_per_non_empty_voxel, 3));
  row("join coarse ms", l(r.join_coarse_ms));
  row("join coarse bytes (all bots)", mb(r.join_coarse_bytes));
  row("join full ms", l(r.join_full_ms));
  row("joins incomplete", std::to_string(r.joins_incomplete));
  row("edit ack ms", l(r.edit_ack_ms));
  row(r.options.servers.size() > 1 ? "edit fan-out ms, same server" : "edit fan-out ms", l(r.edit_fanout_ms));
  row("round trip ms (keepalive pings)", l(r.round_trip_ms));
  row("bots' own io lag ms (10 ms probe)", l(r.bots_io_lag_ms));
  if (r.options.servers.size() > 1) {
    row("edit fan-out ms, other server", l(r.edit_fanout_other_server_ms));
    std::string per;
    for (const auto& [id, n] : r.bots_per_server)
      per += (per.empty() ? "" : ", ") + std::string("server ") + std::to_string(id) + ": " + std::to_string(n);
    row("redirects followed", std::to_string(r.redirects));
    row("bots per server at the end", per);
  }
  row("edits sent / acked / rejected",
      std::to_string(r.edits_sent) + " / " + std::to_string(r.edits_acked) + " / " + std::to_string(r.edits_rejected) +
          (r.edits_sent > 0 ? " (" + fixed(100.0 * static_cast<double>(r.edits_rejected) / static_cast<double>(r.edits_sent), 1) +
                                  " % rejected)"
                            : std::string()));
  // The reasons, most frequent first (the ack percentiles leave them out).
  {
    std::vector<std::pair<std::uint64_t, std::string>> reasons;
    for (const auto& [reason, n] : r.reject_reasons) reasons.emplace_back(n, reason);
    std::sort(reasons.begin(), reasons.end(),
              [](const auto& a, const auto& b) { return a.first != b.first ? a.first > b.first : a.second < b.second; });
    constexpr std::size_t kShown = 6;
    for (std::size_t i = 0; i < reasons.size() && i < kShown; ++i)
      t << "    " << reasons[i].first << " x " << reasons[i].second << "\n";
    if (reasons.size() > kShown) t << "    (" << reasons.size() - kShown << " more reasons in the JSON report)\n";
  }
  row("receivers per edit (mean)", fixed(r.receivers_per_edit, 1));
  row("update bytes per edited voxel per receiver", fixed(r.update_bytes_per_edited_voxel_per_receiver, 2));
  row("replica regions checked", std::to_string(r.replica_regions_checked));
  if (!r.options.chunk_cache_dir.empty())
    row("chunk cache: chunks joined from / saved",
        std::to_string(r.cache_chunks_loaded) + " / " + std::to_string(r.cache_chunks_saved) + " (regions read " +
            std::to_string(r.cache_regions_loaded) + ", damaged " + std::to_string(r.cache_regions_damaged) + ")");
  if (r.shared_chunk_hits + r.shared_chunk_misses > 0)
    row("full chunks shared / packed by a bot",
        std::to_string(r.shared_chunk_hits) + " / " + std::to_string(r.shared_chunk_misses));
  if (r.shared_mips_known + r.shared_mips_decoded > 0)
    row("mip records known / decoded by a bot",
        std::to_string(r.shared_mips_known) + " / " + std::to_string(r.shared_mips_decoded));
  if (r.shared_update_hits + r.shared_update_misses > 0)
    row("updates of shared chunks taken / made by a bot",
        std::to_string(r.shared_update_hits) + " / " + std::to_string(r.shared_update_misses) + " (lineages joined " +
            std::to_string(r.shared_update_twins) + ")");
  if (r.bots > 0 && r.replica_memory.total() > 0) {
    const ReplicaMemory& m = r.replica_memory;
    const auto kib = [&](std::size_t bytes) { return fixed(static_cast<double>(bytes) / 1024.0 / r.bots, 1) + " KiB"; };
    row("replica memory per bot (at the end)", kib(m.total() + r.shared_chunk_bytes));
    row("  full chunks: table / objects / rows / mips",
        kib(m.full.map_bytes) + " / " + kib(m.full.object_bytes) + " / " + kib(m.full.level0_bytes) + " / " +
            kib(m.full.mip_bytes));
    row("  mips: table / voxels", kib(m.entry_table_bytes) + " / " + kib(m.mip_bytes));
    row("  mips held per bot", fixed(static_cast<double>(m.mips) / r.bots, 0));
    row("  horizons: table / images", kib(m.horizon_table_bytes) + " / " + kib(m.horizon_image_bytes));
    row("  shared full chunks (process / bots)", kib(r.shared_chunk_bytes));
  }
  row("replica mismatches", std::to_string(r.mismatches.size()));
  row("hash requests unanswered", std::to_string(r.hash_unanswered));
  row("unexpected disconnects", std::to_string(r.unexpected_disconnects));
  if (r.walk_steps > 0)
    row("walk steps (refused: area/res/steep/block)",
        std::to_string(r.walk_steps) + " (" + std::to_string(r.walk_blocked[0]) + " / " + std::to_string(r.walk_blocked[1]) +
            " / " + std::to_string(r.walk_blocked[2]) + " / " + std::to_string(r.walk_blocked[3]) + ")");
  if (r.teleports > 0) row("teleports", std::to_string(r.teleports));
  if (r.edits_held_back > 0) row("edits not sent: 8 of the bot's unanswered", std::to_string(r.edits_held_back));
  if (r.options.behavior == Behavior::kHotspot)
    row("bots landed at the hotspot", std::to_string(r.bots_at_hotspot) + " of " + std::to_string(r.bots));
  if (r.connect_failures > 0) row("connect failures", std::to_string(r.connect_failures) + ": " + r.first_connect_error);
  if (r.steady_bot_s > 0) {
    // The byte budget: each cause's steady bytes per bot per second.
    std::string causes;
    for (std::size_t c = 0; c < kByteCauseCount; ++c) {
      if (r.steady_bytes_by_cause[c] == 0) continue;
      causes += std::string(causes.empty() ? "" : ", ") + byte_cause_name(c) + " " +
                fixed(static_cast<double>(r.steady_bytes_by_cause[c]) / r.steady_bot_s / 1e3, 2);
    }
    row("steady kB per bot per second", fixed(r.steady_bytes_per_bot_s() / 1e3, 2) + ": " + causes);
  }
  std::snprintf(line, sizeof line, "  %-22s %12s %14s %12s %14s\n", "bots' traffic by type", "frames in",
                "bytes in", "frames out", "bytes out");
  t << line;
  for (std::size_t i = 0; i < kMessageTypeCount; ++i) {
    const auto& m = r.by_message_type[i];
    if (m.frames_in == 0 && m.frames_out == 0) continue;
    std::snprintf(line, sizeof line, "    %-20s %12llu %14llu %12llu %14llu\n", message_type_name(i),
                  static_cast<unsigned long long>(m.frames_in), static_cast<unsigned long long>(m.bytes_in),
                  static_cast<unsigned long long>(m.frames_out), static_cast<unsigned long long>(m.bytes_out));
    t << line;
  }
  if (r.server) {
    const ServerFigures& f = *r.server;
    t << "  the server over the run (its /metrics, " << f.scrapes << " scrapes):\n";
    if (f.scrape_errors > 0) row("  scrapes failed", std::to_string(f.scrape_errors) + ": " + f.first_error);
    row("  CPU", fixed(f.cpu_s, 1) + " s over " + fixed(f.wall_s, 1) + " s (" +
                     fixed(f.wall_s > 0 ? 100 * f.cpu_s / f.wall_s : 0, 0) + "% of one core)");
    row("  resident memory (peak)", fixed(static_cast<double>(f.rss_peak) / (1 << 20), 0) + " MiB");
    row("  ticks (late)", std::to_string(f.ticks) + " (" + std::to_string(f.ticks_late) + ")");
    row("  tick / commit / fan-out p99", bound_ms(f.tick_p99_ms) + " / " + bound_ms(f.commit_p99_ms) + " / " +
                                             bound_ms(f.fanout_p99_ms));
    row("  edit to ack in the server, mean / p99",
        (f.edit_ack_mean_ms ? fixed(*f.edit_ack_mean_ms, 1) + " ms" : std::string("-")) + " / " +
            bound_ms(f.edit_ack_p99_ms));
    row("  edits applied / rejected", std::to_string(f.edits_applied) + " / " + std::to_string(f.edits_rejected));
    row("  streaming paused (server behind)",
        std::to_string(f.stream_gate_closings) + " times, " + fixed(f.stream_gate_closed_s, 1) + " s in all");
    row("  sessions ended", std::to_string(f.disconnects));
    if (f.joins) {
      // Per join: over the bots that joined (walking and editing ones
      // included, so an idle run gives the join alone).
      const double joined = std::max(1, r.bots - r.joins_incomplete);
      row("  until every bot joined: CPU / records",
          fixed(f.joins->cpu_s, 1) + " s over " + fixed(f.joins->wall_s, 1) + " s / " + std::to_string(f.joins->records) +
              " (" + std::to_string(f.joins->stream_bytes / 1000000) + " MB streamed)");
      row("  per join: server CPU / records / bytes", fixed(1000 * f.joins->cpu_s / joined, 1) + " ms / " +
                                                          fixed(static_cast<double>(f.joins->records) / joined, 0) + " / " +
                                                          fixed(static_cast<double>(f.joins->stream_bytes) / joined / 1000, 0) +
                                                          " kB");
    }
    std::snprintf(line, sizeof line, "    %-20s %12s %14s\n", "sent by type", "frames", "bytes");
    t << line;
    for (const auto& [type, fb] : f.sent_by_type) {
      std::snprintf(line, sizeof line, "    %-20s %12llu %14llu\n", type.c_str(),
                    static_cast<unsigned long long>(fb.first), static_cast<unsigned long long>(fb.second));
      t << line;
    }
  }
  const std::size_t shown = std::min<std::size_t>(r.mismatches.size(), 20);
  for (std::size_t i = 0; i < shown; ++i) {
    const Mismatch& m = r.mismatches[i];
    t << "  MISMATCH bot " << m.bot << " " << region_name(m.chunk) << ": " << m.reason
      << (m.final_check ? " (final check)" : "") << "\n";
  }
  if (r.mismatches.size() > shown) t << "  ... " << r.mismatches.size() - shown << " more mismatches in the JSON report\n";
  for (const auto& [bot, reason] : r.disconnects) t << "  DISCONNECTED bot " << bot << ": " << reason << "\n";
  return t.str();
}

namespace {

class JsonFlattener {
 public:
  JsonFlattener(const std::string& s, std::map<std::string, std::string>* out) : s_(s), out_(out) {}
  std::string run() {
    ws();
    if (!value("", 0)) return err_;
    ws();
    if (i_ != s_.size()) return "trailing bytes at offset " + std::to_string(i_);
    return "";
  }

 private:
  static constexpr int kMaxDepth = 32;
  bool fail(const std::string& what) {
    if (err_.empty()) err_ = what + " at offset " + std::to_string(i_);
    return false;
  }
  void ws() {
    while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\n' || s_[i_] == '\r' || s_[i_] == '\t')) ++i_;
  }
  bool string(std::string* v) {
    if (i_ >= s_.size() || s_[i_] != '"') return fail("expected a string");
    ++i_;
    while (i_ < s_.size() && s_[i_] != '"') {
      if (s_[i_] == '\\') {
        if (++i_ >= s_.size()) break;
        const char c = s_[i_];
        if (c == 'u') {
          // \uXXXX as UTF-8 (json_escape writes '<', '>', '&' and control
          // characters so); a surrogate half reads as '?'.
          unsigned code = 0;
          if (s_.size() - i_ < 5) return fail("bad escape");
          for (std::size_t k = 1; k <= 4; ++k) {
            const char h = s_[i_ + k];
            const int d = h >= '0' && h <= '9'   ? h - '0'
                          : h >= 'a' && h <= 'f' ? h - 'a' + 10
                          : h >= 'A' && h <= 'F' ? h - 'A' + 10
                                                 : -1;
            if (d < 0) return fail("bad escape");
            code = code * 16 + static_cast<unsigned>(d);
          }
          if (code >= 0xD800 && code <= 0xDFFF) {
            v->push_back('?');
          } else if (code < 0x80) {
            v->push_back(static_cast<char>(code));
          } else if (code < 0x800) {
            v->push_back(static_cast<char>(0xC0 | (code >> 6)));
            v->push_back(static_cast<char>(0x80 | (code & 0x3F)));
          } else {
            v->push_back(static_cast<char>(0xE0 | (code >> 12)));
            v->push_back(static_cast<char>(0x80 | ((code >> 6) & 0x3F)));
            v->push_back(static_cast<char>(0x80 | (code & 0x3F)));
          }
          i_ += 5;
          continue;
        }
        v->push_back(c == 'n' ? '\n' : c == 't' ? '\t' : c);
        ++i_;
        continue;
      }
      v->push_back(s_[i_++]);
    }
    if (i_ >= s_.size()) return fail("unterminated string");
    ++i_;
    return true;
  }
  bool value(const std::string& path, int depth) {
    if (depth > kMaxDepth) return fail("nesting too deep");
    ws();
    if (i_ >= s_.size()) return fail("unexpected end");
    const char c = s_[i_];
    if (c == '{' || c == '[') {
      const bool obj = c == '{';
      ++i_;
      ws();
      if (i_ < s_.size() && s_[i_] == (obj ? '}' : ']')) return ++i_, true;
      for (std::size_t n = 0;; ++n) {
        std::string key = std::to_string(n);
        if (obj) {
          ws();
          key.clear();
          if (!string(&key)) return false;
          ws();
          if (i_ >= s_.size() || s_[i_] != ':') return fail("expected ':'");
          ++i_;
        }
        if (!value(path.empty() ? key : path + "." + key, depth + 1)) return false;
        ws();
        if (i_ < s_.size() && s_[i_] == ',') {
          ++i_;
          continue;
        }
        if (i_ < s_.size() && s_[i_] == (obj ? '}' : ']')) return ++i_, true;
        return fail(obj ? "expected ',' or '}'" : "expected ',' or ']'");
      }
    }
    std::string v;
    if (c == '"') {
      if (!string(&v)) return false;
    } else {
      const std::size_t start = i_;
      while (i_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[i_])) || s_[i_] == '-' || s_[i_] == '+' ||
                                s_[i_] == '.'))
        ++i_;
      if (i_ == start) return fail("unexpected character");
      v = s_.substr(start, i_ - start);
    }
    (*out_)[path] = v;
    return true;
  }

  const std::string& s_;
  std::map<std::string, std::string>* out_;
  std::size_t i_ = 0;
  std::string err_;
};

}  // namespace

std::string flatten_json(const std::string& text, std::map<std::string, std::string>* out) {
  if (text.size() > (std::size_t{256} << 20)) return "larger than 256 MiB";
  return JsonFlattener(text, out).run();
}

std::string compare_reports(const std::string& name_a, const std::string& a, const std::string& name_b,
                            const std::string& b, std::string* error) {
  std::map<std::string, std::string> fa, fb;
  if (auto e = flatten_json(a, &fa); !e.empty()) return *error = name_a + ": " + e, "";
  if (auto e = flatten_json(b, &fb); !e.empty()) return *error = name_b + ": " + e, "";
  for (const auto* f : {&fa, &fb})
    if (f->count("bots") == 0 || f->count("edit_fanout_ms.p99") == 0)
      return *error = (f == &fa ? name_a : name_b) + ": not a terrane-bots report (no bots / edit_fanout_ms)", "";
  static const char* const kKeys[] = {
      "passed", "bots", "duration_s", "scenario.behavior", "scenario.view_distance", "scenario.full_res_radius",
      "bytes_received", "join_bytes_received", "steady_bytes_received", "steady_bytes_per_bot_s",
      "steady_bytes_by_cause.stream", "steady_bytes_by_cause.refresh", "steady_bytes_by_cause.update",
      "steady_bytes_by_cause.presence", "bytes_sent", "bytes_per_non_empty_voxel", "join_coarse_bytes", "join_coarse_ms.p50", "join_coarse_ms.p99", "join_full_ms.p50", "join_full_ms.p99", "edit_ack_ms.p50",
      "edit_ack_ms.p99", "edit_fanout_ms.p50", "edit_fanout_ms.p95", "edit_fanout_ms.p99", "edit_fanout_ms.count",
      "edits_acked", "edits_rejected", "receivers_per_edit", "update_bytes_per_edited_voxel_per_receiver",
      "replica_regions_checked", "replica_mismatches", "unexpected_disconnects"};
  std::ostringstream t;
  char line[256];
  std::snprintf(line, sizeof line, "%-44s %16s %16s %9s\n", "", name_a.substr(0, 16).c_str(),
                name_b.substr(0, 16).c_str(), "B/A");
  t << line;
  for (const char* k : kKeys) {
    const auto ia = fa.find(k), ib = fb.find(k);
    const std::string va = ia == fa.end() ? "-" : ia->second, vb = ib == fb.end() ? "-" : ib->second;
    std::string ratio;
    char* ea = nullptr;
    char* eb = nullptr;
    const double da = std::strtod(va.c_str(), &ea), db = std::strtod(vb.c_str(), &eb);
    if (ea != va.c_str() && *ea == 0 && eb != vb.c_str() && *eb == 0 && da != 0) ratio = num(db / da) + "x";
    std::snprintf(line, sizeof line, "%-44s %16s %16s %9s\n", k, va.c_str(), vb.c_str(), ratio.c_str());
    t << line;
  }
  return t.str();
}

}  // namespace terrane::bots
