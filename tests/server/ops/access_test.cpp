// AccessControl's bans as admit() applies them: a name, an address, and
// every address of a network; bans that ended are ignored; the list and
// the store (a reopened AccessControl) keep them.
#include "server/ops/access.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <unistd.h>

#include "common/world/sqlite_store.h"
#include "common/world/world.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

constexpr std::int64_t kNow = 1'700'000'000;

class AccessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-access-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    auto store = SqliteStore::create(dir_.string(), default_world_meta());
    ASSERT_TRUE(store.ok()) << store.error().message;
    open_access(std::move(*store));
  }
  void TearDown() override {
    access_.reset();
    fs::remove_all(dir_);
  }
  // An open server's access rules (no tokens) over store.
  void open_access(std::unique_ptr<WorldStore> store) {
    auto a = AccessControl::open(std::move(store), "", {}, "");
    ASSERT_TRUE(a.ok()) << a.error().message;
    access_ = std::move(*a);
  }
  void reopen() {
    access_.reset();
    auto store = SqliteStore::open(dir_.string());
    ASSERT_TRUE(store.ok()) << store.error().message;
    open_access(std::move(*store));
  }
  void ban(const std::string& target, bool address, std::int64_t until = 0, const std::string& reason = "") {
    ASSERT_TRUE(access_->ban(Ban{target, address, until, reason}).ok()) << target;
  }
  // The refusal's reason, or "" when admitted.
  std::string refused(const std::string& name, const std::string& address) const {
    const Admission a = access_->admit(name, "", address, kNow);
    return a.ok ? "" : a.reason;
  }

  fs::path dir_;
  std::unique_ptr<AccessControl> access_;
};

TEST_F(AccessTest, ANetworkBanRefusesEveryAddressInItAndNoOther) {
  ban("10.0.0.0/8", true, 0, "whole subnet");
  ban("2001:db8::/32", true);
  EXPECT_EQ(refused("alice", "10.200.3.4"), "banned: whole subnet");
  EXPECT_EQ(refused("alice", "2001:db8::17"), "banned");
  EXPECT_EQ(refused("alice", "11.0.0.1"), "");
  EXPECT_EQ(refused("alice", "2001:db9::1"), "");
  EXPECT_EQ(refused("10.0.0.0/8", "127.0.0.1"), "") << "a network is not a player's name";
}

TEST_F(AccessTest, NameAndAddressBansAreFoundByTheirTarget) {
  ban("griefer", false, 0, "tunnelling");
  ban("192.168.1.9", true);
  EXPECT_EQ(refused("griefer", "127.0.0.1"), "banned: tunnelling");
  EXPECT_EQ(refused("anyone", "192.168.1.9"), "banned");
  EXPECT_EQ(refused("192.168.1.9", "127.0.0.1"), "") << "an address is not a player's name";
  EXPECT_EQ(refused("anyone", "192.168.1.10"), "");
}

TEST_F(AccessTest, BansThatEndedAreIgnored) {
  ban("10.0.0.0/8", true, kNow, "over");
  ban("griefer", false, kNow - 5);
  ban("192.168.0.0/16", true, kNow + 90, "a while");
  EXPECT_EQ(refused("griefer", "10.0.0.1"), "");
  EXPECT_EQ(refused("anyone", "192.168.4.4"), "banned for 90 s more: a while");
  ASSERT_EQ(access_->bans(kNow).size(), 1u);
  EXPECT_EQ(access_->bans(kNow)[0].target, "192.168.0.0/16");
}

TEST_F(AccessTest, BansAreListedAddressesAndNetworksByTheirTextThenNames) {
  ban("zed", false);
  ban("192.168.1.1", true);
  ban("amy", false);
  ban("10.0.0.5", true);
  ban("10.0.0.0/8", true);
  std::vector<std::string> listed;
  for (const Ban& b : access_->bans(kNow)) listed.push_back(b.target);
  EXPECT_EQ(listed, (std::vector<std::string>{"10.0.0.0/8", "10.0.0.5", "192.168.1.1", "amy", "zed"}));
}

TEST_F(AccessTest, BansSurviveAReopenAndUnbanLiftsANetwork) {
  ban("10.0.0.0/8", true, 0, "kept");
  ban("griefer", false);
  reopen();
  EXPECT_EQ(refused("alice", "10.9.9.9"), "banned: kept");
  EXPECT_EQ(refused("griefer", "127.0.0.1"), "banned");
  auto lifted = access_->unban("10.0.0.0/8");
  ASSERT_TRUE(lifted.ok());
  EXPECT_TRUE(*lifted);
  EXPECT_EQ(refused("alice", "10.9.9.9"), "");
  reopen();
  EXPECT_EQ(refused("alice", "10.9.9.9"), "") << "the store forgot it too";
  EXPECT_EQ(refused("griefer", "127.0.0.1"), "banned");
}

// reload(): new tokens taken, the bans and whitelist another connection
// wrote to the store read again, and what changed said, a line per kind.
TEST_F(AccessTest, AReloadTakesNewTokensAndTheStoresListsAndSaysWhatChanged) {
  auto store = SqliteStore::open(dir_.string());
  ASSERT_TRUE(store.ok()) << store.error().message;
  auto a = AccessControl::open(std::move(*store), "", {{"alice", {"alice-token", false}}, {"bob", {"bob-token", false}}},
                               "");
  ASSERT_TRUE(a.ok()) << a.error().message;
  std::unique_ptr<AccessControl> tokens = std::move(*a);
  const Admission bob = tokens->admit("bob", "bob-token", "127.0.0.1", kNow);
  EXPECT_TRUE(bob.ok && bob.identified) << "a player's own token proves the name";
  EXPECT_FALSE(tokens->admit("carol", "carol-token", "127.0.0.1", kNow).ok);
  EXPECT_FALSE(access_->admit("alice", "", "127.0.0.1", kNow).identified) << "an open server proves no name";
  // Another process (here: the fixture's AccessControl) bans and lists.
  ban("griefer", false, 0, "tunnelling");
  ASSERT_TRUE(access_->whitelist_add("alice").ok());
  ASSERT_TRUE(access_->set_whitelist(true).ok());
  EXPECT_TRUE(tokens->admit("griefer", "", "127.0.0.1", kNow).reason == "authentication failed");

  auto changed = tokens->reload(std::unordered_map<std::string, PlayerToken>{
      {"alice", {"alice-token-2", true}}, {"carol", {"carol-token", false}}, {"griefer", {"g", false}}});
  ASSERT_TRUE(changed.ok()) << changed.error().message;
  EXPECT_EQ(*changed, (std::vector<std::string>{"tokens: +carol +griefer -bob ~alice", "bans: +griefer",
                                                "whitelist: +alice", "whitelist turned on"}));
  EXPECT_FALSE(tokens->admit("bob", "bob-token", "127.0.0.1", kNow).ok);
  EXPECT_FALSE(tokens->admit("alice", "alice-token", "127.0.0.1", kNow).ok);
  const Admission alice = tokens->admit("alice", "alice-token-2", "127.0.0.1", kNow);
  EXPECT_TRUE(alice.ok && alice.admin);
  EXPECT_EQ(tokens->admit("carol", "carol-token", "127.0.0.1", kNow).reason,
            "not on the whitelist: the server admits listed players only (ask an operator)");
  EXPECT_EQ(tokens->admit("griefer", "g", "127.0.0.1", kNow).reason, "banned: tunnelling");
  // Nothing new: nothing said; no tokens given: the tokens stay.
  changed = tokens->reload(std::nullopt);
  ASSERT_TRUE(changed.ok());
  EXPECT_TRUE(changed->empty());
  EXPECT_TRUE(tokens->admit("alice", "alice-token-2", "127.0.0.1", kNow).ok);
}

}  // namespace
}  // namespace terrane
