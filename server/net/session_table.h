// SessionTable: the server's live client sessions, by id (weak: a session
// lives while its socket's handlers keep it), for the client cap, the
// notices and operators' commands that reach every client, and stop(),
// which closes them all. It also hands out the sessions' ids.
//
// Threading: any thread. The acceptor (an io thread) adds, each session's
// strand removes its own when its socket closes, and the admin thread and
// stop() walk it: m_ guards the table (a post would not do: the walks must
// see every session added before them and wait for none). for_each_welcomed
// calls back under m_, which is taken before ClientSession::info_m_.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "server/net/client_session.h"

namespace terrane {

class SessionTable {
 public:
  // max_clients: the client cap (sessions beyond it are refused).
  explicit SessionTable(std::size_t max_clients) : max_clients_(max_clients) {}
  SessionTable(const SessionTable&) = delete;
  SessionTable& operator=(const SessionTable&) = delete;

  // A new session's id: 1, 2, ... never reused.
  std::uint64_t next_id() { return next_id_.fetch_add(1, std::memory_order_relaxed); }
  // Adds client's session as id. False when that puts the table past the
  // cap: the caller closes it (the server is full); it stays counted until
  // removed, as it closes.
  bool add(std::uint64_t id, const std::shared_ptr<ClientSession>& client);
  // Drops id (a session whose socket closed); absent ids are ignored.
  void remove(std::uint64_t id);
  // Sessions in the table (live or closing, not yet removed).
  std::size_t size() const;

  // fn(id, session, info) for each live session whose client was welcomed,
  // under m_: fn must not use the table (Session::send and close only post).
  void for_each_welcomed(
      const std::function<void(std::uint64_t id, Session& session, const ClientSession::Info& info)>& fn) const;
  // What a player's join did to that player's other sessions.
  struct Replacement {
    std::vector<std::uint64_t> ended;    // sessions of the name that joined earlier: closed
    std::optional<std::uint64_t> newer;  // one that joined later: the caller's session is the older
  };
  // The player name was welcomed in session id as the server's
  // join_order-th join: closes (why, text) name's welcomed player sessions
  // that joined earlier, and names one that joined later if there is one.
  // Two joins of one name handled at once on two threads, each seeing the
  // other, pick the same loser: the earlier join.
  Replacement replace_earlier_joins(std::uint64_t id, const std::string& name, std::uint64_t join_order,
                                    CloseReason why, const std::string& text) const;
  // The live sessions now, taken under m_ and used outside it.
  std::vector<std::shared_ptr<Session>> live() const;
  // Closes every live session (why, text: its Disconnect).
  void close_all(CloseReason why, const std::string& text);

 private:
  struct Peer {
    std::weak_ptr<Session> session;
    std::weak_ptr<ClientSession> client;
  };

  const std::size_t max_clients_;
  std::atomic<std::uint64_t> next_id_{1};
  mutable std::mutex m_;  // guards peers_
  std::unordered_map<std::uint64_t, Peer> peers_;
};

}  // namespace terrane
