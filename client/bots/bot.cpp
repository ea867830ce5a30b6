#include "client/bots/bot.h"

#include "common/world/view.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace terrane::bots {

namespace {

constexpr auto kStep = std::chrono::milliseconds(100);
constexpr float kWalkSpeed = 5.0f;   // voxels per second
constexpr float kFlySpeed = 40.0f;   // voxels per second
constexpr float kFlyHeight = 40.0f;  // above the start height
constexpr float kTeleportHeight = 8.0f;  // a teleporting bot's, above the spawn's
// A walker starting above or below the ground moves to it at most this far
// a step: two steps (one ClientState) stay within the server's movement
// slack (kSpeedSlackVoxels, 48) however soon that state follows the last.
// After a redirect the new server's first state may be only milliseconds
// older (the client sends its last one as it links), and a landing in one
// jump of 73 voxels was dropped as moving too fast.
constexpr float kLandStep = 16.0f;
constexpr float kEyeHeight = 1.6f;
// Highest step a walker climbs per step (0.5 voxel forward) and deepest drop.
constexpr float kMaxClimb = 1.0f;
constexpr float kMaxDrop = 3.0f;
// After this many refused steps in a row (walled in by edits, in a dug pit)
// a walker stands on top of its own column again and may climb kEscapeClimb
// in one step, like a jump.
constexpr int kStuckSteps = 10;
constexpr float kEscapeClimb = 3.0f;
// Region-hash retries while the replica's revision differs from the reply's
// before it counts as a mismatch: updates are ordered before the reply, so
// a lasting difference means an update was lost.
constexpr int kMaxHashAttempts = 5;
constexpr auto kHashRetry = std::chrono::milliseconds(250);
constexpr auto kHashTimeout = std::chrono::seconds(10);
// Edits in flight per bot at most (the server queues 64 per client).
constexpr std::size_t kMaxOutstandingEdits = 8;
constexpr Material kBuildMaterials[] = {materials::kBrick, materials::kConcrete, materials::kWoodPlanks,
                                        materials::kCobblestone, materials::kSandstone};

float length(Vec3f v) { return std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z); }

}  // namespace

Bot::Bot(int index, const RunContext& ctx, Vec3f start, Gait gait, EditMode edits, std::uint64_t seed)
    : index_(index),
      ctx_(ctx),
      gait_(gait),
      edits_mode_(edits),
      rng_(seed),
      pos_(start),
      join_view_{start, ctx.view_distance, ctx.full_res_radius} {
  const BotsOptions& o = *ctx_.options;
  ClientOptions co;
  // Several servers of one world: bot i on the (i mod n)-th.
  co.host = o.servers.empty() ? o.host : o.servers[static_cast<std::size_t>(index) % o.servers.size()].first;
  co.port = o.servers.empty() ? o.port : o.servers[static_cast<std::size_t>(index) % o.servers.size()].second;
  BotLogin login = bot_login(o, index);
  co.name = std::move(login.name);
  co.auth_token = std::move(login.token);
  co.start_at_spawn = false;
  co.state = ClientStateMsg{pos_, ctx_.view_distance, ctx_.full_res_radius};
  co.io_context = ctx_.io;
  co.shared_chunks = ctx_.shared_chunks;
  // A bot reads its full chunks' voxels (walking, hashes), never their mips.
  co.full_chunk_mips = Chunk::Mips::kDerived;
  co.chunk_cache = ctx_.chunk_cache;
  co.emulation.latency = std::chrono::milliseconds(o.latency_ms);
  co.emulation.bandwidth_bytes_per_s = static_cast<std::uint64_t>(o.bandwidth_kbps) * 1000 / 8;
  ClientCallbacks cb;
  // Once a batch (a view of 2,048 is about 160,000 chunks of horizon images).
  cb.on_holdings = [this](std::span<const HoldingChange> changes) { on_holdings(changes); };
  cb.on_edit_result = [this](std::uint32_t id, const EditOutcome& outcome) {
    {
      // The bot's own leaving ends the edits still in flight as unknown:
      // the run is over, they are no outcome of the server's.
      std::lock_guard lock(mutex_);
      if (outstanding_edits_ > 0) --outstanding_edits_;
      if (closing_) return;
    }
    ctx_.fanout->edit_result(index_, id, outcome, Clock::now());
  };
  cb.on_round_trip = [this](double ms) {
    if (ctx_.round_trips != nullptr) ctx_.round_trips->add(Clock::now(), ms);
  };
  cb.on_update_batch = [this](std::uint64_t tick, const std::vector<ChunkRevisionMsg>& revisions) {
    ctx_.fanout->update_received(index_, tick, revisions, Clock::now());
  };
  cb.on_chunk_hash = [this](const HashCheck& check) { on_chunk_hash(check); };
  cb.on_disconnected = [this](const std::string& reason) { on_disconnected(reason); };
  // Several servers: ticks and fan-out are told apart by the server the bot
  // is on now (redirects move it).
  cb.on_welcome = [this](const WelcomeMsg& w) { ctx_.fanout->bot_on_server(index_, w.server_id); };
  cb.on_reconnected = [this] {
    if (auto w = client_->welcome()) ctx_.fanout->bot_on_server(index_, w->server_id);
  };
  client_ = std::make_unique<Client>(co, cb);
  std::uniform_real_distribution<float> angle(0.0f, 2.0f * std::numbers::pi_v<float>);
  heading_ = angle(rng_);
}

// The Client's handlers capture this Bot: it goes first.
Bot::~Bot() { client_.reset(); }

bool Bot::connect() {
  connect_at_ = Clock::now();
  next_edit_ = connect_at_;
  next_check_ = connect_at_;
  std::string err;
  if (!client_->connect(&err)) {
    result_.connect_error = err;
    return false;
  }
  result_.connected = true;
  std::lock_guard lock(mutex_);
  // A view with nothing to hold (beyond the world's bounds) is joined at once.
  // From the replica as it is: chunks may have arrived since the Welcome.
  client_->with_replica([&](const Replica& r) { join_count_.emplace(join_view_, ctx_.welcome.bounds(), r); });
  check_join(Clock::now());
  return true;
}

void Bot::on_holdings(std::span<const HoldingChange> changes) {
  const Clock::time_point now = Clock::now();  // the batch's, every change's
  ctx_.fanout->holdings_changed(index_, changes, now);
  std::lock_guard lock(mutex_);
  if (!join_count_) return;
  for (const HoldingChange& c : changes) join_count_->update(c.chunk_pos, c.now ? &*c.now : nullptr);
  check_join(now);
}

void Bot::check_join(Clock::time_point now) {
  const ViewCoverage& v = join_count_->coverage();
  if (!result_.join_coarse_ms && v.not_held == 0) {
    result_.join_coarse_ms = ms_between(connect_at_, now);
    const ClientCounters k = client_->counters();
    for (const auto& t : k.by_message_type) result_.join_coarse_bytes += t.bytes_in;
  }
  if (!joined_ && v.full_region_held()) {
    result_.join_full_ms = ms_between(connect_at_, now);
    const ClientCounters k = client_->counters();
    std::uint64_t delivered = 0;
    for (const auto& t : k.by_message_type) delivered += t.bytes_in;
    result_.join_bytes = delivered;
    result_.join_bytes_by_cause = k.bytes_in_by_cause;
    joined_ = true;
    joined_at_ = now;
  }
  if (joined_ && result_.join_coarse_ms) join_count_.reset();
}

bool Bot::joined() const {
  std::lock_guard lock(mutex_);
  return joined_;
}

std::size_t Bot::outstanding_edits() const {
  std::lock_guard lock(mutex_);
  return outstanding_edits_;
}

void Bot::count_join_voxels() {
  // The full-resolution region as it stood at join (the bot has not moved).
  const std::int32_t full = ctx_.full_res_radius;
  std::uint64_t n = 0;
  client_->with_replica([&](const Replica& r) {
    Chunk::Level0::Row scratch;
    r.for_each_holding([&](Vec3i cp, const Holding& h) {
      if (h.form != HoldingForm::kFull || !within(pos_, cp, full)) return;
      const Chunk* chunk = r.grid().find_chunk(cp);
      if (chunk == nullptr || chunk->empty()) return;
      for (int y = 0; y < kChunkSize; ++y)
        for (int z = 0; z < kChunkSize; ++z) {
          const Voxel* row = chunk->read_row(y, z, scratch);
          for (int x = 0; x < kChunkSize; ++x) n += row[x].material != kAir ? 1 : 0;
        }
    });
    return 0;
  });
  result_.join_non_empty_voxels = n;
}

Vec3i Bot::voxel_at(Vec3f p) const {
  return {static_cast<std::int32_t>(std::floor(p.x)), static_cast<std::int32_t>(std::floor(p.y)),
          static_cast<std::int32_t>(std::floor(p.z))};
}

bool Bot::in_area(float x, float z, float half) const {
  return std::abs(x - ctx_.spawn.x) <= half && std::abs(z - ctx_.spawn.z) <= half;
}

bool Bot::held_full(Vec3i cp) const {
  return client_->with_replica([&](const Replica& r) {
    const Holding* h = r.holding(cp);
    return h != nullptr && h->full_resolution();
  });
}

void Bot::step(Clock::time_point now, bool active) {
  if (!result_.connected) return;
  {
    std::lock_guard lock(mutex_);
    if (!joined_ || closing_) return;
  }
  if (!voxels_counted_) {
    count_join_voxels();
    voxels_counted_ = true;
  }
  if (active) {
    move(now);
    maybe_edit(now);
    schedule_check(now);
  }
  // Hash retries and time-outs.
  checks_pending(now);
}

void Bot::move(Clock::time_point now) {
  ++steps_;
  if (gait_ == Gait::kWalk) walk();
  if (gait_ == Gait::kFly) fly();
  if (gait_ == Gait::kTeleport) teleport(now);
  if (gait_ == Gait::kHotspot) converge();
  // ClientState at most every other step (5 Hz) while moving.
  if (state_dirty_ && steps_ % 2 == 0) {
    client_->set_state(ClientStateMsg{pos_, ctx_.view_distance, ctx_.full_res_radius});
    state_dirty_ = false;
  }
}

void Bot::walk() {
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  if (!landed_) {
    // Start standing on the surface under the spawn column, if known at full resolution.
    const Vec3i v = voxel_at(pos_);
    const auto h = client_->surface_height(v.x, v.z);
    if (!h || client_->resolution_at({v.x, *h - 1, v.z}) != 0) return;
    const float ground = static_cast<float>(*h);
    if (std::abs(ground - pos_.y) <= kLandStep) {
      pos_.y = ground;
      landed_ = true;
    } else {
      pos_.y += ground > pos_.y ? kLandStep : -kLandStep;
    }
    state_dirty_ = true;
    return;
  }
  if (unit(rng_) < 0.02f) heading_ += (unit(rng_) - 0.5f) * std::numbers::pi_v<float>;
  const float stride = kWalkSpeed * std::chrono::duration<float>(kStep).count();
  const Vec3f next{pos_.x + std::cos(heading_) * stride, pos_.y, pos_.z + std::sin(heading_) * stride};
  const Vec3i nv = voxel_at(next);
  const float half = std::max(static_cast<float>(ctx_.options->spread) / 2.0f, 64.0f);
  ++result_.walk_steps;
  int refused = -1;
  std::optional<std::int32_t> h;
  if (!in_area(next.x, next.z, half)) refused = 0;
  if (refused < 0) {
    h = client_->surface_height(nv.x, nv.z);
    // Only where the replica holds the ground and the air above it at full resolution.
    if (!h || client_->resolution_at({nv.x, *h - 1, nv.z}) != 0 || client_->resolution_at({nv.x, *h, nv.z}) != 0)
      refused = 1;
  }
  if (refused < 0) {
    const float dy = static_cast<float>(*h) - pos_.y;
    if (dy > (stuck_steps_ >= kStuckSteps ? kEscapeClimb : kMaxClimb) || dy < -kMaxDrop) refused = 2;
  }
  if (refused < 0) {
    // Nothing solid between here and there at knee height.
    const Vec3f from{pos_.x, pos_.y + 1.2f, pos_.z};
    const Vec3f to{next.x, static_cast<float>(*h) + 1.2f, next.z};
    const Vec3f d = to - from;
    const float len = length(d);
    if (len > 0 && client_->raycast(from, d * (1.0f / len), len).has_value()) refused = 3;
  }
  if (refused >= 0) {
    ++result_.walk_blocked[static_cast<std::size_t>(refused)];
    heading_ += std::numbers::pi_v<float> * (0.5f + unit(rng_));
    if (++stuck_steps_ == kStuckSteps) {
      // An edit may have buried the walker: back on top of its own column.
      const Vec3i v = voxel_at(pos_);
      const auto top = client_->surface_height(v.x, v.z);
      if (top && static_cast<float>(*top) > pos_.y && client_->resolution_at({v.x, *top, v.z}) == 0) {
        pos_.y = static_cast<float>(*top);
        state_dirty_ = true;
      }
    }
    return;
  }
  stuck_steps_ = 0;
  result_.distance_moved += stride;
  pos_ = Vec3f{next.x, static_cast<float>(*h), next.z};
  state_dirty_ = true;
}

void Bot::fly() {
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  if (!landed_) {
    pos_.y = std::min(pos_.y + kFlyHeight, static_cast<float>(ctx_.welcome.bounds_max_y - 2));
    landed_ = true;
    state_dirty_ = true;
    return;
  }
  const float stride = kFlySpeed * std::chrono::duration<float>(kStep).count();
  const float half = std::max(static_cast<float>(ctx_.options->spread) / 2.0f, 128.0f);
  Vec3f dir{std::cos(heading_), 0.0f, std::sin(heading_)};
  const Vec3f next = pos_ + dir * stride;
  if (!in_area(next.x, next.z, half)) {
    heading_ += std::numbers::pi_v<float> * (0.75f + 0.5f * unit(rng_));
    return;
  }
  if (client_->raycast(pos_, dir, stride + 1.0f)) {
    // Terrain ahead: climb instead (never through it).
    pos_.y = std::min(pos_.y + stride, static_cast<float>(ctx_.welcome.bounds_max_y - 2));
  } else {
    pos_ = next;
    result_.distance_moved += stride;
  }
  state_dirty_ = true;
}

void Bot::teleport(Clock::time_point now) {
  const BotsOptions& o = *ctx_.options;
  const auto interval =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.teleport_interval_s));
  const float top = static_cast<float>(ctx_.welcome.bounds_max_y - 2);
  if (!landed_) {
    // Just above the spawn's height wherever the jumps go: the ground there
    // is not known before the jump, and edits need it within the
    // full-resolution radius.
    pos_.y = std::min(ctx_.spawn.y + kTeleportHeight, top);
    landed_ = true;
    state_dirty_ = true;
    next_teleport_ = now + interval;
    return;
  }
  if (now < next_teleport_) return;
  next_teleport_ = now + interval;
  // A jump of exactly teleport_distance to a point within that distance
  // of the spawn (x and z), inside the world's bounds. From anywhere in
  // that square one of the axis directions toward the spawn stays in it.
  const float d = static_cast<float>(o.teleport_distance);
  const WelcomeMsg& w = ctx_.welcome;
  const auto inside = [&](float x, float z) {
    if (std::abs(x - ctx_.spawn.x) > d || std::abs(z - ctx_.spawn.z) > d) return false;
    return !w.bounded_xz || (x >= static_cast<float>(w.bounds_min_x) && x < static_cast<float>(w.bounds_max_x) &&
                             z >= static_cast<float>(w.bounds_min_z) && z < static_cast<float>(w.bounds_max_z));
  };
  std::uniform_real_distribution<float> angle(0.0f, 2.0f * std::numbers::pi_v<float>);
  std::optional<Vec3f> to;
  for (int attempt = 0; attempt < 16 && !to; ++attempt) {
    const float a = angle(rng_);
    const Vec3f p{pos_.x + std::cos(a) * d, pos_.y, pos_.z + std::sin(a) * d};
    if (inside(p.x, p.z)) to = p;
  }
  if (!to) {
    const float dx = pos_.x - ctx_.spawn.x, dz = pos_.z - ctx_.spawn.z;
    const Vec3f p = std::abs(dx) >= std::abs(dz) ? Vec3f{pos_.x - std::copysign(d, dx), pos_.y, pos_.z}
                                                 : Vec3f{pos_.x, pos_.y, pos_.z - std::copysign(d, dz)};
    if (!inside(p.x, p.z)) return;  // a bounded world narrower than the jump: stay
    to = p;
  }
  pos_ = *to;
  result_.distance_moved += d;
  ++result_.teleports;
  state_dirty_ = true;
}

void Bot::converge() {
  const float top = static_cast<float>(ctx_.welcome.bounds_max_y - 2);
  if (result_.at_hotspot) return;  // it stays
  if (!landed_) {
    pos_.y = std::min(pos_.y + kFlyHeight, top);
    landed_ = true;
    state_dirty_ = true;
    return;
  }
  if (!over_hotspot_) {
    // Straight to the spawn at a flyer's speed, climbing over terrain ahead.
    const float stride = kFlySpeed * std::chrono::duration<float>(kStep).count();
    const float dx = ctx_.spawn.x - pos_.x, dz = ctx_.spawn.z - pos_.z;
    const float dist = std::sqrt(dx * dx + dz * dz);
    if (dist <= stride) {
      pos_.x = ctx_.spawn.x;
      pos_.z = ctx_.spawn.z;
      result_.distance_moved += dist;
      over_hotspot_ = true;
    } else {
      const Vec3f dir{dx / dist, 0.0f, dz / dist};
      if (client_->raycast(pos_, dir, stride + 1.0f)) {
        pos_.y = std::min(pos_.y + stride, top);
      } else {
        pos_ = pos_ + dir * stride;
        result_.distance_moved += stride;
      }
    }
    state_dirty_ = true;
    return;
  }
  // Down to the ground there once it is held at full resolution, at most
  // kLandStep a step (the server's movement budget).
  const Vec3i v = voxel_at(pos_);
  const auto h = client_->surface_height(v.x, v.z);
  if (!h || client_->resolution_at({v.x, *h - 1, v.z}) != 0) {
    // The ground may lie beyond the full-resolution radius below: down
    // toward the spawn's height meanwhile, and wait there.
    const float low = ctx_.spawn.y + 2.0f;
    if (pos_.y > low) {
      pos_.y = std::max(low, pos_.y - kLandStep);
      state_dirty_ = true;
    }
    return;
  }
  const float ground = static_cast<float>(*h);
  if (std::abs(ground - pos_.y) <= kLandStep) {
    pos_.y = ground;
    result_.at_hotspot = true;
  } else {
    pos_.y += ground > pos_.y ? kLandStep : -kLandStep;
  }
  state_dirty_ = true;
}

bool Bot::edits_now() const {
  if (edits_mode_ == EditMode::kNone) return false;
  return gait_ != Gait::kHotspot || result_.at_hotspot;
}

std::vector<Voxel> Bot::hut_voxels(const Region& box, bool dig) {
  const Vec3i size = box.max - box.min;
  std::vector<Voxel> out(static_cast<std::size_t>(box.volume()));
  if (dig) return out;
  std::size_t i = 0;
  for (int y = 0; y < size.y; ++y)
    for (int z = 0; z < size.z; ++z)
      for (int x = 0; x < size.x; ++x, ++i) {
        const bool wall = x == 0 || z == 0 || x == size.x - 1 || z == size.z - 1;
        const bool window = y % 4 == 2 && (x + z) % 4 == 1;
        if (y == 0 || y == size.y - 1 || (wall && !window))
          out[i] = solid(kBuildMaterials[static_cast<std::size_t>(y / 2) % std::size(kBuildMaterials)]);
      }
  return out;
}

void Bot::maybe_edit(Clock::time_point now) {
  if (!edits_now() || now < next_edit_) return;
  const BotsOptions& o = *ctx_.options;
  std::exponential_distribution<double> gap(1.0 / o.edit_interval_s);
  next_edit_ = now + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(gap(rng_)));
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const bool dig = edits_mode_ == EditMode::kDig || (edits_mode_ == EditMode::kBoth && unit(rng_) < 0.5f);
  const float shape_draw = unit(rng_);  // drawn whatever the shape: the stream of draws stays the same
  const bool sphere = o.edit_shape == EditShape::kSphere || (o.edit_shape == EditShape::kMixed && shape_draw < 0.8f);
  // Aim down at the ground nearby.
  const float yaw = unit(rng_) * 2.0f * std::numbers::pi_v<float>;
  const float pitch = -(25.0f + 50.0f * unit(rng_)) * std::numbers::pi_v<float> / 180.0f;
  const Vec3f eye{pos_.x, pos_.y + kEyeHeight, pos_.z};
  const Vec3f dir{std::cos(pitch) * std::cos(yaw), std::sin(pitch), std::cos(pitch) * std::sin(yaw)};
  const float reach = gait_ == Gait::kFly || gait_ == Gait::kTeleport ? 96.0f : 48.0f;
  const auto hit = client_->raycast(eye, dir, reach);
  if (!hit) return;
  {
    std::lock_guard lock(mutex_);
    if (outstanding_edits_ >= kMaxOutstandingEdits) {
      ++result_.edits_held_back;
      return;
    }
    ++outstanding_edits_;
  }
  const Vec3i normal = hit->normal == Vec3i{} ? Vec3i{0, 1, 0} : hit->normal;
  const Material material = kBuildMaterials[std::uniform_int_distribution<std::size_t>(0, std::size(kBuildMaterials) - 1)(rng_)];
  // Only where this bot holds the world at full resolution, within its
  // radius (the server refuses the rest; a ray may hit a mip).
  const auto sees = [&](const Region& r) {
    bool ok = true;
    for_each_chunk_in(r, [&](Vec3i cp) { ok = ok && within(pos_, cp, ctx_.full_res_radius) && held_full(cp); });
    return ok;
  };
  EditRequestMsg e;
  std::uint32_t id = 0;
  if (sphere) {
    const float r = 1.0f + (o.edit_radius - 1.0f) * unit(rng_);
    const Vec3i at = dig ? hit->voxel : hit->voxel + normal * static_cast<std::int32_t>(std::ceil(r));
    e.kind = EditKind::kFillSphere;
    e.center = Vec3f{static_cast<float>(at.x) + 0.5f, static_cast<float>(at.y) + 0.5f, static_cast<float>(at.z) + 0.5f};
    e.radius = std::max(0.5f, r);
    const Region b = e.bounds();
    if (sees(b)) {
      double voxels = 0;
      const float reach_r = e.radius + 0.5f;
      for (int y = b.min.y; y < b.max.y; ++y)
        for (int z = b.min.z; z < b.max.z; ++z)
          for (int x = b.min.x; x < b.max.x; ++x) {
            const Vec3f c{static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f, static_cast<float>(z) + 0.5f};
            if (length(c - e.center) < reach_r) voxels += 1;
          }
      id = ctx_.fanout->send_edit(index_, b, voxels, [&] {
        return client_->fill_sphere(e.center, e.radius, dig ? kAir : material);
      });
    }
  } else if (o.edit_shape == EditShape::kWriteBox) {
    // R to 2R a side (R = edit_radius), within the largest raw box: on the
    // surface hit when building, around the hit when digging.
    constexpr int most = 32;  // the side of the largest raw box
    static_assert(std::int64_t{most} * most * most == kMaxRawBoxVolume);
    const int hi = std::clamp(static_cast<int>(2.0f * o.edit_radius), 2, most);
    const int lo = std::clamp(static_cast<int>(o.edit_radius), 2, hi);
    const int s = std::uniform_int_distribution<int>(lo, hi)(rng_);
    const Vec3i at = dig ? hit->voxel - Vec3i{0, s / 2, 0} : hit->voxel + normal;
    const Region box{at - Vec3i{s / 2, 0, s / 2}, at - Vec3i{s / 2, 0, s / 2} + Vec3i{s, s, s}};
    if (sees(box)) {
      const std::vector<Voxel> voxels = hut_voxels(box, dig);
      id = ctx_.fanout->send_edit(index_, box, static_cast<double>(box.volume()),
                                  [&] { return client_->write_box(box, voxels); });
    }
  } else {
    const int max_side = std::max(2, static_cast<int>(2.0f * o.edit_radius));
    const int s = std::uniform_int_distribution<int>(2, max_side)(rng_);
    const Vec3i at = dig ? hit->voxel : hit->voxel + normal;
    const Region box{at - Vec3i{s / 2, s / 2, s / 2}, at - Vec3i{s / 2, s / 2, s / 2} + Vec3i{s, s, s}};
    const Voxel v = dig ? Voxel{} : solid(material);
    if (sees(box))
      id = ctx_.fanout->send_edit(index_, box, static_cast<double>(box.volume()),
                                  [&] { return client_->fill_box(box, v); });
  }
  if (id == 0) {
    std::lock_guard lock(mutex_);
    --outstanding_edits_;
  }
}

void Bot::schedule_check(Clock::time_point now) {
  const BotsOptions& o = *ctx_.options;
  if (o.hash_checks == 0 || now < next_check_) return;
  const double span = hash_check_span_s(o);
  next_check_ = now + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(span));
  const float r = static_cast<float>(ctx_.full_res_radius);
  std::uniform_real_distribution<float> off(-r, r);
  for (int attempt = 0; attempt < 8; ++attempt) {
    const Vec3f p{pos_.x + off(rng_), pos_.y + off(rng_), pos_.z + off(rng_)};
    const Vec3i cp = chunk_of(voxel_at(p));
    if (!within(pos_, cp, ctx_.full_res_radius) || !held_full(cp)) continue;
    {
      std::lock_guard lock(mutex_);
      if (pending_hash_.count(cp) != 0) continue;
    }
    request_hash(cp, false);
    ++checks_done_;
    return;
  }
}

void Bot::request_hash(Vec3i cp, bool final_check) {
  {
    std::lock_guard lock(mutex_);
    PendingHash& p = pending_hash_[cp];
    p.sent_at = Clock::now();
    p.retry_at.reset();
    p.final_check = p.final_check || final_check;
  }
  client_->request_chunk_hash(cp);
}

void Bot::on_chunk_hash(const HashCheck& check) {
  std::lock_guard lock(mutex_);
  auto it = pending_hash_.find(check.chunk_pos);
  if (it == pending_hash_.end() || it->second.retry_at) return;
  PendingHash& p = it->second;
  if (check.match) {
    ++result_.hash_checked;
    pending_hash_.erase(it);
    return;
  }
  if (!check.replica_full) {
    // The chunk left full resolution (or the view) meanwhile: nothing to compare.
    pending_hash_.erase(it);
    return;
  }
  const std::uint64_t mine = check.replica_revision.value_or(0);
  Mismatch m{index_, check.chunk_pos, mine, check.server_revision, "", p.final_check};
  if (mine == check.server_revision) {
    m.reason = "voxels differ at the same revision";
  } else if (++p.attempts < kMaxHashAttempts) {
    p.retry_at = Clock::now() + kHashRetry;
    return;
  } else {
    m.reason = "replica revision " + std::to_string(mine) + " != server revision " +
               std::to_string(check.server_revision) + " after " + std::to_string(kMaxHashAttempts) + " checks";
  }
  ++result_.hash_checked;
  ctx_.mismatches->add(m);
  pending_hash_.erase(it);
}

bool Bot::checks_pending(Clock::time_point now) {
  std::vector<Vec3i> resend;
  bool pending = false;
  {
    std::lock_guard lock(mutex_);
    for (auto it = pending_hash_.begin(); it != pending_hash_.end();) {
      PendingHash& p = it->second;
      if (p.retry_at && now >= *p.retry_at) {
        p.retry_at.reset();
        p.sent_at = now;
        resend.push_back(it->first);
      } else if (!p.retry_at && now - p.sent_at > kHashTimeout) {
        ++result_.hash_unanswered;
        it = pending_hash_.erase(it);
        continue;
      }
      ++it;
    }
    pending = !pending_hash_.empty();
  }
  if (!client_->closed())
    for (const Vec3i cp : resend) client_->request_chunk_hash(cp);
  return pending;
}

void Bot::start_final_check() {
  if (!result_.connected || client_->closed()) return;
  const std::int32_t full = ctx_.full_res_radius;
  std::vector<Vec3i> chunks;
  client_->with_replica([&](const Replica& r) {
    r.for_each_holding([&](Vec3i cp, const Holding& h) {
      if (h.full_resolution() && within(pos_, cp, full)) chunks.push_back(cp);
    });
    return 0;
  });
  for (const Vec3i cp : chunks) request_hash(cp, true);
}

void Bot::on_disconnected(const std::string& reason) {
  std::lock_guard lock(mutex_);
  if (closing_) return;
  result_.unexpected_disconnect = true;
  result_.disconnect_reason = reason;
}

void Bot::finish() {
  {
    std::lock_guard lock(mutex_);
    closing_ = true;
    if (joined_) result_.steady_s = std::chrono::duration<double>(Clock::now() - joined_at_).count();
  }
  result_.checks_during_run = checks_done_;
  if (!result_.connected) return;
  client_->disconnect();
  result_.counters = client_->counters();
  if (auto w = client_->welcome()) result_.server_id = w->server_id;
}

bool Bot::closed() const { return client_->closed(); }
bool Bot::join_settled() const { return !result_.connect_error.empty() || closed() || joined(); }
ClientCounters Bot::counters() const { return client_->counters(); }

ReplicaMemory Bot::replica_memory() const {
  return client_->with_replica([](const Replica& r) { return r.memory(); });
}

}  // namespace terrane::bots
