#include "server/base/thread_role.h"

#include <pthread.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>

namespace terrane {

namespace {
const char* role_name(ThreadRole role) {
  switch (role) {
    case ThreadRole::kWorld: return "terrane-world";
    case ThreadRole::kWriter: return "terrane-writer";
    case ThreadRole::kIo: return "terrane-io";
    case ThreadRole::kLoader: return "terrane-loader";
  }
  return "terrane";
}
}  // namespace

int thread_role_niceness(ThreadRole role) {
  switch (role) {
    case ThreadRole::kWorld:
    case ThreadRole::kWriter:
    case ThreadRole::kIo: return 0;
    case ThreadRole::kLoader: return 5;
  }
  return 0;
}

bool enter_thread_role(ThreadRole role, bool prioritise) {
  pthread_setname_np(pthread_self(), role_name(role));
  const int delta = thread_role_niceness(role);
  if (!prioritise || delta == 0) return true;
  // On Linux a thread has a niceness of its own (PRIO_PROCESS of its id),
  // inherited from the thread that made it: the process's.
  const auto tid = static_cast<id_t>(::gettid());
  errno = 0;
  const int base = ::getpriority(PRIO_PROCESS, tid);
  if (base == -1 && errno != 0) return false;
  return ::setpriority(PRIO_PROCESS, tid, base + delta) == 0;
}

}  // namespace terrane
