// ContextThreads: an asio io_context, the work guard that keeps it running
// while idle, and the threads that run it, all of one role (the server's io
// threads; the world strand's one thread). join() lets it end once its
// queued work is done and waits for its threads.
//
// Threading: run() and join() on the thread that starts and stops the
// server (join() never from one of the context's own threads); context()
// from any. No lock: the threads are started and joined by that one thread.
#pragma once

#include <asio.hpp>
#include <thread>
#include <vector>

#include "server/base/thread_role.h"

namespace terrane {

class ContextThreads {
 public:
  ContextThreads() = default;
  ~ContextThreads() { join(); }
  ContextThreads(const ContextThreads&) = delete;
  ContextThreads& operator=(const ContextThreads&) = delete;

  asio::io_context& context() { return io_; }
  // Runs the context on threads (at least one) named after role, at its
  // niceness when prioritise (server/base/thread_role.h).
  void run(int threads, ThreadRole role, bool prioritise);
  // Lets run() return once no work is queued or pending, and joins the
  // threads; idempotent. The context can then not run again.
  void join();

 private:
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_ = asio::make_work_guard(io_);
  std::vector<std::thread> threads_;
};

}  // namespace terrane
