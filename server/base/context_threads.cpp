#include "server/base/context_threads.h"

#include <algorithm>

namespace terrane {

void ContextThreads::run(int threads, ThreadRole role, bool prioritise) {
  for (int i = 0; i < std::max(1, threads); ++i)
    threads_.emplace_back([this, role, prioritise] {
      enter_thread_role(role, prioritise);
      io_.run();
    });
}

void ContextThreads::join() {
  work_.reset();
  for (auto& t : threads_) t.join();
  threads_.clear();
}

}  // namespace terrane
