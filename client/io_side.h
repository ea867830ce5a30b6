// IoSide: where a connection's handlers run, and for how long: an
// io_context it owns with one thread of its own, or a strand of a shared
// io_context (ClientOptions::io_context) that the application runs on a
// pool of its own (many clients, few threads: the bots). Either way one
// connection's handlers never run concurrently. It also counts the
// handlers pending (each holds a guard()), so the connection can wait until
// none can still touch it.
//
// Threads: context(), strand() and guard() from any thread; run_for() and
// start_thread() from the thread that connects (owned mode only, once);
// finish() from any thread but the io side's.
#pragma once

#include <asio.hpp>
#include <chrono>
#include <memory>
#include <thread>

#include "client/pending_ops.h"

namespace terrane {

class IoSide {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;

  // shared: the application's io_context (not owned; it must outlive this
  // and be running while finish() waits); null: own one.
  explicit IoSide(asio::io_context* shared);
  ~IoSide() { finish(); }
  IoSide(const IoSide&) = delete;
  IoSide& operator=(const IoSide&) = delete;

  bool owned() const { return own_ != nullptr; }
  asio::io_context& context() { return io_; }
  Strand& strand() { return strand_; }
  PendingOps::Guard guard() { return ops_.guard(); }

  // Owned mode, before start_thread(): runs the handlers ready within d on
  // the calling thread (a blocking connect).
  void run_for(std::chrono::milliseconds d) { io_.run_for(d); }
  // Owned mode: the thread that runs every handler from now on, until none
  // is left.
  void start_thread();
  // Waits until no handler is pending: joins the owned thread (which ends
  // once the work runs out), or waits for the last guard in shared mode.
  void finish();

 private:
  PendingOps ops_;  // first: the guards of handlers still queued outlive the rest
  std::unique_ptr<asio::io_context> own_;
  asio::io_context& io_;
  Strand strand_;
  std::thread thread_;
};

}  // namespace terrane
