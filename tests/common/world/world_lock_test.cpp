#include "common/world/world_lock.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "tests/support/scratch_dir.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

class WorldLockTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_support::scratch_dir("terrane-lock");
    fs::create_directories(dir_ / "world");
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string world() const { return (dir_ / "world").string(); }
  fs::path dir_;
};

std::string host() {
  char buf[256] = {};
  ::gethostname(buf, sizeof buf - 1);
  return buf;
}

TEST_F(WorldLockTest, ASecondWriterIsRefusedNamingTheHolder) {
  auto first = WorldLock::take(world(), "terrane-server on 127.0.0.1:7777");
  ASSERT_TRUE(first.ok()) << first.error().message;
  EXPECT_TRUE(first->held());
  // Another open file of the same process is refused as another process is.
  auto second = WorldLock::take(world(), "terrane-world import");
  ASSERT_FALSE(second.ok());
  const std::string& m = second.error().message;
  EXPECT_NE(m.find("world " + world() + ": in use by pid " + std::to_string(::getpid()) + " on host " + host() +
                   " (terrane-server on 127.0.0.1:7777), since 20"),
            std::string::npos)
      << m;
  EXPECT_NE(m.find("one writer at a time"), std::string::npos) << m;
  EXPECT_EQ(WorldLock::holder(world()).rfind("pid " + std::to_string(::getpid()), 0), 0u) << WorldLock::holder(world());
}

TEST_F(WorldLockTest, ASymlinkToTheDirectoryMeetsTheSameLock) {
  fs::create_directory_symlink(dir_ / "world", dir_ / "link");
  auto first = WorldLock::take(world(), "first");
  ASSERT_TRUE(first.ok());
  auto through_link = WorldLock::take((dir_ / "link").string(), "second");
  ASSERT_FALSE(through_link.ok());
  EXPECT_NE(through_link.error().message.find("(first)"), std::string::npos) << through_link.error().message;
  auto dotted = WorldLock::take((dir_ / "link" / "." / "").string(), "third");
  EXPECT_FALSE(dotted.ok());
}

TEST_F(WorldLockTest, ReleasingLetsTheNextWriterInAndLeavesNoName) {
  {
    auto first = WorldLock::take(world(), "first");
    ASSERT_TRUE(first.ok());
    WorldLock moved = std::move(*first);
    EXPECT_FALSE(first->held());
    EXPECT_TRUE(moved.held());
    EXPECT_FALSE(WorldLock::take(world(), "second").ok());
  }
  EXPECT_EQ(WorldLock::holder(world()), "");
  EXPECT_TRUE(fs::exists(dir_ / "world" / kWorldLockName));  // kept: deleting it would race
  auto next = WorldLock::take(world(), "second");
  ASSERT_TRUE(next.ok()) << next.error().message;
  next->release();
  EXPECT_FALSE(next->held());
  EXPECT_TRUE(WorldLock::take(world(), "third").ok());
}

TEST_F(WorldLockTest, AStaleNameInAnUnlockedFileBlocksNobody) {
  std::ofstream(dir_ / "world" / kWorldLockName) << "pid=1 host=elsewhere since=2020-01-01 00:00:00 UTC program=old\n";
  EXPECT_EQ(WorldLock::holder(world()), "");
  EXPECT_TRUE(WorldLock::take(world(), "new").ok());
}

TEST_F(WorldLockTest, AGarbledNameIsQuotedSafelyNotTrusted) {
  auto first = WorldLock::take(world(), "first");
  ASSERT_TRUE(first.ok());
  // Someone overwrote the holder's line (the lock itself is untouched).
  std::ofstream(dir_ / "world" / kWorldLockName, std::ios::trunc) << std::string("pid=\x01\x1b[2J", 8)
                                                                   << std::string(5000, 'x');
  auto second = WorldLock::take(world(), "second");
  ASSERT_FALSE(second.ok());
  const std::string& m = second.error().message;
  EXPECT_NE(m.find("another process (its lock file names it as 'pid="), std::string::npos) << m;
  EXPECT_EQ(m.find('\x1b'), std::string::npos);
  EXPECT_LT(m.size(), 1500u);  // the file is read up to a bound
}

TEST_F(WorldLockTest, AMissingDirectoryIsAClearError) {
  auto r = WorldLock::take(world() + "/nope", "x");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("cannot open the lock file " + world() + "/nope/world.lock"), std::string::npos)
      << r.error().message;
}

// The lock dies with its holder however it ends: SIGKILL runs nothing on
// the way out.
TEST_F(WorldLockTest, AHolderKilledWithSigkillLeavesTheWorldFree) {
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(ready[0]);
    auto lock = WorldLock::take(world(), "terrane-server (child)");
    const char ok = lock.ok() ? 'y' : 'n';
    if (::write(ready[1], &ok, 1) != 1) ::_exit(3);
    for (;;) ::pause();
  }
  ::close(ready[1]);
  char got = 0;
  ASSERT_EQ(::read(ready[0], &got, 1), 1);
  ::close(ready[0]);
  ASSERT_EQ(got, 'y');
  auto refused = WorldLock::take(world(), "parent");
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("in use by pid " + std::to_string(child)), std::string::npos)
      << refused.error().message;
  ASSERT_EQ(::kill(child, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_EQ(WorldLock::holder(world()), "");
  auto taken = WorldLock::take(world(), "parent");
  EXPECT_TRUE(taken.ok()) << taken.error().message;
}

}  // namespace
}  // namespace terrane
