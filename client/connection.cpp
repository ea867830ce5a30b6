#include "client/connection.h"

#include <fmt/format.h>

#include <algorithm>
#include <future>
#include <memory>
#include <utility>

#include "client/client_log.h"

namespace terrane {

namespace {

// The start of what a peer sent, up to its first line end, printable (at
// most 60 characters; other bytes as \xNN).
std::string first_line(std::span<const std::uint8_t> bytes) {
  std::string out;
  for (const std::uint8_t b : bytes) {
    if (b == '\r' || b == '\n' || out.size() >= 60) break;
    if (b >= 0x20 && b < 0x7f) out += static_cast<char>(b);
    else out += fmt::format("\\x{:02x}", b);
  }
  return out;
}

// The room a connection's FrameReader keeps between frames; a larger
// frame's is freed once it is read (Connection::feed).
constexpr std::size_t kKeptFrameBytes = 16 * 1024;

}  // namespace

Connection::Connection(const ClientOptions& options, ConnectionHandler& handler)
    : options_(options),
      handler_(handler),
      io_(options_.io_context),
      socket_(io_.strand()),
      keepalive_(io_.strand()),
      delivery_(io_.strand()),
      reconnect_timer_(io_.strand()),
      redirect_timer_(io_.strand()),
      queue_(options_.max_send_queue_bytes),
      link_(options_.emulation),
      redirects_(options_.follow_redirects) {}

Connection::~Connection() { disconnect(); }

bool Connection::connect(std::string* error) {
  asio::error_code ec;
  asio::ip::tcp::resolver resolver(io_.context());
  const auto endpoints = resolver.resolve(options_.host, std::to_string(options_.port), ec);
  if (ec || endpoints.empty()) {
    if (error) *error = "cannot resolve " + options_.host + ": " + ec.message();
    return false;
  }
  endpoints_ = endpoints;
  if (!io_.owned()) {
    if (!connect_shared(endpoints, error)) return false;
    started_ = true;
    asio::post(io_.strand(), [this, g = guard()] { start_session(); });
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
  started_ = true;
  start_session();
  io_.start_thread();
  return true;
}

bool Connection::connect_shared(const asio::ip::tcp::resolver::results_type& endpoints, std::string* error) {
  auto done = std::make_shared<std::promise<asio::error_code>>();
  auto result = done->get_future();
  asio::post(io_.strand(), [this, endpoints, done, g = guard()] {
    asio::async_connect(socket_, endpoints, [done, g2 = guard()](const asio::error_code& e, const asio::ip::tcp::endpoint&) {
      done->set_value(e);
    });
  });
  bool timed_out = false;
  if (result.wait_for(options_.connect_timeout) != std::future_status::ready) {
    timed_out = true;
    asio::post(io_.strand(), [this, g = guard()] {
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
  io_.finish();
  return false;
}

void Connection::start_session() {
  asio::error_code ec;
  socket_.set_option(asio::ip::tcp::no_delay(true), ec);
  // Reads happen once the socket is readable (do_read) and must never block
  // an io thread shared with other connections.
  socket_.non_blocking(true, ec);
  reader_ = FrameReader();
  HelloMsg hello;
  hello.protocol_version = options_.protocol_version;
  hello.client_name = options_.name;
  hello.auth_token = options_.auth_token;
  hello.resume_token = redirects_.take_token();
  hello.features = options_.features;
  std::vector<Outbound> frames;
  frames.push_back({build_hello(hello), wire::Body::Hello});
  for (Outbound& o : handler_.session_frames(session_)) frames.push_back(std::move(o));
  // Positions queued while the link was down (or a Redirect held the
  // queue) are older than the one just put first: sent after it, they
  // would move the client back in a burst, faster than a server allows.
  if (std::any_of(frames.begin(), frames.end(), [](const Outbound& o) { return o.type == wire::Body::ClientState; }))
    queue_.drop(wire::Body::ClientState);
  // Ahead of anything the application queued while the link was down.
  queue_.push_front(std::move(frames));
  linked_ = true;
  framed_ = false;
  last_heard_ = std::chrono::steady_clock::now();
  do_write();
  do_read();
  arm_keepalive();
}

void Connection::lost(const std::string& reason, bool may_return) {
  // A Redirect waiting for answers is followed now: this server is gone.
  if (redirects_.pending() && !leaving_ && !closed_) return follow_redirect();
  const bool retry = options_.reconnect && !leaving_ && !closed_ && may_return;
  if (!retry) return close(reason);
  drop_socket();
  queue_.clear();
  client_log().info("'{}': connection lost ({}); reconnecting", options_.name, reason);
  handler_.on_reconnecting(reason);
  attempts_ = 0;
  backoff_ = options_.reconnect_min;
  schedule_reconnect();
}

void Connection::drop_socket() {
  ++generation_;
  linked_ = false;
  asio::error_code ec;
  socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ec);
  socket_.close(ec);
  socket_ = asio::ip::tcp::socket(io_.strand());
  keepalive_.cancel();
  // Bytes of the old connection still on the emulated link go with it.
  delivery_.cancel();
  link_.clear();
  redirects_.cancel();
  redirect_timer_.cancel();
  redirect_timer_armed_ = false;
}

bool Connection::offer_redirect(RedirectMsg r) {
  const RedirectMsg shown = r;
  if (!redirects_.offer(std::move(r), std::chrono::steady_clock::now())) return false;
  client_log().info("'{}': server asks to go on at server {} ({}:{})", options_.name, shown.server_id, shown.host,
                    shown.port);
  return true;
}

void Connection::follow_when_ready() {
  if (!redirects_.pending() || closed_ || leaving_) return;
  if (!queue_.writing() && !handler_.awaiting_answers()) return follow_redirect();
  if (redirect_timer_armed_) return;
  redirect_timer_armed_ = true;
  redirect_timer_.expires_after(options_.redirect_wait);
  const std::uint64_t gen = generation_;
  redirect_timer_.async_wait([this, gen, g = guard()](const asio::error_code& ec) {
    if (ec || gen != generation_ || closed_ || leaving_ || !redirects_.pending()) return;
    follow_redirect();
  });
}

void Connection::follow_redirect() {
  const RedirectMsg to = redirects_.follow();
  const std::string target = Redirects::target_of(to);
  std::uint32_t cut_edit = 0;
  if (!queue_.writing()) {
    // Nothing half written: the old server is told why.
    asio::error_code ignored;
    const Frame bye = build_disconnect("redirected to " + target);
    asio::write(socket_, asio::buffer(bye), ignored);
  } else {
    // redirect_wait ran out during a write: the frame may or may not have
    // gone, so it is not sent again.
    cut_edit = queue_.abandon_write();
  }
  drop_socket();
  client_log().info("'{}': redirected to server {} at {}", options_.name, to.server_id, target);
  handler_.on_redirected(to, cut_edit);
  if (closed_ || leaving_) return;
  session_ = SessionStart::kRedirect;
  const std::uint64_t gen = generation_;
  auto resolver = std::make_shared<asio::ip::tcp::resolver>(io_.strand());
  resolver->async_resolve(
      to.host, std::to_string(to.port),
      [this, gen, resolver, target, g = guard()](const asio::error_code& ec,
                                                 asio::ip::tcp::resolver::results_type endpoints) {
        if (gen != generation_ || closed_ || leaving_) return;
        if (ec || endpoints.empty()) return redirect_failed(gen, target, "cannot resolve: " + ec.message());
        // A target that never answers is given up after connect_timeout.
        redirect_timer_.expires_after(options_.connect_timeout);
        redirect_timer_.async_wait([this, gen, g2 = guard()](const asio::error_code& e) {
          if (e || gen != generation_ || linked_) return;
          asio::error_code ignored;
          socket_.cancel(ignored);
        });
        asio::async_connect(socket_, endpoints,
                            [this, gen, endpoints, target, g2 = guard()](const asio::error_code& e,
                                                                         const asio::ip::tcp::endpoint&) {
                              if (gen != generation_ || closed_ || leaving_) return;
                              redirect_timer_.cancel();
                              if (e)
                                return redirect_failed(
                                    gen, target, e == asio::error::operation_aborted ? std::string("timed out") : e.message());
                              endpoints_ = endpoints;  // reconnects go here from now on
                              start_session();
                            });
      });
}

void Connection::redirect_failed(std::uint64_t gen, const std::string& target, const std::string& why) {
  // Back to the server that sent it (its endpoints are still endpoints_),
  // which may serve it on; Redirects to this target are not followed for a
  // while.
  if (gen != generation_ || closed_ || leaving_) return;
  client_log().warn("'{}': cannot go on at {}: {}; back to the server that sent it", options_.name, target, why);
  redirects_.unreachable(target, std::chrono::steady_clock::now());
  asio::error_code ignored;
  socket_.close(ignored);
  socket_ = asio::ip::tcp::socket(io_.strand());
  if (options_.reconnect) {
    attempts_ = 0;
    backoff_ = options_.reconnect_min;
    return schedule_reconnect();
  }
  asio::async_connect(socket_, endpoints_, [this, gen, target, g = guard()](const asio::error_code& e,
                                                                            const asio::ip::tcp::endpoint&) {
    if (gen != generation_ || closed_ || leaving_) return;
    if (e) return close("redirect to " + target + " failed, and the server that sent it: " + e.message());
    start_session();
  });
}

void Connection::schedule_reconnect() {
  reconnect_timer_.expires_after(backoff_);
  reconnect_timer_.async_wait([this, g = guard()](const asio::error_code& ec) {
    if (ec || closed_ || leaving_) return;
    ++attempts_;
    const std::uint64_t gen = generation_;
    asio::async_connect(socket_, endpoints_, [this, gen, g2 = guard()](const asio::error_code& e,
                                                                       const asio::ip::tcp::endpoint&) {
      if (gen != generation_ || closed_ || leaving_) return;
      if (e) {
        if (options_.reconnect_attempts > 0 && attempts_ >= options_.reconnect_attempts)
          return close("reconnect failed after " + std::to_string(attempts_) + " attempts: " + e.message());
        asio::error_code ignored;
        socket_.close(ignored);
        backoff_ = std::min(backoff_ * 2, options_.reconnect_max);
        return schedule_reconnect();
      }
      session_ = SessionStart::kReconnect;
      start_session();
    });
  });
}

void Connection::disconnect() {
  if (!started_) return;
  // Once; a second caller waits until the first is done, so every caller
  // returns with the connection closed and its last calls made.
  std::call_once(disconnect_once_, [this] {
    leaving_ = true;
    asio::post(io_.strand(), [this, g = guard()] {
      reconnect_timer_.cancel();
      if (closed_) return;
      asio::error_code ec;
      const Frame bye = build_disconnect("client leaving");
      asio::write(socket_, asio::buffer(bye), ec);
      close("disconnected by client");
    });
    io_.finish();
  });
}

void Connection::close(const std::string& reason) {
  if (closed_.exchange(true)) return;
  asio::error_code ec;
  socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ec);
  socket_.close(ec);
  keepalive_.cancel();
  reconnect_timer_.cancel();
  delivery_.cancel();
  redirect_timer_.cancel();
  redirects_.cancel();
  handler_.on_closed(reason);
}

void Connection::post(std::function<void()> fn) {
  asio::post(io_.strand(), [this, fn = std::move(fn), g = guard()] {
    if (!closed_) fn();
  });
}

bool Connection::send(Frame frame, wire::Body type, std::uint32_t edit_id) {
  if (closed_) return false;
  if (!queue_.reserve(frame.size())) return false;
  asio::post(io_.strand(), [this, f = std::move(frame), type, edit_id, g = guard()]() mutable {
    if (closed_) {
      queue_.unreserve(f.size());
      return;
    }
    queue_.push_back({std::move(f), type, edit_id});
    do_write();
  });
  return true;
}

void Connection::do_write() {
  // A pending Redirect holds what is queued for the next server.
  if (closed_ || !linked_ || redirects_.pending()) return;
  const Outbound* next = queue_.start_write();
  if (next == nullptr) return;
  const std::uint64_t gen = generation_;
  asio::async_write(socket_, asio::buffer(next->frame), [this, gen, g = guard()](const asio::error_code& ec, std::size_t) {
    if (gen != generation_) return;  // a connection that is gone (its queue was dropped)
    if (ec) {
      queue_.finish_write();
      return lost("write failed: " + ec.message(), true);
    }
    // Before the frame leaves the queue: on_written reads it.
    handler_.on_written(queue_.in_flight());
    queue_.finish_write();
    if (redirects_.pending()) return follow_when_ready();
    do_write();
  });
}

void Connection::arm_keepalive() {
  // Often enough that the Pongs keep a short silence_timeout from firing
  // on a server that answers.
  auto every = options_.keepalive;
  if (options_.silence_timeout.count() > 0)
    every = std::min(every, std::max(std::chrono::milliseconds(100), options_.silence_timeout / 2));
  keepalive_.expires_after(every);
  const std::uint64_t gen = generation_;
  keepalive_.async_wait([this, gen, g = guard()](const asio::error_code& ec) {
    if (ec || closed_ || gen != generation_) return;
    const auto now = std::chrono::steady_clock::now();
    // Bytes waiting in the socket are no silence (this thread was slow to read them).
    asio::error_code avail_ec;
    if (options_.silence_timeout.count() > 0 && now - last_heard_ >= options_.silence_timeout &&
        socket_.available(avail_ec) == 0) {
      const double silent_s = std::chrono::duration<double>(now - last_heard_).count();
      const std::string silent = fmt::format("no answer from the server for {:.1f} s", silent_s);
      // Reconnected to a socket that accepts but never answers: a hung
      // server (stopped, or its process wedged), which retrying would
      // wait on for ever.
      if (session_ == SessionStart::kReconnect && !framed_)
        return close(silent + " since reconnecting: it accepts connections but does not answer");
      return lost(silent, true);
    }
    // Its nonce is the steady clock in microseconds: the Pong times the round trip.
    const auto now_us = std::chrono::duration_cast<std::chrono::microseconds>(now.time_since_epoch()).count();
    send(build_ping(static_cast<std::uint64_t>(std::max<std::int64_t>(1, now_us))), wire::Body::Ping);
    arm_keepalive();
  });
}

void Connection::do_read() {
  const std::uint64_t gen = generation_;
  socket_.async_wait(asio::ip::tcp::socket::wait_read, [this, gen, g = guard()](const asio::error_code& wait_ec) {
    if (closed_ || gen != generation_) return;
    if (wait_ec) return lost(wait_ec.message(), true);
    // A few reads per wake, as long as bytes are there: bytes that came
    // while the last were handled are read without another wait (as a
    // speculative read does), and a busy connection still gives way to
    // the others.
    constexpr int kReadsPerWake = 4;
    // Its io thread's buffer, not one per connection (a 64 KiB buffer per
    // connection was a tenth of a bot's memory); the emulated link copies.
    const std::span<std::uint8_t> buf = thread_read_buffer();
    for (int i = 0; i < kReadsPerWake; ++i) {
      asio::error_code ec;
      const std::size_t n = socket_.read_some(asio::buffer(buf.data(), buf.size()), ec);
      if (ec == asio::error::would_block || ec == asio::error::try_again) break;  // nothing more for now
      if (ec) return lost(ec == asio::error::eof ? "server closed the connection" : ec.message(), true);
      last_heard_ = std::chrono::steady_clock::now();
      handler_.on_bytes_read(n);
      const std::span<const std::uint8_t> bytes(buf.data(), n);
      if (link_.active()) {
        const bool more = link_.carry(bytes, std::chrono::steady_clock::now());
        arm_delivery();
        if (!more) return;  // (the link reads again once it drains)
        continue;
      }
      if (!feed(bytes) || gen != generation_) return;
    }
    do_read();
  });
}

bool Connection::feed(std::span<const std::uint8_t> bytes) {
  // A frame that ends the connection (a Disconnect before a reconnect)
  // makes the rest of these bytes belong to a connection that is gone.
  const std::uint64_t gen = generation_;
  bool large = false;
  const auto st = reader_.feed(bytes, [&](std::span<const std::uint8_t> body) {
    large = large || body.size() > kKeptFrameBytes;
    if (closed_ || gen != generation_) return;
    framed_ = true;
    handler_.on_frame(body);
    if (!closed_ && gen == generation_ && redirects_.pending()) follow_when_ready();
  });
  if (gen != generation_) return false;
  // A large frame's room is not kept for the frames after it: most are
  // small, and a process of many connections (terrane-bots) kept a stream
  // batch's worth (64 KiB and more) per connection. Between frames the
  // reader holds nothing else, so it starts afresh (its error offsets then
  // count from here).
  if (st && large && reader_.buffered() == 0) reader_ = FrameReader();
  if (!st) {
    handler_.on_framing_error();
    // Bytes that never made one frame: something else listens there (an
    // HTTP port, say); its first line says what.
    if (!framed_) close("not a terrane-server (it sent '" + first_line(bytes) + "', which is no frame)");
    else close(std::string("protocol error: ") + st.error().detail);
    return false;
  }
  return !closed_;
}

void Connection::arm_delivery() {
  const auto at = link_.next_at();
  if (delivery_armed_ || !at || closed_) return;
  delivery_armed_ = true;
  delivery_.expires_at(*at);
  delivery_.async_wait([this, g = guard()](const asio::error_code& ec) {
    delivery_armed_ = false;
    if (ec || closed_) return;
    const auto now = std::chrono::steady_clock::now();
    while (auto bytes = link_.take_due(now))
      if (!feed(*bytes)) return;
    if (link_.resume()) do_read();
    arm_delivery();
  });
}

}  // namespace terrane
