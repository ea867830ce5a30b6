// SharedAuthority on the world strand against a real PostgreSQL world
// (skipped where PostgreSQL is not installed) with this server's lease
// keeper, a real Residency and FanOut, and a fake edit queue: a free
// region is claimed as an edit asks (waiting until held, then writable);
// a region another server holds is not writable and names its holder; a
// chunk another server changed that nobody here holds is forgotten.
#include "server/world/shared_authority.h"

#include <gtest/gtest.h>

#include <asio.hpp>
#include <future>
#include <thread>

#include "server/cluster/cluster_control.h"
#include "server/cluster/lease_keeper.h"
#include "tests/support/eventually.h"
#include "tests/support/postgres.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;

class NoEdits final : public EditQueue {
 public:
  void queue_forwarded(EditRequestMsg, std::string, Forwarded) override { ++queued; }
  void reject(ClientId, const EditRequestMsg&, RejectReason, const std::string&) override { ++rejected; }
  int queued = 0, rejected = 0;
};

class SharedAuthorityTest : public testing_support::PostgresTest {
 protected:
  void SetUp() override {
    PostgresTest::SetUp();
    if (IsSkipped() || HasFatalFailure()) return;
    auto store = PostgresStore::open(url_);
    ASSERT_TRUE(store.ok()) << store.error().message;
    ASSERT_TRUE((*store)->create_world(default_world_meta()).ok());
    auto keeper = LeaseKeeper::open(url_, 1, LeaseTimes{}, nullptr);
    ASSERT_TRUE(keeper.ok()) << keeper.error().message;
    keeper_ = std::move(*keeper);
    auto control = ClusterControl::open(url_, *keeper_);
    ASSERT_TRUE(control.ok()) << control.error().message;
    control_ = std::move(*control);
    (*store)->set_lease_source(keeper_->held_source(), options_.lease);
    const PostgresStore& chunks = **store;
    auto w = World::open(std::unique_ptr<WorldStore>(std::move(*store)));
    ASSERT_TRUE(w.ok()) << w.error().message;
    world_ = std::move(*w);
    const Storage::Shared shared{chunks, *control_};
    auto s = Storage::open(*world_, 1, false, &shared);
    ASSERT_TRUE(s.ok()) << s.error().message;
    storage_ = std::move(*s);
    fan_out_ = std::make_unique<FanOut>(options_, counters_);
    horizons_ = std::make_unique<HorizonCache>(strand_, *storage_, *fan_out_);
    residency_ =
        std::make_unique<Residency>(strand_, *storage_, options_, counters_, clock_, *fan_out_, *horizons_);
    authority_ = std::make_unique<SharedAuthority>(strand_, *world_, *storage_, options_, counters_, clock_,
                                                   *residency_, *fan_out_, edits_);
    residency_->watch_loads(*authority_);
    thread_ = std::thread([this] { io_.run(); });
  }
  void TearDown() override {
    if (control_) control_->stop();
    if (storage_) {
      storage_->stop();
      on_strand([] {});
    }
    work_.reset();
    if (thread_.joinable()) thread_.join();
    authority_.reset();
    residency_.reset();
    horizons_.reset();
    fan_out_.reset();
    storage_.reset();
    world_.reset();
    control_.reset();
    keeper_.reset();
  }
  void on_strand(const std::function<void()>& fn) {
    std::promise<void> done;
    asio::post(strand_, [&] {
      fn();
      done.set_value();
    });
    done.get_future().wait();
  }
  Authority::Writable writable(const Region& r, std::string* why = nullptr,
                               std::optional<std::uint32_t>* holder = nullptr) {
    Authority::Writable w{};
    std::string ignored;
    on_strand([&] { w = authority_->writable(r, why != nullptr ? why : &ignored, holder, ClaimRule::kAny); });
    return w;
  }

  ServerOptions options_;
  ServerCounters counters_;
  WorldClock clock_;
  NoEdits edits_;
  std::unique_ptr<LeaseKeeper> keeper_;
  std::unique_ptr<ClusterControl> control_;
  std::unique_ptr<World> world_;
  std::unique_ptr<Storage> storage_;
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_{asio::make_work_guard(io_)};
  asio::strand<asio::io_context::executor_type> strand_{asio::make_strand(io_)};
  std::unique_ptr<FanOut> fan_out_;
  std::unique_ptr<HorizonCache> horizons_;
  std::unique_ptr<Residency> residency_;
  std::unique_ptr<SharedAuthority> authority_;
  std::thread thread_;
};

TEST_F(SharedAuthorityTest, AFreeRegionIsClaimedAsAnEditAsksAndThenWritable) {
  const Region box{{4, 1, 4}, {6, 3, 6}};
  const Vec3i region = lease_region_of(Vec3i{0, 0, 0});
  EXPECT_EQ(writable(box), Authority::Writable::kWaiting);  // a claim starts
  on_strand([&] { EXPECT_TRUE(authority_->claiming(box)); });
  ASSERT_TRUE(testing_support::eventually([&] { return writable(box) == Authority::Writable::kYes; }));
  on_strand([&] {
    EXPECT_TRUE(authority_->writes_region(region));
    EXPECT_FALSE(authority_->claiming(box));
  });
  EXPECT_TRUE(keeper_->holds(region));
}

TEST_F(SharedAuthorityTest, ARegionAnotherServerHoldsIsNotWritableAndNamesItsHolder) {
  const Vec3i region = lease_region_of(Vec3i{0, 0, 0});
  auto other = LeaseKeeper::open(url_, 2, LeaseTimes{}, nullptr);
  ASSERT_TRUE(other.ok()) << other.error().message;
  ASSERT_TRUE((*other)->ensure(std::span(&region, 1)).ok());
  const Region box{{4, 1, 4}, {6, 3, 6}};
  std::string why;
  std::optional<std::uint32_t> holder;
  ASSERT_TRUE(testing_support::eventually(
      [&] { return writable(box, &why, &holder) == Authority::Writable::kNo; }));
  EXPECT_EQ(holder, std::optional<std::uint32_t>(2));
  EXPECT_FALSE(why.empty());
  on_strand([&] { EXPECT_FALSE(authority_->writes_region(region)); });
  EXPECT_FALSE(keeper_->holds(region));
}

TEST_F(SharedAuthorityTest, AChunkAnotherServerChangedThatNobodyHereHoldsIsForgotten) {
  const Vec3i cp{40, 0, 40};  // in a region this server does not write
  ASSERT_NE(lease_region_of(cp), lease_region_of(Vec3i{0, 0, 0}));
  on_strand([&] { residency_->request(cp); });
  ASSERT_TRUE(testing_support::eventually([&] {
    bool loaded = false;
    on_strand([&] { loaded = residency_->loaded(cp); });
    return loaded;
  }));
  std::uint64_t revision = 0;
  on_strand([&] { revision = residency_->revision(cp); });
  on_strand([&] {
    authority_->changed_elsewhere({ChunkChange{cp, revision + 1, {}, 9}});
    EXPECT_EQ(residency_->find(cp), nullptr);
    EXPECT_FALSE(authority_->stale(cp));
  });
  EXPECT_EQ(counters_.chunks_forgotten_elsewhere.load(), 1u);
  EXPECT_EQ(edits_.queued + edits_.rejected, 0);
}

}  // namespace
}  // namespace terrane
