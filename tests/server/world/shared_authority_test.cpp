// SharedAuthority on the world strand against a real PostgreSQL world
// (skipped where PostgreSQL is not installed) with this server's lease
// keeper, a real Residency and FanOut, and a fake edit queue: a free
// region is claimed as an edit asks (waiting until held, then writable);
// a region another server holds is not writable and names its holder; a
// chunk another server changed that nobody here holds is forgotten; an
// edit from a server this one asked for the same region at once goes back
// to it, unclaimed, if that server's id is the lower; a forwarded edit is
// refused once its wait ran out untaken (never taken after), called
// unknown once taken and not answered, and rejected in Terrane's words
// when the database fails it.
#include "server/world/shared_authority.h"

#include <gtest/gtest.h>

#include <asio.hpp>
#include <future>
#include <thread>

#include "server/cluster/cluster_control.h"
#include "server/cluster/cluster_store.h"
#include "server/cluster/lease_keeper.h"
#include "server/storage/forwarded_edit.h"
#include "tests/support/eventually.h"
#include "tests/support/postgres.h"
#include "tests/support/world_strand.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::run_sql;

class NoEdits final : public EditQueue {
 public:
  void queue_forwarded(EditRequestMsg, std::string, Forwarded f) override {
    ++queued;
    forwarded.push_back(f);
  }
  void reject(ClientId, const EditRequestMsg&, RejectReason why, const std::string& reason) override {
    ++rejected;
    reasons.push_back(reason);
    whys.push_back(why);
  }
  int queued = 0, rejected = 0;
  std::vector<Forwarded> forwarded;
  std::vector<std::string> reasons;  // the world strand's
  std::vector<RejectReason> whys;    // the same rejections' reasons (the world strand's)
};

EditRequestMsg fill(Region box) {
  EditRequestMsg e;
  e.edit_id = 1;
  e.kind = EditKind::kFillBox;
  e.box = box;
  e.material = materials::kBrick;
  e.occupancy = 255;
  return e;
}

class SharedAuthorityTest : public testing_support::PostgresTest {
 protected:
  void SetUp() override {
    PostgresTest::SetUp();
    if (IsSkipped() || HasFatalFailure()) return;
    auto store = PostgresStore::open(url_);
    ASSERT_TRUE(store.ok()) << store.error().message;
    ASSERT_TRUE((*store)->create_world(default_world_meta()).ok());
    cluster_.server_id = kThisServer;
    auto keeper = LeaseKeeper::open(url_, kThisServer, LeaseTimes{}, nullptr);
    ASSERT_TRUE(keeper.ok()) << keeper.error().message;
    keeper_ = std::move(*keeper);
    auto control = ClusterControl::open(url_, *keeper_);
    ASSERT_TRUE(control.ok()) << control.error().message;
    control_ = std::move(*control);
    (*store)->set_lease_source(keeper_->held_source(), cluster_.lease);
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
    authority_ = std::make_unique<SharedAuthority>(strand_, *world_, *storage_, options_, cluster_, counters_, clock_,
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
  // A client of this server's (its forwarded edits' rejections reach
  // edits_), and an edit of it for server 3, whose region this is.
  static constexpr ClientId kAnn = 7;
  static constexpr std::uint32_t kOwner = 3;
  static const Region& box() {
    static const Region b{{4, 1, 4}, {6, 3, 6}};
    return b;
  }
  void forward_anns_edit() {
    on_strand([&] { fan_out_->join(kAnn, std::make_shared<testing_support::RecordingClient>()); });
    EditRequestMsg e;
    e.edit_id = 1;
    e.kind = EditKind::kFillBox;
    e.box = box();
    e.material = 3;
    e.occupancy = 255;
    on_strand([&] { authority_->forward(kAnn, e, "ann", box(), kOwner); });
  }
  // What ann was told of her forwarded edit, waited for (the tick settles
  // forwarded edits every tick: here the test does).
  std::string anns_rejection() {
    std::string reason = "no rejection";
    testing_support::eventually([&] {
      bool told = false;
      on_strand([&] {
        authority_->settle();
        if (!edits_.reasons.empty()) reason = edits_.reasons.front(), told = true;
      });
      return told;
    });
    return reason;
  }
  // What server 2 takes of its inbox now.
  std::vector<InboxEdit> owners_inbox() {
    auto cs = ClusterStore::open(url_);
    EXPECT_TRUE(cs.ok()) << (cs.ok() ? "" : cs.error().message);
    if (!cs.ok()) return {};
    auto got = (*cs)->inbox(kOwner, 0, 10);
    EXPECT_TRUE(got.ok()) << (got.ok() ? "" : got.error().message);
    return got.ok() ? *got : std::vector<InboxEdit>{};
  }

  Authority::Writable writable(const Region& r, std::string* why = nullptr,
                               std::optional<std::uint32_t>* holder = nullptr) {
    Authority::Writable w{};
    std::string ignored;
    on_strand([&] { w = authority_->writable(r, why != nullptr ? why : &ignored, holder, ClaimRule::kAny); });
    return w;
  }

  // Forwards edit as client 7 of this server to server to.
  void forward(const Region& box, std::uint32_t to) {
    on_strand([&] {
      fan_out_->join(7, client_);
      authority_->forward(7, fill(box), "bob", box, to);
    });
  }
  // Puts an edit of box from server from in this server's inbox and has it
  // read; what the authority queued for it.
  std::optional<Forwarded> from_inbox(std::uint32_t from, const Region& box) {
    auto other = ClusterStore::open(url_);
    EXPECT_TRUE(other.ok()) << other.error().message;
    if (!other.ok()) return std::nullopt;
    const auto edit = encode_forwarded_edit(fill(box));
    // Its deadline a minute on by the database's clock.
    const std::int64_t expires_us =
        std::stoll(testing_support::sql_value(url_, "SELECT (extract(epoch FROM clock_timestamp()) * 1000000)::bigint")) +
        60'000'000;
    EXPECT_TRUE((*other)->forward(from, kThisServer, "ann", edit, expires_us).ok());
    std::size_t before = 0;
    on_strand([&] {
      before = edits_.forwarded.size();
      authority_->inbox_has_edits();
    });
    std::optional<Forwarded> got;
    testing_support::eventually([&] {
      on_strand([&] {
        if (edits_.forwarded.size() > before) got = edits_.forwarded.back();
      });
      return got.has_value();
    });
    return got;
  }

  static constexpr std::uint32_t kThisServer = 2;
  WorldOptions options_;
  ClusterOptions cluster_;
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
  std::shared_ptr<testing_support::RecordingClient> client_ = std::make_shared<testing_support::RecordingClient>();
  std::thread thread_;
};

TEST_F(SharedAuthorityTest, AFreeRegionIsClaimedAsAnEditAsksAndThenWritable) {
  const Region box{{4, 1, 4}, {6, 3, 6}};
  const Vec3i region = lease_region_of(Vec3i{0, 0, 0});
  // A claim starts, and is under way until the strand hears from the
  // database (asked in the same strand task: the answer may come at once).
  on_strand([&] {
    std::string why;
    EXPECT_EQ(authority_->writable(box, &why, nullptr, ClaimRule::kAny), Authority::Writable::kWaiting);
    EXPECT_TRUE(authority_->claiming(box));
  });
  ASSERT_TRUE(testing_support::eventually([&] { return writable(box) == Authority::Writable::kYes; }));
  on_strand([&] {
    EXPECT_TRUE(authority_->writes_region(region));
    EXPECT_FALSE(authority_->claiming(box));
  });
  EXPECT_TRUE(keeper_->holds(region));
}

TEST_F(SharedAuthorityTest, ARegionAnotherServerHoldsIsNotWritableAndNamesItsHolder) {
  const Vec3i region = lease_region_of(Vec3i{0, 0, 0});
  auto other = LeaseKeeper::open(url_, 3, LeaseTimes{}, nullptr);
  ASSERT_TRUE(other.ok()) << other.error().message;
  ASSERT_TRUE((*other)->ensure(std::span(&region, 1)).ok());
  const Region box{{4, 1, 4}, {6, 3, 6}};
  std::string why;
  std::optional<std::uint32_t> holder;
  ASSERT_TRUE(testing_support::eventually(
      [&] { return writable(box, &why, &holder) == Authority::Writable::kNo; }));
  EXPECT_EQ(holder, std::optional<std::uint32_t>(3));
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

// Two servers asking each other for one region at once: this server (2)
// forwarded an edit there to server 1 and gets one of server 1's there.
// Server 1 wins: the edit goes back to it, and nothing is claimed for it.
TEST_F(SharedAuthorityTest, AnEditFromALowerIdAskedForTheSameRegionAtOnceGoesBackUnclaimed) {
  const Region mine{{4, 1, 4}, {6, 3, 6}}, theirs{{8, 1, 4}, {10, 3, 6}};
  const Vec3i region = lease_region_of(Vec3i{0, 0, 0});
  ASSERT_EQ(lease_region_of(chunk_of(theirs.min)), region);
  forward(mine, 1);
  const auto got = from_inbox(1, theirs);
  ASSERT_TRUE(got.has_value());
  EXPECT_TRUE(got->back);
  EXPECT_FALSE(got->own);
  EXPECT_EQ(got->from, 1u);
  on_strand([&] {
    EXPECT_FALSE(authority_->claiming(theirs));
    EXPECT_FALSE(authority_->writes_region(region));
    EXPECT_TRUE(authority_->passes_back_to(1));
    EXPECT_FALSE(authority_->passes_back_to(3));
  });
  EXPECT_FALSE(keeper_->holds(region));
}

// Not passed back: an edit from a lower id that this server did not ask for
// the region, or from a higher id that it did (this server wins and takes
// it); this server's own edit back is marked as such.
TEST_F(SharedAuthorityTest, AnEditIsPassedBackOnlyToALowerIdAskedForTheSameRegion) {
  const Region mine{{4, 1, 4}, {6, 3, 6}}, theirs{{8, 1, 4}, {10, 3, 6}};
  auto got = from_inbox(1, theirs);
  ASSERT_TRUE(got.has_value());
  EXPECT_FALSE(got->back);
  forward(mine, 3);
  got = from_inbox(3, theirs);
  ASSERT_TRUE(got.has_value());
  EXPECT_FALSE(got->back);
  EXPECT_FALSE(got->own);
  got = from_inbox(kThisServer, theirs);
  ASSERT_TRUE(got.has_value());
  EXPECT_FALSE(got->back);
  EXPECT_TRUE(got->own);
}

// A forward held up on its way (here: the inbox locked; in the fault
// suite, a partition between its sender and the database) until its wait
// has run out lands with its deadline passed: its owner never takes it,
// and its player is told it was not applied.
TEST_F(SharedAuthorityTest, AForwardHeldUpPastItsWaitIsRefusedAndNeverTaken) {
  cluster_.lease = 1000ms;  // a forward waits 2 s
  PGconn* lock = PQconnectdb(url_.c_str());
  ASSERT_EQ(PQstatus(lock), CONNECTION_OK) << PQerrorMessage(lock);
  auto command = [&](const char* sql) {
    PGresult* r = PQexec(lock, sql);
    std::string error = PQresultStatus(r) == PGRES_COMMAND_OK ? "" : PQresultErrorMessage(r);
    PQclear(r);
    return error;
  };
  ASSERT_EQ(command("BEGIN"), "");
  ASSERT_EQ(command("LOCK TABLE terrane_inbox IN SHARE MODE"), "");
  forward_anns_edit();
  // The lock goes once the row has waited on it for longer than the
  // forward's wait, by the database's clock.
  EXPECT_TRUE(testing_support::eventually([&] {
    return testing_support::sql_value(
               url_, "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock'"
                     " AND query LIKE 'INSERT INTO terrane_inbox%'"
                     " AND clock_timestamp() > query_start + interval '2000 milliseconds'") == "1";
  }));
  ASSERT_EQ(command("COMMIT"), "");
  PQfinish(lock);
  const std::string told = anns_rejection();
  EXPECT_NE(told.find("not applied"), std::string::npos) << told;
  on_strand([&] { EXPECT_EQ(edits_.whys.front(), RejectReason::kNotOwner); });
  EXPECT_TRUE(owners_inbox().empty()) << "the owner took an edit its sender gave up on";
  EXPECT_EQ(testing_support::sql_value(url_, "SELECT count(*) FROM terrane_inbox"), "0") << "not taken back";
}

// The owner took the edit and never answered (it stopped, say): its
// sender cannot take it back, waits a while longer, then says its outcome
// is unknown (it may still have been applied).
TEST_F(SharedAuthorityTest, AForwardTakenAndNeverAnsweredEndsWithItsOutcomeUnknown) {
  cluster_.lease = 1000ms;
  forward_anns_edit();
  std::vector<InboxEdit> taken;
  ASSERT_TRUE(testing_support::eventually([&] {
    taken = owners_inbox();
    return !taken.empty();
  }));
  EXPECT_EQ(taken.front().player, "ann");
  const std::string told = anns_rejection();
  EXPECT_NE(told.find("outcome unknown"), std::string::npos) << told;
  on_strand([&] { EXPECT_EQ(edits_.whys.front(), RejectReason::kOutcomeUnknown); });
  EXPECT_EQ(testing_support::sql_value(url_, "SELECT count(*) FROM terrane_inbox"), "1") << "a taken row went";
}

// A player is told what became of the edit in Terrane's words, never the
// database's (here every session of the world's database is ended as the
// edit goes: its forward fails before it is sent).
TEST_F(SharedAuthorityTest, AForwardTheDatabaseFailedIsRejectedInTerranesWords) {
  ASSERT_EQ(run_sql(url_, "SELECT pg_terminate_backend(pid) FROM pg_stat_activity"
                          " WHERE datname = current_database() AND pid <> pg_backend_pid()"),
            "");
  forward_anns_edit();
  const std::string told = anns_rejection();
  EXPECT_EQ(told.find("postgresql"), std::string::npos) << told;
  EXPECT_EQ(told.find("connection"), std::string::npos) << told;
  EXPECT_NE(told.find("the world's database cannot be reached; the edit was not applied"), std::string::npos) << told;
}

}  // namespace
}  // namespace terrane
