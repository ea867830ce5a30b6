#include "server/net/session.h"

#include <algorithm>
#include <array>

#include "server/base/log.h"

namespace terrane {

namespace {
// A write gathers queued frames up to about this many bytes.
constexpr std::size_t kWriteGatherBytes = 256 * 1024;
// Buffers handed to one system call (Linux takes up to IOV_MAX, 1,024).
constexpr std::size_t kMaxWriteBuffers = 64;
// A run of a session's gathered buffers, as asio takes a buffer sequence
// (held by value in the write operation, so no copy of the vector).
struct BufferRange {
  const asio::const_buffer* first;
  const asio::const_buffer* last;
  const asio::const_buffer* begin() const { return first; }
  const asio::const_buffer* end() const { return last; }
};
// How often the watchdog checks the read/write deadlines.
constexpr std::chrono::milliseconds kWatchdogPeriod{200};

// A client that leaves with our data unread makes its kernel answer with a
// reset, not a FIN: the read or the write then fails with ECONNRESET or
// EPIPE. It is still the client closing, not a fault of the socket.
CloseReason close_reason_of(const asio::error_code& ec) {
  if (ec == asio::error::eof || ec == asio::error::connection_reset || ec == asio::error::broken_pipe) {
    return CloseReason::kPeerClosed;
  }
  return CloseReason::kSocketError;
}
}  // namespace

Session::Session(asio::ip::tcp::socket socket, std::uint64_t id, const SessionLimits& limits, InboundFn on_message,
                 ClosedFn on_closed, DrainedFn on_drained)
    : socket_(std::move(socket)),
      watchdog_(socket_.get_executor()),
      id_(id),
      limits_(limits),
      on_message_(std::move(on_message)),
      on_closed_(std::move(on_closed)),
      on_drained_(std::move(on_drained)),
      reader_(limits.max_frame_bytes),
      inbound_(limits.inbound_bytes_per_second, limits.inbound_burst_bytes) {
  asio::error_code ec;
  const auto ep = socket_.remote_endpoint(ec);
  address_ = ec ? std::string("?") : canonical_address(ep.address().to_string());
  remote_ = ec ? std::string("?") : address_ + ":" + std::to_string(ep.port());
}

void Session::start() {
  asio::dispatch(socket_.get_executor(), [self = shared_from_this()] {
    asio::error_code ec;
    self->socket_.set_option(asio::ip::tcp::no_delay(true), ec);
    if (self->limits_.socket_send_buffer_bytes > 0)
      self->socket_.set_option(asio::socket_base::send_buffer_size(self->limits_.socket_send_buffer_bytes), ec);
    // Reads do not block: do_read waits for the socket to be readable and
    // reads what is there into its io thread's buffer.
    self->socket_.non_blocking(true, ec);
    self->last_read_ = Clock::now();
    self->arm_watchdog();
    self->do_read();
  });
}

void Session::send(OutFrame frame, SendClass cls) {
  asio::dispatch(socket_.get_executor(), [self = shared_from_this(), f = std::move(frame), cls]() mutable {
    if (self->state_ != State::kReading) return;
    self->enqueue(std::move(f), cls);
  });
}

void Session::close(CloseReason why, std::string text) {
  asio::dispatch(socket_.get_executor(),
                 [self = shared_from_this(), why, t = std::move(text)] { self->begin_close(why, t); });
}

void Session::arm_watchdog() {
  watchdog_.expires_after(kWatchdogPeriod);
  watchdog_.async_wait([self = shared_from_this()](const asio::error_code& ec) {
    if (ec || self->state_ == State::kClosed) return;
    const auto now = Clock::now();
    switch (self->state_) {
      case State::kReading: {
        const auto limit = self->welcomed_ ? self->limits_.idle_timeout : self->limits_.handshake_timeout;
        if (now - self->last_read_ > limit) {
          if (self->welcomed_)
            self->begin_close(CloseReason::kIdleTimeout, "idle timeout");
          else
            self->begin_close(CloseReason::kHandshakeTimeout, "handshake timeout");
        } else if (self->partial_frame_ && now - self->frame_started_ > self->limits_.frame_timeout) {
          violations().warn("session " + std::to_string(self->id_) + " (" + self->remote_ +
                            "): frame not completed in time; dropping");
          self->begin_close(CloseReason::kFrameTimeout, "frame not completed within " + std::to_string(self->limits_.frame_timeout.count()) +
                            " ms");
        } else if (self->writing_ && now - self->write_started_ > self->limits_.write_timeout) {
          // The client stopped reading. Its reason goes after the write in
          // flight, in case it resumes within the linger time.
          server_log().warn("session {} ({}): too slow, no data taken for {} ms; dropping", self->id_, self->remote_,
                            self->limits_.write_timeout.count());
          self->begin_close(CloseReason::kTooSlow, "too slow: no data taken for " + std::to_string(self->limits_.write_timeout.count()) +
                            " ms");
        }
        break;
      }
      case State::kClosing:
      case State::kDraining:
        if (now - self->close_started_ > self->limits_.linger) {
          self->finish_close();
          return;
        }
        break;
      case State::kClosed:
        return;
    }
    self->arm_watchdog();
  });
}

void Session::do_read() {
  socket_.async_wait(asio::ip::tcp::socket::wait_read, [self = shared_from_this()](const asio::error_code& wait_ec) {
    if (self->state_ == State::kClosed) return;
    if (wait_ec) return self->read_failed(wait_ec);
    // A few reads per wake, as long as bytes are there: what came while the
    // last were handled is read without another wait, and a busy session
    // still gives way to the others.
    constexpr int kReadsPerWake = 4;
    const std::span<std::uint8_t> buf = thread_read_buffer();  // its io thread's, not a buffer per session
    for (int i = 0; i < kReadsPerWake; ++i) {
      asio::error_code ec;
      const std::size_t n = self->socket_.read_some(asio::buffer(buf.data(), buf.size()), ec);
      if (ec == asio::error::would_block || ec == asio::error::try_again) break;  // nothing more for now
      if (ec) return self->read_failed(ec);
      if (!self->on_bytes(buf.first(n))) break;
      if (self->state_ == State::kClosed) return;
    }
    self->do_read();
  });
}

void Session::read_failed(const asio::error_code& ec) {
  if (state_ == State::kReading) {
    close_reason_ = ec == asio::error::eof ? "peer closed" : ec.message();
    close_why_ = close_reason_of(ec);
  }
  finish_close();
}

bool Session::on_bytes(std::span<const std::uint8_t> bytes) {
  if (state_ != State::kReading) return true;  // closing: discard input until EOF or the linger deadline
  last_read_ = Clock::now();
  bytes_received_.fetch_add(bytes.size(), std::memory_order_relaxed);
  if (!inbound_.take(static_cast<double>(bytes.size()), last_read_)) {
    violations().warn("session " + std::to_string(id_) + " (" + remote_ + "): inbound rate limit; dropping");
    begin_close(CloseReason::kInboundRate, "inbound rate limit: over " +
                std::to_string(static_cast<long long>(limits_.inbound_bytes_per_second)) + " bytes/s");
    return false;
  }
  const auto st = reader_.feed(bytes, [&](std::span<const std::uint8_t> body) {
    if (state_ == State::kReading) on_frame(body);
  });
  if (reader_.buffered() == 0) {
    partial_frame_ = false;
  } else if (!partial_frame_) {
    partial_frame_ = true;
    frame_started_ = last_read_;
  }
  if (!st) {
    violations().warn("session " + std::to_string(id_) + " (" + remote_ + "): bad frame: " + st.error().describe());
    begin_close(CloseReason::kProtocolError, std::string("protocol error: ") + st.error().detail);
    return false;
  }
  return true;
}

void Session::on_frame(std::span<const std::uint8_t> body) {
  auto msg = verify_message(body);
  if (!msg) {
    violations().warn("session " + std::to_string(id_) + " (" + remote_ + "): " + msg.error().describe());
    begin_close(CloseReason::kProtocolError, std::string("protocol error: ") + msg.error().detail);
    return;
  }
  const wire::Message& m = **msg;
  if (limits_.counters != nullptr) {
    const auto type = static_cast<std::size_t>(m.body_type());
    if (type < NetCounters::kTypes) {
      limits_.counters->net.received_bytes[type].fetch_add(body.size() + kFrameHeaderBytes, std::memory_order_relaxed);
      limits_.counters->net.received_frames[type].fetch_add(1, std::memory_order_relaxed);
    }
  }
  auto fail = [&](const DecodeError& e) {
    violations().warn("session " + std::to_string(id_) + " (" + remote_ + "): " + e.detail);
    begin_close(CloseReason::kProtocolError, std::string("protocol error: ") + e.detail);
  };
  if (!welcomed_) {
    if (m.body_type() != wire::Body::Hello) return fail(DecodeError{DecodeErrorCode::kInvalidValue, 0, "expected Hello"});
    auto hello = parse_hello(*m.body_as_Hello());
    if (!hello) return fail(hello.error());
    welcomed_ = true;
    on_message_(id_, std::move(*hello));
    return;
  }
  switch (m.body_type()) {
    case wire::Body::ClientState: {
      auto s = parse_client_state(*m.body_as_ClientState());
      if (!s) return fail(s.error());
      on_message_(id_, *s);
      return;
    }
    case wire::Body::EditRequest: {
      const auto* req = m.body_as_EditRequest();
      auto e = parse_edit_request(*req);
      // A meaningless edit is rejected, not a reason to disconnect.
      if (!e) {
        if (limits_.counters != nullptr) limits_.counters->rejected(RejectReason::kInvalid);
        return enqueue(build_edit_reject(req->edit_id(), e.error().detail), SendClass::kControl);
      }
      on_message_(id_, *e);
      return;
    }
    case wire::Body::ChunkHashRequest: {
      auto p = parse_chunk_hash_request(*m.body_as_ChunkHashRequest());
      if (!p) return fail(p.error());
      on_message_(id_, ChunkHashRequestMsg{*p});
      return;
    }
    case wire::Body::Holdings: {
      auto h = parse_holdings(*m.body_as_Holdings());
      if (!h) return fail(h.error());
      on_message_(id_, HoldingsMsg{std::move(*h), m.body_as_Holdings()->world_id()});
      return;
    }
    case wire::Body::ReadBox: {
      auto r = parse_read_box(*m.body_as_ReadBox());
      if (!r) return fail(r.error());
      on_message_(id_, *r);
      return;
    }
    case wire::Body::AdminRequest: {
      auto r = parse_admin_request(*m.body_as_AdminRequest());
      if (!r) return fail(r.error());
      on_message_(id_, std::move(*r));
      return;
    }
    case wire::Body::Ping:
      return enqueue(build_pong(m.body_as_Ping()->nonce()), SendClass::kControl);
    case wire::Body::Pong:
      on_message_(id_, PongMsg{m.body_as_Pong()->nonce()});
      return;
    case wire::Body::Disconnect:
      close_reason_ = "client disconnected";
      close_why_ = CloseReason::kClientBye;
      begin_close(CloseReason::kClientBye, "bye");
      return;
    default:
      return fail(DecodeError{DecodeErrorCode::kInvalidValue, 0, "message not accepted from a client"});
  }
}

void Session::enqueue(OutFrame frame, SendClass cls) {
  const std::size_t now = queued_bytes_.load(std::memory_order_relaxed);
  if (now + frame.size() > limits_.max_queue_bytes) {
    server_log().warn("session {} ({}): {} bytes queued, dropping", id_, remote_, now);
    begin_close(CloseReason::kTooFarBehind, "too far behind");
    return;
  }
  add_queued(static_cast<std::int64_t>(frame.size()));
  const std::span<const std::uint8_t> first = frame.first_segment();
  if (limits_.counters != nullptr && first.size() > kFrameHeaderBytes) {
    // Our own frame: its type is read without verification, from its first
    // segment, which holds the Message table (protocol/out_frame.h).
    const auto type = static_cast<std::size_t>(
        flatbuffers::GetRoot<wire::Message>(first.data() + kFrameHeaderBytes)->body_type());
    if (type < NetCounters::kTypes) {
      limits_.counters->net.sent_bytes[type].fetch_add(frame.size(), std::memory_order_relaxed);
      limits_.counters->net.sent_frames[type].fetch_add(1, std::memory_order_relaxed);
    }
  }
  (cls == SendClass::kControl ? control_queue_ : queue_).push_back(std::move(frame));
  schedule_write();
}

void Session::schedule_write() {
  // A frame sent to an idle session would otherwise be written at once, in
  // a system call of its own, and the frames queued by the handlers right
  // behind it (a fan-out's update, the replicator's stream batch, a pong)
  // in the next: one post, and they share one.
  if (writing_ || write_scheduled_) return;
  write_scheduled_ = true;
  asio::post(socket_.get_executor(), [self = shared_from_this()] {
    self->write_scheduled_ = false;
    self->do_write();
  });
}

void Session::do_write() {
  if (writing_ || state_ == State::kClosed) return;
  // Before the first data frame (the Welcome, or the Disconnect of a
  // refused Hello) control frames wait: the protocol lets a server send
  // nothing else first, and a client may send a Ping before its Welcome.
  if (queue_.empty() && (control_queue_.empty() || !data_started_)) return;
  writing_ = true;
  write_started_ = Clock::now();
  if (limits_.counters != nullptr) limits_.counters->net.writes.fetch_add(1, std::memory_order_relaxed);
  // Every segment of the frames gathered, in one write: shared bytes go
  // from their owners' buffers to the socket.
  write_bufs_.clear();
  write_next_ = 0;
  write_gathered_ = 0;
  const bool control_first = data_started_;
  data_started_ = true;
  for (auto* q : control_first ? std::array{&control_queue_, &queue_} : std::array{&queue_, &control_queue_}) {
    while (!q->empty() && (write_gathered_ == 0 || write_gathered_ + q->front().size() <= kWriteGatherBytes)) {
      write_gathered_ += q->front().size();
      q->front().for_each_segment([&](std::span<const std::uint8_t> s) {
        if (!s.empty()) write_bufs_.emplace_back(s.data(), s.size());
      });
      inflight_.push_back(std::move(q->front()));
      q->pop_front();
    }
  }
  write_some();
}

void Session::write_some() {
  // At most kMaxWriteBuffers iovecs a system call: asio's async_write
  // would hand sendmsg 16 at a time (asio 1.22), and a stream batch is
  // mostly shared chunk bytes, a segment each.
  const std::size_t end = std::min(write_bufs_.size(), write_next_ + kMaxWriteBuffers);
  socket_.async_write_some(BufferRange{write_bufs_.data() + write_next_, write_bufs_.data() + end},
                           [self = shared_from_this()](const asio::error_code& ec, std::size_t n) {
                             self->on_written(ec, n);
                           });
}

void Session::on_written(const asio::error_code& ec, std::size_t n) {
  bytes_sent_.fetch_add(n, std::memory_order_relaxed);
  if (n > 0) write_started_ = Clock::now();  // the watchdog drops writes that make no progress
  if (!ec && state_ != State::kClosed) {
    while (write_next_ < write_bufs_.size() && n >= write_bufs_[write_next_].size())
      n -= write_bufs_[write_next_++].size();
    if (write_next_ < write_bufs_.size()) {
      write_bufs_[write_next_] += n;  // a buffer written in part
      return write_some();
    }
  }
  writing_ = false;
  inflight_.clear();
  add_queued(-static_cast<std::int64_t>(write_gathered_));
  if (state_ == State::kClosed) return;
  if (ec) {
    if (close_reason_.empty()) {
      close_reason_ = ec.message();
      close_why_ = close_reason_of(ec);
    }
    finish_close();
    return;
  }
  if (!queue_.empty() || !control_queue_.empty()) return do_write();
  if (state_ == State::kReading && on_drained_) on_drained_(id_);
  // (The owner may have queued more, or closed the session, its Disconnect
  // now on its way.)
  if (writing_ || write_scheduled_ || !queue_.empty() || !control_queue_.empty()) return;
  if (state_ == State::kClosing) {
    // Reason delivered: stop sending, wait for the peer to close.
    state_ = State::kDraining;
    asio::error_code ignored;
    socket_.shutdown(asio::ip::tcp::socket::shutdown_send, ignored);
  }
}

void Session::add_queued(std::int64_t delta) {
  if (delta >= 0)
    queued_bytes_.fetch_add(static_cast<std::size_t>(delta), std::memory_order_relaxed);
  else
    queued_bytes_.fetch_sub(static_cast<std::size_t>(-delta), std::memory_order_relaxed);
  if (limits_.counters != nullptr) limits_.counters->net.queued_bytes.fetch_add(delta, std::memory_order_relaxed);
}

void Session::begin_close(CloseReason why, const std::string& reason) {
  if (state_ != State::kReading) return;
  if (close_reason_.empty()) {
    close_reason_ = reason;
    close_why_ = why;
  }
  state_ = State::kClosing;
  close_started_ = Clock::now();
  // Drop the world data queued but not in flight; control frames (acks,
  // rejections, notices, admin answers: small, and what the peer most needs
  // to know) still go out, ahead of the reason.
  for (const auto& f : queue_) add_queued(-static_cast<std::int64_t>(f.size()));
  queue_.clear();
  if (!data_started_) {
    // Never welcomed (or its Welcome not yet written, now dropped): the
    // Disconnect goes alone, as the protocol allows nothing else first.
    for (const auto& f : control_queue_) add_queued(-static_cast<std::int64_t>(f.size()));
    control_queue_.clear();
  }
  OutFrame bye = build_disconnect(reason);
  add_queued(static_cast<std::int64_t>(bye.size()));
  queue_.push_back(std::move(bye));
  schedule_write();
}

void Session::finish_close() {
  if (state_ == State::kClosed) return;
  state_ = State::kClosed;
  asio::error_code ignored;
  watchdog_.cancel();
  socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
  socket_.close(ignored);
  for (auto* q : {&control_queue_, &queue_}) {
    for (const auto& f : *q) add_queued(-static_cast<std::int64_t>(f.size()));
    q->clear();
  }
  if (on_closed_) on_closed_(id_, close_reason_.empty() ? std::string("closed") : close_reason_);
  // After the owner's books (clients connected) are settled.
  if (limits_.counters != nullptr) limits_.counters->net.disconnected(close_why_);
  on_closed_ = nullptr;
  on_message_ = nullptr;
  on_drained_ = nullptr;
}

}  // namespace terrane
