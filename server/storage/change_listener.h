// ChangeListener: the other servers' writes to a shared PostgreSQL world, as
// they commit (server/storage/STORE_POSTGRESQL.md, "Notices").
//
// A thread of its own holds a connection subscribed to terrane_changes and
// hands each notice's chunks and revisions to on_changes. When the
// connection breaks, notices may have been missed: it connects again
// (every second until it can), subscribes, and then calls on_missed, so the
// owner reads again what it holds of regions it does not write.
//
// Threading: the callbacks run on the listener's thread. The destructor
// stops the thread; no callback runs after it returns.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "server/storage/postgres_store.h"

namespace terrane {

class ChangeListener {
 public:
  using ChangesFn = std::function<void(std::vector<ChunkChange>)>;
  using MissedFn = std::function<void()>;

  // Connects and subscribes before returning, so no commit after open() is
  // missed.
  static StoreResult<std::unique_ptr<ChangeListener>> open(const std::string& url, ChangesFn on_changes,
                                                           MissedFn on_missed);
  ~ChangeListener();
  ChangeListener(const ChangeListener&) = delete;
  ChangeListener& operator=(const ChangeListener&) = delete;

  std::uint64_t notices() const { return notices_.load(std::memory_order_relaxed); }
  std::uint64_t reconnects() const { return reconnects_.load(std::memory_order_relaxed); }

 private:
  ChangeListener(std::string url, ChangesFn on_changes, MissedFn on_missed, std::unique_ptr<PostgresStore> conn);
  void run();

  const std::string url_;
  const ChangesFn on_changes_;
  const MissedFn on_missed_;
  std::unique_ptr<PostgresStore> conn_;  // the thread's
  std::atomic<std::uint64_t> notices_{0}, reconnects_{0};
  std::mutex mutex_;  // guards stopping_
  std::condition_variable wake_;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace terrane
