#include "client/client.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <tuple>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <future>
#include <memory>
#include <utility>

namespace terrane {

namespace {

constexpr std::size_t kReadChunkBytes = 64 * 1024;

// Bytes wait while more than this is queued on the emulated link: one
// bandwidth-delay product, and at least one socket read's worth.
std::size_t emulation_queue_cap(const NetworkEmulation& e) {
  if (e.bandwidth_bytes_per_s == 0) return std::size_t{64} << 20;  // latency only: never the bottleneck
  const double bdp = static_cast<double>(e.bandwidth_bytes_per_s) * static_cast<double>(e.latency.count()) / 1000.0;
  return std::max<std::size_t>(kReadChunkBytes, static_cast<std::size_t>(bdp));
}

spdlog::logger& client_log() {
  static std::shared_ptr<spdlog::logger> log = [] {
    auto l = spdlog::get("client");
    if (!l) l = spdlog::stdout_color_mt("client");
    return l;
  }();
  return *log;
}

}  // namespace

// Every handler the client starts holds one of these: disconnect() in
// shared mode waits until no handler can still touch the Client.
class Client::OpGuard {
 public:
  explicit OpGuard(Client* c) : c_(c) { c_->pending_ops_.fetch_add(1, std::memory_order_relaxed); }
  OpGuard(OpGuard&& o) noexcept : c_(std::exchange(o.c_, nullptr)) {}
  OpGuard(const OpGuard&) = delete;
  OpGuard& operator=(const OpGuard&) = delete;
  OpGuard& operator=(OpGuard&&) = delete;
  ~OpGuard() {
    if (c_ == nullptr) return;
    if (c_->pending_ops_.fetch_sub(1, std::memory_order_acq_rel) == 1) {
      std::lock_guard lock(c_->ops_mutex_);
      c_->ops_done_.notify_all();
    }
  }

 private:
  Client* c_;
};

const char* message_type_name(std::size_t type) {
  if (type >= kMessageTypeCount) return "unknown";
  return wire::EnumNameBody(static_cast<wire::Body>(type));
}

Client::Client(ClientOptions options, ClientCallbacks callbacks)
    : options_(std::move(options)),
      callbacks_(std::move(callbacks)),
      own_io_(options_.io_context != nullptr ? nullptr : std::make_unique<asio::io_context>()),
      io_(options_.io_context != nullptr ? *options_.io_context : *own_io_),
      strand_(asio::make_strand(io_)),
      socket_(strand_),
      keepalive_(strand_),
      delivery_(strand_),
      read_buf_(kReadChunkBytes),
      reconnect_timer_(strand_),
      redirect_timer_(strand_) {
  replica_.share_decoded(options_.shared_chunks);
}

Client::~Client() { disconnect(); }

bool Client::connect(std::string* error) {
  asio::error_code ec;
  asio::ip::tcp::resolver resolver(io_);
  const auto endpoints = resolver.resolve(options_.host, std::to_string(options_.port), ec);
  if (ec || endpoints.empty()) {
    if (error) *error = "cannot resolve " + options_.host + ": " + ec.message();
    return false;
  }
  endpoints_ = endpoints;
  if (!options_.start_at_spawn && options_.stream) {
    std::lock_guard lock(mutex_);
    last_state_ = options_.state;
  }
  if (own_io_ == nullptr) {
    if (!connect_shared(endpoints, error)) return false;
    started_ = true;
    asio::post(strand_, [this, g = OpGuard(this)] { start_io(); });
    return true;
  }
  asio::error_code result = asio::error::would_block;
  asio::async_connect(socket_, endpoints, [&](const asio::error_code& e, const asio::ip::tcp::endpoint&) { result = e; });
  io_.run_for(options_.connect_timeout);
  if (result == asio::error::would_block || result) {
    if (error)
      *error = "cannot connect to " + options_.host + ":" + std::to_string(options_.port) + ": " +
               (result == asio::error::would_block ? std::string("timed out") : result.message());
    socket_.close(ec);
    return false;
  }
  io_.restart();
  started_ = true;
  start_io();
  thread_ = std::thread([this] { io_.run(); });
  return true;
}

bool Client::connect_shared(const asio::ip::tcp::resolver::results_type& endpoints, std::string* error) {
  auto done = std::make_shared<std::promise<asio::error_code>>();
  auto result = done->get_future();
  asio::post(strand_, [this, endpoints, done, g = OpGuard(this)] {
    asio::async_connect(socket_, endpoints,
                        [done, g2 = OpGuard(this)](const asio::error_code& e, const asio::ip::tcp::endpoint&) {
                          done->set_value(e);
                        });
  });
  bool timed_out = false;
  if (result.wait_for(options_.connect_timeout) != std::future_status::ready) {
    timed_out = true;
    asio::post(strand_, [this, g = OpGuard(this)] {
      asio::error_code ignored;
      socket_.close(ignored);
    });
  }
  const asio::error_code ec = result.get();  // the handler always runs (aborted when closed)
  if (!timed_out && !ec) return true;
  if (error)
    *error = "cannot connect to " + options_.host + ":" + std::to_string(options_.port) + ": " +
             (timed_out ? std::string("timed out") : ec.message());
  // Let the close (if any) finish before the caller may destroy us.
  std::unique_lock lock(ops_mutex_);
  ops_done_.wait(lock, [&] { return pending_ops_.load(std::memory_order_acquire) == 0; });
  return false;
}

void Client::start_io() { start_session(); }

void Client::start_session() {
  asio::error_code ec;
  socket_.set_option(asio::ip::tcp::no_delay(true), ec);
  reader_ = FrameReader();
  HelloMsg hello;
  hello.protocol_version = options_.protocol_version;
  hello.client_name = options_.name;
  hello.auth_token = options_.auth_token;
  hello.resume_token = std::exchange(resume_token_, std::string());
  std::vector<Outbound> frames;
  frames.push_back({build_hello(hello), wire::Body::Hello});
  {
    std::lock_guard lock(mutex_);
    if (resumed_) {
      // What the replica still holds, so current chunks are not resent.
      std::vector<HeldChunkMsg> held;
      replica_.for_each_holding([&](Vec3i cp, const Holding& h) {
        // Not the chunk's own voxels (an estimate, a horizon image): streamed again.
        if (claimable(h.form)) held.push_back(HeldChunkMsg{cp, h});
      });
      for (std::size_t i = 0; i < held.size(); i += kMaxHoldingsPerMessage)
        frames.push_back({build_holdings(std::span<const HeldChunkMsg>(held).subspan(
                              i, std::min(kMaxHoldingsPerMessage, held.size() - i))),
                          wire::Body::Holdings});
    }
    if (last_state_) frames.push_back({build_client_state(*last_state_), wire::Body::ClientState});
  }
  // Positions queued while the link was down (or a Redirect held the
  // queue) are older than the one just put first: sent after it, they
  // would move the client back in a burst, faster than a server allows.
  if (std::any_of(frames.begin(), frames.end(), [](const Outbound& o) { return o.type == wire::Body::ClientState; }))
    std::erase_if(send_queue_, [&](const Outbound& o) {
      if (o.type != wire::Body::ClientState) return false;
      queued_bytes_.fetch_sub(o.frame.size(), std::memory_order_relaxed);
      return true;
    });
  // Ahead of anything the application queued while the link was down.
  for (auto it = frames.rbegin(); it != frames.rend(); ++it) {
    queued_bytes_.fetch_add(it->frame.size(), std::memory_order_relaxed);
    send_queue_.push_front(std::move(*it));
  }
  linked_ = true;
  last_heard_ = std::chrono::steady_clock::now();
  do_write();
  do_read();
  arm_keepalive();
}

void Client::connection_lost(const std::string& reason, bool server_said) {
  // Reconnect only when nobody meant to end it: a drop without a reason, or
  // the server going away. A reason like "authentication failed" or a
  // limit would only repeat.
  bool not_returning = false;
  {
    std::lock_guard lock(mutex_);
    not_returning = server_not_returning_;
  }
  // A Redirect waiting for answers is followed now: this server is gone.
  if (redirect_ && !leaving_ && !io_closed_) return follow_redirect();
  const bool retry = options_.reconnect && !leaving_ && !io_closed_ &&
                     (!server_said || (reason == "server shutting down" && !not_returning));
  if (!retry) return close_locked_io(reason);
  drop_socket();
  writing_ = false;
  send_queue_.clear();
  edits_on_wire_.clear();
  queued_bytes_.store(0, std::memory_order_relaxed);
  std::vector<std::pair<std::uint32_t, EditOutcome>> unknown;
  {
    std::lock_guard lock(mutex_);
    unknown = settle_unanswered();
  }
  changed_.notify_all();
  client_log().info("'{}': connection lost ({}); reconnecting", options_.name, reason);
  if (callbacks_.on_connection_lost) callbacks_.on_connection_lost(reason);
  if (callbacks_.on_edit_result)
    for (const auto& [id, o] : unknown) callbacks_.on_edit_result(id, o);
  attempts_ = 0;
  backoff_ = options_.reconnect_min;
  schedule_reconnect();
}

std::vector<std::pair<std::uint32_t, EditOutcome>> Client::settle_unanswered() {
  std::vector<std::pair<std::uint32_t, EditOutcome>> unknown;
  for (const std::uint32_t id : unanswered_edits_) {
    EditOutcome o{false, 0, kEditOutcomeUnknown, {}, {}};
    edits_[id] = o;
    unknown.emplace_back(id, o);
  }
  unanswered_edits_.clear();
  return unknown;
}

void Client::drop_socket() {
  ++generation_;
  linked_ = false;
  asio::error_code ec;
  socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ec);
  socket_.close(ec);
  socket_ = asio::ip::tcp::socket(strand_);
  keepalive_.cancel();
  // Bytes of the old connection still on the emulated link go with it.
  delivery_.cancel();
  delayed_.clear();
  delayed_bytes_ = 0;
  read_paused_ = false;
  redirect_.reset();
  redirect_timer_.cancel();
  redirect_timer_armed_ = false;
}

void Client::follow_when_ready() {
  if (!redirect_ || io_closed_ || leaving_) return;
  if (!writing_ && edits_on_wire_.empty()) return follow_redirect();
  if (redirect_timer_armed_) return;
  redirect_timer_armed_ = true;
  redirect_timer_.expires_after(options_.redirect_wait);
  const std::uint64_t gen = generation_;
  redirect_timer_.async_wait([this, gen, g = OpGuard(this)](const asio::error_code& ec) {
    if (ec || gen != generation_ || io_closed_ || leaving_ || !redirect_) return;
    follow_redirect();
  });
}

void Client::follow_redirect() {
  const RedirectMsg to = *redirect_;
  const std::string target = to.host + ":" + std::to_string(to.port);
  if (!writing_) {
    // Nothing half written: the old server is told why.
    asio::error_code ignored;
    const Frame bye = build_disconnect("redirected to " + target);
    asio::write(socket_, asio::buffer(bye), ignored);
  } else {
    // redirect_wait ran out during a write: the frame may or may not have
    // gone, so it is not sent again. It stays queued (the write may still
    // read it) and is dropped when the next connection's writes reach it.
    Outbound& front = send_queue_.front();
    if (front.edit_id != 0) edits_on_wire_.insert(front.edit_id);
    front.skip = true;
    writing_ = false;
  }
  drop_socket();
  // Edits the old server has not answered may or may not be applied.
  std::vector<std::pair<std::uint32_t, EditOutcome>> unknown;
  {
    std::lock_guard lock(mutex_);
    for (const std::uint32_t id : edits_on_wire_) {
      EditOutcome o{false, 0, kEditOutcomeUnknown, {}, {}};
      unanswered_edits_.erase(id);
      edits_[id] = o;
      unknown.emplace_back(id, o);
    }
    ++counters_.redirects;
  }
  edits_on_wire_.clear();
  changed_.notify_all();
  client_log().info("'{}': redirected to server {} at {}", options_.name, to.server_id, target);
  if (callbacks_.on_redirected) callbacks_.on_redirected(to);
  if (callbacks_.on_edit_result)
    for (const auto& [id, o] : unknown) callbacks_.on_edit_result(id, o);
  if (io_closed_ || leaving_) return;
  resume_token_ = to.token;
  resumed_ = true;
  const std::uint64_t gen = generation_;
  // Back to the server that sent it (its endpoints are still endpoints_),
  // which may serve it on; Redirects to this target are not followed for a
  // while.
  auto failed = [this, gen, target](const std::string& why) {
    if (gen != generation_ || io_closed_ || leaving_) return;
    client_log().warn("'{}': cannot go on at {}: {}; back to the server that sent it", options_.name, target, why);
    unreachable_ = target;
    unreachable_until_ = std::chrono::steady_clock::now() + kUnreachableFor;
    resume_token_.clear();
    asio::error_code ignored;
    socket_.close(ignored);
    socket_ = asio::ip::tcp::socket(strand_);
    if (options_.reconnect) {
      attempts_ = 0;
      backoff_ = options_.reconnect_min;
      return schedule_reconnect();
    }
    asio::async_connect(socket_, endpoints_, [this, gen, target, g = OpGuard(this)](const asio::error_code& e,
                                                                                    const asio::ip::tcp::endpoint&) {
      if (gen != generation_ || io_closed_ || leaving_) return;
      if (e) return close_locked_io("redirect to " + target + " failed, and the server that sent it: " + e.message());
      start_session();
    });
  };
  auto resolver = std::make_shared<asio::ip::tcp::resolver>(strand_);
  resolver->async_resolve(
      to.host, std::to_string(to.port),
      [this, gen, resolver, failed, g = OpGuard(this)](const asio::error_code& ec,
                                                      asio::ip::tcp::resolver::results_type endpoints) {
        if (gen != generation_ || io_closed_ || leaving_) return;
        if (ec || endpoints.empty()) return failed("cannot resolve: " + ec.message());
        // A target that never answers is given up after connect_timeout.
        redirect_timer_.expires_after(options_.connect_timeout);
        redirect_timer_.async_wait([this, gen, g2 = OpGuard(this)](const asio::error_code& e) {
          if (e || gen != generation_ || linked_) return;
          asio::error_code ignored;
          socket_.cancel(ignored);
        });
        asio::async_connect(socket_, endpoints,
                            [this, gen, endpoints, failed, g2 = OpGuard(this)](const asio::error_code& e,
                                                                              const asio::ip::tcp::endpoint&) {
                              if (gen != generation_ || io_closed_ || leaving_) return;
                              redirect_timer_.cancel();
                              if (e) return failed(e == asio::error::operation_aborted ? std::string("timed out")
                                                                                       : e.message());
                              endpoints_ = endpoints;  // reconnects go here from now on
                              start_session();
                            });
      });
}

void Client::schedule_reconnect() {
  reconnect_timer_.expires_after(backoff_);
  reconnect_timer_.async_wait([this, g = OpGuard(this)](const asio::error_code& ec) {
    if (ec || io_closed_ || leaving_) return;
    ++attempts_;
    const std::uint64_t gen = generation_;
    asio::async_connect(socket_, endpoints_,
                        [this, gen, g2 = OpGuard(this)](const asio::error_code& e, const asio::ip::tcp::endpoint&) {
      if (gen != generation_ || io_closed_ || leaving_) return;
      if (e) {
        if (options_.reconnect_attempts > 0 && attempts_ >= options_.reconnect_attempts)
          return close_locked_io("reconnect failed after " + std::to_string(attempts_) + " attempts: " + e.message());
        asio::error_code ignored;
        socket_.close(ignored);
        backoff_ = std::min(backoff_ * 2, options_.reconnect_max);
        return schedule_reconnect();
      }
      resumed_ = true;
      {
        std::lock_guard lock(mutex_);
        ++counters_.reconnects;
      }
      start_session();
    });
  });
}

void Client::disconnect() {
  if (!started_) return;
  // Once; a second caller waits until the first is done, so every caller
  // returns with the client closed and its last callbacks made.
  std::call_once(disconnect_once_, [this] {
    leaving_ = true;
    asio::post(strand_, [this, g = OpGuard(this)] {
      reconnect_timer_.cancel();
      if (io_closed_) return;
      asio::error_code ec;
      const Frame bye = build_disconnect("client leaving");
      asio::write(socket_, asio::buffer(bye), ec);
      close_locked_io("disconnected by client");
    });
    if (thread_.joinable()) {
      thread_.join();
      return;
    }
    std::unique_lock lock(ops_mutex_);
    ops_done_.wait(lock, [&] { return pending_ops_.load(std::memory_order_acquire) == 0; });
  });
}

bool Client::send(Frame frame, wire::Body type, std::uint32_t edit_id) {
  if (io_closed_) return false;
  const std::size_t n = frame.size();
  if (queued_bytes_.load(std::memory_order_relaxed) + n > options_.max_send_queue_bytes) return false;
  queued_bytes_.fetch_add(n, std::memory_order_relaxed);
  asio::post(strand_, [this, f = std::move(frame), type, edit_id, g = OpGuard(this)]() mutable {
    if (io_closed_) {
      queued_bytes_.fetch_sub(f.size(), std::memory_order_relaxed);
      return;
    }
    send_queue_.push_back({std::move(f), type, edit_id});
    do_write();
  });
  return true;
}

void Client::do_write() {
  // A pending Redirect holds what is queued for the next server.
  if (writing_ || io_closed_ || !linked_ || redirect_) return;
  while (!send_queue_.empty() && send_queue_.front().skip) {
    queued_bytes_.fetch_sub(send_queue_.front().frame.size(), std::memory_order_relaxed);
    send_queue_.pop_front();
  }
  if (send_queue_.empty()) return;
  writing_ = true;
  const std::uint64_t gen = generation_;
  asio::async_write(socket_, asio::buffer(send_queue_.front().frame),
                    [this, gen, g = OpGuard(this)](const asio::error_code& ec, std::size_t) {
                      if (gen != generation_) return;  // a connection that is gone (its queue was dropped)
                      writing_ = false;
                      const Outbound& sent = send_queue_.front();
                      queued_bytes_.fetch_sub(sent.frame.size(), std::memory_order_relaxed);
                      if (!ec) {
                        std::lock_guard lock(mutex_);
                        ++counters_.frames_out;
                        counters_.bytes_out += sent.frame.size();
                        auto& t = counters_.by_message_type[static_cast<std::size_t>(sent.type)];
                        ++t.frames_out;
                        t.bytes_out += sent.frame.size();
                      }
                      if (!ec && sent.edit_id != 0) {
                        // Its answer may have been read before this ran.
                        std::lock_guard lock(mutex_);
                        if (unanswered_edits_.count(sent.edit_id) != 0) edits_on_wire_.insert(sent.edit_id);
                      }
                      send_queue_.pop_front();
                      if (ec) return connection_lost("write failed: " + ec.message(), false);
                      if (redirect_) return follow_when_ready();
                      do_write();
                    });
}

void Client::arm_keepalive() {
  keepalive_.expires_after(options_.keepalive);
  const std::uint64_t gen = generation_;
  keepalive_.async_wait([this, gen, g = OpGuard(this)](const asio::error_code& ec) {
    if (ec || io_closed_ || gen != generation_) return;
    const auto now = std::chrono::steady_clock::now();
    // Bytes waiting in the socket are no silence (this thread was slow to read them).
    asio::error_code avail_ec;
    if (options_.silence_timeout.count() > 0 && now - last_heard_ >= options_.silence_timeout &&
        socket_.available(avail_ec) == 0)
      return connection_lost(fmt::format("no answer from the server for {:.1f} s",
                                         std::chrono::duration<double>(now - last_heard_).count()),
                             false);
    // Its nonce is the steady clock in microseconds: the Pong times the round trip.
    const auto now_us = std::chrono::duration_cast<std::chrono::microseconds>(now.time_since_epoch()).count();
    send(build_ping(static_cast<std::uint64_t>(std::max<std::int64_t>(1, now_us))), wire::Body::Ping);
    arm_keepalive();
  });
}

void Client::do_read() {
  const std::uint64_t gen = generation_;
  socket_.async_read_some(asio::buffer(read_buf_), [this, gen, g = OpGuard(this)](const asio::error_code& ec, std::size_t n) {
    if (io_closed_ || gen != generation_) return;
    if (ec) return connection_lost(ec == asio::error::eof ? "server closed the connection" : ec.message(), false);
    last_heard_ = std::chrono::steady_clock::now();
    {
      std::lock_guard lock(mutex_);
      counters_.bytes_in += n;
    }
    if (options_.emulation.active()) {
      delay_bytes(n);
      return;
    }
    if (feed(std::span<const std::uint8_t>(read_buf_.data(), n)) && gen == generation_) do_read();
  });
}

bool Client::feed(std::span<const std::uint8_t> bytes) {
  // A frame that ends the connection (a Disconnect before a reconnect)
  // makes the rest of these bytes belong to a connection that is gone.
  const std::uint64_t gen = generation_;
  const auto st = reader_.feed(bytes, [&](std::span<const std::uint8_t> body) {
    if (!io_closed_ && gen == generation_) handle_frame(body);
  });
  if (gen != generation_) return false;
  if (!st) {
    {
      std::lock_guard lock(mutex_);
      ++counters_.protocol_errors;
      ++counters_.by_message_type[static_cast<std::size_t>(wire::Body::NONE)].frames_in;
    }
    close_locked_io(std::string("protocol error: ") + st.error().detail);
    return false;
  }
  return !io_closed_;
}

void Client::delay_bytes(std::size_t n) {
  using clock = std::chrono::steady_clock;
  const auto now = clock::now();
  const NetworkEmulation& e = options_.emulation;
  auto sent_at = now;
  if (e.bandwidth_bytes_per_s > 0) {
    const auto on_wire = std::chrono::nanoseconds(static_cast<std::int64_t>(
        static_cast<double>(n) * 1e9 / static_cast<double>(e.bandwidth_bytes_per_s)));
    link_free_ = std::max(link_free_, now) + on_wire;
    sent_at = link_free_;
  }
  delayed_.push_back(Delayed{sent_at + e.latency, std::vector<std::uint8_t>(read_buf_.begin(), read_buf_.begin() +
                                                                                           static_cast<std::ptrdiff_t>(n))});
  delayed_bytes_ += n;
  if (delayed_bytes_ < emulation_queue_cap(e))
    do_read();
  else
    read_paused_ = true;
  arm_delivery();
}

void Client::arm_delivery() {
  if (delivery_armed_ || delayed_.empty() || io_closed_) return;
  delivery_armed_ = true;
  delivery_.expires_at(delayed_.front().deliver_at);
  delivery_.async_wait([this, g = OpGuard(this)](const asio::error_code& ec) {
    delivery_armed_ = false;
    if (ec || io_closed_) return;
    const auto now = std::chrono::steady_clock::now();
    while (!delayed_.empty() && delayed_.front().deliver_at <= now) {
      Delayed d = std::move(delayed_.front());
      delayed_.pop_front();
      delayed_bytes_ -= d.bytes.size();
      if (!feed(d.bytes)) return;
    }
    if (read_paused_ && delayed_bytes_ < emulation_queue_cap(options_.emulation)) {
      read_paused_ = false;
      do_read();
    }
    arm_delivery();
  });
}

void Client::handle_frame(std::span<const std::uint8_t> body) {
  auto verified = verify_message(body);
  std::unique_lock lock(mutex_);
  ++counters_.frames_in;
  {
    const auto type = verified ? static_cast<std::size_t>((*verified)->body_type()) : std::size_t{0};
    auto& t = counters_.by_message_type[type < kMessageTypeCount ? type : 0];
    ++t.frames_in;
    t.bytes_in += body.size() + kFrameHeaderBytes;
  }
  auto fail = [&](const DecodeError& e) {
    ++counters_.protocol_errors;
    lock.unlock();
    client_log().warn("'{}': bad message from server: {}", options_.name, e.describe());
    close_locked_io(std::string("protocol error: ") + e.detail);
  };
  if (!verified) return fail(verified.error());
  const wire::Message& m = **verified;
  std::function<void()> after;  // callback to run without the lock
  switch (m.body_type()) {
    case wire::Body::Welcome: {
      auto w = parse_welcome(*m.body_as_Welcome());
      if (!w) return fail(w.error());
      if (w->protocol_version != kProtocolVersion)
        return fail(DecodeError{DecodeErrorCode::kBadVersion, 0, "welcome: protocol version mismatch"});
      welcome_ = *w;
      server_not_returning_ = false;
      if (resumed_) {
        if (callbacks_.on_reconnected) after = [this] { callbacks_.on_reconnected(); };
        break;
      }
      if (options_.start_at_spawn && options_.stream && !last_state_) {
        ClientStateMsg s = options_.state;
        s.position = {w->spawn.x + options_.spawn_offset.x, w->spawn.y + options_.spawn_offset.y,
                      w->spawn.z + options_.spawn_offset.z};
        last_state_ = s;
        lock.unlock();
        send(build_client_state(s), wire::Body::ClientState);
        lock.lock();
      }
      if (callbacks_.on_welcome) after = [this, w = *w] { callbacks_.on_welcome(w); };
      break;
    }
    case wire::Body::Disconnect: {
      auto r = parse_disconnect(*m.body_as_Disconnect());
      const std::string reason = r ? *r : std::string("(bad reason)");
      lock.unlock();
      connection_lost(reason, true);
      return;
    }
    case wire::Body::StreamBatch: {
      auto records = parse_stream_batch(*m.body_as_StreamBatch());
      if (!records) return fail(records.error());
      // (chunk, its holding now; nullopt: released), for on_holding.
      std::vector<std::pair<Vec3i, std::optional<Holding>>> changes;
      const bool tell = static_cast<bool>(callbacks_.on_holding);
      const auto st = decode_stream_batch(*records, stream_scratch_, [&](const StreamRecord& r) -> Status {
        if (r.kind == StreamRecordKind::kHorizon) {
          // A whole region: each chunk it newly covers is a change.
          horizon_covered_.clear();
          replica_.apply_horizon(r, horizon_covered_);
          counters_.horizon_chunks += horizon_covered_.size();
          if (tell)
            for (const Vec3i cp : horizon_covered_) changes.emplace_back(cp, Holding{horizon_form(r.level), 0});
          return Ok{};
        }
        replica_.apply_stream_record(r);
        switch (r.kind) {
          case StreamRecordKind::kEmpty:
            ++counters_.empty_records;
            break;
          case StreamRecordKind::kReleased:
            ++counters_.released;
            break;
          case StreamRecordKind::kFull:
            ++counters_.full_records;
            counters_.chunk_units += 8;
            break;
          case StreamRecordKind::kEstimate:
            ++counters_.mips;
            ++counters_.estimates;
            break;
          default:
            ++counters_.mips;
            break;
        }
        if (tell)
          changes.emplace_back(r.chunk_pos, gives_form(r.kind) ? std::optional<Holding>(Holding{r.form(), r.revision})
                                                               : std::nullopt);
        return Ok{};
      });
      // Records before a bad one were applied: the replica stays consistent.
      if (!st) return fail(st.error());
      if (!changes.empty())
        after = [this, ch = std::move(changes)] {
          for (const auto& [p, h] : ch) callbacks_.on_holding(p, h ? &*h : nullptr);
        };
      break;
    }
    case wire::Body::UpdateBatch: {
      auto b = parse_update_batch(*m.body_as_UpdateBatch());
      if (!b) return fail(b.error());
      std::vector<Region> changed;
      auto n = replica_.apply_update_batch(*b, callbacks_.on_update ? &changed : nullptr);
      if (!n) return fail(n.error());
      ++counters_.update_batches;
      counters_.units_updated += *n;
      if (callbacks_.on_update_batch || callbacks_.on_update)
        after = [this, info = UpdateInfo{b->tick, std::move(b->revisions), std::move(changed)}] {
          if (callbacks_.on_update_batch) callbacks_.on_update_batch(info.tick, info.revisions);
          if (callbacks_.on_update) callbacks_.on_update(info);
        };
      break;
    }
    case wire::Body::EditAck: {
      const auto* a = m.body_as_EditAck();
      EditOutcome o{true, a->tick(), {}, {}, {}};
      unanswered_edits_.erase(a->edit_id());
      edits_on_wire_.erase(a->edit_id());
      edits_[a->edit_id()] = o;
      ++counters_.edits_acked;
      if (callbacks_.on_edit_result) after = [this, id = a->edit_id(), o] { callbacks_.on_edit_result(id, o); };
      break;
    }
    case wire::Body::EditReject: {
      auto r = parse_edit_reject(*m.body_as_EditReject());
      if (!r) return fail(r.error());
      EditOutcome o{false, 0, std::move(r->reason), r->box, std::move(r->voxels)};
      unanswered_edits_.erase(r->edit_id);
      edits_on_wire_.erase(r->edit_id);
      ++counters_.edits_rejected;
      if (callbacks_.on_edit_result) after = [this, id = r->edit_id, o] { callbacks_.on_edit_result(id, o); };
      edits_[r->edit_id] = std::move(o);
      break;
    }
    case wire::Body::ReadBoxResult: {
      auto r = parse_read_box_result(*m.body_as_ReadBoxResult());
      if (!r) return fail(r.error());
      ++counters_.read_results;
      // Bounded: a server cannot grow this past the ids we asked for.
      if (r->request_id == 0 || r->request_id >= next_request_id_.load()) break;
      read_results_[r->request_id] = std::move(*r);
      break;
    }
    case wire::Body::Presence: {
      auto p = parse_presence(*m.body_as_Presence());
      if (!p) return fail(p.error());
      presence_ = std::move(*p);
      ++counters_.presence_updates;
      if (callbacks_.on_presence) after = [this, p = presence_] { callbacks_.on_presence(p); };
      break;
    }
    case wire::Body::ChunkHash: {
      auto h = parse_chunk_hash(*m.body_as_ChunkHash());
      if (!h) return fail(h.error());
      const auto mine = replica_.hash(h->chunk_pos);
      const auto rev = replica_.revision(h->chunk_pos);
      const bool match = mine && rev && *rev == h->revision && *mine == h->hash;
      hash_checks_[h->chunk_pos] = match;
      ++(match ? counters_.hash_matches : counters_.hash_mismatches);
      const Holding* held = replica_.holding(h->chunk_pos);
      const HashCheck check{h->chunk_pos, h->revision, rev, held != nullptr && held->full_resolution(), match};
      if (callbacks_.on_hash_checked || callbacks_.on_chunk_hash)
        after = [this, check] {
          if (callbacks_.on_hash_checked) callbacks_.on_hash_checked(check.chunk_pos, check.match);
          if (callbacks_.on_chunk_hash) callbacks_.on_chunk_hash(check);
        };
      break;
    }
    case wire::Body::Pong: {
      ++counters_.pongs;
      // Only a nonce this client could have sent (a time not in the future).
      const std::uint64_t nonce = m.body_as_Pong()->nonce();
      const auto now_us = static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::microseconds>(
                                                         std::chrono::steady_clock::now().time_since_epoch())
                                                         .count());
      if (nonce == 0 || nonce > now_us) break;
      const double ms = static_cast<double>(now_us - nonce) / 1000.0;
      counters_.last_round_trip_ms = ms;
      if (callbacks_.on_round_trip) after = [this, ms] { callbacks_.on_round_trip(ms); };
      break;
    }
    case wire::Body::ServerNotice: {
      auto n = parse_server_notice(*m.body_as_ServerNotice());
      if (!n) return fail(n.error());
      if (n->kind == wire::NoticeKind::Shutdown) server_not_returning_ = !n->reconnect;
      client_log().info("'{}': server notice: {}", options_.name, n->text);
      notices_.push_back(*n);
      if (notices_.size() > kMaxNotices) notices_.pop_front();
      if (callbacks_.on_notice) after = [this, n = *n] { callbacks_.on_notice(n); };
      break;
    }
    case wire::Body::Redirect: {
      auto r = parse_redirect(*m.body_as_Redirect());
      if (!r) return fail(r.error());
      // One at a time; a client that does not follow stays (and is closed
      // by the server after its grace).
      if (!options_.follow_redirects || redirect_) break;
      if (r->host + ":" + std::to_string(r->port) == unreachable_ && std::chrono::steady_clock::now() < unreachable_until_)
        break;  // failed a moment ago: stay
      client_log().info("'{}': server asks to go on at server {} ({}:{})", options_.name, r->server_id, r->host, r->port);
      redirect_ = std::move(*r);
      break;
    }
    case wire::Body::AdminResult: {
      auto r = parse_admin_result(*m.body_as_AdminResult());
      if (!r) return fail(r.error());
      // Bounded: a server cannot grow this past the ids we asked for.
      if (r->request_id == 0 || r->request_id >= next_request_id_.load()) break;
      admin_results_[r->request_id] = *r;
      if (callbacks_.on_admin_result) after = [this, r = *r] { callbacks_.on_admin_result(r); };
      break;
    }
    case wire::Body::Ping: {
      const std::uint64_t nonce = m.body_as_Ping()->nonce();
      lock.unlock();
      send(build_pong(nonce), wire::Body::Pong);
      lock.lock();
      break;
    }
    default:
      return fail(DecodeError{DecodeErrorCode::kInvalidValue, 0, "message not accepted from a server"});
  }
  lock.unlock();
  changed_.notify_all();
  if (after) after();
  if (redirect_) follow_when_ready();
}

void Client::close_locked_io(const std::string& reason) {
  if (io_closed_.exchange(true)) return;
  asio::error_code ec;
  socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ec);
  socket_.close(ec);
  keepalive_.cancel();
  reconnect_timer_.cancel();
  delivery_.cancel();
  redirect_timer_.cancel();
  redirect_.reset();
  std::string r;
  // Edits sent and never answered get their outcome now: unknown.
  std::vector<std::pair<std::uint32_t, EditOutcome>> unknown;
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    if (disconnect_reason_.empty()) disconnect_reason_ = reason;
    r = disconnect_reason_;
    unknown = settle_unanswered();
  }
  changed_.notify_all();
  if (callbacks_.on_edit_result)
    for (const auto& [id, o] : unknown) callbacks_.on_edit_result(id, o);
  if (callbacks_.on_disconnected) callbacks_.on_disconnected(r);
}

bool Client::set_state(const ClientStateMsg& state) {
  {
    std::lock_guard lock(mutex_);
    last_state_ = state;
  }
  return send(build_client_state(state), wire::Body::ClientState);
}

std::uint32_t Client::fill_box(const Region& box, Voxel v) {
  EditRequestMsg e;
  e.kind = EditKind::kFillBox;
  e.box = box;
  e.material = v.material;
  e.occupancy = v.occupancy;
  return send_edit(std::move(e));
}

std::uint32_t Client::fill_sphere(Vec3f center, float radius, Material material) {
  EditRequestMsg e;
  e.kind = EditKind::kFillSphere;
  e.center = center;
  e.radius = radius;
  e.material = material;
  return send_edit(std::move(e));
}

namespace {
EditRequestMsg sphere_edit(EditKind kind, Vec3f center, float radius, Material material, std::uint8_t occupancy) {
  EditRequestMsg e;
  e.kind = kind;
  e.center = center;
  e.radius = radius;
  e.material = material;
  e.occupancy = occupancy;
  return e;
}
}  // namespace

std::uint32_t Client::send_edit(EditRequestMsg e) {
  e.edit_id = next_edit_id_.fetch_add(1);
  {
    std::lock_guard lock(mutex_);
    unanswered_edits_.insert(e.edit_id);
  }
  if (send(build_edit_request(e), wire::Body::EditRequest, e.edit_id)) return e.edit_id;
  std::lock_guard lock(mutex_);
  unanswered_edits_.erase(e.edit_id);
  return 0;
}

std::uint32_t Client::dig(Vec3f center, float radius) {
  return send_edit(sphere_edit(EditKind::kDig, center, radius, kAir, 0));
}

std::uint32_t Client::paint(Vec3f center, float radius, Material material) {
  return send_edit(sphere_edit(EditKind::kPaint, center, radius, material, 0));
}

std::uint32_t Client::smooth(Vec3f center, float radius, float strength) {
  const float s = std::clamp(strength, 1.0f / 255.0f, 1.0f);
  return send_edit(sphere_edit(EditKind::kSmooth, center, radius, kAir, static_cast<std::uint8_t>(std::lround(s * 255.0f))));
}

std::uint32_t Client::write_box(const Region& box, std::span<const Voxel> voxels) {
  if (box.empty() || box.volume() > kMaxRawBoxVolume || voxels.size() != static_cast<std::size_t>(box.volume())) return 0;
  EditRequestMsg e;
  e.kind = EditKind::kWriteBox;
  e.box = box;
  e.voxels.assign(voxels.begin(), voxels.end());
  return send_edit(std::move(e));
}

std::uint32_t Client::undo() {
  EditRequestMsg e;
  e.kind = EditKind::kUndo;
  return send_edit(std::move(e));
}

std::uint32_t Client::redo() {
  EditRequestMsg e;
  e.kind = EditKind::kRedo;
  return send_edit(std::move(e));
}

std::uint32_t Client::request_read_box(const Region& box) {
  if (box.empty() || box.volume() > kMaxRawBoxVolume) return 0;
  const std::uint32_t id = next_request_id_.fetch_add(1);
  return send(build_read_box(id, box), wire::Body::ReadBox) ? id : 0;
}

std::vector<PresenceEntryMsg> Client::presence() const {
  std::lock_guard lock(mutex_);
  return presence_;
}

std::uint32_t Client::admin(const std::string& command, const std::vector<std::string>& args) {
  if (command.empty() || command.size() > kMaxAdminCommandBytes || args.size() > kMaxAdminArgs) return 0;
  for (const auto& a : args)
    if (a.size() > kMaxAdminArgBytes) return 0;
  const std::uint32_t id = next_request_id_.fetch_add(1);
  return send(build_admin_request(AdminRequestMsg{id, command, args}), wire::Body::AdminRequest) ? id : 0;
}

std::optional<ClientStateMsg> Client::last_state() const {
  std::lock_guard lock(mutex_);
  return last_state_;
}

std::vector<ServerNoticeMsg> Client::notices() const {
  std::lock_guard lock(mutex_);
  return {notices_.begin(), notices_.end()};
}

bool Client::request_chunk_hash(Vec3i chunk_pos) {
  return send(build_chunk_hash_request(chunk_pos), wire::Body::ChunkHashRequest);
}
bool Client::ping(std::uint64_t nonce) { return send(build_ping(nonce), wire::Body::Ping); }
bool Client::send_raw(Frame bytes) { return send(std::move(bytes), wire::Body::NONE); }

ClientView Client::view() const {
  return ClientView{replica_,     counters_,     welcome_.has_value(), closed_,  disconnect_reason_,
                    edits_,       hash_checks_,  read_results_,        presence_, notices_,
                    admin_results_};
}

bool Client::wait_until(const std::function<bool(const ClientView&)>& pred, std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  return changed_.wait_for(lock, timeout, [&] { return pred(view()); });
}

Voxel Client::get(Vec3i voxel) const {
  std::lock_guard lock(mutex_);
  return replica_.get(voxel);
}

void Client::read_box(Vec3i min, Box& out) const {
  std::lock_guard lock(mutex_);
  replica_.read_box(min, out);
}

int Client::resolution_at(Vec3i voxel) const {
  std::lock_guard lock(mutex_);
  return replica_.resolution_at(voxel);
}

std::optional<RayHit> Client::raycast(Vec3f origin, Vec3f direction, float max_distance) const {
  std::lock_guard lock(mutex_);
  return replica_.raycast(origin, direction, max_distance);
}

std::optional<std::int32_t> Client::surface_height(std::int32_t x, std::int32_t z) const {
  std::lock_guard lock(mutex_);
  if (!welcome_) return std::nullopt;
  return replica_.surface_height(x, z, welcome_->bounds_min_y, welcome_->bounds_max_y);
}

std::optional<WelcomeMsg> Client::welcome() const {
  std::lock_guard lock(mutex_);
  return welcome_;
}

ClientCounters Client::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

bool Client::closed() const {
  std::lock_guard lock(mutex_);
  return closed_;
}

std::string Client::disconnect_reason() const {
  std::lock_guard lock(mutex_);
  return disconnect_reason_;
}

}  // namespace terrane
