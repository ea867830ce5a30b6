// Thread roles: each names its thread, and sets its niceness relative to
// the process's (the loaders below, the rest unchanged); with priorities
// off, nothing but the name changes.
#include "server/base/thread_role.h"

#include <gtest/gtest.h>
#include <pthread.h>
#include <sys/resource.h>
#include <unistd.h>

#include <string>
#include <thread>

namespace terrane {
namespace {

struct Entered {
  bool ok = false;
  int before = 0, after = 0;
  std::string name;
};

// Enters role on a new thread (a thread's niceness is its own on Linux).
Entered enter_on_a_thread(ThreadRole role, bool prioritise) {
  Entered e;
  std::thread([&] {
    const auto tid = static_cast<id_t>(::gettid());
    e.before = ::getpriority(PRIO_PROCESS, tid);
    e.ok = enter_thread_role(role, prioritise);
    e.after = ::getpriority(PRIO_PROCESS, tid);
    char name[16] = {};
    pthread_getname_np(pthread_self(), name, sizeof name);
    e.name = name;
  }).join();
  return e;
}

TEST(ThreadRole, ALoaderRunsBelowTheProcessAndIsNamed) {
  const Entered e = enter_on_a_thread(ThreadRole::kLoader, true);
  ASSERT_TRUE(e.ok);
  EXPECT_EQ(e.after, std::min(e.before + thread_role_niceness(ThreadRole::kLoader), 19));
  EXPECT_GT(thread_role_niceness(ThreadRole::kLoader), 0);
  EXPECT_EQ(e.name, "terrane-loader");
}

TEST(ThreadRole, TheWorldAndTheWriterRunAtTheProcesssNiceness) {
  for (const ThreadRole role : {ThreadRole::kWorld, ThreadRole::kWriter}) {
    const Entered e = enter_on_a_thread(role, true);
    EXPECT_TRUE(e.ok);
    EXPECT_EQ(e.after, e.before);
  }
  EXPECT_EQ(enter_on_a_thread(ThreadRole::kWorld, true).name, "terrane-world");
  EXPECT_EQ(enter_on_a_thread(ThreadRole::kWriter, true).name, "terrane-writer");
}

TEST(ThreadRole, IoThreadsAndPrioritiesOffKeepTheProcesssNiceness) {
  Entered e = enter_on_a_thread(ThreadRole::kIo, true);
  EXPECT_TRUE(e.ok);
  EXPECT_EQ(e.after, e.before);
  EXPECT_EQ(e.name, "terrane-io");
  e = enter_on_a_thread(ThreadRole::kLoader, false);
  EXPECT_TRUE(e.ok);
  EXPECT_EQ(e.after, e.before);
  EXPECT_EQ(e.name, "terrane-loader");
  e = enter_on_a_thread(ThreadRole::kWriter, false);
  EXPECT_EQ(e.after, e.before);
  EXPECT_EQ(e.name, "terrane-writer");
}

}  // namespace
}  // namespace terrane
