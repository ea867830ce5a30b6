#include "server/world/world_owner.h"

#include "server/base/log.h"
#include "server/world/shared_authority.h"

namespace terrane {

namespace {

std::unique_ptr<Authority> make_authority(WorldOwner::Strand& strand, World& world, Storage& storage,
                                          const WorldOptions& options, const ClusterOptions& cluster,
                                          ServerCounters& counters, const WorldClock& clock, Residency& residency,
                                          FanOut& clients, EditQueue& queue) {
  if (!storage.leased()) return std::make_unique<LocalAuthority>();
  return std::make_unique<SharedAuthority>(strand, world, storage, options, cluster, counters, clock, residency,
                                           clients, queue);
}

}  // namespace

WorldOwner::WorldOwner(asio::io_context& io, World& world, Storage& storage, const WorldOptions& options,
                       ServerCounters& counters, const ClusterOptions& cluster)
    : options_(options),
      strand_(asio::make_strand(io)),
      fan_out_(options, counters),
      horizons_(strand_, storage, fan_out_),
      residency_(strand_, storage, options, counters, clock_, fan_out_, horizons_),
      authority_(
          make_authority(strand_, world, storage, options, cluster, counters, clock_, residency_, fan_out_, tick_)),
      tick_(strand_, world, storage, options, counters, clock_, residency_, fan_out_, *authority_),
      requests_(strand_, [this](WorldRequest& r) { handle(r); }) {
  residency_.watch_loads(*authority_);
}

void WorldOwner::start() {
  asio::post(strand_, [this] {
    tick_.start();
    // Edits forwarded while this server was away.
    authority_->start();
  });
}

void WorldOwner::stop() { tick_.stop(); }

// --- the request queue ---------------------------------------------------------

void WorldOwner::join(ClientId id, std::string name, std::shared_ptr<WorldClient> client, bool identified,
                      bool presence_records) {
  requests_.push(WorldRequest{id, {}, JoinRequest{std::move(name), std::move(client), identified, presence_records}});
}

void WorldOwner::leave(ClientId id) { requests_.push(WorldRequest{id, {}, LeaveRequest{}}); }

void WorldOwner::moved(ClientId id, Vec3f position, std::int32_t view_distance, std::int32_t full_res_radius) {
  requests_.push(WorldRequest{id, {}, MovedRequest{position, view_distance, full_res_radius}});
}

void WorldOwner::want(ClientId id, std::vector<ChunkWant> chunks) {
  requests_.push(WorldRequest{id, {}, std::move(chunks)});
}

void WorldOwner::release(ClientId id, std::vector<Vec3i> chunks) {
  requests_.push(WorldRequest{id, {}, std::move(chunks)});
}

void WorldOwner::want_horizon(ClientId id, std::vector<HorizonWant> wants) {
  requests_.push(WorldRequest{id, {}, std::move(wants)});
}

void WorldOwner::holds_full(ClientId id, std::vector<Vec3i> chunks) {
  requests_.push(WorldRequest{id, {}, HoldsFullRequest{std::move(chunks)}});
}

void WorldOwner::handle(WorldRequest& r) {
  std::visit(
      [&](auto& what) {
        using T = std::decay_t<decltype(what)>;
        if constexpr (std::is_same_v<T, std::vector<ChunkWant>>) {
          residency_.want(r.id, what);
        } else if constexpr (std::is_same_v<T, std::vector<Vec3i>>) {
          fan_out_.release(r.id, what);
        } else if constexpr (std::is_same_v<T, std::vector<HorizonWant>>) {
          horizons_.want(r.id, what);
        } else if constexpr (std::is_same_v<T, JoinRequest>) {
          tick_.join(r.id, what.name, what.identified);
          fan_out_.join(r.id, std::move(what.link), std::move(what.name), what.presence_records);
        } else if constexpr (std::is_same_v<T, LeaveRequest>) {
          // The replicator released what it held or had asked for just
          // before; after this nothing more is granted to id. Its queued
          // edits stay queued (their acks go nowhere).
          tick_.leave(r.id);
          fan_out_.leave(r.id);
          residency_.leave(r.id);
        } else if constexpr (std::is_same_v<T, HoldsFullRequest>) {
          fan_out_.holds_full(r.id, what.chunks);
        } else {
          fan_out_.moved(r.id, what.position, what.view_distance, what.full_res_radius);
        }
      },
      r.what);
}

// --- the tick --------------------------------------------------------------------

void WorldOwner::edit(ClientId id, EditRequestMsg e) {
  asio::post(strand_, [this, id, e = std::move(e), received = std::chrono::steady_clock::now()]() mutable {
    tick_.edit(id, std::move(e), received);
  });
}

void WorldOwner::refuse(ClientId id, EditRequestMsg e, RejectReason why, std::string reason) {
  asio::post(strand_, [this, id, e = std::move(e), why, reason = std::move(reason)] { tick_.reject(id, e, why, reason); });
}

void WorldOwner::rollback(std::string actor, std::vector<EditLogEntry> entries, std::optional<Region> within,
                          std::function<void(RollbackResult)> done) {
  asio::post(strand_, [this, actor = std::move(actor), entries = std::move(entries), within,
                       done = std::move(done)]() mutable {
    tick_.rollback(std::move(actor), std::move(entries), within, std::move(done));
  });
}

void WorldOwner::fail_rollbacks(const std::string& why) { tick_.fail_rollbacks(why); }

void WorldOwner::read_box(ClientId id, ReadBoxMsg req) {
  asio::post(strand_, [this, id, req] { tick_.read_box(id, req); });
}

void WorldOwner::hash(ClientId id, Vec3i cp) {
  asio::post(strand_, [this, id, cp] { tick_.hash(id, cp); });
}

void WorldOwner::flush(std::function<void(std::uint64_t tick, bool stored)> done) {
  asio::post(strand_, [this, done = std::move(done)]() mutable { tick_.flush(std::move(done)); });
}

void WorldOwner::lease_lost(Vec3i region, std::string why) {
  asio::post(strand_, [this, region, why = std::move(why)] {
    // Another server may have written the region since: what this one holds
    // of it may be stale, so it must not write there again. Stopping is the
    // safe answer (a restart reads the region afresh); writes in flight are
    // fenced by the database whatever happens here.
    server_log().critical("region ({},{},{}): lease lost ({}); stopping", region.x, region.y, region.z, why);
    tick_.fatal_storage("lease lost");
  });
}

// --- the authority -----------------------------------------------------------------

void WorldOwner::changed_elsewhere(std::vector<ChunkChange> changes) {
  asio::post(strand_, [this, changes = std::move(changes)]() mutable { authority_->changed_elsewhere(std::move(changes)); });
}

void WorldOwner::read_again_elsewhere(std::vector<Vec3i> regions) {
  asio::post(strand_, [this, regions = std::move(regions)]() mutable { authority_->read_again_elsewhere(std::move(regions)); });
}

void WorldOwner::inbox_has_edits() {
  asio::post(strand_, [this] { authority_->inbox_has_edits(); });
}

void WorldOwner::answered(ForwardAnswer answer) {
  asio::post(strand_, [this, answer = std::move(answer)]() mutable { authority_->answered(std::move(answer)); });
}

// --- tests and tools -----------------------------------------------------------------

void WorldOwner::inspect(const std::function<void(const WorldView&)>& fn) {
  std::promise<void> done;
  asio::post(strand_, [&] {
    fn(residency_);
    done.set_value();
  });
  done.get_future().wait();
}

}  // namespace terrane
