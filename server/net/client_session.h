// ClientSession: one client's session above the framing (net/session.h):
// the handshake (the Hello, its protocol version, the admission, the
// Welcome), pings and their round trip, operators' commands sent by
// admins, and who the client is, for operators (Info). Once the client is
// admitted, the messages about the world go to its ClientReplica
// (replication's Replicator), which never sees tokens, roles, pings or
// admin commands.
//
//   [connected] --Hello, another version--> Disconnect naming both versions
//        |      --Hello, refused----------> Disconnect with the Admitter's reason
//        +------Hello, admitted-----------> replica.join(name, identified), Welcome, Ping
//                                                |
//   [joined] <-----------------------------------+
//     ClientState, EditRequest, ReadBox, Holdings, ChunkHashRequest -> the replica
//     AdminRequest -> the AdminFn (an admin) or a refusal (anyone else)
//     Pong -> the round trip (Info::ping_ms); a Ping every kPingPeriod
//   socket closed -> replica.closed(), once, joined or not
//
// Threading: every member runs on the session's strand, except info()
// (any thread: operators' commands read it on the admin thread; info_m_).
// Lifetime: shared, kept by the session's callbacks (until the socket
// closes) and by the ping timer's wait.
#pragma once

#include <asio.hpp>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "protocol/messages.h"
#include "server/base/counters.h"
#include "server/net/net_options.h"
#include "server/net/admission.h"
#include "server/net/session.h"

namespace terrane {

// What an admitted client's session hands on: the messages about the world.
// Every call is made on the session strand.
class ClientReplica {
 public:
  virtual ~ClientReplica() = default;
  // Once, when the client is admitted as name, before its Welcome is sent.
  // identified: the Admission's (the name is proven the player's).
  // features: its Hello's (kFeature* bits: what it can take).
  virtual void join(const std::string& name, bool identified, std::uint32_t features) = 0;
  // A move; false if it was refused (the session is then closing).
  virtual bool move(const ClientStateMsg& state) = 0;
  virtual void edit(EditRequestMsg edit) = 0;
  virtual void read_box(const ReadBoxMsg& req) = 0;
  virtual void holdings(const HoldingsMsg& held) = 0;
  virtual void hash_request(Vec3i chunk_pos) = 0;
  // The send queue ran empty (after the join): room to stream more.
  virtual void drained() = 0;
  // The socket closed: once, whether or not the client joined.
  virtual void closed() = 0;
};

class ClientSession : public std::enable_shared_from_this<ClientSession> {
 public:
  // An admin command from the client name, answered through reply (any thread).
  using AdminFn = std::function<void(const std::string& who, AdminRequestMsg req,
                                     std::function<void(AdminResultMsg)> reply)>;
  // What every session of a server shares; outlives them all.
  struct Context {
    const WelcomeMsg& welcome;  // the parts of the Welcome that do not vary
    const Admitter& admitter;
    const AdminFn& admin;
    ServerCounters& counters;
    // A session's socket closed (its id), before the replica is told:
    // the server drops it from its table.
    std::function<void(std::uint64_t id)> forget;
    // A player (not an admin) was welcomed as name, the server's
    // join_order-th join: the server ends that name's sessions that joined
    // before it, and answers false if that name joined again since (the
    // later join wins: the session ends). Unset: nothing is done.
    std::function<bool(std::uint64_t id, const std::string& name, std::uint64_t join_order)> joined = nullptr;
  };
  // Who the client is, for operators (any thread).
  struct Info {
    std::string name;
    Vec3f position;
    bool admin = false;
    bool welcomed = false;
    std::chrono::steady_clock::time_point joined;
    double ping_ms = -1;  // the last round trip measured; -1 before the first
    std::uint64_t join_order = 0;  // the server's n-th join (1, 2, ...); 0 before the Welcome
  };
  // The server pings each client this often (its round trip, for operators;
  // the answers keep a quiet client within its idle timeout).
  static constexpr std::chrono::seconds kPingPeriod{5};

  // A session on socket (not started) whose admitted client's world
  // messages go to replica. context outlives the session.
  static std::shared_ptr<ClientSession> open(asio::ip::tcp::socket socket, std::uint64_t id,
                                             const SessionLimits& limits, const Context& context,
                                             std::shared_ptr<ClientReplica> replica);

  // The framing underneath: for the replica to send through, and for the
  // server's table. Null once the socket closed.
  const std::shared_ptr<Session>& session() const { return session_; }
  Info info() const;

 private:
  ClientSession(std::uint64_t id, const Context& context, std::shared_ptr<ClientReplica> replica);

  void on_message(InboundMessage msg);
  void on_hello(const HelloMsg& hello);
  void on_admin(AdminRequestMsg req);
  void on_pong(std::uint64_t nonce);
  void on_closed(const std::string& reason);
  void ping();

  const std::uint64_t id_;
  const Context& context_;
  std::shared_ptr<ClientReplica> replica_;
  // Dropped when the socket closes (it and the session's callbacks keep
  // each other alive).
  std::shared_ptr<Session> session_;
  std::unique_ptr<asio::steady_timer> ping_timer_;
  std::uint64_t ping_nonce_ = 0;  // of the Ping awaiting its Pong
  bool joined_ = false;
  bool closed_ = false;
  bool admin_ = false;
  std::string name_;
  mutable std::mutex info_m_;
  Info info_;  // a copy of name, position and role for other threads
};

}  // namespace terrane
