// Interest management: what each client should hold, and streaming it
// mip-first then nearest-first (see the Server comment in server/server.h).
#include <algorithm>
#include <cmath>
#include <array>
#include <unordered_set>

#include "common/net_codec.h"
#include "common/view.h"
#include "server/log.h"
#include "server/server.h"

namespace terrane {

namespace {

// Work one pump may do for one client, in units (a mip or empty record is
// one, a full chunk nine): bounds the owner strand's work per client per
// tick (a 16^3 unit encodes in tens of microseconds).
constexpr int kMaxFramesPerPump = 256;
// Chunk loads requested ahead of the streaming cursor.
constexpr std::size_t kPrefetch = 48;

Vec3i voxel_of(Vec3f p) {
  return {static_cast<std::int32_t>(std::floor(p.x)), static_cast<std::int32_t>(std::floor(p.y)),
          static_cast<std::int32_t>(std::floor(p.z))};
}

}  // namespace

void Server::on_client_state(Peer& peer, const ClientStateMsg& state) {
  // The first position is where the client joins; after that it moves at
  // most max_speed (with some slack for jitter).
  const auto now = std::chrono::steady_clock::now();
  if (peer.moved && options_.max_speed > 0) {
    const Vec3f a = peer.state.position, b = state.position;
    const double d = std::sqrt(double{b.x - a.x} * (b.x - a.x) + double{b.y - a.y} * (b.y - a.y) +
                               double{b.z - a.z} * (b.z - a.z));
    const double allowed = options_.max_speed * std::chrono::duration<double>(now - peer.moved_at).count() + kSpeedSlackVoxels;
    if (d > allowed) {
      counters_.limit_violations.fetch_add(1, std::memory_order_relaxed);
      violations().warn("session " + std::to_string(peer.session->id()) + " (" + peer.name + "): moved " +
                        std::to_string(static_cast<long long>(d)) + " voxels at once; dropping");
      peer.session->close("moving too fast: " + std::to_string(static_cast<long long>(d)) + " voxels (limit " +
                          std::to_string(static_cast<long long>(options_.max_speed)) + " voxels/s)");
      return;
    }
  }
  peer.moved = true;
  peer.moved_at = now;
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
  return terrane::desired_level(peer.state.position, cp, peer.state.full_res_radius);
}

void Server::replan(Peer& peer) {
  const Vec3f p = peer.state.position;
  const std::int32_t vd = peer.state.view_distance;
  const WorldBounds& b = world_->meta().bounds;
  const Vec3i v = voxel_of(p);
  std::vector<Vec3i> in_view = chunks_in_view(p, vd, b.min_y, b.max_y);
  std::erase_if(in_view, [&](Vec3i cp) { return !b.touches_chunk(cp); });
  peer.plan.clear();
  peer.plan.reserve(in_view.size());
  std::unordered_set<Vec3i, Vec3iHash> keep;
  keep.reserve(in_view.size());
  for (const Vec3i cp : in_view) {
    peer.plan.push_back(cp);
    keep.insert(cp);
  }
  // Release what left the view, on both sides (and claims outside it).
  std::size_t released = 0;
  for (auto it = peer.claims.begin(); it != peer.claims.end();) {
    if (keep.count(it->first) != 0) {
      ++it;
      continue;
    }
    stream(peer, StreamRecordKind::kReleased, it->first, it->second.revision);
    it = peer.claims.erase(it);
  }
  for (auto it = peer.held.begin(); it != peer.held.end();) {
    if (keep.count(it->first) != 0) {
      ++it;
      continue;
    }
    stream(peer, StreamRecordKind::kReleased, it->first, it->second.revision);
    release(it->first);
    it = peer.held.erase(it);
    ++released;
  }
  peer.plan_valid = true;
  peer.plan_chunk = chunk_of(v);
  peer.plan_view = vd;
  peer.plan_full = peer.state.full_res_radius;
  peer.coarse = 0;
  peer.refine = 0;
  flush_stream(peer);
  SPDLOG_LOGGER_DEBUG(&server_log(), "session {}: plan of {} chunks, {} released", peer.session->id(), peer.plan.size(),
                      released);
}

void Server::hold(Peer& peer, Vec3i cp, Held h) {
  auto [it, inserted] = peer.held.insert_or_assign(cp, h);
  if (inserted) ++interest_[cp];
}

void Server::release(Vec3i cp) {
  auto it = interest_.find(cp);
  if (it != interest_.end() && --it->second == 0) interest_.erase(it);
}

const Server::EncodedChunk& Server::encoded(Vec3i cp, int level) {
  // Chunks near many clients are encoded once per revision, not once per
  // client; the cache is bounded in bytes and forgets the oldest entries.
  const std::uint64_t rev = cache_->revision(cp);
  const EncodeKey key{cp, level};
  auto it = encode_cache_.find(key);
  if (it != encode_cache_.end() && it->second.revision == rev) {
    counters_.encode_cache_hits.fetch_add(1, std::memory_order_relaxed);
    return it->second;
  }
  counters_.encode_cache_misses.fetch_add(1, std::memory_order_relaxed);
  EncodedChunk e;
  e.revision = rev;
  const Chunk* c = cache_->chunk(cp);
  if (level > 0) {
    const int n = kChunkSize >> level;
    Box box({n, n, n});
    if (c != nullptr) c->read_level(level, box);
    net_codec_encode(n, box.voxels(), e.payload);
  } else {
    Box box({kChunkDataUnit, kChunkDataUnit, kChunkDataUnit});
    for (int i = 0; i < 8; ++i) {
      const Vec3i u{i & 1, (i >> 1) & 1, (i >> 2) & 1};
      if (c != nullptr)
        c->read_box(u * kChunkDataUnit, box, Vec3i{0, 0, 0}, Vec3i{kChunkDataUnit, kChunkDataUnit, kChunkDataUnit});
      else
        box.fill(Voxel{});
      net_codec_encode(kChunkDataUnit, box.voxels(), e.payload);
    }
  }
  if (it != encode_cache_.end()) {
    encode_cache_bytes_ -= it->second.payload.size();
    it->second = std::move(e);
  } else {
    it = encode_cache_.emplace(key, std::move(e)).first;
    encode_order_.push_back(key);
  }
  encode_cache_bytes_ += it->second.payload.size();
  // FIFO eviction, never the entry just made (the deque may hold keys
  // already dropped by unload: skip those).
  while (encode_cache_bytes_ > options_.encode_cache_bytes && encode_order_.size() > 1) {
    const EncodeKey old = encode_order_.front();
    encode_order_.pop_front();
    if (old == key) {
      encode_order_.push_back(old);
      continue;
    }
    if (auto o = encode_cache_.find(old); o != encode_cache_.end()) {
      encode_cache_bytes_ -= o->second.payload.size();
      encode_cache_.erase(o);
    }
  }
  return encode_cache_.at(key);
}

void Server::unload_unwatched() {
  if (cache_->loaded_count() <= options_.resident_chunks) return;
  std::unordered_set<Vec3i, Vec3iHash> busy;
  for (const PendingEdit& pe : edits_)
    for_each_chunk_in(world_->meta().bounds.clamp(pe.edit.reads()), [&](Vec3i cp) { busy.insert(cp); });
  std::vector<Vec3i> drop;
  cache_->for_each_loaded([&](Vec3i cp) {
    if (interest_.count(cp) == 0 && busy.count(cp) == 0) drop.push_back(cp);
  });
  // Edits are persisted at the tick that applies them, so dropping a
  // chunk loses nothing: it comes back from the store (or the generator).
  const std::size_t excess = cache_->loaded_count() - options_.resident_chunks;
  if (drop.size() > excess) drop.resize(excess);
  for (const Vec3i cp : drop) {
    cache_->unload(cp);
    hash_cache_.erase(cp);
    for (int level = 0; level < kMipLevels; ++level)
      if (auto it = encode_cache_.find(EncodeKey{cp, level}); it != encode_cache_.end()) {
        encode_cache_bytes_ -= it->second.payload.size();
        encode_cache_.erase(it);
      }
  }
  counters_.chunks_unloaded.fetch_add(drop.size(), std::memory_order_relaxed);
  if (!drop.empty())
    SPDLOG_LOGGER_DEBUG(&server_log(), "unloaded {} chunks nobody holds; {} stay loaded", drop.size(),
                        cache_->loaded_count());
}

void Server::stream(Peer& peer, StreamRecordKind kind, Vec3i cp, std::uint64_t revision,
                    std::span<const std::uint8_t> payload) {
  peer.batch.add(kind, cp, revision, payload);
  if (peer.batch.size_bytes() >= kStreamBatchTargetBytes || peer.batch.records() >= kMaxStreamRecords)
    flush_stream(peer);
}

void Server::flush_stream(Peer& peer) {
  if (peer.batch.empty()) return;
  Frame f = peer.batch.finish();
  peer.outbound.spend(static_cast<double>(f.size()));
  counters_.stream_bytes.fetch_add(f.size(), std::memory_order_relaxed);
  peer.session->send(std::move(f));
}

void Server::on_holdings(Peer& peer, const HoldingsMsg& h) {
  for (const HeldChunkMsg& c : h.chunks) {
    if (peer.claims.size() >= options_.max_claims_per_client) break;
    if (peer.held.count(c.chunk_pos) != 0) continue;  // already streamed this session
    const Held held = c.level == kHeldEmpty ? Held{HeldKind::kEmpty, 0, c.revision}
                      : c.level == 0        ? Held{HeldKind::kFull, 0, c.revision}
                                            : Held{HeldKind::kMip, c.level, c.revision};
    peer.claims[c.chunk_pos] = held;
  }
  // Claims outside the view are released at the next plan.
  if (peer.plan_valid) replan(peer);
}

bool Server::adopt_claim(Peer& peer, Vec3i cp) {
  auto it = peer.claims.find(cp);
  if (it == peer.claims.end()) return false;
  const Held claim = it->second;
  peer.claims.erase(it);
  // Same revision means same voxels: revisions of a stored chunk only grow,
  // and a never-stored chunk (revision 0) is what the generator makes.
  const bool empty = cache_->chunk(cp) == nullptr;
  if (claim.revision != cache_->revision(cp) || (claim.kind == HeldKind::kEmpty) != empty) return false;
  hold(peer, cp, claim);
  counters_.chunks_resumed.fetch_add(1, std::memory_order_relaxed);
  return true;
}

void Server::send_coarse(Peer& peer, Vec3i cp) {
  if (adopt_claim(peer, cp)) return;
  const std::uint64_t rev = cache_->revision(cp);
  if (cache_->chunk(cp) == nullptr) {
    stream(peer, StreamRecordKind::kEmpty, cp, rev);
    hold(peer, cp, Held{HeldKind::kEmpty, 0, rev});
    counters_.empties_sent.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  send_level(peer, cp, kMipLevels - 1);
}

void Server::send_level(Peer& peer, Vec3i cp, int level) {
  const EncodedChunk& e = encoded(cp, level);
  stream(peer, level > 0 ? static_cast<StreamRecordKind>(level) : StreamRecordKind::kFull, cp, e.revision, e.payload);
  if (level > 0) {
    counters_.mips_sent.fetch_add(1, std::memory_order_relaxed);
    hold(peer, cp, Held{HeldKind::kMip, level, e.revision});
  } else {
    counters_.chunks_sent.fetch_add(1, std::memory_order_relaxed);
    hold(peer, cp, Held{HeldKind::kFull, 0, e.revision});
  }
}

void Server::pump(Peer& peer) {
  if (!peer.welcomed || !peer.plan_valid) return;
  serve_hash_requests(peer);
  pump_stream(peer);
  flush_stream(peer);
}

void Server::pump_stream(Peer& peer) {
  int frames = 0;
  // The outbound budget is charged for what was batched when the pump ends
  // (flush_stream), so a client over its rate waits for the next tick.
  const bool budget = peer.outbound.available() > 0;
  auto room = [&] {
    return budget && frames < kMaxFramesPerPump &&
           peer.session->queued_bytes() + peer.batch.size_bytes() < options_.stream_window_bytes &&
           static_cast<double>(peer.batch.size_bytes()) < peer.outbound.available();
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

}  // namespace terrane
