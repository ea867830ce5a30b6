// ClusterNode: none for a SQLite world; for a PostgreSQL world (a real
// PostgreSQL started by the test) its parts start and stop in order: its
// leases fence the chunk store and are held, its listener hears another
// server's forwarded edit, start() advertises this server and publishes
// the map of writers, and then stop_listening() ends the listener's
// connection, stop_control() the control thread, release() gives the
// leases and the advertised row up so another server claims at once.
#include "server/cluster/cluster_node.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>

#include "common/world/world.h"
#include "tests/support/eventually.h"
#include "tests/support/postgres_stores.h"
#include "tests/support/scratch_dir.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::eventually;
using testing_support::sql_value;

class ClusterNodeTest : public testing_support::PostgresStoresTest {
 protected:
  // Connections named as server 1's change listener.
  std::string listeners() {
    return sql_value(url_, "SELECT count(*) FROM pg_stat_activity WHERE application_name = '" +
                               ChangeListener::name_of(1) + "'");
  }
  // Whether server id is seen running (within lease).
  bool running(ClusterStore& other, std::uint32_t id) {
    auto ids = other.running(lease_);
    return ids.ok() && std::find(ids->begin(), ids->end(), id) != ids->end();
  }
  const std::chrono::milliseconds lease_{3000};
};

TEST_F(ClusterNodeTest, StartsAndStopsItsPartsInOrder) {
  auto store = open();
  ASSERT_TRUE(store);
  ASSERT_TRUE(store->create_world(default_world_meta()).ok());
  ClusterStore* other = cl(store);  // server 2's leases and inbox
  ASSERT_NE(other, nullptr);
  ClusterOptions o;
  o.store_url = url_;
  o.server_id = 1;
  o.lease = lease_;
  auto opened = ClusterNode::open(o, *store, [](const RegionLease&, const std::string&) {});
  ASSERT_TRUE(opened.ok()) << opened.error().message;
  std::unique_ptr<ClusterNode> node = std::move(*opened);
  ASSERT_NE(node, nullptr);
  EXPECT_EQ(node->shared().cluster.server_id(), 1u);
  EXPECT_EQ(&node->shared().store, store.get());

  // Its leases are the writer's: a region claimed is held, and refused to
  // another server.
  const Vec3i region{0, 0, 0};
  ASSERT_TRUE(node->leases().ensure(std::span(&region, 1)).ok());
  EXPECT_TRUE(node->shared().cluster.holds(region));
  auto refused = other->claim(region, 2, lease_);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().kind, StoreError::Kind::kOwned);

  // Listening: another server's forwarded edit reaches it.
  std::atomic<int> inbox{0};
  ChangeListener::Handlers on;
  on.changes = [](std::vector<ChunkChange>) {};
  on.inbox = [&] { ++inbox; };
  on.answer = [](ForwardAnswer) {};
  on.missed = [](std::vector<Vec3i>) {};
  ASSERT_TRUE(node->listen(std::move(on)).ok());
  EXPECT_EQ(listeners(), "1");
  const std::uint8_t edit[] = {1, 2, 3};
  ASSERT_TRUE(other->forward(2, 1, "alice", edit, testing_support::database_now_us(url_) + 20'000'000).ok());
  EXPECT_TRUE(eventually([&] { return inbox.load() >= 1; }));

  // Started: it is seen running at its address, and publishes who writes what.
  EXPECT_EQ(node->directory().current(), nullptr);
  node->start("127.0.0.1:4100");
  EXPECT_TRUE(eventually([&] { return running(*other, 1); }));
  EXPECT_TRUE(eventually([&] { return node->directory().current() != nullptr; }));
  auto cluster = other->cluster(lease_);
  ASSERT_TRUE(cluster.ok());
  EXPECT_NE(std::find(cluster->servers.begin(), cluster->servers.end(), ServerAddress{1, "127.0.0.1", 4100}),
            cluster->servers.end());
  // Alone until another server runs.
  auto alone = node->others_running();
  ASSERT_TRUE(alone.ok());
  EXPECT_TRUE(alone->empty());
  ASSERT_TRUE(other->advertise(2, "").ok());
  auto others = node->others_running();
  ASSERT_TRUE(others.ok());
  EXPECT_EQ(*others, std::vector<std::uint32_t>{2});

  // Stopped in order: the listener's connection ends first, then the
  // control thread; the leases are released last, at once.
  node->stop_listening();
  EXPECT_TRUE(eventually([&] { return listeners() == "0"; }));
  node->stop_control();
  EXPECT_TRUE(node->leases().holds(region)) << "held until released";
  node->release();
  EXPECT_TRUE(other->claim(region, 2, lease_).ok()) << "another server claims at once";
  EXPECT_FALSE(running(*other, 1)) << "no longer advertised";
  node.reset();
}

}  // namespace
}  // namespace terrane
