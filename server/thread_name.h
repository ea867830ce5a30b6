// Names the calling thread (at most 15 characters shown), so `top -H`,
// `perf report --sort comm` and a debugger tell the server's owners apart:
// terrane-world (the world strand), terrane-io (sessions and replicators),
// terrane-loader (the storage's loads) and terrane-writer (its commits).
// Best effort: a failure changes nothing.
#pragma once

#include <pthread.h>

namespace terrane {

inline void name_this_thread(const char* name) { pthread_setname_np(pthread_self(), name); }

}  // namespace terrane
