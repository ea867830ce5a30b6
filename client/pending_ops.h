// PendingOps: counts the handlers a connection has started and not yet
// finished, so the one who ends it can wait until none can still touch it
// (in shared mode the io_context outlives the connection, and its threads
// may be running a handler when disconnect() is called).
//
// Every handler holds a Guard from start to end. Any thread may take or
// drop a guard; wait_idle() blocks the calling thread (never one of the
// handlers') until the count is zero. The mutex exists only for the
// condition variable: the count itself is atomic.
#pragma once

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <utility>

namespace terrane {

class PendingOps {
 public:
  // One pending handler: counted from construction to destruction
  // (move-only; a moved-from guard counts nothing).
  class Guard {
   public:
    explicit Guard(PendingOps* ops) : ops_(ops) { ops_->count_.fetch_add(1, std::memory_order_relaxed); }
    Guard(Guard&& o) noexcept : ops_(std::exchange(o.ops_, nullptr)) {}
    Guard(const Guard&) = delete;
    Guard& operator=(const Guard&) = delete;
    Guard& operator=(Guard&&) = delete;
    ~Guard() {
      if (ops_ != nullptr) ops_->done();
    }

   private:
    PendingOps* ops_;
  };

  Guard guard() { return Guard(this); }
  int pending() const { return count_.load(std::memory_order_acquire); }
  // Blocks until no guard is alive.
  void wait_idle() {
    std::unique_lock lock(mutex_);
    idle_.wait(lock, [&] { return count_.load(std::memory_order_acquire) == 0; });
  }

 private:
  void done() {
    if (count_.fetch_sub(1, std::memory_order_acq_rel) == 1) {
      std::lock_guard lock(mutex_);
      idle_.notify_all();
    }
  }

  std::atomic<int> count_{0};
  std::mutex mutex_;
  std::condition_variable idle_;
};

}  // namespace terrane
