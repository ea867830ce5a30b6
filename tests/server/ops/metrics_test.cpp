// The operator's endpoint: /metrics in Prometheus' text format, checked by
// Prometheus' own promtool, counters that move when a client joins, edits
// and leaves, and /health; over real sockets on 127.0.0.1.
#include "server/ops/metrics.h"

#include <gtest/gtest.h>
#include <httplib.h>

#include <cstdio>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>

#include "server/ops/http_endpoint.h"
#include "tests/support/eventually.h"
#include "tests/support/run_command.h"
#include "tests/support/scratch_dir.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using testing_support::msg;
using testing_support::RawPeer;
using testing_support::ServerTest;
using namespace std::chrono_literals;

// promtool's verdict on an exposition: its exit status and what it printed.
struct Verdict {
  int status = -1;
  std::string output;
};

Verdict promtool_check(const std::string& text) {
  const auto dir = testing_support::scratch_dir("terrane-promtool");
  std::filesystem::create_directories(dir);
  const auto file = dir / "metrics.txt";
  std::ofstream(file) << text;
  Verdict v;
  v.status = testing_support::run_command("promtool check metrics < '" + file.string() + "'", &v.output);
  std::filesystem::remove_all(dir);
  return v;
}

// The value of one sample (name with its labels, exactly as rendered).
std::optional<double> sample(const std::string& text, const std::string& series) {
  const std::string key = "\n" + series + " ";
  const auto at = ("\n" + text).find(key);
  if (at == std::string::npos) return std::nullopt;
  return std::stod(text.substr(at + key.size() - 1));
}

void expect_promtool_accepts(const std::string& text) {
  ASSERT_EQ(std::system("command -v promtool > /dev/null 2>&1"), 0)
      << "promtool (Debian package prometheus) is not installed: run scripts/install-deps.sh";
  const Verdict v = promtool_check(text);
  EXPECT_EQ(v.status, 0) << v.output;
  EXPECT_EQ(v.output, "") << "promtool lint findings:\n" << v.output;  // lint problems print, even at status 0
}

TEST(Metrics, EveryFamilyHasHelpAndTypeAndHistogramsAreCumulative) {
  ServerCounters c;
  StorageCounters st;
  EncodeCounters enc;
  c.clients = 3;
  c.admin_sessions = 1;
  c.edits_applied = 41;
  c.rejected(RejectReason::kOutsideWorld, 2);
  c.net.disconnected(CloseReason::kIdleTimeout);
  c.tick_duration.observe(300us);   // le 0.0005
  c.tick_duration.observe(2ms);     // le 0.0025
  c.tick_duration.observe(2s);      // +Inf only
  c.net.sent_bytes[static_cast<std::size_t>(wire::Body::StreamBatch)] = 1234;
  enc.asked = 10;
  enc.made = 4;
  const std::string text = render_metrics(MetricsSources{c, st, enc, false, read_process_stats()});
  EXPECT_EQ(sample(text, "terrane_clients"), 3);
  EXPECT_EQ(sample(text, "terrane_admin_sessions"), 1);
  EXPECT_EQ(sample(text, "terrane_edits_applied_total"), 41);
  EXPECT_EQ(sample(text, "terrane_edits_rejected_total{reason=\"outside_world\"}"), 2);
  EXPECT_EQ(sample(text, "terrane_edits_rejected_total{reason=\"queue_full\"}"), 0);
  EXPECT_EQ(sample(text, "terrane_disconnects_total{reason=\"idle_timeout\"}"), 1);
  EXPECT_EQ(sample(text, "terrane_tick_duration_seconds_bucket{le=\"0.0005\"}"), 1);
  EXPECT_EQ(sample(text, "terrane_tick_duration_seconds_bucket{le=\"0.001\"}"), 1);
  EXPECT_EQ(sample(text, "terrane_tick_duration_seconds_bucket{le=\"0.0025\"}"), 2);
  EXPECT_EQ(sample(text, "terrane_tick_duration_seconds_bucket{le=\"1\"}"), 2);
  EXPECT_EQ(sample(text, "terrane_tick_duration_seconds_bucket{le=\"+Inf\"}"), 3);
  EXPECT_EQ(sample(text, "terrane_tick_duration_seconds_count"), 3);
  EXPECT_NEAR(*sample(text, "terrane_tick_duration_seconds_sum"), 2.0023, 1e-6);
  EXPECT_EQ(sample(text, "terrane_sent_bytes_total{type=\"StreamBatch\"}"), 1234);
  EXPECT_EQ(sample(text, "terrane_encode_cache_hits_total"), 6);
  EXPECT_EQ(sample(text, "terrane_encode_cache_misses_total"), 4);
  EXPECT_GT(*sample(text, "process_resident_memory_bytes"), 0);
  EXPECT_GT(*sample(text, "process_start_time_seconds"), 1.6e9);
  // Each family declared once, before its samples.
  // (No std::regex: GCC 12 warns inside it under the sanitizer build.)
  std::set<std::string> families;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("# TYPE ", 0) != 0) continue;
    const std::string name = line.substr(7, line.find(' ', 7) - 7);
    const std::string type = line.substr(line.find(' ', 7) + 1);
    EXPECT_TRUE(type == "counter" || type == "gauge" || type == "histogram") << line;
    EXPECT_TRUE(families.insert(name).second) << "declared twice: " << name;
  }
  EXPECT_GT(families.size(), 40u);
  expect_promtool_accepts(text);
}

TEST(Metrics, HealthWantsRecentTicksAndAWorkingStore) {
  ServerCounters c;
  const auto now = std::chrono::steady_clock::now();
  EXPECT_FALSE(check_health(c, false, 20, now).ok());  // not ticking yet
  EXPECT_EQ(check_health(c, false, 20, now).state, HealthState::kStarting);
  c.last_tick_at_ns = steady_ns(now);
  EXPECT_TRUE(check_health(c, false, 20, now + 900ms).ok());
  const Health late = check_health(c, false, 20, now + 1500ms);
  EXPECT_FALSE(late.ok());
  EXPECT_EQ(late.state, HealthState::kFailing);
  EXPECT_NE(late.text.find("no tick for 1500 ms"), std::string::npos) << late.text;
  EXPECT_TRUE(check_health(c, false, 1, now + 9s).ok());  // 1 Hz: ten periods allowed
  const Health failed = check_health(c, true, 20, now);
  EXPECT_FALSE(failed.ok());
  EXPECT_NE(failed.text.find("storage failed"), std::string::npos);
}

TEST(Metrics, HealthWantsASharedWorldsDatabaseWithinReach) {
  ServerCounters c;
  const auto now = std::chrono::steady_clock::now();
  c.last_tick_at_ns = steady_ns(now);
  DatabaseCounters& db = c.database;
  db.lease_renewed_at_ns = steady_ns(now);
  EXPECT_TRUE(check_health(c, false, 20, now, 1000ms).ok());
  // Renewals: two periods may pass, not more.
  EXPECT_TRUE(check_health(c, false, 20, now + 900ms, 1000ms).ok()) << check_health(c, false, 20, now + 900ms, 1000ms).text;
  db.lease_renewed_at_ns = steady_ns(now - 1900ms);
  EXPECT_TRUE(check_health(c, false, 20, now, 1000ms).ok());
  db.lease_renewed_at_ns = steady_ns(now - 2100ms);
  const Health lagging = check_health(c, false, 20, now, 1000ms);
  EXPECT_FALSE(lagging.ok());
  EXPECT_NE(lagging.text.find("leases not renewed for 2100 ms"), std::string::npos) << lagging.text;
  // A world directory has no leases: the same counters mean nothing there.
  EXPECT_TRUE(check_health(c, false, 20, now).ok());
  db.lease_renewed_at_ns = steady_ns(now);
  // A commit tried again: the world's changes wait (SQLite's commits are
  // never tried again; the counter stays 0 there).
  db.commits_retrying = 1;
  db.commit_retries = 3;
  for (const auto renewal : {1000ms, 0ms}) {
    const Health retrying = check_health(c, false, 20, now, renewal);
    EXPECT_FALSE(retrying.ok());
    EXPECT_NE(retrying.text.find("storage retrying"), std::string::npos) << retrying.text;
    EXPECT_NE(retrying.text.find("3 failed attempts"), std::string::npos) << retrying.text;
  }
  db.commits_retrying = 0;
  EXPECT_TRUE(check_health(c, false, 20, now, 1000ms).ok());
  db.listener_down = 1;
  const Health deaf = check_health(c, false, 20, now, 1000ms);
  EXPECT_FALSE(deaf.ok());
  EXPECT_NE(deaf.text.find("database connection broken"), std::string::npos) << deaf.text;
  db.listener_down = 0;
  db.inbox_failing = 1;
  const Health inbox = check_health(c, false, 20, now, 1000ms);
  EXPECT_FALSE(inbox.ok());
  EXPECT_NE(inbox.text.find("inbox"), std::string::npos) << inbox.text;
  db.inbox_failing = 0;
  EXPECT_TRUE(check_health(c, false, 20, now, 1000ms).ok());
  // A failed commit says so, whatever else is wrong; every reason is one line.
  db.listener_down = 1;
  const Health failed = check_health(c, true, 20, now, 1000ms);
  EXPECT_FALSE(failed.ok());
  EXPECT_NE(failed.text.find("storage failed"), std::string::npos) << failed.text;
  for (const Health& h : {lagging, deaf, inbox, failed}) EXPECT_EQ(h.text.find('\n'), std::string::npos) << h.text;
}

TEST(Metrics, TheDatabaseLinksAreGauges) {
  ServerCounters c;
  StorageCounters st;
  EncodeCounters enc;
  MetricsSources s{c, st, enc, false, read_process_stats()};
  const std::string directory = render_metrics(s);
  EXPECT_EQ(sample(directory, "terrane_storage_retrying"), 0);
  EXPECT_EQ(sample(directory, "terrane_lease_renewal_age_seconds"), 0);
  c.database.commits_retrying = 1;
  c.database.commit_retries = 4;
  c.database.listener_down = 1;
  c.database.inbox_failing = 1;
  c.database.lease_renewed_at_ns = steady_ns(s.now - 2500ms);
  const std::string text = render_metrics(s);
  EXPECT_EQ(sample(text, "terrane_storage_retrying"), 1);
  EXPECT_EQ(sample(text, "terrane_storage_retries_total"), 4);
  EXPECT_NEAR(*sample(text, "terrane_lease_renewal_age_seconds"), 2.5, 1e-6);
  EXPECT_EQ(sample(text, "terrane_database_listener_down"), 1);
  EXPECT_EQ(sample(text, "terrane_inbox_read_failing"), 1);
  expect_promtool_accepts(text);
}

TEST(Metrics, TheBorderIsFourGaugesOnlyWhileTheWorldHasOne) {
  ServerCounters c;
  StorageCounters st;
  EncodeCounters enc;
  MetricsSources s{c, st, enc, false, read_process_stats()};
  const std::string open = render_metrics(s);
  EXPECT_EQ(sample(open, "terrane_world_bounded"), 0);
  EXPECT_EQ(open.find("terrane_world_border_voxels"), std::string::npos) << open;
  s.bounds = WorldBounds{-128, 256, true, -1000, 2000, -30, 40};
  const std::string bounded = render_metrics(s);
  EXPECT_EQ(sample(bounded, "terrane_world_bounded"), 1);
  EXPECT_EQ(sample(bounded, "terrane_world_border_voxels{edge=\"min_x\"}"), -1000);
  EXPECT_EQ(sample(bounded, "terrane_world_border_voxels{edge=\"max_x\"}"), 2000);
  EXPECT_EQ(sample(bounded, "terrane_world_border_voxels{edge=\"min_z\"}"), -30);
  EXPECT_EQ(sample(bounded, "terrane_world_border_voxels{edge=\"max_z\"}"), 40);
  expect_promtool_accepts(bounded);
}

TEST(Metrics, HostPortIsParsedOrNamedWrong) {
  EXPECT_EQ(parse_host_port("127.0.0.1:9464").value(), std::make_pair(std::string("127.0.0.1"), std::uint16_t{9464}));
  EXPECT_EQ(parse_host_port("[::1]:0").value(), std::make_pair(std::string("::1"), std::uint16_t{0}));
  EXPECT_NE(parse_host_port("9464").error().message.find("not HOST:PORT"), std::string::npos);
  EXPECT_NE(parse_host_port("localhost:http").error().message.find("port must be a number"), std::string::npos);
  EXPECT_NE(parse_host_port("localhost:70000").error().message.find("port must be a number"), std::string::npos);
}

// A world directory on a file system with less free space than
// --min-free-mb: the server refuses to start and says why.
TEST(Metrics, TooLittleFreeSpaceRefusesTheStart) {
  const auto dir = testing_support::scratch_dir("terrane-free-space");
  ServerOptions o;
  o.world_dir = (dir / "world").string();
  o.storage.min_free_mb = std::uint64_t{1} << 40;  // a million TiB: more than any disk here
  auto server = Server::create(o);
  ASSERT_FALSE(server.ok());
  EXPECT_NE(server.error().message.find("MiB free on its file system, below --min-free-mb 1099511627776"),
            std::string::npos)
      << server.error().message;
  o.storage.min_free_mb = 0;  // no check
  auto started = Server::create(o);
  ASSERT_TRUE(started.ok()) << started.error().message;
  started->reset();
  std::filesystem::remove_all(dir);
}

class MetricsEndpointTest : public ServerTest {
 protected:
  std::string get(const std::string& path, int* status = nullptr) {
    httplib::Client http("127.0.0.1", server_->metrics_port());
    http.set_connection_timeout(10, 0);
    http.set_read_timeout(30, 0);
    auto res = http.Get(path);
    EXPECT_TRUE(res) << "GET " << path << ": " << httplib::to_string(res.error());
    if (!res) return {};
    if (status != nullptr) *status = res->status;
    return res->body;
  }
  // Scrapes until pred holds (a counter another thread moves), or a deadline.
  template <class Pred>
  std::string scrape_until(Pred pred) {
    std::string text;
    testing_support::eventually([&] { return pred(text = get("/metrics")); });
    return text;
  }
};

TEST_F(MetricsEndpointTest, PromtoolAcceptsTheEndpointAndItsCountersMoveWhenAClientEdits) {
  ServerOptions o;
  o.ops.metrics_address = "127.0.0.1:0";
  start(o);
  ASSERT_NE(server_->metrics_port(), 0);
  // Healthy from the first tick on (503 "not ticking yet" before it).
  int status = 0;
  std::string health;
  testing_support::eventually([&] {
    health = get("/health", &status);
    if (status != 200) {
      EXPECT_EQ(health, "starting: not ticking yet\n");
    }
    return status == 200;
  });
  EXPECT_EQ(status, 200);
  EXPECT_EQ(health, "ready\n");
  const std::string before = get("/metrics");
  expect_promtool_accepts(before);
  // The state as a gauge, and the world directory's free space.
  EXPECT_EQ(sample(before, "terrane_health_state{state=\"ready\"}"), 1);
  EXPECT_EQ(sample(before, "terrane_health_state{state=\"starting\"}"), 0);
  EXPECT_GT(sample(before, "terrane_disk_free_bytes").value_or(0), 0);
  EXPECT_EQ(sample(before, "terrane_joins_total"), 0);
  EXPECT_EQ(sample(before, "terrane_edits_applied_total"), 0);

  auto p = join("editor");
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, cp));
  for (std::uint32_t id = 1; id <= 3; ++id) {
    const EditRequestMsg e = testing_support::fill_box_edit(id, Region{{1001, 11, 1001}, {1003, 13, 1003}}, materials::kBrick, static_cast<std::uint8_t>(100 + id));
    ASSERT_TRUE(p->send(build_edit_request(e)));
    ASSERT_TRUE(p->next_of(wire::Body::EditAck));
  }
  EditRequestMsg outside;  // beyond the world's height: refused with a reason
  outside.edit_id = 9;
  outside.kind = EditKind::kFillBox;
  outside.box = {{1001, 100000, 1001}, {1003, 100002, 1003}};
  outside.material = materials::kBrick;
  outside.occupancy = 255;
  ASSERT_TRUE(p->send(build_edit_request(outside)));
  ASSERT_TRUE(p->next_of(wire::Body::EditReject));

  const std::string during = get("/metrics");
  expect_promtool_accepts(during);
  EXPECT_EQ(sample(during, "terrane_clients"), 1);
  EXPECT_EQ(sample(during, "terrane_joins_total"), 1);
  EXPECT_EQ(sample(during, "terrane_edits_applied_total"), 3);
  EXPECT_EQ(sample(during, "terrane_edits_rejected_total{reason=\"outside_world\"}"), 1);
  EXPECT_EQ(sample(during, "terrane_received_frames_total{type=\"EditRequest\"}"), 4);
  EXPECT_GE(sample(during, "terrane_sent_frames_total{type=\"EditAck\"}"), 3);
  EXPECT_GT(sample(during, "terrane_sent_bytes_total{type=\"StreamBatch\"}"), 0);
  EXPECT_GE(sample(during, "terrane_commits_total"), 1);
  EXPECT_GE(sample(during, "terrane_commit_duration_seconds_count"), 1);
  // Each acknowledged edit's time in the server, and only theirs.
  EXPECT_EQ(sample(during, "terrane_edit_ack_duration_seconds_count"), 3);
  EXPECT_GT(sample(during, "terrane_edit_ack_duration_seconds_sum"), 0);
  EXPECT_GE(sample(during, "terrane_chunks_written_total"), 1);
  // The edit log's size, as the writer keeps it (known from its start on,
  // grown by each commit before its acknowledgements).
  EXPECT_EQ(sample(during, "terrane_edit_log_entries"), 3);
  EXPECT_GT(sample(during, "terrane_edit_log_bytes").value_or(0), 0);
  EXPECT_GT(sample(during, "terrane_chunks_resident"), 0);
  EXPECT_GT(sample(during, "terrane_chunks_generated_total"), 0);
  EXPECT_GT(sample(during, "terrane_streamed_chunks_total{kind=\"full\"}"), 0);
  EXPECT_GT(sample(during, "terrane_ticks_total"), sample(before, "terrane_ticks_total"));
  // The memory the client costs, by part: its replicator's slots, the
  // world's record of what it holds, the chunks held for it.
  for (const char* part : {"chunk_slots", "interest", "residency"}) {
    EXPECT_EQ(sample(before, std::string("terrane_memory_bytes{part=\"") + part + "\"}"), 0) << part;
    EXPECT_GT(sample(during, std::string("terrane_memory_bytes{part=\"") + part + "\"}"), 0) << part;
  }
  // SQLite's memory: the server's world is open (its schema and
  // statements) before any client, and its chunks were read and written
  // since.
  EXPECT_GT(sample(before, "terrane_memory_bytes{part=\"store\"}"), 0);
  EXPECT_GT(sample(during, "terrane_memory_bytes{part=\"store\"}"), 0);

  // The client leaves with a reset, as one that quits with stream data
  // unread does: still the client closing, counted once the server sees it.
  p->reset();
  // Once it left, its slots are gone and the interest index holds nothing.
  const std::string after = scrape_until([&](const std::string& t) {
    return sample(t, "terrane_disconnects_total{reason=\"peer_closed\"}") == 1 &&
           sample(t, "terrane_memory_bytes{part=\"chunk_slots\"}") == 0 &&
           sample(t, "terrane_memory_bytes{part=\"interest\"}") == 0;
  });
  EXPECT_EQ(sample(after, "terrane_disconnects_total{reason=\"peer_closed\"}"), 1) << after;
  EXPECT_EQ(sample(after, "terrane_clients"), 0);
  EXPECT_EQ(sample(after, "terrane_send_queue_bytes"), 0);
  EXPECT_EQ(sample(after, "terrane_memory_bytes{part=\"chunk_slots\"}"), 0) << after;
  EXPECT_EQ(sample(after, "terrane_memory_bytes{part=\"interest\"}"), 0) << after;
}

// The border as the running server has it: the world's, whatever the
// start's options said (a restart without --border keeps it, --border none
// removes it).
TEST_F(MetricsEndpointTest, TheWorldBorderShowsWhileTheWorldHasOne) {
  ServerOptions o;
  o.ops.metrics_address = "127.0.0.1:0";
  o.border_set = true;
  o.border = WorldBounds{0, 1, true, -64, 96, 0, 32};  // x in [-64, 96), z in [0, 32)
  start(o);
  const std::string bounded = get("/metrics");
  expect_promtool_accepts(bounded);
  EXPECT_EQ(sample(bounded, "terrane_world_bounded"), 1) << bounded;
  EXPECT_EQ(sample(bounded, "terrane_world_border_voxels{edge=\"min_x\"}"), -64) << bounded;
  EXPECT_EQ(sample(bounded, "terrane_world_border_voxels{edge=\"max_x\"}"), 96) << bounded;
  EXPECT_EQ(sample(bounded, "terrane_world_border_voxels{edge=\"min_z\"}"), 0) << bounded;
  EXPECT_EQ(sample(bounded, "terrane_world_border_voxels{edge=\"max_z\"}"), 32) << bounded;
  server_->stop();
  server_.reset();

  ServerOptions kept;  // no --border: the world's
  kept.ops.metrics_address = "127.0.0.1:0";
  start(kept);
  EXPECT_EQ(sample(get("/metrics"), "terrane_world_border_voxels{edge=\"max_x\"}"), 96);
  server_->stop();
  server_.reset();

  ServerOptions none = kept;  // --border none
  none.border_set = true;
  start(none);
  const std::string open = get("/metrics");
  expect_promtool_accepts(open);
  EXPECT_EQ(sample(open, "terrane_world_bounded"), 0) << open;
  EXPECT_EQ(open.find("terrane_world_border_voxels"), std::string::npos) << open;
}

TEST_F(MetricsEndpointTest, ABadOrTakenAddressIsAClearError) {
  ServerOptions o;
  o.ops.metrics_address = "127.0.0.1:0";
  start(o);
  ServerOptions again;
  again.world_dir = (dir_ / "second").string();
  again.ops.metrics_address = "127.0.0.1:" + std::to_string(server_->metrics_port());
  auto taken = Server::create(again);
  ASSERT_FALSE(taken.ok());
  EXPECT_NE(taken.error().message.find("metrics: cannot listen on 127.0.0.1:"), std::string::npos)
      << taken.error().message;
  again.ops.metrics_address = "nowhere";
  auto bad = Server::create(again);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("--metrics: 'nowhere' is not HOST:PORT"), std::string::npos)
      << bad.error().message;
}

}  // namespace
}  // namespace terrane
