// StreamGate: when streaming yields to live traffic. The rule from probe
// lateness (hysteresis, either probe, a hold), real probes on io contexts
// that fall behind, and a server whose streaming is paused: no chunk is
// streamed, edits and updates go on, and streaming resumes once it opens.
#include "server/replication/stream_gate.h"

#include <gtest/gtest.h>

#include <thread>

#include "tests/support/eventually.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::eventually;
using testing_support::msg;
using Probe = StreamGate::Probe;

TEST(StreamGate, ALateProbeClosesItAndOnlyEveryProbeBackWithinHalfOpensIt) {
  StreamGate g(20ms);
  EXPECT_TRUE(g.open());
  g.observe(Probe::kIo, 15ms);  // late, within the threshold
  EXPECT_TRUE(g.open());
  g.observe(Probe::kIo, 25ms);
  EXPECT_FALSE(g.open());
  EXPECT_EQ(g.closed_count(), 1u);
  g.observe(Probe::kIo, 15ms);  // better, not yet within half
  EXPECT_FALSE(g.open());
  g.observe(Probe::kIo, 10ms);
  EXPECT_TRUE(g.open());
  // Either probe closes it; both must be back.
  g.observe(Probe::kWorld, 30ms);
  EXPECT_FALSE(g.open());
  g.observe(Probe::kIo, 0ms);
  EXPECT_FALSE(g.open());
  g.observe(Probe::kWorld, 1ms);
  EXPECT_TRUE(g.open());
  EXPECT_EQ(g.closed_count(), 2u);
  EXPECT_GT(g.closed_seconds(), 0.0);
}

TEST(StreamGate, AHoldKeepsItClosedWhateverTheProbesSay) {
  StreamGate g(20ms);
  g.hold_closed(true);
  EXPECT_FALSE(g.open());
  EXPECT_TRUE(g.held());
  g.observe(Probe::kIo, 0ms);
  g.observe(Probe::kWorld, 0ms);
  EXPECT_FALSE(g.open());
  g.hold_closed(false);
  EXPECT_TRUE(g.open());
  EXPECT_FALSE(g.held());
}

TEST(StreamGate, ThresholdZeroNeverCloses) {
  StreamGate g(0ms);
  g.observe(Probe::kIo, 10s);
  EXPECT_TRUE(g.open());
  EXPECT_EQ(g.closed_count(), 0u);
}

TEST(StreamGate, ProbesCloseItWhileAContextFallsBehindAndOpenItWhenItCatchesUp) {
  asio::io_context io, world;
  auto io_work = asio::make_work_guard(io);
  auto world_work = asio::make_work_guard(world);
  std::thread io_thread([&] { io.run(); });
  std::thread world_thread([&] { world.run(); });
  StreamGate g(20ms);
  g.start(io, world);
  // The world falls behind: handlers that each keep it busy past the
  // threshold, queued until the gate is seen closed (the probe that closes
  // it waited behind one of them).
  std::atomic<bool> seen_closed{false};
  std::function<void()> busy = [&] {
    const auto until = std::chrono::steady_clock::now() + 30ms;
    while (std::chrono::steady_clock::now() < until) {
    }
    if (!seen_closed) asio::post(world, busy);
  };
  asio::post(world, busy);
  EXPECT_TRUE(eventually([&] { return !g.open(); }));
  seen_closed = true;
  // Idle again: the next probes are on time.
  EXPECT_TRUE(eventually([&] { return g.open(); }));
  EXPECT_GE(g.closed_count(), 1u);
  g.stop();
  io_work.reset();
  world_work.reset();
  io_thread.join();  // the probes are gone: nothing keeps the contexts running
  world_thread.join();
}

class StreamGateServerTest : public testing_support::ServerTest {};

TEST_F(StreamGateServerTest, WhileClosedNothingIsStreamedButEditsAndUpdatesGoOn) {
  ServerOptions o;
  o.replication.horizon_images = false;  // a new view's first pump asks for chunks at once (not after its horizon images)
  start(o);
  StreamGate& gate = server_->stream_gate();
  gate.hold_closed(true);
  auto p = join("walker");
  const Vec3f pos{1002.0f, 12.0f, 1002.0f};
  ASSERT_TRUE(p->send(build_client_state(ClientStateMsg{pos, 96, 24})));
  // Its streaming yielded (the pump that the ClientState ran found the gate
  // closed). The answer to a later ping is sent after that handler ended
  // (one strand, in order): by then nothing was asked of the world, and no
  // chunk's record came.
  ASSERT_TRUE(eventually([&] { return server_->counters().stream_yields.load() >= 1; }));
  std::size_t chunk_records = 0;
  ASSERT_TRUE(records_until_pong(*p, 7, [&](const StreamRecord& r) {
    if (r.kind != StreamRecordKind::kHorizon && r.kind != StreamRecordKind::kReleased) ++chunk_records;
  }));
  EXPECT_EQ(chunk_records, 0u);
  EXPECT_EQ(server_->counters().chunks_asked.load(), 0u);
  // Opened: streaming resumes (on the replicator's timer) and completes.
  gate.hold_closed(false);
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  ASSERT_TRUE(hold_full(*p, pos, cp));
  // Closed again: an edit in what the client holds is acknowledged and
  // its update arrives.
  gate.hold_closed(true);
  const EditRequestMsg e =
      testing_support::fill_box_edit(1, Region{{1001, 11, 1001}, {1003, 13, 1003}}, materials::kBrick, 255);
  ASSERT_TRUE(p->send(build_edit_request(e)));
  EXPECT_TRUE(p->next_of_both(wire::Body::EditAck, wire::Body::UpdateBatch).has_value());
  gate.hold_closed(false);
}

TEST_F(StreamGateServerTest, WhileClosedRefreshesOfMipsWaitAndComeOnceItOpens) {
  ServerOptions o;
  // Every distant chunk sent as its own mip: no estimate is corrected by a
  // refresh of its own while the test counts refreshes.
  o.replication.horizon_estimates = false;
  start(o);
  StreamGate& gate = server_->stream_gate();
  // The editor holds the edited chunk at full resolution; the watcher, 60
  // voxels away, holds it as mip 1.
  const EditRequestMsg e = testing_support::fill_box_edit(1, Region{{1060, 8, 1002}, {1063, 11, 1005}}, materials::kBrick, 255);
  const Vec3i cp = chunk_of(e.box.min);
  auto editor = join("editor");
  ASSERT_TRUE(hold_full(*editor, {1062.0f, 12.0f, 1002.0f}, cp));
  auto watcher = join("watcher");
  ASSERT_TRUE(hold_at(*watcher, {1002.0f, 12.0f, 1002.0f}, {{cp, 1}}));
  gate.hold_closed(true);
  ASSERT_TRUE(editor->send(build_edit_request(e)));
  EXPECT_TRUE(editor->next_of_both(wire::Body::EditAck, wire::Body::UpdateBatch).has_value());
  // The watcher's refresh came due and waited; a ping answered after that
  // finds nothing of the chunk sent.
  ASSERT_TRUE(eventually([&] { return server_->counters().mip_refresh_yields.load() >= 1; }));
  std::size_t records_of_cp = 0;
  std::uint64_t revision = 0;
  auto note = [&](const StreamRecord& r) {
    if (r.chunk_pos == cp) ++records_of_cp, revision = r.revision;
  };
  ASSERT_TRUE(records_until_pong(*watcher, 7, note));
  EXPECT_EQ(records_of_cp, 0u);
  EXPECT_EQ(server_->counters().mip_refreshes.load(), 0u);
  // Opened: the refresh comes, with the edit's revision.
  gate.hold_closed(false);
  while (revision == 0) {
    auto f = watcher->next_of(wire::Body::StreamBatch);
    ASSERT_TRUE(f.has_value());
    ASSERT_TRUE(for_each_record(msg(*f), note));
  }
  EXPECT_EQ(revision, 1u);
  EXPECT_EQ(server_->counters().mip_refreshes.load(), 1u);
}

TEST_F(StreamGateServerTest, ClosedByTheProbesStreamingSlowsButNeverStops) {
  // A threshold so long that the probes (every quarter of it) neither close
  // nor reopen the gate during the test: one late observation closes it.
  ServerOptions o;
  o.replication.stream_yield = std::chrono::minutes(10);
  start(o);
  StreamGate& gate = server_->stream_gate();
  gate.observe(Probe::kIo, std::chrono::minutes(11));
  ASSERT_FALSE(gate.open());
  ASSERT_FALSE(gate.held());
  auto p = join("walker");
  const Vec3f pos{1002.0f, 12.0f, 1002.0f};
  // The view fills while the gate stays closed: each yield ends after
  // at most 2 s with one pump.
  EXPECT_TRUE(hold_full(*p, pos, chunk_of(Vec3i{1002, 12, 1002})));
  EXPECT_FALSE(gate.open());
  EXPECT_GE(server_->counters().stream_yields.load(), 1u);
}

}  // namespace
}  // namespace terrane
