#include "client/client.h"

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
      read_buf_(kReadChunkBytes) {}

Client::~Client() { disconnect(); }

bool Client::connect(std::string* error) {
  asio::error_code ec;
  asio::ip::tcp::resolver resolver(io_);
  const auto endpoints = resolver.resolve(options_.host, std::to_string(options_.port), ec);
  if (ec || endpoints.empty()) {
    if (error) *error = "cannot resolve " + options_.host + ": " + ec.message();
    return false;
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

void Client::start_io() {
  asio::error_code ec;
  socket_.set_option(asio::ip::tcp::no_delay(true), ec);
  HelloMsg hello;
  hello.protocol_version = options_.protocol_version;
  hello.client_name = options_.name;
  hello.auth_token = options_.auth_token;
  send_queue_.push_back({build_hello(hello), wire::Body::Hello});
  if (!options_.start_at_spawn) send_queue_.push_back({build_client_state(options_.state), wire::Body::ClientState});
  for (const Outbound& o : send_queue_) queued_bytes_.fetch_add(o.frame.size(), std::memory_order_relaxed);
  do_write();
  do_read();
  arm_keepalive();
}

void Client::disconnect() {
  if (!started_ || disconnected_.exchange(true)) return;
  asio::post(strand_, [this, g = OpGuard(this)] {
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
}

bool Client::send(Frame frame, wire::Body type) {
  if (io_closed_) return false;
  const std::size_t n = frame.size();
  if (queued_bytes_.load(std::memory_order_relaxed) + n > options_.max_send_queue_bytes) return false;
  queued_bytes_.fetch_add(n, std::memory_order_relaxed);
  asio::post(strand_, [this, f = std::move(frame), type, g = OpGuard(this)]() mutable {
    if (io_closed_) {
      queued_bytes_.fetch_sub(f.size(), std::memory_order_relaxed);
      return;
    }
    send_queue_.push_back({std::move(f), type});
    do_write();
  });
  return true;
}

void Client::do_write() {
  if (writing_ || send_queue_.empty() || io_closed_) return;
  writing_ = true;
  asio::async_write(socket_, asio::buffer(send_queue_.front().frame),
                    [this, g = OpGuard(this)](const asio::error_code& ec, std::size_t) {
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
                      send_queue_.pop_front();
                      if (ec) return close_locked_io("write failed: " + ec.message());
                      do_write();
                    });
}

void Client::arm_keepalive() {
  keepalive_.expires_after(options_.keepalive);
  keepalive_.async_wait([this, g = OpGuard(this)](const asio::error_code& ec) {
    if (ec || io_closed_) return;
    send(build_ping(0), wire::Body::Ping);
    arm_keepalive();
  });
}

void Client::do_read() {
  socket_.async_read_some(asio::buffer(read_buf_), [this, g = OpGuard(this)](const asio::error_code& ec, std::size_t n) {
    if (io_closed_) return;
    if (ec) return close_locked_io(ec == asio::error::eof ? "server closed the connection" : ec.message());
    {
      std::lock_guard lock(mutex_);
      counters_.bytes_in += n;
    }
    if (options_.emulation.active()) {
      delay_bytes(n);
      return;
    }
    if (feed(std::span<const std::uint8_t>(read_buf_.data(), n))) do_read();
  });
}

bool Client::feed(std::span<const std::uint8_t> bytes) {
  const auto st = reader_.feed(bytes, [&](std::span<const std::uint8_t> body) {
    if (!io_closed_) handle_frame(body);
  });
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
      if (options_.start_at_spawn) {
        ClientStateMsg s = options_.state;
        s.position = w->spawn;
        lock.unlock();
        send(build_client_state(s), wire::Body::ClientState);
        lock.lock();
      }
      if (callbacks_.on_welcome) after = [this, w = *w] { callbacks_.on_welcome(w); };
      break;
    }
    case wire::Body::Disconnect: {
      auto r = parse_disconnect(*m.body_as_Disconnect());
      disconnect_reason_ = r ? *r : std::string("(bad reason)");
      lock.unlock();
      close_locked_io(disconnect_reason_);
      return;
    }
    case wire::Body::ChunkData: {
      auto c = parse_chunk_data(*m.body_as_ChunkData());
      if (!c) return fail(c.error());
      if (auto st = replica_.apply_chunk_data(*c); !st) return fail(st.error());
      ++counters_.chunk_units;
      break;
    }
    case wire::Body::MipData: {
      auto d = parse_mip_data(*m.body_as_MipData());
      if (!d) return fail(d.error());
      if (auto st = replica_.apply_mip_data(*d); !st) return fail(st.error());
      ++counters_.mips;
      if (callbacks_.on_coverage)
        after = [this, p = d->chunk_pos, l = d->level] { callbacks_.on_coverage(p, wire::CoverageKind::Mip, l); };
      break;
    }
    case wire::Body::Coverage: {
      auto c = parse_coverage(*m.body_as_Coverage());
      if (!c) return fail(c.error());
      replica_.apply_coverage(*c);
      if (c->kind == wire::CoverageKind::Empty) ++counters_.coverage_empty;
      if (c->kind == wire::CoverageKind::Full) ++counters_.coverage_full;
      if (c->kind == wire::CoverageKind::Released) ++counters_.released;
      if (callbacks_.on_coverage) after = [this, c = *c] { callbacks_.on_coverage(c.chunk_pos, c.kind, c.level); };
      break;
    }
    case wire::Body::UpdateBatch: {
      auto b = parse_update_batch(*m.body_as_UpdateBatch());
      if (!b) return fail(b.error());
      auto n = replica_.apply_update_batch(*b);
      if (!n) return fail(n.error());
      ++counters_.update_batches;
      counters_.units_updated += *n;
      if (callbacks_.on_update_batch)
        after = [this, tick = b->tick, revs = std::move(b->revisions)] { callbacks_.on_update_batch(tick, revs); };
      break;
    }
    case wire::Body::EditAck: {
      const auto* a = m.body_as_EditAck();
      EditOutcome o{true, a->tick(), {}};
      edits_[a->edit_id()] = o;
      ++counters_.edits_acked;
      if (callbacks_.on_edit_result) after = [this, id = a->edit_id(), o] { callbacks_.on_edit_result(id, o); };
      break;
    }
    case wire::Body::EditReject: {
      const auto* r = m.body_as_EditReject();
      EditOutcome o{false, 0, r->reason() != nullptr ? r->reason()->str().substr(0, kMaxReasonBytes) : std::string()};
      edits_[r->edit_id()] = o;
      ++counters_.edits_rejected;
      if (callbacks_.on_edit_result) after = [this, id = r->edit_id(), o] { callbacks_.on_edit_result(id, o); };
      break;
    }
    case wire::Body::RegionHash: {
      auto h = parse_region_hash(*m.body_as_RegionHash());
      if (!h) return fail(h.error());
      const auto mine = replica_.hash(h->chunk_pos);
      const auto rev = replica_.revision(h->chunk_pos);
      const bool match = mine && rev && *rev == h->revision && *mine == h->hash;
      hash_checks_[h->chunk_pos] = match;
      ++(match ? counters_.hash_matches : counters_.hash_mismatches);
      const ChunkCoverage* cov = replica_.coverage(h->chunk_pos);
      const HashCheck check{h->chunk_pos, h->revision, rev, cov != nullptr && cov->state != CoverageState::kMip, match};
      if (callbacks_.on_hash_checked || callbacks_.on_region_hash)
        after = [this, check] {
          if (callbacks_.on_hash_checked) callbacks_.on_hash_checked(check.chunk_pos, check.match);
          if (callbacks_.on_region_hash) callbacks_.on_region_hash(check);
        };
      break;
    }
    case wire::Body::Pong:
      ++counters_.pongs;
      break;
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
}

void Client::close_locked_io(const std::string& reason) {
  if (io_closed_.exchange(true)) return;
  asio::error_code ec;
  socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ec);
  socket_.close(ec);
  keepalive_.cancel();
  delivery_.cancel();
  std::string r;
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    if (disconnect_reason_.empty()) disconnect_reason_ = reason;
    r = disconnect_reason_;
  }
  changed_.notify_all();
  if (callbacks_.on_disconnected) callbacks_.on_disconnected(r);
}

bool Client::set_state(const ClientStateMsg& state) { return send(build_client_state(state), wire::Body::ClientState); }

std::uint32_t Client::fill_box(const Region& box, Voxel v) {
  EditRequestMsg e;
  e.edit_id = next_edit_id_.fetch_add(1);
  e.kind = EditKind::kFillBox;
  e.box = box;
  e.material = v.material;
  e.occupancy = v.occupancy;
  return send(build_edit_request(e), wire::Body::EditRequest) ? e.edit_id : 0;
}

std::uint32_t Client::fill_sphere(Vec3f center, float radius, Material material) {
  EditRequestMsg e;
  e.edit_id = next_edit_id_.fetch_add(1);
  e.kind = EditKind::kFillSphere;
  e.center = center;
  e.radius = radius;
  e.material = material;
  return send(build_edit_request(e), wire::Body::EditRequest) ? e.edit_id : 0;
}

bool Client::request_region_hash(Vec3i chunk_pos) {
  return send(build_region_hash_request(chunk_pos), wire::Body::RegionHashRequest);
}
bool Client::ping(std::uint64_t nonce) { return send(build_ping(nonce), wire::Body::Ping); }
bool Client::send_raw(Frame bytes) { return send(std::move(bytes), wire::Body::NONE); }

ClientView Client::view() const {
  return ClientView{replica_, counters_, welcome_.has_value(), closed_, disconnect_reason_, edits_, hash_checks_};
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
