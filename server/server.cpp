#include "server/server.h"

#include <future>

#include "server/log.h"

namespace terrane {

FileResult<std::unique_ptr<Server>> Server::create(const ServerOptions& options) {
  if (options.auth_token.empty() && options.player_tokens.empty() && !options.allow_open &&
      !is_loopback_address(options.bind_address))
    return FileError{"refusing to serve " + options.bind_address +
                         " without authentication: give --auth-token or --tokens-file, or --open to allow anyone",
                     {}};
  std::unique_ptr<Server> s(new Server(options));
  auto world = WorldStore::exists(options.world_dir) ? World::open(options.world_dir)
                                                     : World::create(options.world_dir, default_world_meta());
  if (!world) return world.error();
  s->world_ = std::move(*world);
  const std::uint64_t epoch = s->world_->meta().epoch + 1;
  if (auto st = s->world_->store().set_epoch(epoch); !st) return st.error();

  asio::error_code ec;
  const auto addr = asio::ip::make_address(options.bind_address, ec);
  if (ec) return FileError{"bad bind address " + options.bind_address + ": " + ec.message(), {}};
  const asio::ip::tcp::endpoint ep(addr, options.port);
  s->acceptor_.open(ep.protocol(), ec);
  if (!ec) s->acceptor_.set_option(asio::ip::tcp::acceptor::reuse_address(true), ec);
  if (!ec) s->acceptor_.bind(ep, ec);
  if (!ec) s->acceptor_.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) return FileError{"cannot listen on " + options.bind_address + ":" + std::to_string(options.port) + ": " +
                               ec.message(), {}};
  s->port_ = s->acceptor_.local_endpoint().port();

  s->cache_ = std::make_unique<ChunkCache>(*s->world_, s->owner_, s->workers_, [srv = s.get()] { srv->schedule_pump(); });
  s->spawn_ = find_spawn(*s->world_);
  return s;
}

Vec3f Server::find_spawn(World& world) {
  if (const TerrainGenerator* gen = world.generator()) return {0.5f, gen->surface_height(0, 0) + 2.0f, 0.5f};
  // No generator (an imported world): above the ground at the centre of
  // what is stored, so clients start where the content is.
  Vec3i lo{0, 0, 0}, hi{0, 0, 0};
  bool any = false;
  (void)world.store().for_each_chunk([&](Vec3i cp, std::uint64_t, std::span<const std::uint8_t>) {
    lo = any ? min3(lo, cp) : cp;
    hi = any ? max3(hi, cp) : cp;
    any = true;
  });
  if (!any) return {0.5f, static_cast<float>(std::max(0, world.meta().bounds.min_y)), 0.5f};
  const std::int32_t x = (lo.x + hi.x + 1) * kChunkSize / 2, z = (lo.z + hi.z + 1) * kChunkSize / 2;
  const WorldBounds& b = world.meta().bounds;
  Box column({1, b.max_y - b.min_y, 1});
  std::int32_t top = b.min_y;
  if (world.read_box({x, b.min_y, z}, column))
    for (int y = column.size().y - 1; y >= 0; --y)
      if (column.get(0, y, 0).material != kAir) {
        top = b.min_y + y + 1;
        break;
      }
  return {static_cast<float>(x) + 0.5f, static_cast<float>(top) + 2.0f, static_cast<float>(z) + 0.5f};
}

Server::Server(const ServerOptions& options)
    : options_(options),
      work_(asio::make_work_guard(io_)),
      owner_(asio::make_strand(io_)),
      acceptor_(owner_),  // accept handlers run on the owner strand
      tick_timer_(owner_),
      workers_(static_cast<std::size_t>(std::max(1, options.worker_threads))) {
  options_.tick_hz = std::clamp<std::uint32_t>(options_.tick_hz, 1, 1000);
  options_.session.max_frame_bytes = std::min(options_.session.max_frame_bytes, kDefaultMaxFrameBytes);
  options_.session.traffic = &counters_.traffic;
  faults_left_ = options_.fault_drop_updates;
  corruptions_left_ = options_.fault_corrupt_updates;
}

Server::~Server() { stop(); }

void Server::start() {
  if (started_) return;
  started_ = true;
  server_log().info("world {} (epoch {}), tick {} Hz", world_->store().dir(), world_->meta().epoch, options_.tick_hz);
  if (!options_.player_tokens.empty())
    server_log().info("authentication: per-player tokens ({} players)", options_.player_tokens.size());
  else if (!options_.auth_token.empty())
    server_log().info("authentication: shared token");
  else
    server_log().warn("authentication: none, anyone who can connect may play ({})",
                      is_loopback_address(options_.bind_address) ? "loopback only" : "--open");
  server_log().info("listening on {}:{}", options_.bind_address, port_);
  asio::post(owner_, [this] { arm_tick(); });
  do_accept();
  for (int i = 0; i < std::max(1, options_.io_threads); ++i) threads_.emplace_back([this] { io_.run(); });
}

void Server::stop() {
  if (stopped_.exchange(true)) return;
  if (!started_) return;
  std::promise<void> closed;
  asio::post(owner_, [this, &closed] {
    stopping_ = true;
    asio::error_code ignored;
    acceptor_.close(ignored);
    tick_timer_.cancel();
    // Edits received but not yet applied at this point are applied now so
    // nothing acknowledged-to-be is lost (unless the store already failed).
    if (!storage_failed_) apply_edits();
    for (auto& [id, peer] : peers_) peer.session->close("server shutting down");
    closed.set_value();
  });
  closed.get_future().wait();
  workers_.join();
  work_.reset();
  for (auto& t : threads_) t.join();
  threads_.clear();
  const ServerCounters& c = counters_;
  server_log().info(
      "stopped after {} ticks; sessions {} accepted, {} closed; edits {} applied, {} rejected; streamed {} full "
      "chunks, {} mips, {} empty ({} bytes), {} resumed; {} update batches; world saved",
      c.ticks.load(), c.sessions_accepted.load(), c.sessions_closed.load(), c.edits_applied.load(),
      c.edits_rejected.load(), c.chunks_sent.load(), c.mips_sent.load(), c.empties_sent.load(), c.stream_bytes.load(), c.chunks_resumed.load(),
      c.update_batches_sent.load());
  std::string by_type;
  for (std::size_t t = 1; t < TrafficCounters::kTypes; ++t) {
    const std::uint64_t f = c.traffic.sent_frames[t].load(), r = c.traffic.received_frames[t].load();
    if (f == 0 && r == 0) continue;
    by_type += fmt::format(" {} out {} / {} B, in {} / {} B;", wire::EnumNameBody(static_cast<wire::Body>(t)), f,
                           c.traffic.sent_bytes[t].load(), r, c.traffic.received_bytes[t].load());
  }
  if (!by_type.empty()) server_log().info("messages by type (frames / bytes):{}", by_type);
}

void Server::inspect(const std::function<void(const ChunkCache&)>& fn) {
  std::promise<void> done;
  asio::post(owner_, [&] {
    fn(*cache_);
    done.set_value();
  });
  done.get_future().wait();
}

void Server::do_accept() {
  acceptor_.async_accept(asio::make_strand(io_), [this](const asio::error_code& ec, asio::ip::tcp::socket socket) {
    if (ec) {
      if (ec != asio::error::operation_aborted && acceptor_.is_open()) do_accept();
      return;
    }
    asio::post(owner_, [this, sock = std::make_shared<asio::ip::tcp::socket>(std::move(socket))]() mutable {
      if (stopping_) return;
      const std::uint64_t id = next_session_id_++;
      auto session = std::make_shared<Session>(
          std::move(*sock), id, options_.session,
          [this](std::uint64_t sid, InboundMessage msg) {
            asio::post(owner_, [this, sid, m = std::move(msg)]() mutable { on_inbound(sid, std::move(m)); });
          },
          [this](std::uint64_t sid, const std::string& reason) {
            asio::post(owner_, [this, sid, reason] { on_session_closed(sid, reason); });
          },
          [this](std::uint64_t sid) {
            asio::post(owner_, [this, sid] {
              auto it = peers_.find(sid);
              if (it != peers_.end() && !stopping_) pump(it->second);
            });
          });
      counters_.sessions_accepted.fetch_add(1, std::memory_order_relaxed);
      Peer& peer = peers_[id];
      peer.session = session;
      peer.state.view_distance = options_.default_view_distance;
      peer.state.full_res_radius = options_.default_full_res_radius;
      session->start();
      if (peers_.size() > options_.max_clients) session->close("server full");
    });
    do_accept();
  });
}

void Server::on_session_closed(std::uint64_t id, const std::string& reason) {
  auto it = peers_.find(id);
  if (it == peers_.end()) return;
  server_log().info("session {} ({}) closed: {}", id, it->second.name.empty() ? it->second.session->remote() : it->second.name,
                    reason);
  counters_.sessions_closed.fetch_add(1, std::memory_order_relaxed);
  for (const auto& [cp, h] : it->second.held) release(cp);
  peers_.erase(it);
  // Its queued edits stay queued; their acks go nowhere.
}

void Server::on_inbound(std::uint64_t id, InboundMessage msg) {
  auto it = peers_.find(id);
  if (it == peers_.end() || stopping_) return;
  Peer& peer = it->second;
  if (auto* hello = std::get_if<HelloMsg>(&msg)) return on_hello(peer, *hello);
  if (!peer.welcomed) return;
  if (auto* state = std::get_if<ClientStateMsg>(&msg)) return on_client_state(peer, *state);
  if (auto* edit = std::get_if<EditRequestMsg>(&msg)) return on_edit(peer, std::move(*edit));
  if (auto* read = std::get_if<ReadBoxMsg>(&msg)) return on_read_box(peer, *read);
  if (auto* h = std::get_if<HoldingsMsg>(&msg)) return on_holdings(peer, *h);
  if (auto* req = std::get_if<RegionHashRequestMsg>(&msg)) {
    // Only chunks this client holds: a hash request must not make the
    // server load or generate arbitrary chunks.
    if (peer.held.count(req->chunk_pos) == 0 && peer.claims.count(req->chunk_pos) == 0) return;
    if (peer.hash_requests.size() >= 1024) {
      peer.session->close("too many region hash requests");
      return;
    }
    peer.hash_requests.push_back(req->chunk_pos);
    serve_hash_requests(peer);
  }
}

void Server::on_hello(Peer& peer, const HelloMsg& hello) {
  if (hello.protocol_version != kProtocolVersion) {
    server_log().warn("session {}: protocol version {} rejected", peer.session->id(), hello.protocol_version);
    peer.session->close("protocol version mismatch: server speaks " + std::to_string(kProtocolVersion) + ", client " +
                        std::to_string(hello.protocol_version));
    return;
  }
  bool allowed = true;
  if (!options_.player_tokens.empty()) {
    auto it = options_.player_tokens.find(hello.client_name);
    allowed = it != options_.player_tokens.end() && it->second == hello.auth_token;
  } else if (!options_.auth_token.empty()) {
    allowed = hello.auth_token == options_.auth_token;
  }
  if (!allowed) {
    counters_.auth_failures.fetch_add(1, std::memory_order_relaxed);
    violations().warn("session " + std::to_string(peer.session->id()) + " (" + peer.session->remote() +
                      "): authentication failed for '" + hello.client_name + "'");
    peer.session->close("authentication failed");
    return;
  }
  peer.edit_rate = TokenBucket(options_.edits_per_second, options_.edits_per_second * 2);
  peer.outbound = TokenBucket(options_.outbound_bytes_per_second, options_.outbound_bytes_per_second / 4);
  peer.name = hello.client_name;
  peer.welcomed = true;
  peer.state.position = spawn_;
  WelcomeMsg w;
  w.server_epoch = world_->meta().epoch;
  w.spawn = spawn_;
  w.materials = world_->meta().materials;
  w.bounds_min_y = world_->meta().bounds.min_y;
  w.bounds_max_y = world_->meta().bounds.max_y;
  w.max_view_distance = options_.max_view_distance;
  w.max_full_res_radius = options_.max_full_res_radius;
  w.max_frame_bytes = static_cast<std::uint32_t>(options_.session.max_frame_bytes);
  w.tick_hz = options_.tick_hz;
  peer.session->send(build_welcome(w));
  server_log().info("session {} ({}) joined as '{}'", peer.session->id(), peer.session->remote(), peer.name);
  // Streaming starts with the client's first ClientState.
}

void Server::arm_tick() {
  if (stopping_) return;
  tick_timer_.expires_after(std::chrono::microseconds(1'000'000 / options_.tick_hz));
  tick_timer_.async_wait([this](const asio::error_code& ec) {
    if (ec || stopping_) return;
    on_tick();
    arm_tick();
  });
}

void Server::on_tick() {
  ++tick_;
  counters_.ticks.fetch_add(1, std::memory_order_relaxed);
  apply_edits();
  if (options_.presence_hz > 0 && tick_ % std::max<std::uint64_t>(1, options_.tick_hz / options_.presence_hz) == 0)
    send_presence();
  if (options_.hash_push_ms > 0 &&
      tick_ % std::max<std::uint64_t>(1, std::uint64_t{options_.hash_push_ms} * options_.tick_hz / 1000) == 0)
    push_region_hashes();
  if (tick_ % options_.tick_hz == 0) unload_unwatched();
  if (tick_ % (options_.tick_hz * 10) == 0) log_stats();
  pump_all();
}

void Server::log_stats() {
  const auto now = std::chrono::steady_clock::now();
  const double dt = std::max(1e-3, std::chrono::duration<double>(now - stats_at_).count());
  std::uint64_t sent = 0, received = 0;
  for (std::size_t t = 0; t < TrafficCounters::kTypes; ++t) {
    sent += counters_.traffic.sent_bytes[t].load(std::memory_order_relaxed);
    received += counters_.traffic.received_bytes[t].load(std::memory_order_relaxed);
  }
  const std::uint64_t edits = counters_.edits_applied.load(std::memory_order_relaxed);
  server_log().info("{} clients; {:.1f} edits/s; out {:.2f} MB/s, in {:.3f} MB/s; {} chunks loaded",
                    peers_.size(), static_cast<double>(edits - stats_edits_) / dt,
                    static_cast<double>(sent - stats_sent_) / dt / 1e6,
                    static_cast<double>(received - stats_received_) / dt / 1e6, cache_->loaded_count());
  stats_at_ = now;
  stats_edits_ = edits;
  stats_sent_ = sent;
  stats_received_ = received;
}

void Server::schedule_pump() {
  if (pump_scheduled_) return;
  pump_scheduled_ = true;
  asio::post(owner_, [this] {
    pump_scheduled_ = false;
    if (!stopping_) pump_all();
  });
}

}  // namespace terrane
