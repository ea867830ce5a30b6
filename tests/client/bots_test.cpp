// terrane-bots (client/bots): in-process runs against the real
// terrane-server on 127.0.0.1 (port 0), the fault flags that must fail a
// run, option and scenario parsing, reports, and the binary's usage errors.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "client/bots/bot.h"
#include "client/bots/merge.h"
#include "client/client.h"
#include "client/bots/options.h"
#include "client/bots/report.h"
#include "client/bots/runner.h"
#include "client/bots/stats.h"
#include "tests/client/bots/parse_flags.h"
#include "tests/support/run_command.h"
#include "tests/support/server_process.h"

namespace terrane::bots {
namespace {

namespace fs = std::filesystem;
using testing_support::ServerProcess;

class BotsRunTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-bots-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override {
    if (server_) {
      EXPECT_EQ(server_->stop(), 0);
      if (HasFailure()) std::fprintf(stderr, "--- server output ---\n%s", server_->output().c_str());
    }
    fs::remove_all(dir_);
  }
  void start_server(const std::vector<std::string>& extra = {}) {
    server_ = std::make_unique<ServerProcess>(dir_.string(), extra);
    ASSERT_NE(server_->port(), 0) << server_->output();
  }
  // Small and short: tens of bots, a few seconds, a small view.
  BotsOptions small_run(int bots, Behavior behavior) const {
    BotsOptions o;
    o.port = server_->port();
    o.bots = bots;
    o.duration_s = 4;
    o.behavior = behavior;
    o.spread = 96;
    o.view_distance = 96;
    o.full_res_radius = 32;
    o.edit_interval_s = 0.5;
    o.hash_checks = 3;
    o.quiet_s = 0.5;
    // The duration starts once every bot has joined: a loaded machine
    // (sanitizers, parallel tests) slows joins, never shortens the run.
    o.join_timeout_s = 240;
    o.threads = 2;
    o.progress = "off";
    return o;
  }

  fs::path dir_;
  std::unique_ptr<ServerProcess> server_;
};

TEST_F(BotsRunTest, ShortMixedRunHasNoMismatchesAndSaneFigures) {
  start_server({"--metrics", "127.0.0.1:0"});
  const std::string line = "metrics on http://127.0.0.1:";
  ASSERT_TRUE(server_->wait_for_output("/metrics", testing_support::kServerStartDeadline)) << server_->output();
  const std::string out = server_->output();
  BotsOptions o = small_run(20, Behavior::kMixed);
  o.ramp_up_s = 1;
  o.metrics_host = "127.0.0.1";
  o.metrics_port = static_cast<std::uint16_t>(std::stoi(out.substr(out.find(line) + line.size())));
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  EXPECT_TRUE(r.passed()) << report_table(r);
  EXPECT_EQ(r.mismatches.size(), 0u);
  EXPECT_EQ(r.unexpected_disconnects, 0);
  EXPECT_EQ(r.connect_failures, 0);
  EXPECT_EQ(r.bots, 20);
  EXPECT_EQ(r.join_full_ms.count, 20u) << "every bot completed its full-resolution region";
  EXPECT_EQ(r.joins_incomplete, 0);
  EXPECT_GT(r.join_coarse_ms.p50, 0);
  EXPECT_GT(r.join_full_ms.p50, 0);
  EXPECT_GT(r.edits_acked, 0u);
  EXPECT_GT(r.edit_ack_ms.count, 0u);
  EXPECT_GT(r.edit_fanout_ms.count, 0u);
  EXPECT_GT(r.receivers_per_edit, 0);
  EXPECT_GT(r.bytes_received, 0u);
  EXPECT_GT(r.bytes_sent, 0u);
  EXPECT_EQ(r.join_bytes_received + r.steady_bytes_received, r.bytes_received);
  // The byte budget: every bot joined, so its causes are the steady bytes;
  // the editing bots' units went to bots holding the chunks at full
  // resolution, and the keepalive pings were answered.
  {
    std::uint64_t by_cause = 0, handled = 0;
    for (const std::uint64_t b : r.steady_bytes_by_cause) by_cause += b;
    for (const MessageTypeCounters& m : r.by_message_type) handled += m.bytes_in;  // (frames read whole)
    EXPECT_EQ(by_cause, handled - r.join_bytes_received);
    EXPECT_GT(r.steady_bytes_by_cause[static_cast<std::size_t>(ByteCause::kUpdate)], 0u);
    EXPECT_GT(r.steady_bot_s, 0);
    EXPECT_LE(r.steady_bot_s, 20 * r.duration_s);
    EXPECT_GT(r.steady_bytes_per_bot_s(), 0);
  }
  // Bytes per non-empty voxel is a fraction of a byte with this codec, far
  // below the 2 bytes of a raw voxel.
  EXPECT_GT(r.bytes_per_non_empty_voxel, 0.01);
  EXPECT_LT(r.bytes_per_non_empty_voxel, 2.0);
  EXPECT_GT(r.update_bytes_per_edited_voxel_per_receiver, 0);
  // Checks during the run plus every bot's final region check.
  EXPECT_GE(r.replica_regions_checked, 20u * 4);
  EXPECT_EQ(r.hash_unanswered, 0u);
  EXPECT_GT(r.by_message_type[static_cast<std::size_t>(wire::Body::StreamBatch)].bytes_in, 0u);
  EXPECT_GT(r.by_message_type[static_cast<std::size_t>(wire::Body::UpdateBatch)].frames_in, 0u);
  EXPECT_FALSE(r.timeline.empty());
  // The bots' own io lag was sampled (10 ms probe) over the measured run.
  EXPECT_GT(r.bots_io_lag_ms.count, 0u);
  EXPECT_GE(r.bots_io_lag_ms.p50, 0);
  // Bots near one another took Full records of the same bytes: some were
  // packed once for several (20 bots over a small area).
  EXPECT_GT(r.shared_chunk_misses, 0u);
  EXPECT_GT(r.shared_chunk_hits, 0u);
  // And mip records of the same bytes: some were found before decoding.
  EXPECT_GT(r.shared_mips_decoded, 0u);
  EXPECT_GT(r.shared_mips_known, 0u);
  // Bots holding one shared chunk were sent the same units: the update was
  // applied once for several.
  EXPECT_GT(r.shared_update_misses, 0u);
  EXPECT_GT(r.shared_update_hits, 0u);
  // The server's own books agree with the bots': only they edit.
  ASSERT_TRUE(r.server.has_value());
  EXPECT_EQ(r.server->scrape_errors, 0) << r.server->first_error;
  EXPECT_GE(r.server->scrapes, 2);
  EXPECT_EQ(r.server->edits_applied, r.edits_acked);
  EXPECT_EQ(r.server->edits_rejected, r.edits_rejected);
  EXPECT_GT(r.server->cpu_s, 0);
  EXPECT_GT(r.server->rss_peak, 0u);
  EXPECT_GT(r.server->ticks, 0u);
  EXPECT_TRUE(r.server->tick_p99_ms.has_value());
  // What the joins cost the server: scraped once every bot joined, within
  // the run, with at least one record streamed to each of the 20 bots.
  ASSERT_TRUE(r.server->joins.has_value());
  EXPECT_GT(r.server->joins->cpu_s, 0);
  EXPECT_LE(r.server->joins->cpu_s, r.server->cpu_s);
  EXPECT_LE(r.server->joins->wall_s, r.server->wall_s);
  EXPECT_GE(r.server->joins->records, 20u);
  EXPECT_GT(r.server->joins->stream_bytes, 0u);
  EXPECT_LE(r.server->joins->stream_bytes, r.server->sent_by_type.at("StreamBatch").second);
  {  // and the JSON report carries it through merge's reader
    BotsReport back;
    ASSERT_EQ(report_from_json(report_json(r), &back), "");
    ASSERT_TRUE(back.server && back.server->joins);
    EXPECT_EQ(back.server->joins->records, r.server->joins->records);
    EXPECT_EQ(back.server->joins->stream_bytes, r.server->joins->stream_bytes);
    EXPECT_NEAR(back.server->joins->cpu_s, r.server->joins->cpu_s, 1e-3);
  }
  EXPECT_NE(report_table(r).find("per join: server CPU / records / bytes"), std::string::npos);
  EXPECT_TRUE(r.server->commit_p99_ms.has_value());
  // The server's share of an edit's round trip: it waits for a tick, so
  // more than nothing.
  ASSERT_TRUE(r.server->edit_ack_mean_ms.has_value());
  EXPECT_GT(*r.server->edit_ack_mean_ms, 0);
  EXPECT_TRUE(r.server->edit_ack_p99_ms.has_value());
  EXPECT_NE(report_table(r).find("edit to ack in the server"), std::string::npos) << report_table(r);
  EXPECT_GT(r.server->sent_by_type["StreamBatch"].second, 0u);
  EXPECT_EQ(r.server->sent_by_type["EditAck"].first, r.edits_acked);
  EXPECT_NE(report_table(r).find("the server over the run"), std::string::npos) << report_table(r);
  // Second by second too: the intervals between scrapes add up to the
  // server's edits over the run (each point takes the scrapes since the
  // previous one; the last scrape, at the end, may come after the last point).
  std::uint64_t applied = 0;
  bool ack_mean = false;
  for (const TimelinePoint& p : r.timeline) {
    if (!p.server) continue;
    applied += p.server->edits_applied;
    EXPECT_GE(p.server->cpu_share, 0);
    ack_mean = ack_mean || (p.server->edit_ack_ms_mean && *p.server->edit_ack_ms_mean > 0);
  }
  EXPECT_GT(applied, 0u);
  EXPECT_LE(applied, r.server->edits_applied);
  EXPECT_TRUE(ack_mean);

  std::map<std::string, std::string> j;
  ASSERT_EQ(flatten_json(report_json(r), &j), "");
  for (const char* key :
       {"bots", "duration_s", "bytes_received", "bytes_sent", "bytes_per_non_empty_voxel", "join_coarse_ms.p50",
        "join_full_ms.p95", "edit_ack_ms.p99", "edit_fanout_ms.p50", "edit_fanout_ms.p95", "edit_fanout_ms.p99",
        "edit_fanout_ms.count", "edits_acked", "receivers_per_edit", "replica_regions_checked", "replica_mismatches",
        "unexpected_disconnects", "by_message_type.StreamBatch.bytes_in", "join_bytes_received",
        "steady_bytes_received", "update_bytes_per_edited_voxel_per_receiver", "timeline.0.mb_per_s_in",
        "server_counters.cpu_s", "server_counters.rss_peak_bytes", "server_counters.tick_p99_ms_bound",
        "server_counters.sent_by_type.StreamBatch.bytes", "bots_io_lag_ms.p99", "shared_chunk_hits", "shared_mips_known", "shared_update_hits",
        "server_counters.stream_gate_closed_s", "steady_bot_s", "steady_bytes_per_bot_s",
        "steady_bytes_by_cause.refresh", "steady_bytes_by_cause.keepalive"})
    EXPECT_EQ(j.count(key), 1u) << key;
  EXPECT_EQ(j["bots"], "20");
  EXPECT_EQ(j["replica_mismatches"], "0");
  EXPECT_EQ(j["passed"], "true");

  EXPECT_EQ(j.count("timeline.0.joins"), 1u);
  EXPECT_EQ(j.count("timeline.0.bytes_in_by_type.StreamBatch"), 1u);

  // Self-contained: the data, the page's script and the chart library are
  // in the page, and nothing is fetched (the charts are drawn in a real
  // browser in report_html_test.cpp).
  const std::string html = report_html(r);
  EXPECT_NE(html.find("<script type=\"application/json\" id=\"report-data\">"), std::string::npos);
  EXPECT_NE(html.find("var uPlot="), std::string::npos);
  EXPECT_EQ(html.find(" src="), std::string::npos);
  EXPECT_EQ(html.find("<pre>terrane-bots:"), std::string::npos) << "tables, not the text table";
  EXPECT_NE(html.find("<table class=\"latency\">"), std::string::npos);
}

// The fault flags make the server send wrong or no UpdateBatches: the run
// must fail and name the region. Every batch is faulty so that no later
// edit of the same 4^3 unit can repair the replica before the check (a
// fault that a later update overwrites is invisible to any hash).
void expect_failure_naming_region(const BotsReport& r) {
  EXPECT_FALSE(r.passed());
  ASSERT_FALSE(r.mismatches.empty()) << report_table(r);
  const std::string table = report_table(r);
  EXPECT_NE(table.find("MISMATCH bot"), std::string::npos) << table;
  const Vec3i c = r.mismatches.front().chunk;
  EXPECT_NE(table.find("chunk (" + std::to_string(c.x) + "," + std::to_string(c.y) + "," + std::to_string(c.z) + ")"),
            std::string::npos)
      << table;
  std::map<std::string, std::string> j;
  ASSERT_EQ(flatten_json(report_json(r), &j), "");
  EXPECT_EQ(j["passed"], "false");
  EXPECT_EQ(j["mismatches.0.chunk.0"], std::to_string(c.x));
}

// With a join wait, edits are measured from the moment every bot has
// joined: a bot that joined first edits while others still join (here all
// connect at once, with no ramp-up), and none of those edits counts. No
// second wholly before joined_s holds an edit's latency. (Round trips are
// shown for every second, the joins' too.)
TEST_F(BotsRunTest, EditsAreMeasuredOnlyOnceEveryBotHasJoined) {
  // Joins of a few seconds however fast the machine: each bot's takes about
  // 650 kB here, streamed at most 256 KiB a second.
  start_server({"--outbound-bytes-per-second", "262144"});
  BotsOptions o = small_run(40, Behavior::kMixed);
  o.ramp_up_s = 0;
  o.duration_s = 2;
  o.edit_interval_s = 0.1;
  // A wider view, bots farther apart.
  o.view_distance = 384;
  o.full_res_radius = 96;
  o.spread = 384;
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  EXPECT_TRUE(r.passed()) << report_table(r);
  ASSERT_GT(r.joined_s, 1.0) << "the joins took under a second: nothing was tried";
  EXPECT_GT(r.edit_ack_ms.count, 0u);
  for (std::size_t s = 0; s < r.timeline.size() && static_cast<double>(s + 1) <= r.joined_s; ++s) {
    EXPECT_EQ(r.timeline[s].ack_ms.count, 0u) << "second " << s;
    EXPECT_EQ(r.timeline[s].fanout_ms.count, 0u) << "second " << s;
  }
}

// --measure-from start (a join wave): edits count from the first
// connection, so the bots that joined early are measured while the rest of
// the ramp-up still connects (by default nothing sent before its end counts).
TEST_F(BotsRunTest, AJoinWaveMeasuresEditsSentDuringTheRampUp) {
  start_server();
  BotsOptions o = small_run(8, Behavior::kDig);
  o.join_timeout_s = 0;
  // Bot 0 joins in well under a second even under a sanitizer; the last
  // connects at 4 s and has 8 s to finish its join, which takes up to ~5 s
  // under ThreadSanitizer on a loaded machine.
  o.ramp_up_s = 4;
  o.duration_s = 12;
  o.edit_interval_s = 0.2;
  o.measure_from_start = true;
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  EXPECT_TRUE(r.passed()) << report_table(r);
  std::uint64_t during_ramp_up = 0;
  for (std::size_t s = 0; s + 1 < r.timeline.size() && s + 1 <= 4; ++s) during_ramp_up += r.timeline[s].ack_ms.count;
  EXPECT_GT(during_ramp_up, 0u) << report_table(r);
}

// --behavior teleport: every bot jumps --teleport-distance at each
// --teleport-interval, beyond twice its view distance (96 here), within the
// server's movement budget (default --max-speed 256: 256 x 2 + 48 voxels):
// no bot is dropped, each is streamed its whole view again after a jump,
// and every replica stays right.
TEST_F(BotsRunTest, TeleportingBotsAreStreamedEachNewViewAndStayRight) {
  start_server();
  BotsOptions o = small_run(4, Behavior::kTeleport);
  o.teleport_interval_s = 2;
  o.teleport_distance = 256;
  o.duration_s = 5;  // from the last join: two jumps each, the first 2 s after it rose
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  EXPECT_TRUE(r.passed()) << report_table(r);
  EXPECT_EQ(r.mismatches.size(), 0u);
  EXPECT_EQ(r.unexpected_disconnects, 0) << report_table(r);
  EXPECT_GE(r.teleports, 4u) << report_table(r);
  EXPECT_GT(r.edits_acked, 0u);
  // Every bot checks its region at the end, at the place of its last jump.
  EXPECT_GE(r.replica_regions_checked, 4u);
  // After the joins the bots were streamed at least another view each.
  const std::uint64_t streamed = r.by_message_type[static_cast<std::size_t>(wire::Body::StreamBatch)].bytes_in;
  EXPECT_GT(streamed, r.join_bytes_received) << report_table(r);
  std::map<std::string, std::string> j;
  ASSERT_EQ(flatten_json(report_json(r), &j), "");
  EXPECT_EQ(j["teleports"], std::to_string(r.teleports));
  // Open loop: no edit waited for a reply (none fell due with 8 unanswered).
  EXPECT_EQ(j["edits_held_back"], "0");
}

// --behavior hotspot: the bots fly from their starts (96 x 96 voxels) to
// the spawn, land there and edit the ground around it; every one gets
// there and every replica stays right.
TEST_F(BotsRunTest, HotspotBotsLandAtTheSpawnAndEditAroundIt) {
  start_server();
  BotsOptions o = small_run(6, Behavior::kHotspot);
  // Bots start within 24 voxels of the spawn, inside every other bot's
  // full-resolution radius (32): the flight is under a second of steps, and
  // an edit at the spawn reaches every bot whether or not it has landed, so
  // a slow machine (sanitizers, parallel tests) leaves most of the run to
  // the edits.
  o.spread = 24;
  o.duration_s = 8;
  o.edit_interval_s = 0.3;
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  EXPECT_TRUE(r.passed()) << report_table(r);
  EXPECT_EQ(r.mismatches.size(), 0u);
  EXPECT_EQ(r.unexpected_disconnects, 0);
  EXPECT_EQ(r.bots_at_hotspot, 6) << report_table(r);
  EXPECT_GT(r.edits_acked, 0u);
  // An edit near the spawn reaches most of the other five.
  EXPECT_GT(r.receivers_per_edit, 3.0) << report_table(r);
}

// --edit-shape write-box: builders send raw boxes (write_box) of edit-radius
// to twice that a side, each request carrying its voxels; every replica
// stays right.
TEST_F(BotsRunTest, BuildersWriteRawBoxesAndEveryReplicaStaysRight) {
  start_server();
  BotsOptions o = small_run(4, Behavior::kBuild);
  o.edit_shape = EditShape::kWriteBox;
  o.edit_radius = 8;  // boxes of 8 to 16 a side
  o.edit_interval_s = 0.3;
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  EXPECT_TRUE(r.passed()) << report_table(r);
  EXPECT_EQ(r.mismatches.size(), 0u);
  EXPECT_GT(r.edits_acked, 0u);
  EXPECT_EQ(r.edits_rejected, 0u) << report_table(r);
  // A fill_box or sphere request is under 100 bytes; a hut of 8^3 voxels
  // or more, run-length coded, hundreds.
  const MessageTypeCounters& req = r.by_message_type[static_cast<std::size_t>(wire::Body::EditRequest)];
  ASSERT_GT(req.frames_out, 0u);
  EXPECT_GT(req.bytes_out / req.frames_out, 200u) << report_table(r);
}

// A walker starting above the ground comes down to it in steps within the
// server's movement slack alone, however soon its next state follows the
// last (after a redirect, the state the new server got first may be
// milliseconds older). Here the limit is 1 voxel a second and the walkers
// start 80 voxels above the spawn: a landing in one jump is dropped.
TEST_F(BotsRunTest, AWalkerStartingAboveTheGroundComesDownWithinTheSpeedLimit) {
  start_server({"--max-speed", "1"});
  Vec3f spawn;
  {
    ClientOptions co;
    co.port = server_->port();
    co.name = "probe";
    Client probe(co);
    std::string err;
    ASSERT_TRUE(probe.connect(&err)) << err;
    ASSERT_TRUE(probe.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, std::chrono::seconds(60)));
    ASSERT_TRUE(probe.welcome().has_value()) << probe.disconnect_reason();
    spawn = probe.welcome()->spawn;
    probe.disconnect();
  }
  BotsOptions o = small_run(4, Behavior::kWalk);
  o.spawn_set = true;
  o.spawn = Vec3i{static_cast<int>(std::floor(spawn.x)), static_cast<int>(std::floor(spawn.y)) + 80,
                  static_cast<int>(std::floor(spawn.z))};
  o.spread = 8;
  o.view_distance = 160;
  o.full_res_radius = 128;  // the ground below at full resolution
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  EXPECT_EQ(r.unexpected_disconnects, 0) << report_table(r);
  EXPECT_EQ(r.joins_incomplete, 0);
  EXPECT_GT(r.walk_steps, 0u) << "the walkers landed and walked";
}

TEST_F(BotsRunTest, CorruptedUpdatesFailTheRunAndNameTheRegion) {
  start_server({"--test-corrupt-updates", "1000000"});
  BotsOptions o = small_run(10, Behavior::kDig);
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  EXPECT_GT(r.edits_acked, 0u);
  expect_failure_naming_region(r);
}

TEST_F(BotsRunTest, DroppedUpdatesFailTheRunAndNameTheRegion) {
  start_server({"--test-drop-updates", "1000000"});
  BotsOptions o = small_run(10, Behavior::kBuild);
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  EXPECT_GT(r.edits_acked, 0u);
  expect_failure_naming_region(r);
}

TEST_F(BotsRunTest, ARunWhoseBotNeverJoinedOrEditedFails) {
  // The server streams at most 16 KiB a second to a client, and a join
  // refines the full-resolution region only once the coarse pass over the
  // whole view (thousands of records at view 512) is sent: however fast the
  // machine, the bot cannot finish its join within the run (a cold server
  // alone once joined in 0.29 s).
  start_server({"--outbound-bytes-per-second", "16384"});
  BotsOptions o = small_run(1, Behavior::kDig);
  o.join_timeout_s = 0;
  o.duration_s = 0.2;
  o.quiet_s = 0;
  o.view_distance = 512;
  o.full_res_radius = 128;
  BotsReport r;
  std::string err;
  ASSERT_TRUE(run_bots(o, nullptr, &r, &err)) << err;
  ASSERT_EQ(r.joins_incomplete, 1) << report_table(r);
  EXPECT_FALSE(r.passed());
  const std::string table = report_table(r);
  EXPECT_NE(table.find("FAILED: 1 of 1 bots never completed their join"), std::string::npos) << table;
  EXPECT_NE(table.find("FAILED: the bots were to edit, but no edit was acknowledged"), std::string::npos) << table;
  std::map<std::string, std::string> j;
  ASSERT_EQ(flatten_json(report_json(r), &j), "");
  EXPECT_EQ(j["passed"], "false");
  EXPECT_EQ(j.count("failures.1"), 1u);
}

TEST_F(BotsRunTest, UnreachableServerIsAnError) {
  BotsOptions o;
  asio::io_context io;
  asio::ip::tcp::acceptor a(io, {asio::ip::make_address("127.0.0.1"), 0});
  o.port = a.local_endpoint().port();
  a.close();
  o.progress = "off";
  BotsReport r;
  std::string err;
  EXPECT_FALSE(run_bots(o, nullptr, &r, &err));
  EXPECT_NE(err.find("cannot connect to 127.0.0.1:" + std::to_string(o.port)), std::string::npos) << err;
}

// A run waits for every bot's join (--wait-joined) until each has settled:
// joined, closed, or unable to connect. A bot whose connect failed (a
// server too busy to complete it within the connect timeout) once held a
// world 1,000 run up for the whole wait, 600 s.
TEST(BotJoin, ABotWhoseConnectFailedHasSettledItsJoin) {
  asio::io_context io;
  auto work = asio::make_work_guard(io);
  std::thread runner([&] { io.run(); });
  BotsOptions o;
  {
    asio::ip::tcp::acceptor a(io, {asio::ip::make_address("127.0.0.1"), 0});
    o.port = a.local_endpoint().port();
  }  // closed: nothing listens there
  RunContext ctx;
  ctx.options = &o;
  ctx.io = &io;
  ctx.view_distance = 64;
  ctx.full_res_radius = 32;
  {
    Bot b(0, ctx, Vec3f{0, 0, 0}, Gait::kIdle, EditMode::kNone, 1);
    EXPECT_FALSE(b.join_settled()) << "not tried yet";
    ASSERT_FALSE(b.connect());
    EXPECT_FALSE(b.result().connect_error.empty());
    EXPECT_FALSE(b.joined());
    EXPECT_FALSE(b.closed());
    EXPECT_TRUE(b.join_settled());
  }
  work.reset();
  runner.join();
}

// --- options -------------------------------------------------------------------

// Several servers: a receiver on another server is measured by the chunks
// the edit changed, not by every chunk its box reaches. Bot 0 edits on
// server 1; bot 1 (server 2) holds only the box's second chunk, bot 2
// (server 2) both; the edit changes only the first.
TEST(ReasonClassTest, RefusalsOfOneKindCountTogether) {
  EXPECT_EQ(reason_class("server 12 refused the forwarded edit: not held by the server it was sent to: region (1,0,-2) "
                         "is leased to server 3 (epoch 2) until 2026-11-28 06:19:21.916469+00"),
            "server N refused the forwarded edit: not held by the server it was sent to: region (N,N,-N) is leased to "
            "server N (epoch N)");
  EXPECT_EQ(reason_class("forwarded to server 2, no answer within 5000 ms (it may still be applied)"),
            reason_class("forwarded to server 3, no answer within 5000 ms (it may still be applied)"));
  EXPECT_EQ(reason_class("edit outside the full-resolution region"), "edit outside the full-resolution region");
  EXPECT_EQ(reason_class(""), "");
}

class FanoutTrackerTest : public ::testing::Test {
 protected:
  FanoutTrackerTest() : f_(std::chrono::steady_clock::now(), std::chrono::steady_clock::now(), 2) {
    const auto t0 = std::chrono::steady_clock::now();
    f_.bot_on_server(0, 1);
    f_.bot_on_server(1, 2);
    f_.bot_on_server(2, 2);
    // Bots 0 and 2 as a bot tells them, a batch at once (a coarser form
    // first: a release, then the full one); bot 1 chunk by chunk.
    const Holding full{HoldingForm::kFull, 1}, mip{HoldingForm::kMip1, 1};
    const HoldingChange both[] = {{kChanged, mip}, {kChanged, full}, {kReached, full}};
    f_.holdings_changed(0, both, t0);
    f_.chunk_arrived(1, kReached, t0);
    f_.holdings_changed(2, both, t0);
  }
  // Bot 0's edit id acknowledged at t, naming tick.
  void acked(std::uint32_t id, std::uint64_t tick, std::chrono::steady_clock::time_point t) {
    EditOutcome ok;
    ok.accepted = true;
    ok.tick = tick;
    f_.edit_result(0, id, ok, t);
  }
  static constexpr Vec3i kChanged{0, 0, 0}, kReached{1, 0, 0};
  static constexpr Region kBox{{30, 0, 0}, {34, 4, 4}};  // across both chunks
  FanoutTracker f_;
};

TEST_F(FanoutTrackerTest, ALocalEditIsMeasuredByTheChunksItsTicksUpdatesChanged) {
  using namespace std::chrono_literals;
  const std::uint32_t id = f_.send_edit(0, kBox, 8, [] { return 7u; });
  ASSERT_EQ(id, 7u);
  const auto sent = std::chrono::steady_clock::now();
  acked(id, 5, sent + 20ms);
  f_.update_received(0, 5, {ChunkRevisionMsg{kChanged, 2}}, sent + 20ms);
  // Bot 2 gets the change from its server 40 ms on; the second chunk
  // changes 1.5 s on, by another edit, and reaches bots 1 and 2.
  f_.chunk_arrived(2, kChanged, sent + 40ms);
  f_.chunk_arrived(1, kReached, sent + 1500ms);
  f_.chunk_arrived(2, kReached, sent + 1500ms);
  f_.settle(sent + 10s, 0s);
  const auto other = f_.fanout_other_server_ms();
  ASSERT_EQ(other.count(), 1u) << "bot 1, which holds no chunk the edit changed, was measured";
  EXPECT_GE(other.max_ms(), 40.0);
  EXPECT_LT(other.max_ms(), 1000.0);
}

TEST_F(FanoutTrackerTest, AForwardedEditIsMeasuredByTheChunksArrivingAtTheEditorBeforeItsAck) {
  using namespace std::chrono_literals;
  // No update of the editor's server's tick says what a forwarded edit
  // changed; its chunks arrive again at the editor before the ack (which
  // waits for them). A change of the second chunk after the ack is another
  // edit's.
  const std::uint32_t id = f_.send_edit(0, kBox, 8, [] { return 8u; });
  const auto sent = std::chrono::steady_clock::now();
  f_.chunk_arrived(0, kChanged, sent + 30ms);
  acked(id, 9, sent + 35ms);
  f_.chunk_arrived(2, kChanged, sent + 50ms);
  f_.chunk_arrived(0, kReached, sent + 1500ms);
  f_.chunk_arrived(1, kReached, sent + 1500ms);
  f_.chunk_arrived(2, kReached, sent + 1500ms);
  f_.settle(sent + 10s, 0s);
  const auto other = f_.fanout_other_server_ms();
  ASSERT_EQ(other.count(), 1u) << "bot 1, which holds no chunk the edit changed, was measured";
  EXPECT_GE(other.max_ms(), 50.0);
  EXPECT_LT(other.max_ms(), 1000.0);
}

// An edit that changed nothing (the editor holds its chunks and no update
// of its tick came) is seen nowhere: the next change of its chunks is
// another edit's, often seconds later.
TEST_F(FanoutTrackerTest, AnEditThatChangedNothingIsMeasuredNowhere) {
  using namespace std::chrono_literals;
  const std::uint32_t id = f_.send_edit(0, kBox, 8, [] { return 3u; });
  const auto sent = std::chrono::steady_clock::now();
  acked(id, 4, sent + 8ms);
  f_.update_received(2, 11, {ChunkRevisionMsg{kChanged, 2}}, sent + 1500ms);
  f_.chunk_arrived(2, kReached, sent + 1800ms);
  f_.settle(sent + 10s, 0s);
  EXPECT_TRUE(f_.fanout_other_server_ms().empty()) << f_.fanout_other_server_ms().max_ms();
  EXPECT_EQ(f_.totals().edits_measured, 1u);
}

// A receiver on another server is measured by the change the edit made:
// not by an older revision landing after the edit was sent (an earlier
// edit's), and not at all if it did not hold the chunk when the edit was
// sent (it got the chunk, edit included, whole; its next update is a later
// edit's).
TEST_F(FanoutTrackerTest, AReceiverOnAnotherServerIsMeasuredByTheRevisionTheEditMade) {
  using namespace std::chrono_literals;
  f_.bot_on_server(3, 2);
  const std::uint32_t id = f_.send_edit(0, kBox, 8, [] { return 5u; });
  const auto sent = std::chrono::steady_clock::now();
  f_.update_received(2, 20, {ChunkRevisionMsg{kChanged, 1}}, sent + 10ms);  // an earlier edit
  acked(id, 6, sent + 20ms);
  f_.update_received(0, 6, {ChunkRevisionMsg{kChanged, 2}}, sent + 20ms);
  f_.update_received(2, 21, {ChunkRevisionMsg{kChanged, 2}}, sent + 60ms);
  f_.chunk_arrived(3, kChanged, sent + 100ms);  // bot 3's first copy
  f_.update_received(3, 22, {ChunkRevisionMsg{kChanged, 3}}, sent + 1500ms);
  f_.settle(sent + 10s, 0s);
  const auto other = f_.fanout_other_server_ms();
  ASSERT_EQ(other.count(), 1u) << "bot 3, which got the chunk after the edit was sent, was measured";
  EXPECT_GE(other.max_ms(), 60.0) << "bot 2 was measured by the earlier revision";
  EXPECT_LT(other.max_ms(), 1000.0);
}

TEST(BotsOptions, ScenarioFileHoldsEverythingAndFlagsOverrideIt) {
  const fs::path file = fs::temp_directory_path() / ("terrane-bots-scenario-" + std::to_string(::getpid()));
  {
    std::ofstream f(file);
    f << "# a scenario\nconnect = 10.0.0.2:7000\nbots=250\nduration = 60\nbehavior = walk\n"
         "spawn = 10,70,-20\nspread = 512\nview-distance = 512\nfull-res-radius = 64\nramp-up = 20\n"
         "seed = 9\nedit-interval = 2\nedit-radius = 3\nlatency-ms = 40\nbandwidth-kbps = 2000\n"
         "measure-from = start\n";
  }
  BotsOptions o;
  ASSERT_EQ(parse_flags({"--scenario", file.string(), "--bots", "300", "--behavior=mixed"}, &o), "");
  EXPECT_EQ(o.host, "10.0.0.2");
  EXPECT_EQ(o.port, 7000);
  EXPECT_EQ(o.bots, 300);  // the flag wins
  EXPECT_EQ(o.behavior, Behavior::kMixed);
  EXPECT_EQ(o.duration_s, 60);
  EXPECT_TRUE(o.spawn_set);
  EXPECT_EQ(o.spawn, (Vec3i{10, 70, -20}));
  EXPECT_EQ(o.spread, 512);
  EXPECT_EQ(o.view_distance, 512);
  EXPECT_EQ(o.full_res_radius, 64);
  EXPECT_EQ(o.ramp_up_s, 20);
  EXPECT_EQ(o.seed, 9u);
  EXPECT_EQ(o.latency_ms, 40);
  EXPECT_EQ(o.bandwidth_kbps, 2000);
  EXPECT_TRUE(o.measure_from_start);
  // The saved scenario reproduces the options.
  OptionValues kv;
  ASSERT_EQ(parse_scenario_text(scenario_text(o), "saved", &kv), "");
  BotsOptions again;
  ASSERT_EQ(apply_option_values(kv, &again), "");
  EXPECT_EQ(scenario_text(again), scenario_text(o));
  fs::remove(file);
}

// --shard I/N runs the bots i with i mod N == I, each placed, cast and
// seeded as when one process runs them all.
TEST(BotsOptions, ShardsSplitTheBotsAsOneProcessPlansThem) {
  BotsOptions o;
  o.bots = 11;
  o.spread = 200;
  o.seed = 5;
  o.behavior = Behavior::kMixed;
  const Vec3f spawn{10, 70, -20};
  const std::vector<BotPlan> all = plan_bots(o, spawn);
  ASSERT_EQ(all.size(), 11u);
  std::vector<BotPlan> joined;
  for (int i = 0; i < 3; ++i) {
    BotsOptions part = o;
    part.shard_index = i;
    part.shard_count = 3;
    for (const BotPlan& p : plan_bots(part, spawn)) {
      EXPECT_EQ(p.id % 3, i);
      joined.push_back(p);
    }
  }
  std::sort(joined.begin(), joined.end(), [](const BotPlan& a, const BotPlan& b) { return a.id < b.id; });
  ASSERT_EQ(joined.size(), all.size());
  for (std::size_t i = 0; i < all.size(); ++i) {
    EXPECT_EQ(joined[i].id, all[i].id);
    EXPECT_EQ(joined[i].start, all[i].start) << i;
    EXPECT_EQ(joined[i].gait, all[i].gait) << i;
    EXPECT_EQ(joined[i].edits, all[i].edits) << i;
    EXPECT_EQ(joined[i].seed, all[i].seed) << i;
  }
  // The flag, in a scenario file and its errors.
  ASSERT_EQ(parse_flags({"--connect", "h:1", "--bots", "11", "--shard", "2/3"}, &o), "");
  EXPECT_EQ(o.shard_index, 2);
  EXPECT_EQ(o.shard_count, 3);
  EXPECT_NE(scenario_text(o).find("shard = 2/3\n"), std::string::npos);
  BotsOptions bad_shard;
  for (const char* v : {"3/3", "-1/3", "1", "1/0", "a/b"})
    EXPECT_NE(parse_flags({"--connect", "h:1", "--shard", v}, &bad_shard).find(std::string("--shard: '") + v + "'"),
              std::string::npos)
        << v;
  EXPECT_NE(parse_flags({"--connect", "h:1", "--bots", "2", "--shard", "0/3"}, &bad_shard).find("leave a part without bots"),
            std::string::npos);
}

TEST(BotsOptions, IoThreadsAreOnePerCoreUnlessGiven) {
  BotsOptions o;
  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  EXPECT_EQ(io_threads(o), cores);
  ASSERT_EQ(parse_flags({"--connect", "127.0.0.1:7777", "--threads", "3"}, &o), "");
  EXPECT_EQ(io_threads(o), 3);
}

TEST(BotsOptions, SharedChunksScaleWithTheBotsUnlessGiven) {
  BotsOptions o;
  o.bots = 100;
  EXPECT_EQ(shared_chunks_for(o), 4096u);  // at least 4,096
  o.bots = 1000;
  EXPECT_EQ(shared_chunks_for(o), 16000u);  // 16 a bot
  o.shard_count = 2;
  EXPECT_EQ(shared_chunks_for(o), 8000u);  // of this process's shard
  EXPECT_EQ(scenario_text(o).find("shared-chunks"), std::string::npos) << "the default is not written down";
  ASSERT_EQ(parse_flags({"--connect", "h:1", "--bots", "1000", "--shared-chunks", "0"}, &o), "");
  EXPECT_EQ(shared_chunks_for(o), 0u);
  ASSERT_EQ(parse_flags({"--connect", "h:1", "--bots", "1000", "--shared-chunks", "500"}, &o), "");
  EXPECT_EQ(shared_chunks_for(o), 500u);
  EXPECT_NE(scenario_text(o).find("shared-chunks = 500\n"), std::string::npos);
}

// Every bot makes at least --hash-checks checks in the measured run, and
// not many more: a ramp-up longer than the duration (which --wait-joined
// allows: the duration starts after the joins) once made the span negative,
// so every bot asked for a hash every 0.2 s instead of every 10 s.
TEST(BotsOptions, HashChecksAreSpreadOverTheMeasuredRun) {
  BotsOptions crowd;
  crowd.duration_s = 60;
  crowd.ramp_up_s = 20;
  crowd.hash_checks = 5;
  EXPECT_DOUBLE_EQ(hash_check_span_s(crowd), 40.0 / 6);  // the last bot connects 20 s in
  BotsOptions world = crowd;
  world.ramp_up_s = 200;
  world.join_timeout_s = 600;
  EXPECT_DOUBLE_EQ(hash_check_span_s(world), 10.0);  // 60 s measured after the joins
  world.duration_s = 300;
  EXPECT_DOUBLE_EQ(hash_check_span_s(world), 10.0);  // at most 10 s apart
  world.hash_checks = 999;
  EXPECT_DOUBLE_EQ(hash_check_span_s(world), 0.3);
  world.hash_checks = 100000;
  EXPECT_DOUBLE_EQ(hash_check_span_s(world), 0.2);   // at least 0.2 s apart
  BotsOptions wave = crowd;
  wave.measure_from_start = true;
  EXPECT_DOUBLE_EQ(hash_check_span_s(wave), 10.0);  // 60 s measured from the first connection
}

TEST(BotsOptions, BadFlagsAndScenarioLinesAreNamed) {
  BotsOptions o;
  EXPECT_NE(parse_flags({"--bots", "3"}, &o).find("--connect"), std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "127.0.0.1:1", "--bots", "0"}, &o).find("--bots: '0'"), std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "127.0.0.1:1", "--behavior", "swim"}, &o).find("--behavior: 'swim'"),
            std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "nohost"}, &o).find("--connect: 'nohost'"), std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--spawn", "1,2"}, &o).find("--spawn"), std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--edit-radius", "40"}, &o).find("--edit-radius"), std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--frobnicate", "1"}, &o).find("unknown option --frobnicate"),
            std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--duration"}, &o).find("--duration: missing value"), std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--duration", "5", "--ramp-up", "5"}, &o).find("--ramp-up"),
            std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--scenario", "/nonexistent/x"}, &o).find("--scenario: cannot read"),
            std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--measure-from", "noon"}, &o).find("--measure-from: 'noon'"),
            std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--measure-from", "start", "--wait-joined", "60"}, &o).find("give one"),
            std::string::npos);
  OptionValues kv;
  EXPECT_EQ(parse_scenario_text("bots = 2\nwings = 2\n", "s.txt", &kv), "s.txt:2: unknown key 'wings'");
  EXPECT_EQ(parse_scenario_text("bots 2\n", "s.txt", &kv), "s.txt:1: expected key=value, got 'bots 2'");
  kv.clear();
  ASSERT_EQ(parse_scenario_text("\n# c\nbots = many\n", "s.txt", &kv), "");
  EXPECT_NE(apply_option_values(kv, &o).find("s.txt:3: bots: 'many'"), std::string::npos);
}

// Who the bots join as: name prefix and one token (from the command line or
// a file), or a tokens file's player lines in order; the forms exclude each
// other, and a tokens file must have a player line for every bot.
TEST(BotsOptions, BotsJoinAsTheirPrefixOrTheirTokensFilesPlayers) {
  const fs::path dir = fs::temp_directory_path() / ("terrane-bots-logins-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string token_file = (dir / "token").string(), tokens_file = (dir / "tokens").string(),
                    empty_file = (dir / "empty").string();
  std::ofstream(token_file) << "  secret-1  \nignored\n";
  std::ofstream(tokens_file) << "# players\nops t0 admin\nann t1\nben t2 player # the second\n";
  std::ofstream(empty_file) << "\n";
  BotsOptions o;
  ASSERT_EQ(parse_flags({"--connect", "h:1", "--bots", "2"}, &o), "");
  EXPECT_EQ(bot_login(o, 0).name, "bot-0");
  EXPECT_EQ(bot_login(o, 1).name, "bot-1");
  EXPECT_EQ(bot_login(o, 1).token, "");
  o = {};
  ASSERT_EQ(parse_flags({"--connect", "h:1", "--token-file", token_file, "--name-prefix", "load-"}, &o), "");
  EXPECT_EQ(bot_login(o, 7).name, "load-7");
  EXPECT_EQ(bot_login(o, 7).token, "secret-1");
  // The saved scenario names the file, never the token in it.
  EXPECT_NE(scenario_text(o).find("token-file = " + token_file), std::string::npos) << scenario_text(o);
  EXPECT_EQ(scenario_text(o).find("secret-1"), std::string::npos) << scenario_text(o);
  o = {};
  ASSERT_EQ(parse_flags({"--connect", "h:1", "--bots", "2", "--tokens-file", tokens_file}, &o), "");
  EXPECT_EQ(bot_login(o, 0).name, "ann");
  EXPECT_EQ(bot_login(o, 0).token, "t1");
  EXPECT_EQ(bot_login(o, 1).name, "ben");
  EXPECT_EQ(bot_login(o, 1).token, "t2");
  OptionValues kv;
  ASSERT_EQ(parse_scenario_text(scenario_text(o), "saved", &kv), "");
  BotsOptions again;
  ASSERT_EQ(apply_option_values(kv, &again), "");
  EXPECT_EQ(bot_login(again, 1).name, "ben");

  o = {};
  EXPECT_EQ(parse_flags({"--connect", "h:1", "--bots", "3", "--tokens-file", tokens_file}, &o),
            "--tokens-file: " + tokens_file + " has 2 player lines for 3 bots (bot i joins as the i-th)");
  EXPECT_NE(parse_flags({"--connect", "h:1", "--bots", "2", "--tokens-file", tokens_file, "--token", "x"}, &o)
                .find("not with --token"),
            std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--bots", "2", "--tokens-file", tokens_file, "--name-prefix", "p"}, &o)
                .find("not with --token, --token-file or --name-prefix"),
            std::string::npos);
  EXPECT_EQ(parse_flags({"--connect", "h:1", "--token", "x", "--token-file", token_file}, &o),
            "--token and --token-file: give one of them");
  EXPECT_EQ(parse_flags({"--connect", "h:1", "--token-file", (dir / "none").string()}, &o),
            "--token-file: '" + (dir / "none").string() + "' cannot be read");
  EXPECT_EQ(parse_flags({"--connect", "h:1", "--token-file", empty_file}, &o),
            "--token-file: '" + empty_file + "' has no token on its first line");
  EXPECT_EQ(parse_flags({"--connect", "h:1", "--tokens-file", (dir / "none").string()}, &o),
            "--tokens-file: cannot read tokens file " + (dir / "none").string());
  EXPECT_NE(parse_flags({"--connect", "h:1", "--name-prefix", "a b"}, &o).find("--name-prefix: 'a b'"),
            std::string::npos);
  fs::remove_all(dir);
}

// --- reports -------------------------------------------------------------------

TEST(BotsReport, CompareShowsBothReportsSideBySide) {
  BotsReport a, b;
  a.bots = 100;
  b.bots = 200;
  a.edit_fanout_ms = LatencySummary{10, 20, 40, 1000, 50, {}};
  b.edit_fanout_ms = LatencySummary{12, 30, 80, 2000, 90, {}};
  std::string err;
  const std::string t = compare_reports("a.json", report_json(a), "b.json", report_json(b), &err);
  EXPECT_EQ(err, "");
  EXPECT_NE(t.find("edit_fanout_ms.p99"), std::string::npos) << t;
  EXPECT_NE(t.find("2x"), std::string::npos) << t;  // p99 40 -> 80, bots 100 -> 200
  EXPECT_EQ(compare_reports("a.json", "{\"bots\": 1,", "b.json", report_json(b), &err), "");
  EXPECT_NE(err.find("a.json: "), std::string::npos) << err;
  EXPECT_EQ(compare_reports("a.json", report_json(a), "b.json", "{\"x\": 1}", &err), "");
  EXPECT_NE(err.find("b.json: not a terrane-bots report"), std::string::npos) << err;
}

TEST(BotsReport, JsonFlattenerRejectsMalformedInput) {
  std::map<std::string, std::string> j;
  EXPECT_NE(flatten_json("{\"a\": [1, 2}", &j), "");
  EXPECT_NE(flatten_json("{\"a\": 1} x", &j).find("trailing"), std::string::npos);
  EXPECT_NE(flatten_json(std::string(100, '['), &j).find("too deep"), std::string::npos);
  j.clear();
  ASSERT_EQ(flatten_json("{\"a\": {\"b\": [1, \"x\"]}, \"c\": true}", &j), "");
  EXPECT_EQ(j["a.b.0"], "1");
  EXPECT_EQ(j["a.b.1"], "x");
  EXPECT_EQ(j["c"], "true");
  // \u escapes read back as what json_escape wrote them for.
  j.clear();
  ASSERT_EQ(flatten_json("{\"e\": \"a\\u003cb \\u00e9 \\ud800\"}", &j), "");
  EXPECT_EQ(j["e"], "a<b \xc3\xa9 ?");
  EXPECT_NE(flatten_json("{\"e\": \"\\u00g0\"}", &j), "");
}

// --- the binary ------------------------------------------------------------------

// terrane-bots with args: its exit status; *output is what it printed.
int run_binary(const std::string& args, std::string* output) {
  output->clear();
  return testing_support::run_command(std::string(TERRANE_BIN_DIR) + "/terrane-bots " + args, output);
}

TEST(BotsBinary, BadUsageExitsTwoNamingTheFlag) {
  std::string out;
  EXPECT_EQ(run_binary("--connect 127.0.0.1:1 --bots lots", &out), 2);
  EXPECT_NE(out.find("--bots: 'lots'"), std::string::npos) << out;
  EXPECT_EQ(run_binary("--help", &out), 0);
  EXPECT_NE(out.find("--behavior"), std::string::npos) << out;
  EXPECT_EQ(run_binary("compare only-one.json", &out), 2);
  EXPECT_NE(out.find("compare takes two JSON reports"), std::string::npos) << out;
  EXPECT_EQ(run_binary("--connect 127.0.0.1:1 --threshold 'fanout_p99<<100'", &out), 2);
  EXPECT_NE(out.find("--threshold: 'fanout_p99<<100': '<100' is not a number"), std::string::npos) << out;
  EXPECT_EQ(run_binary("--connect 127.0.0.1:1 --threshold 'latency<1'", &out), 2);
  EXPECT_NE(out.find("unknown metric 'latency' (known: fanout_p50"), std::string::npos) << out;
}

// Four local shards of one scenario, run at once and merged, against one
// process running it all on the same server: what the scenario determines
// (bots, their joins and connections, no edit, no mismatch, each bot's
// Hello and Welcome) matches exactly. Latencies and bytes differ from run
// to run by more than the histograms' precision whatever the sharding
// (streaming depends on timing); that parts merge into the whole within
// that precision is tests/client/bots/merge_test.cpp's.
TEST_F(BotsRunTest, FourMergedShardsCountWhatOneProcessCounts) {
  start_server();
  const std::string run = "--connect 127.0.0.1:" + std::to_string(server_->port()) +
                          " --bots 8 --behavior idle --duration 1 --spread 64 --view-distance 64"
                          " --full-res-radius 32 --hash-checks 1 --quiet 0 --wait-joined 120 --threads 2"
                          " --progress off --threshold joins_incomplete==0";
  const auto path = [&](const std::string& name) { return (dir_ / name).string(); };
  std::string out;
  ASSERT_EQ(run_binary(run + " --report " + path("one.json"), &out), 0) << out;
  // The shards run at once, as on four machines.
  constexpr int kShards = 4;
  std::vector<std::string> outs(kShards);
  std::vector<int> statuses(kShards, -1);
  {
    std::vector<std::thread> parts;
    for (int i = 0; i < kShards; ++i)
      parts.emplace_back([&, i] {
        statuses[i] = run_binary(run + " --shard " + std::to_string(i) + "/4 --report " +
                                     path("p" + std::to_string(i) + ".json"),
                                 &outs[i]);
      });
    for (std::thread& t : parts) t.join();
  }
  for (int i = 0; i < kShards; ++i) EXPECT_EQ(statuses[i], 0) << outs[i];
  ASSERT_EQ(run_binary("merge " + path("p0.json") + " " + path("p1.json") + " " + path("p2.json") + " " +
                           path("p3.json") + " --report " + path("all.json") + " --html " + path("all.html"),
                       &out),
            0)
      << out;
  EXPECT_NE(out.find("terrane-bots: 8 bots, idle"), std::string::npos) << out;
  auto read = [&](const char* name) {
    std::ifstream f(path(name));
    std::stringstream text;
    text << f.rdbuf();
    std::map<std::string, std::string> flat;
    EXPECT_EQ(flatten_json(text.str(), &flat), "") << name;
    return flat;
  };
  auto one = read("one.json"), all = read("all.json"), p0 = read("p0.json"), p3 = read("p3.json");
  EXPECT_EQ(p0["bots"], "2");
  EXPECT_EQ(p3["bots"], "2");
  EXPECT_EQ(p3["scenario.shard"], "3/4");
  EXPECT_EQ(all["scenario.shard"], "0/1");
  for (const char* key :
       {"bots", "scenario.bots", "join_coarse_ms.count", "join_full_ms.count", "joins_incomplete", "connect_failures",
        "unexpected_disconnects", "replica_mismatches", "edits_sent", "edits_acked", "hash_unanswered", "passed",
        "exit_status", "thresholds.0.value", "by_message_type.Hello.frames_out", "by_message_type.Welcome.frames_in"})
    EXPECT_EQ(all[key], one[key]) << key;
  EXPECT_EQ(one["join_full_ms.count"], "8");
  EXPECT_TRUE(fs::exists(path("all.html")));
}

// A server that admits by a tokens file: the bots join with a tokens file
// of their own (bot i as its i-th player line, admin lines skipped), or
// with one token read from a file and a name prefix. The server's file
// lists only those players: the probe that reads the Welcome joins as the
// shard's first bot, so no other name is needed.
TEST_F(BotsRunTest, BotsJoinATokensFileServerAsItsPlayers) {
  fs::create_directories(dir_);
  const auto path = [&](const char* name) { return (dir_ / name).string(); };
  std::ofstream(path("server-tokens")) << "# the server's players\nops ops-token admin\nalice alice-token\n"
                                          "bob bob-token player  # a comment\ncarol carol-token\n"
                                          "load-0 shared-token\nload-1 shared-token\n";
  std::ofstream(path("bots-tokens")) << "ops ops-token admin\nalice alice-token\nbob bob-token player\n"
                                        "carol carol-token\n";
  std::ofstream(path("bot-token")) << "shared-token\n";
  start_server({"--tokens-file", path("server-tokens")});
  const std::string run = "--connect 127.0.0.1:" + std::to_string(server_->port()) +
                          " --behavior idle --duration 1 --spread 64 --view-distance 64"
                          " --full-res-radius 32 --hash-checks 1 --quiet 0 --wait-joined 120 --threads 2"
                          " --progress off --threshold joins_incomplete==0 --threshold connect_failures==0";
  std::string out;
  ASSERT_EQ(run_binary(run + " --bots 3 --tokens-file " + path("bots-tokens"), &out), 0) << out;
  for (const char* name : {"alice", "bob", "carol"})
    EXPECT_TRUE(server_->wait_for_output(std::string("joined as '") + name + "'", std::chrono::seconds(10))) << name;
  ASSERT_EQ(run_binary(run + " --bots 2 --token-file " + path("bot-token") + " --name-prefix load-", &out), 0) << out;
  for (const char* name : {"load-0", "load-1"})
    EXPECT_TRUE(server_->wait_for_output(std::string("joined as '") + name + "'", std::chrono::seconds(10))) << name;
  const std::string log = server_->output();
  EXPECT_EQ(log.find("refused"), std::string::npos) << log;
  EXPECT_EQ(log.find("ops"), std::string::npos) << "a bot joined as the admin line";
}

// A real short run against a local server: a threshold it cannot meet
// exits 3 and is named with its value in the table and the JSON report;
// the same run with thresholds it meets exits 0.
TEST_F(BotsRunTest, ABrokenThresholdExitsThreeNamingItsValue) {
  start_server();
  const fs::path report = dir_ / "thresholds.json";
  const std::string run = "--connect 127.0.0.1:" + std::to_string(server_->port()) +
                          " --bots 3 --behavior idle --duration 1 --view-distance 64 --full-res-radius 32"
                          " --hash-checks 1 --quiet 0 --wait-joined 120 --threads 2 --progress off";
  std::string out;
  EXPECT_EQ(run_binary(run + " --threshold mismatches==0 --threshold 'join_full_p99 < 0' --report " + report.string(),
                       &out),
            3)
      << out;
  EXPECT_NE(out.find("FAILED: threshold join_full_p99 < 0 broken: join_full_p99 = "), std::string::npos) << out;
  EXPECT_NE(out.find("ok   mismatches==0"), std::string::npos) << out;
  std::ifstream f(report);
  std::stringstream text;
  text << f.rdbuf();
  std::map<std::string, std::string> json;
  ASSERT_EQ(flatten_json(text.str(), &json), "");
  EXPECT_EQ(json["exit_status"], "3");
  EXPECT_EQ(json["thresholds.1.metric"], "join_full_p99");
  EXPECT_EQ(json["thresholds.1.passed"], "false");
  EXPECT_GT(std::stod(json["thresholds.1.value"]), 0);
  EXPECT_EQ(json["thresholds.1.value"], json["join_full_ms.p99"]);
  EXPECT_EQ(run_binary(run + " --threshold mismatches==0 --threshold 'join_full_p99>0'", &out), 0) << out;
}

}  // namespace
}  // namespace terrane::bots

namespace terrane::bots {
namespace {

TEST(ServerWatch, ReadsTheExpositionAndAHistogramsQuantileBetweenTwoScrapes) {
  const Scrape a = parse_exposition(
      "# HELP x_total help\n# TYPE x_total counter\nx_total 5\n"
      "t_seconds_bucket{le=\"0.001\"} 10\nt_seconds_bucket{le=\"0.01\"} 10\nt_seconds_bucket{le=\"+Inf\"} 10\n"
      "labelled_total{reason=\"a b\"} 2\nbroken line\nnan_total abc\n");
  EXPECT_EQ(a.at("x_total"), 5);
  EXPECT_EQ(a.at("labelled_total{reason=\"a b\"}"), 2);
  EXPECT_EQ(a.count("broken"), 0u);
  EXPECT_EQ(a.count("nan_total"), 0u);
  // Between the scrapes 100 more observations: 98 at most 1 ms, 2 in (1, 10] ms.
  const Scrape b = parse_exposition(
      "t_seconds_bucket{le=\"0.001\"} 108\nt_seconds_bucket{le=\"0.01\"} 110\nt_seconds_bucket{le=\"+Inf\"} 110\n");
  EXPECT_EQ(histogram_quantile_ms(a, b, "t_seconds", 0.5), 1.0);
  EXPECT_EQ(histogram_quantile_ms(a, b, "t_seconds", 0.99), 10.0);
  EXPECT_EQ(histogram_quantile_ms(a, a, "t_seconds", 0.99), std::nullopt);  // nothing observed
  const Scrape c = parse_exposition("t_seconds_bucket{le=\"0.001\"} 10\nt_seconds_bucket{le=\"0.01\"} 10\n"
                                    "t_seconds_bucket{le=\"+Inf\"} 20\n");
  EXPECT_TRUE(std::isinf(*histogram_quantile_ms(a, c, "t_seconds", 0.99)));
}

TEST(ServerWatch, AJoinsCostIsTheGrowthOfCpuRecordsAndStreamBytesUntilEveryBotJoined) {
  const Scrape a = parse_exposition(
      "process_cpu_seconds_total 10\nterrane_streamed_chunks_total{kind=\"full\"} 5\n"
      "terrane_streamed_chunks_total{kind=\"mip\"} 100\nterrane_horizon_images_sent_total 2\n"
      "terrane_sent_bytes_total{type=\"StreamBatch\"} 1000\nterrane_sent_bytes_total{type=\"Presence\"} 50\n");
  const Scrape b = parse_exposition(
      "process_cpu_seconds_total 12.5\nterrane_streamed_chunks_total{kind=\"full\"} 25\n"
      "terrane_streamed_chunks_total{kind=\"mip\"} 400\nterrane_streamed_chunks_total{kind=\"empty\"} 7\n"
      "terrane_horizon_images_sent_total 12\n"
      "terrane_sent_bytes_total{type=\"StreamBatch\"} 91000\nterrane_sent_bytes_total{type=\"Presence\"} 9050\n");
  const JoinCost c = join_cost(a, 100.0, b, 104.0);
  EXPECT_DOUBLE_EQ(c.wall_s, 4.0);
  EXPECT_DOUBLE_EQ(c.cpu_s, 2.5);
  EXPECT_EQ(c.records, 20u + 300u + 7u + 10u);  // every kind of chunk record, and the horizon images
  EXPECT_EQ(c.stream_bytes, 90000u);            // StreamBatch only
}

TEST(ServerWatch, AnIntervalIsTheServersGrowthBetweenTwoScrapes) {
  const Scrape a = parse_exposition(
      "process_cpu_seconds_total 10\nterrane_edits_applied_total 100\n"
      "terrane_edit_ack_duration_seconds_sum 2\nterrane_edit_ack_duration_seconds_count 100\n"
      "terrane_edit_ack_duration_seconds_bucket{le=\"0.05\"} 100\n"
      "terrane_edit_ack_duration_seconds_bucket{le=\"0.1\"} 100\n"
      "terrane_edit_ack_duration_seconds_bucket{le=\"+Inf\"} 100\n"
      "terrane_tick_duration_seconds_sum 1\nterrane_tick_duration_seconds_count 50\n"
      "terrane_tick_duration_seconds_bucket{le=\"0.005\"} 50\nterrane_tick_duration_seconds_bucket{le=\"0.25\"} 50\n"
      "terrane_tick_duration_seconds_bucket{le=\"+Inf\"} 50\nterrane_ticks_late_total 3\n");
  const Scrape b = parse_exposition(
      "process_cpu_seconds_total 11.5\nterrane_edits_applied_total 140\n"
      "terrane_edit_ack_duration_seconds_sum 3.2\nterrane_edit_ack_duration_seconds_count 140\n"
      "terrane_edit_ack_duration_seconds_bucket{le=\"0.05\"} 138\n"
      "terrane_edit_ack_duration_seconds_bucket{le=\"0.1\"} 140\n"
      "terrane_edit_ack_duration_seconds_bucket{le=\"+Inf\"} 140\n"
      "terrane_tick_duration_seconds_sum 1\nterrane_tick_duration_seconds_count 80\n"
      "terrane_tick_duration_seconds_bucket{le=\"0.005\"} 79\nterrane_tick_duration_seconds_bucket{le=\"0.25\"} 80\n"
      "terrane_tick_duration_seconds_bucket{le=\"+Inf\"} 80\nterrane_ticks_late_total 4\n"
      "process_resident_memory_bytes 31457280\nterrane_send_queue_bytes 4096\n");
  const ServerInterval i = server_interval(a, 100.0, b, 102.0);
  EXPECT_DOUBLE_EQ(i.cpu_share, 0.75);  // 1.5 s of CPU over 2 s
  EXPECT_EQ(i.edits_applied, 40u);
  ASSERT_TRUE(i.edit_ack_ms_mean.has_value());
  EXPECT_NEAR(*i.edit_ack_ms_mean, 30.0, 1e-9);  // 1.2 s over 40 edits
  EXPECT_EQ(i.edit_ack_p99_ms, 100.0);  // 38 of the 40 within 50 ms, the last 2 within 100
  ASSERT_TRUE(i.tick_ms_mean.has_value());
  EXPECT_NEAR(*i.tick_ms_mean, 0.0, 1e-9);  // 30 ticks, no time added
  EXPECT_FALSE(i.commit_ms_mean.has_value());  // no commits observed
  EXPECT_EQ(i.tick_ms_max, 250.0);  // 29 of the 30 ticks within 5 ms, one within 250
  EXPECT_FALSE(i.commit_ms_max.has_value());
  EXPECT_EQ(i.ticks_late, 1u);
  EXPECT_EQ(i.tick_p99_ms, 250.0);  // the 30th tick is the p99's
  // The gauges at the interval's end; absent from a scrape, none.
  EXPECT_EQ(i.rss_bytes, 31457280u);
  EXPECT_EQ(i.send_queue_bytes, 4096u);
  EXPECT_EQ(server_interval(b, 100.0, a, 102.0).rss_bytes, std::nullopt);
  EXPECT_EQ(histogram_mean_ms(b, b, "terrane_edit_ack_duration_seconds"), std::nullopt);
}

}  // namespace
}  // namespace terrane::bots
