// Interest management: what each client should hold, and streaming it
// mip-first then nearest-first (see the Server comment in server/server.h).
#include <algorithm>
#include <cmath>
#include <unordered_set>

#include "common/net_codec.h"
#include "server/log.h"
#include "server/server.h"

namespace terrane {

namespace {

// Frames one pump may queue for one client: bounds the owner strand's work
// per client per tick (a 16^3 unit encodes in tens of microseconds).
constexpr int kMaxFramesPerPump = 256;
// Chunk loads requested ahead of the streaming cursor.
constexpr std::size_t kPrefetch = 48;

float dist_to_chunk(Vec3f p, Vec3i cp) {
  const Vec3i o = chunk_origin(cp);
  auto axis = [](float v, std::int32_t lo) {
    const float a = static_cast<float>(lo), b = static_cast<float>(lo + kChunkSize);
    return v < a ? a - v : (v > b ? v - b : 0.0f);
  };
  const float dx = axis(p.x, o.x), dy = axis(p.y, o.y), dz = axis(p.z, o.z);
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

float dist_to_center(Vec3f p, Vec3i cp) {
  const Vec3i o = chunk_origin(cp);
  const float h = kChunkSize / 2.0f;
  const float dx = static_cast<float>(o.x) + h - p.x, dy = static_cast<float>(o.y) + h - p.y,
              dz = static_cast<float>(o.z) + h - p.z;
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

Vec3i voxel_of(Vec3f p) {
  return {static_cast<std::int32_t>(std::floor(p.x)), static_cast<std::int32_t>(std::floor(p.y)),
          static_cast<std::int32_t>(std::floor(p.z))};
}

}  // namespace

void Server::on_client_state(Peer& peer, const ClientStateMsg& state) {
  // 0 asks for the server's default; everything is capped.
  peer.state = state;
  const std::int32_t view = state.view_distance == 0 ? options_.default_view_distance : state.view_distance;
  const std::int32_t full = state.full_res_radius == 0 ? options_.default_full_res_radius : state.full_res_radius;
  peer.state.view_distance = std::min(view, options_.max_view_distance);
  peer.state.full_res_radius = std::min({full, options_.max_full_res_radius, peer.state.view_distance});
  const Vec3i c = chunk_of(voxel_of(peer.state.position));
  if (!peer.plan_valid || c != peer.plan_chunk || peer.plan_view != peer.state.view_distance ||
      peer.plan_full != peer.state.full_res_radius) {
    replan(peer);
  }
  pump(peer);
}

int Server::desired_level(const Peer& peer, Vec3i cp) const {
  const float d = dist_to_chunk(peer.state.position, cp);
  const float full = static_cast<float>(peer.state.full_res_radius);
  if (d <= full) return 0;
  const float step = std::max(full, static_cast<float>(kChunkSize));
  if (d <= 2.0f * step) return 1;
  if (d <= 4.0f * step) return 2;
  return 3;
}

void Server::replan(Peer& peer) {
  const Vec3f p = peer.state.position;
  const std::int32_t vd = peer.state.view_distance;
  const WorldBounds& b = world_->meta().bounds;
  const Vec3i v = voxel_of(p);
  Vec3i c0 = chunk_of(v - Vec3i{vd, vd, vd}), c1 = chunk_of(v + Vec3i{vd, vd, vd});
  c0.y = std::max(c0.y, floor_div(b.min_y, kChunkSize));
  c1.y = std::min(c1.y, floor_div(b.max_y - 1, kChunkSize));
  std::vector<std::pair<float, Vec3i>> in_view;
  for (int y = c0.y; y <= c1.y; ++y)
    for (int z = c0.z; z <= c1.z; ++z)
      for (int x = c0.x; x <= c1.x; ++x) {
        const Vec3i cp{x, y, z};
        if (!b.touches_chunk(cp) || dist_to_chunk(p, cp) > static_cast<float>(vd)) continue;
        in_view.emplace_back(dist_to_center(p, cp), cp);
      }
  std::sort(in_view.begin(), in_view.end(), [](const auto& a, const auto& c) {
    if (a.first != c.first) return a.first < c.first;
    const Vec3i u = a.second, w = c.second;
    return std::tie(u.y, u.z, u.x) < std::tie(w.y, w.z, w.x);
  });
  peer.plan.clear();
  peer.plan.reserve(in_view.size());
  std::unordered_set<Vec3i, Vec3iHash> keep;
  keep.reserve(in_view.size());
  for (const auto& [d, cp] : in_view) {
    peer.plan.push_back(cp);
    keep.insert(cp);
  }
  // Release what left the view, on both sides.
  std::size_t released = 0;
  for (auto it = peer.held.begin(); it != peer.held.end();) {
    if (keep.count(it->first) != 0) {
      ++it;
      continue;
    }
    peer.session->send(build_coverage(CoverageMsg{it->first, wire::CoverageKind::Released, 0, it->second.revision}));
    it = peer.held.erase(it);
    ++released;
  }
  peer.plan_valid = true;
  peer.plan_chunk = chunk_of(v);
  peer.plan_view = vd;
  peer.plan_full = peer.state.full_res_radius;
  peer.coarse = 0;
  peer.refine = 0;
  SPDLOG_LOGGER_DEBUG(&server_log(), "session {}: plan of {} chunks, {} released", peer.session->id(), peer.plan.size(),
                      released);
}

Frame Server::mip_frame(Vec3i cp, int level) const {
  const int n = kChunkSize >> level;
  Box box({n, n, n});
  if (const Chunk* c = cache_->chunk(cp)) c->read_level(level, box);
  std::vector<std::uint8_t> data;
  net_codec_encode(n, box.voxels(), data);
  return build_mip_data(cp, level, cache_->revision(cp), data);
}

void Server::send_coarse(Peer& peer, Vec3i cp) {
  const std::uint64_t rev = cache_->revision(cp);
  Frame f;
  if (cache_->chunk(cp) == nullptr) {
    f = build_coverage(CoverageMsg{cp, wire::CoverageKind::Empty, 0, rev});
    peer.held[cp] = Held{HeldKind::kEmpty, 0, rev};
    counters_.empties_sent.fetch_add(1, std::memory_order_relaxed);
  } else {
    f = mip_frame(cp, kMipLevels - 1);
    peer.held[cp] = Held{HeldKind::kMip, kMipLevels - 1, rev};
    counters_.mips_sent.fetch_add(1, std::memory_order_relaxed);
  }
  counters_.stream_bytes.fetch_add(f.size(), std::memory_order_relaxed);
  peer.session->send(std::move(f));
}

void Server::send_level(Peer& peer, Vec3i cp, int level) {
  const std::uint64_t rev = cache_->revision(cp);
  if (level > 0) {
    Frame f = mip_frame(cp, level);
    counters_.stream_bytes.fetch_add(f.size(), std::memory_order_relaxed);
    counters_.mips_sent.fetch_add(1, std::memory_order_relaxed);
    peer.session->send(std::move(f));
    peer.held[cp] = Held{HeldKind::kMip, level, rev};
    return;
  }
  // The eight 16^3 units, nearest first, then the coverage that completes them.
  const Chunk* c = cache_->chunk(cp);
  std::array<std::pair<float, int>, 8> order;
  for (int i = 0; i < 8; ++i) {
    const Vec3i u{i & 1, (i >> 1) & 1, (i >> 2) & 1};
    const Vec3i lo = chunk_origin(cp) + u * kChunkDataUnit;
    const float h = kChunkDataUnit / 2.0f;
    const float dx = static_cast<float>(lo.x) + h - peer.state.position.x;
    const float dy = static_cast<float>(lo.y) + h - peer.state.position.y;
    const float dz = static_cast<float>(lo.z) + h - peer.state.position.z;
    order[static_cast<std::size_t>(i)] = {dx * dx + dy * dy + dz * dz, i};
  }
  std::sort(order.begin(), order.end());
  Box box({kChunkDataUnit, kChunkDataUnit, kChunkDataUnit});
  std::vector<std::uint8_t> data;
  for (const auto& [d, i] : order) {
    const Vec3i u{i & 1, (i >> 1) & 1, (i >> 2) & 1};
    if (c != nullptr)
      c->read_box(u * kChunkDataUnit, box, Vec3i{0, 0, 0}, Vec3i{kChunkDataUnit, kChunkDataUnit, kChunkDataUnit});
    else
      box.fill(Voxel{});
    data.clear();
    net_codec_encode(kChunkDataUnit, box.voxels(), data);
    Frame f = build_chunk_data(cp * 2 + u, rev, data);
    counters_.stream_bytes.fetch_add(f.size(), std::memory_order_relaxed);
    peer.session->send(std::move(f));
  }
  Frame done = build_coverage(CoverageMsg{cp, wire::CoverageKind::Full, 0, rev});
  counters_.stream_bytes.fetch_add(done.size(), std::memory_order_relaxed);
  peer.session->send(std::move(done));
  counters_.chunks_sent.fetch_add(1, std::memory_order_relaxed);
  peer.held[cp] = Held{HeldKind::kFull, 0, rev};
}

void Server::pump(Peer& peer) {
  if (!peer.welcomed || !peer.plan_valid) return;
  serve_hash_requests(peer);
  int frames = 0;
  auto room = [&] {
    return frames < kMaxFramesPerPump && peer.session->queued_bytes() < options_.stream_window_bytes;
  };
  // Pass 1: the whole view at its coarsest, nearest first.
  while (peer.coarse < peer.plan.size()) {
    if (!room()) return;
    const Vec3i cp = peer.plan[peer.coarse];
    if (peer.held.count(cp) != 0) {
      ++peer.coarse;
      continue;
    }
    if (!cache_->request(cp)) {
      for (std::size_t i = peer.coarse + 1; i < peer.plan.size() && i <= peer.coarse + kPrefetch; ++i)
        cache_->request(peer.plan[i]);
      return;  // resumes when the chunk arrives (ChunkCache calls schedule_pump)
    }
    send_coarse(peer, cp);
    ++frames;
    ++peer.coarse;
  }
  // Pass 2: refine nearest first.
  while (peer.refine < peer.plan.size()) {
    if (!room()) return;
    const Vec3i cp = peer.plan[peer.refine];
    auto it = peer.held.find(cp);
    if (it == peer.held.end() || it->second.kind != HeldKind::kMip) {
      ++peer.refine;
      continue;
    }
    const int want = desired_level(peer, cp);
    if (want >= it->second.level) {
      ++peer.refine;
      continue;
    }
    send_level(peer, cp, want);
    frames += want == 0 ? 9 : 1;
    ++peer.refine;
  }
}

void Server::pump_all() {
  for (auto& [id, peer] : peers_) pump(peer);
}

void Server::serve_hash_requests(Peer& peer) {
  auto& reqs = peer.hash_requests;
  std::size_t kept = 0;
  for (std::size_t i = 0; i < reqs.size(); ++i) {
    const Vec3i cp = reqs[i];
    if (!cache_->request(cp)) {
      reqs[kept++] = cp;
      continue;
    }
    const std::uint64_t rev = cache_->revision(cp);
    peer.session->send(build_region_hash(RegionHashMsg{cp, rev, region_hash(cache_->chunk(cp), rev)}));
  }
  reqs.resize(kept);
}

}  // namespace terrane
