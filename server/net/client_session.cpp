#include "server/net/client_session.h"

#include "common/cli/json.h"

#include "server/base/log.h"

namespace terrane {

namespace {

std::uint64_t steady_micros(std::chrono::steady_clock::time_point t) {
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::microseconds>(t.time_since_epoch()).count());
}

}  // namespace

ClientSession::ClientSession(std::uint64_t id, const Context& context, std::shared_ptr<ClientReplica> replica)
    : id_(id), context_(context), replica_(std::move(replica)) {}

std::shared_ptr<ClientSession> ClientSession::open(asio::ip::tcp::socket socket, std::uint64_t id,
                                                   const SessionLimits& limits, const Context& context,
                                                   std::shared_ptr<ClientReplica> replica) {
  std::shared_ptr<ClientSession> self(new ClientSession(id, context, std::move(replica)));
  self->session_ = std::make_shared<Session>(
      std::move(socket), id, limits,
      [self](std::uint64_t, InboundMessage msg) { self->on_message(std::move(msg)); },
      [self](std::uint64_t, const std::string& reason) { self->on_closed(reason); },
      [self](std::uint64_t) {
        if (self->joined_ && !self->closed_) self->replica_->drained();
      });
  self->ping_timer_ = std::make_unique<asio::steady_timer>(self->session_->executor());
  return self;
}

ClientSession::Info ClientSession::info() const {
  std::lock_guard lock(info_m_);
  return info_;
}

void ClientSession::on_message(InboundMessage msg) {
  if (closed_) return;
  if (auto* hello = std::get_if<HelloMsg>(&msg)) return on_hello(*hello);
  if (!joined_) return;
  if (auto* state = std::get_if<ClientStateMsg>(&msg)) {
    if (!replica_->move(*state)) return;
    std::lock_guard lock(info_m_);
    info_.position = state->position;
    return;
  }
  if (auto* edit = std::get_if<EditRequestMsg>(&msg)) return replica_->edit(std::move(*edit));
  if (auto* read = std::get_if<ReadBoxMsg>(&msg)) return replica_->read_box(*read);
  if (auto* held = std::get_if<HoldingsMsg>(&msg)) return replica_->holdings(*held);
  if (auto* req = std::get_if<ChunkHashRequestMsg>(&msg)) return replica_->hash_request(req->chunk_pos);
  if (auto* admin = std::get_if<AdminRequestMsg>(&msg)) return on_admin(std::move(*admin));
  if (auto* pong = std::get_if<PongMsg>(&msg)) return on_pong(pong->nonce);
}

void ClientSession::on_hello(const HelloMsg& hello) {
  if (hello.protocol_version != kProtocolVersion) {
    server_log().warn("session {}: protocol version {} rejected", id_, hello.protocol_version);
    session_->close(CloseReason::kVersionMismatch,
                    "protocol version " + std::to_string(hello.protocol_version) +
                        " is not supported: this server speaks version " + std::to_string(kProtocolVersion) +
                        " (protocol/PROTOCOL.md); update the client");
    return;
  }
  const auto now_unix =
      std::chrono::duration_cast<std::chrono::seconds>(std::chrono::system_clock::now().time_since_epoch()).count();
  const Admission admission =
      context_.admitter.admit(hello.client_name, hello.auth_token, session_->address(), now_unix);
  if (!admission.ok) {
    if (admission.why == CloseReason::kAuthFailed) {
      context_.counters.auth_failures.fetch_add(1, std::memory_order_relaxed);
      violations().warn("session " + std::to_string(id_) + " (" + session_->remote() +
                        "): authentication failed for '" + hello.client_name + "'");
    } else {
      server_log().info("session {} ({}): '{}' refused: {}", id_, session_->remote(), hello.client_name,
                        admission.reason);
    }
    session_->close(admission.why, admission.reason);
    return;
  }
  admin_ = admission.admin;
  name_ = hello.client_name;
  joined_ = true;
  // The join's place in the server's order of joins (1, 2, ...): of two
  // sessions of one player, the later join wins, whichever thread gets
  // there first.
  const std::uint64_t join_order = context_.counters.joins.fetch_add(1, std::memory_order_relaxed) + 1;
  {
    std::lock_guard lock(info_m_);
    info_ = Info{name_, context_.welcome.spawn, admin_, true, std::chrono::steady_clock::now(), -1, join_order};
  }
  replica_->join(name_, admission.identified, hello.features);
  (admin_ ? context_.counters.admin_sessions : context_.counters.clients).fetch_add(1, std::memory_order_relaxed);
  session_->send(build_welcome(context_.welcome));
  if (!admin_ && context_.joined && !context_.joined(id_, name_, join_order)) {
    session_->close(CloseReason::kReplaced, "logged in from another location: the same player joined again");
    return;
  }
  // A Redirect's token says where the client comes from (it grants nothing).
  if (!hello.resume_token.empty()) context_.counters.redirects_received.fetch_add(1, std::memory_order_relaxed);
  // Names and resume tokens are printable (parse_hello refuses control
  // characters): they cannot end a log line.
  server_log().info("session {} ({}) joined as '{}'{}{}", id_, session_->remote(), name_, admin_ ? " (admin)" : "",
                    hello.resume_token.empty() ? std::string() : " (redirected: " + hello.resume_token + ")");
  ping();
  // Streaming starts with the client's first ClientState.
}

void ClientSession::ping() {
  // The nonce is the steady clock in microseconds when the Ping goes out.
  const auto now = std::chrono::steady_clock::now();
  ping_nonce_ = steady_micros(now);
  session_->send(build_ping(ping_nonce_), SendClass::kControl);
  ping_timer_->expires_at(now + kPingPeriod);
  ping_timer_->async_wait([self = shared_from_this()](const asio::error_code& ec) {
    if (ec || self->closed_) return;
    self->ping();
  });
}

void ClientSession::on_pong(std::uint64_t nonce) {
  // Only the answer to the last Ping sent counts, once.
  if (nonce == 0 || nonce != ping_nonce_) return;
  ping_nonce_ = 0;
  const std::uint64_t now = steady_micros(std::chrono::steady_clock::now());
  std::lock_guard lock(info_m_);
  info_.ping_ms = static_cast<double>(static_cast<std::int64_t>(now - nonce)) / 1000.0;
}

void ClientSession::on_admin(AdminRequestMsg req) {
  if (!admin_) {
    const std::string why = "not an admin: this session's token does not have the admin role";
    AdminResultMsg r{req.request_id, false, why + "\n", "{\"error\": " + json_string(why) + "}"};
    session_->send(build_admin_result(r), SendClass::kControl);
    return;
  }
  context_.admin(name_, std::move(req), [weak = std::weak_ptr<Session>(session_)](AdminResultMsg r) {
    if (auto s = weak.lock()) s->send(build_admin_result(r), SendClass::kControl);
  });
}

void ClientSession::on_closed(const std::string& reason) {
  if (closed_) return;
  closed_ = true;
  ping_timer_->cancel();
  if (context_.forget) context_.forget(id_);
  replica_->closed();
  if (joined_)
    (admin_ ? context_.counters.admin_sessions : context_.counters.clients).fetch_sub(1, std::memory_order_relaxed);
  server_log().info("session {} ({}) closed: {}", id_, name_.empty() ? session_->remote() : name_, reason);
  session_.reset();  // breaks the cycle with the session's callbacks
}

}  // namespace terrane
