// ChangeListener: the news from the other servers of a shared PostgreSQL
// world, as they commit (server/storage/STORE_POSTGRESQL.md, "Notices" and
// "Forwarded edits").
//
// A thread of its own holds a connection subscribed to the three channels
// and hands on: each change notice's chunks and revisions (changes); that
// this server's inbox has edits (inbox); an answer to an edit this server
// forwarded (answer). Notices for other servers are left out.
//
// It follows each region's write sequence (+1 per commit writing it, in
// the notices): it reads them all once subscribed, then from the notices.
// When the connection breaks, notices may have been missed: it connects
// again (every second until it can), subscribes, reads the sequences again
// and calls missed with the regions whose sequence moved meanwhile, so the
// owner reads again what it holds of those, and its inbox; then hands on
// the answers kept for it in the database (ClusterStore::take_answers),
// whose notices it may have missed. A notice whose sequence skips one (a
// notice lost, which PostgreSQL does not do while connected) calls missed
// with its region too.
//
// Threading: the callbacks run on the listener's thread. The destructor
// stops the thread; no callback runs after it returns.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <tuple>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "server/base/counters.h"
#include "server/cluster/cluster_store.h"

namespace terrane {

class ChangeListener {
 public:
  struct Handlers {
    std::function<void(std::vector<ChunkChange>)> changes;
    std::function<void()> inbox;
    std::function<void(ForwardAnswer)> answer;
    std::function<void(std::vector<Vec3i> regions)> missed;
  };

  // Connects and subscribes before returning, so no commit after open() is
  // missed. server: this server's id (whose inbox and answers are its own).
  // counters (may be null; must outlive the listener): listener_down is 1
  // from a broken connection until it listens again.
  static StoreResult<std::unique_ptr<ChangeListener>> open(const std::string& url, std::uint32_t server,
                                                           Handlers handlers, DatabaseCounters* counters = nullptr);
  ~ChangeListener();
  // Its connection's application_name in pg_stat_activity.
  static std::string name_of(std::uint32_t server);
  ChangeListener(const ChangeListener&) = delete;
  ChangeListener& operator=(const ChangeListener&) = delete;

 private:
  ChangeListener(std::string url, std::uint32_t server, Handlers handlers, std::unique_ptr<ClusterStore> conn,
                 DatabaseCounters* counters);
  // The connection given up (it broke): down until listening again.
  void lose_connection();
  void run();
  // answered: the ids of answers to this server handed on.
  void hand_on(const ClusterStore::Notice& n, std::vector<std::int64_t>& answered);
  // Reads every region's sequence; returns those that moved since known
  // (all of them the first time: nothing is held yet then).
  StoreResult<std::vector<Vec3i>> read_seqs();

  const std::string url_;
  const std::uint32_t server_;
  const std::string server_text_;  // as inbox notices name it
  const Handlers on_;
  DatabaseCounters* const counters_;  // may be null
  std::unique_ptr<ClusterStore> conn_;  // the thread's
  std::map<std::tuple<int, int, int>, std::uint64_t> seqs_;  // the thread's: region -> write sequence seen
  std::mutex mutex_;  // guards stopping_
  std::condition_variable wake_;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace terrane
