// ClusterControl against a real PostgreSQL started by the test: what the
// world owner asks of the other servers through Storage runs on the
// control thread, in the order asked. A claim holds the region and lists
// what another server stored there; a region held elsewhere names its
// holder; forwarded edits reach the addressee's inbox in order, a relay
// readdresses one, and a refusal reaches the sender's answers.
#include "server/cluster/cluster_control.h"

#include <gtest/gtest.h>

#include <chrono>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include "common/world/world.h"
#include "server/storage/forwarded_edit.h"
#include "server/storage/postgres_store.h"
#include "tests/support/postgres.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;

constexpr auto kDeadline = 30s;

class ClusterControlTest : public testing_support::PostgresTest {
 protected:
  // A server's side of the cluster room: its leases and its control thread.
  struct Side {
    std::unique_ptr<LeaseKeeper> keeper;
    std::unique_ptr<ClusterControl> control;
  };
  Side side(std::uint32_t id) {
    Side s;
    auto k = LeaseKeeper::open(url_, id, LeaseTimes{}, nullptr);
    EXPECT_TRUE(k.ok()) << (k.ok() ? "" : k.error().message);
    if (!k.ok()) return s;
    s.keeper = std::move(*k);
    auto c = ClusterControl::open(url_, *s.keeper);
    EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
    if (c.ok()) s.control = std::move(*c);
    return s;
  }
  // What an asynchronous call hands its done, waited for with a deadline.
  template <class T>
  static std::optional<T> wait(std::future<T>& f) {
    if (f.wait_for(kDeadline) != std::future_status::ready) return std::nullopt;
    return f.get();
  }
  RegionClaim claim(ClusterControl& c, Vec3i region) {
    auto done = std::make_shared<std::promise<RegionClaim>>();
    auto f = done->get_future();
    c.claim(region, ClaimRule::kAny, [done](RegionClaim got) { done->set_value(std::move(got)); });
    auto got = wait(f);
    EXPECT_TRUE(got) << "the claim was never answered";
    return got.value_or(RegionClaim{});
  }
  std::vector<InboxEdit> inbox(ClusterControl& c) {
    auto done = std::make_shared<std::promise<StoreResult<std::vector<InboxEdit>>>>();
    auto f = done->get_future();
    c.read_inbox(0, 10, [done](StoreResult<std::vector<InboxEdit>> got) { done->set_value(std::move(got)); });
    auto got = wait(f);
    EXPECT_TRUE(got && got->ok()) << (got && !got->ok() ? got->error().message : "never answered");
    return got && got->ok() ? **got : std::vector<InboxEdit>{};
  }
};

TEST_F(ClusterControlTest, AClaimHoldsTheRegionAndListsWhatAnotherServerStoredThere) {
  // Server 9 writes a chunk of region (0,0,0), then gives the region up.
  {
    auto keeper = LeaseKeeper::open(url_, 9, LeaseTimes{}, nullptr);
    ASSERT_TRUE(keeper.ok()) << keeper.error().message;
    auto store = PostgresStore::open(url_);
    ASSERT_TRUE(store.ok()) << store.error().message;
    (*store)->set_lease_source((*keeper)->claiming_source());
    const ChunkWrite w{{1, 2, 3}, 4, encode_chunk_blob(Box({kChunkSize, kChunkSize, kChunkSize}))};
    ASSERT_TRUE((*store)->save_chunks(std::span(&w, 1)).ok());
    ASSERT_TRUE((*keeper)->release_all().ok());
  }
  Side one = side(1), two = side(2);
  ASSERT_TRUE(one.control && two.control);
  EXPECT_EQ(one.control->server_id(), 1u);
  EXPECT_FALSE(one.control->holds({0, 0, 0}));
  const RegionClaim got = claim(*one.control, {0, 0, 0});
  ASSERT_TRUE(got.held) << got.why;
  EXPECT_EQ(got.stored, (std::vector<std::pair<Vec3i, std::uint64_t>>{{{1, 2, 3}, 4}}));
  EXPECT_TRUE(one.control->holds({0, 0, 0}));
  // Held by server 1: server 2's claim names it, and holds nothing.
  const RegionClaim refused = claim(*two.control, {0, 0, 0});
  EXPECT_FALSE(refused.held);
  EXPECT_FALSE(refused.unreachable);
  EXPECT_EQ(refused.holder, std::optional<std::uint32_t>(1));
  EXPECT_NE(refused.why.find("server 1"), std::string::npos) << refused.why;
  EXPECT_FALSE(two.control->holds({0, 0, 0}));
}

TEST_F(ClusterControlTest, ForwardedEditsReachTheInboxInOrderAndARefusalReachesTheSender) {
  Side one = side(1), two = side(2);
  ASSERT_TRUE(one.control && two.control);
  // Server 1 holds region (5,0,0) and hands it over with its first forward.
  ASSERT_TRUE(claim(*one.control, {5, 0, 0}).held);
  std::vector<std::future<StoreResult<std::int64_t>>> rows;
  std::vector<EditRequestMsg> sent;
  for (const std::uint32_t b : {1u, 2u}) {
    EditRequestMsg e;
    e.edit_id = b;
    e.kind = EditKind::kFillBox;
    e.box = Region{{0, 0, 0}, {2, 2, 2}};
    e.material = materials::kBrick;
    e.occupancy = 255;
    sent.push_back(e);
    auto done = std::make_shared<std::promise<StoreResult<std::int64_t>>>();
    rows.push_back(done->get_future());
    one.control->forward(2, "ann", e, b == 1 ? std::vector<Vec3i>{{5, 0, 0}} : std::vector<Vec3i>{},
                         std::chrono::steady_clock::now() + kDeadline,
                         [done](StoreResult<std::int64_t> id) { done->set_value(std::move(id)); });
  }
  std::vector<std::int64_t> ids;
  for (auto& f : rows) {
    auto id = wait(f);
    ASSERT_TRUE(id && id->ok()) << (id && !id->ok() ? id->error().message : "never answered");
    ids.push_back(**id);
  }
  EXPECT_LT(ids[0], ids[1]) << "forwarded in the order asked";
  EXPECT_FALSE(one.control->holds({5, 0, 0})) << "handed over before the edit went";
  const auto edits = inbox(*two.control);
  ASSERT_EQ(edits.size(), 2u);
  EXPECT_EQ(edits[0].id, ids[0]);
  EXPECT_EQ(edits[0].from, 1u);
  EXPECT_EQ(edits[0].player, "ann");
  // Each row holds its edit's EditRequest frame (the inbox's format).
  EXPECT_EQ(edits[0].edit, build_edit_request(sent[0]));
  EXPECT_EQ(edits[1].edit, build_edit_request(sent[1]));
  auto first = decode_forwarded_edit(edits[0].edit);
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(first->edit_id, 1u);
  // Server 2 passes the first on to server 3 and refuses the second.
  auto relayed = std::make_shared<std::promise<StoreResult<Ok>>>();
  auto relay_done = relayed->get_future();
  two.control->relay(ids[0], 3, {}, [relayed](StoreResult<Ok> r) { relayed->set_value(std::move(r)); });
  auto r = wait(relay_done);
  ASSERT_TRUE(r && r->ok()) << (r && !r->ok() ? r->error().message : "never answered");
  two.control->answer({ForwardAnswer{ids[1], 1, false, 0, "refused here"}});
  const auto left = inbox(*two.control);  // after the answer: the control thread runs in order
  EXPECT_TRUE(left.empty()) << left.size() << " edits still in server 2's inbox";
  auto cluster = ClusterStore::open(url_);
  ASSERT_TRUE(cluster.ok()) << cluster.error().message;
  auto at_three = (*cluster)->inbox(3, 0, 10);
  ASSERT_TRUE(at_three.ok()) << at_three.error().message;
  ASSERT_EQ(at_three->size(), 1u);
  EXPECT_EQ(at_three->front().from, 1u) << "a relay keeps the sender";
  auto answers = (*cluster)->take_answers(1);
  ASSERT_TRUE(answers.ok()) << answers.error().message;
  EXPECT_EQ(*answers, (std::vector<ForwardAnswer>{{ids[1], 1, false, 0, "refused here"}}));
}

// The database restarted while the control thread's connection was idle:
// the next inbox read still succeeds (the connection opened again), and
// inbox_failing says whether the last read failed.
TEST_F(ClusterControlTest, AnInboxReadAfterTheDatabaseRestartedSucceeds) {
  DatabaseCounters counters;
  auto k = LeaseKeeper::open(url_, 2, LeaseTimes{}, nullptr);
  ASSERT_TRUE(k.ok()) << k.error().message;
  auto c = ClusterControl::open(url_, **k, &counters);
  ASSERT_TRUE(c.ok()) << c.error().message;
  ClusterControl& control = **c;
  EXPECT_TRUE(inbox(control).empty());
  ASSERT_TRUE(pg_->restart()) << pg_->why();
  EXPECT_TRUE(inbox(control).empty());
  EXPECT_EQ(counters.inbox_failing.load(), 0u);
  // Down: the read fails, and says so until a read succeeds.
  ASSERT_TRUE(pg_->stop()) << pg_->why();
  auto done = std::make_shared<std::promise<StoreResult<std::vector<InboxEdit>>>>();
  auto f = done->get_future();
  control.read_inbox(0, 10, [done](StoreResult<std::vector<InboxEdit>> got) { done->set_value(std::move(got)); });
  const auto failed = wait(f);
  const bool started_again = pg_->start_again();
  ASSERT_TRUE(started_again) << pg_->why();
  ASSERT_TRUE(failed) << "never answered";
  EXPECT_FALSE(failed->ok());
  EXPECT_EQ(counters.inbox_failing.load(), 1u);
  EXPECT_TRUE(inbox(control).empty());
  EXPECT_EQ(counters.inbox_failing.load(), 0u);
  control.stop();
}

}  // namespace
}  // namespace terrane
