// Replicator: what a move releases and asks for. A chunk is asked for when
// it comes into view and released only once it is more than kKeepMargin
// beyond the view: a client stepping into the next chunk and back has
// nothing released and nothing asked again, while one that goes on
// releases the shell it left behind (and only chunks beyond the margin).
#include "server/replication/replicator.h"

#include <gtest/gtest.h>

#include "common/world/view.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using testing_support::msg;

class ReplicatorTest : public testing_support::ServerTest {
 protected:
  static constexpr std::int32_t kView = 96, kFull = 24;

  struct Seen {
    std::vector<Vec3i> released;
    std::size_t chunk_records = 0;  // Empty, Full, Mip, Estimate
  };

  // Sends the move, then a ping, and reads up to its Pong (sent after the
  // move was handled: one strand), noting the records that came.
  Seen move_and_sync(testing_support::RawPeer& p, Vec3f pos, std::uint64_t nonce) {
    Seen seen;
    EXPECT_TRUE(p.send(build_client_state(ClientStateMsg{pos, kView, kFull})));
    EXPECT_TRUE(records_until_pong(p, nonce, [&](const StreamRecord& r) { note(r, seen); }));
    return seen;
  }

  // Moves p to pos and reads the stream until every chunk in view is held
  // at the level the view rule gives it (Empty counts as full resolution;
  // an Estimate as coarser than any level).
  bool stream_whole_view(testing_support::RawPeer& p, Vec3f pos) {
    if (!p.send(build_client_state(ClientStateMsg{pos, kView, kFull}))) return false;
    auto complete = [&] {
      for (const Vec3i cp : chunks_in_view(pos, kView, bounds_)) {
        auto it = held_.find(cp);
        if (it == held_.end() || it->second > desired_level(pos, cp, kFull)) return false;
      }
      return true;
    };
    Seen ignored;
    while (!complete()) {
      auto f = p.next_of(wire::Body::StreamBatch);
      if (!f || !for_each_record(msg(*f), [&](const StreamRecord& r) { note(r, ignored); })) return false;
    }
    return true;
  }

  // What the client holds after r, and what r was.
  void note(const StreamRecord& r, Seen& seen) {
    switch (r.kind) {
      case StreamRecordKind::kHorizon: break;
      case StreamRecordKind::kReleased:
        seen.released.push_back(r.chunk_pos);
        held_.erase(r.chunk_pos);
        break;
      default:
        ++seen.chunk_records;
        held_[r.chunk_pos] = r.kind == StreamRecordKind::kFull || r.kind == StreamRecordKind::kEmpty ? 0
                             : r.kind == StreamRecordKind::kEstimate                                 ? kMipLevels
                                                                                                     : r.level;
    }
  }

  // Joins, keeping the world's bounds from the Welcome.
  std::unique_ptr<testing_support::RawPeer> join_keeping_bounds(const std::string& name) {
    auto p = std::make_unique<testing_support::RawPeer>(server_->port());
    EXPECT_TRUE(p->send(build_hello(HelloMsg{kProtocolVersion, name, "", {}})));
    auto f = p->next_of(wire::Body::Welcome);
    EXPECT_TRUE(f.has_value());
    if (f) {
      auto w = parse_welcome(*msg(*f).body_as_Welcome());
      EXPECT_TRUE(w.ok());
      if (w.ok()) bounds_ = w->bounds();
    }
    return p;
  }

  Vec3iMap<int> held_;  // what the client holds, at which level
  WorldBounds bounds_;
};

TEST_F(ReplicatorTest, AStepIntoTheNextChunkAndBackReleasesNothingAndAsksForNothingAgain) {
  ServerOptions o;
  o.replication.max_speed = 0;  // it steps a chunk at a time, at once
  // Every distant chunk sent as its own mip: no estimate is corrected later
  // by a record of its own.
  o.replication.horizon_estimates = false;
  start(o);
  auto p = join_keeping_bounds("stepper");
  const Vec3f a{1008.0f, 12.0f, 1008.0f};
  const Vec3f b = a + Vec3f{32.0f, 0.0f, 0.0f};  // the next chunk in x
  ASSERT_TRUE(stream_whole_view(*p, a));
  // Forward: the shell behind leaves the view but stays within the margin.
  ASSERT_TRUE(stream_whole_view(*p, b));
  Seen seen = move_and_sync(*p, b, 1);  // (anything still on its way for b)
  EXPECT_TRUE(seen.released.empty());
  // And back: every chunk in view is still held.
  const std::uint64_t asked = server_->counters().chunks_asked.load();
  seen = move_and_sync(*p, a, 2);
  EXPECT_TRUE(seen.released.empty());
  EXPECT_EQ(seen.chunk_records, 0u);
  EXPECT_EQ(server_->counters().chunks_asked.load(), asked);
}

TEST_F(ReplicatorTest, ChunksAreReleasedOnlyBeyondTheViewAndItsMargin) {
  ServerOptions o;
  o.replication.max_speed = 0;
  o.replication.horizon_estimates = false;
  start(o);
  auto p = join_keeping_bounds("walker");
  Vec3f pos{1008.0f, 12.0f, 1008.0f};
  ASSERT_TRUE(stream_whole_view(*p, pos));
  std::vector<Vec3i> released;
  for (int step = 1; step <= 4; ++step) {
    pos = pos + Vec3f{32.0f, 0.0f, 0.0f};
    const Seen seen = move_and_sync(*p, pos, static_cast<std::uint64_t>(step));
    for (const Vec3i cp : seen.released) {
      // Beyond the view and its margin from where the client is now.
      EXPECT_FALSE(within(pos, cp, kView + Replicator::kKeepMargin)) << cp.x << "," << cp.y << "," << cp.z;
      released.push_back(cp);
    }
  }
  // Four chunks on, the chunks of the first view's back edge are released.
  EXPECT_FALSE(released.empty());
  const Vec3i back = view_chunk({1008.0f, 12.0f, 1008.0f}) - Vec3i{kView / kChunkSize, 0, 0};
  EXPECT_NE(std::find(released.begin(), released.end(), back), released.end());
}

}  // namespace
}  // namespace terrane
