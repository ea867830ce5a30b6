// Queries and awareness on the owner strand: ReadBox, presence of other
// clients, and region hashes (asked for, and pushed periodically so every
// client keeps verifying its replica without asking).
#include <algorithm>
#include <cmath>

#include "server/log.h"
#include "server/server.h"

namespace terrane {

void Server::on_read_box(Peer& peer, const ReadBoxMsg& req) {
  // Only chunks the client holds (at any resolution): a read must never make
  // the server load or generate chunks nobody is looking at.
  const Region r = req.box;
  bool held = true;
  for_each_chunk_in(r, [&](Vec3i cp) {
    if (!held) return;
    held = peer.held.count(cp) != 0 && cache_->loaded(cp);
  });
  if (!held) {
    peer.session->send(build_read_box_error(req.request_id, r, "box outside the chunks this client holds"));
    return;
  }
  Box box(r.size());
  cache_->grid().read_box(r.min, box);
  // On the data queue: the voxels are the state after every update queued
  // before them, as the client's replica will be when it reads this.
  peer.session->send(build_read_box_result(req.request_id, r, box.voxels()));
}

void Server::send_presence() {
  std::vector<std::pair<float, PresenceEntryMsg>> near;
  std::vector<PresenceEntryMsg> entries;
  for (auto& [id, peer] : peers_) {
    if (!peer.welcomed || !peer.plan_valid) continue;
    const Vec3f p = peer.state.position;
    const float vd = static_cast<float>(peer.state.view_distance);
    near.clear();
    for (const auto& [other_id, other] : peers_) {
      if (other_id == id || !other.welcomed || !other.plan_valid) continue;
      const Vec3f q = other.state.position;
      const float dx = q.x - p.x, dy = q.y - p.y, dz = q.z - p.z;
      const float d2 = dx * dx + dy * dy + dz * dz;
      if (d2 > vd * vd) continue;
      near.emplace_back(d2, PresenceEntryMsg{static_cast<std::uint32_t>(other_id), q});
    }
    const std::size_t keep = std::min(near.size(), options_.presence_max_entries);
    std::partial_sort(near.begin(), near.begin() + static_cast<std::ptrdiff_t>(keep), near.end(),
                      [](const auto& a, const auto& b) {
                        return a.first < b.first || (a.first == b.first && a.second.client_id < b.second.client_id);
                      });
    entries.clear();
    for (std::size_t i = 0; i < keep; ++i) entries.push_back(near[i].second);
    // Only when something changed: idle crowds cost nothing.
    auto same = [](const PresenceEntryMsg& a, const PresenceEntryMsg& b) {
      return a.client_id == b.client_id && a.position.x == b.position.x && a.position.y == b.position.y &&
             a.position.z == b.position.z;
    };
    if (entries.size() == peer.presence.size() &&
        std::equal(entries.begin(), entries.end(), peer.presence.begin(), same))
      continue;
    peer.presence = entries;
    peer.session->send(build_presence(entries));
    counters_.presence_sent.fetch_add(1, std::memory_order_relaxed);
  }
}

void Server::push_region_hashes() {
  for (auto& [id, peer] : peers_) {
    if (!peer.welcomed || !peer.plan_valid || peer.plan.empty()) continue;
    // The next chunk in the plan this client holds at full resolution.
    for (std::size_t tries = 0; tries < peer.plan.size(); ++tries) {
      const Vec3i cp = peer.plan[peer.hash_cursor++ % peer.plan.size()];
      auto it = peer.held.find(cp);
      if (it == peer.held.end() || it->second.kind != HeldKind::kFull || !cache_->loaded(cp)) continue;
      const std::uint64_t rev = cache_->revision(cp);
      peer.session->send(build_region_hash(RegionHashMsg{cp, rev, chunk_hash(cp)}));
      counters_.hashes_pushed.fetch_add(1, std::memory_order_relaxed);
      break;
    }
  }
}

std::uint64_t Server::chunk_hash(Vec3i cp) {
  // Many clients verify the same chunks: hash each revision once.
  const std::uint64_t rev = cache_->revision(cp);
  auto it = hash_cache_.find(cp);
  if (it != hash_cache_.end() && it->second.first == rev) return it->second.second;
  const std::uint64_t h = region_hash(cache_->chunk(cp), rev);
  hash_cache_[cp] = {rev, h};
  return h;
}

void Server::serve_hash_requests(Peer& peer) {
  auto& reqs = peer.hash_requests;
  std::size_t kept = 0;
  for (std::size_t i = 0; i < reqs.size(); ++i) {
    const Vec3i cp = reqs[i];
    if (peer.held.count(cp) == 0) {
      // Claimed by a resuming client but not yet adopted or resent: answer
      // once it is, so the hash follows the data it describes.
      if (peer.claims.count(cp) != 0) reqs[kept++] = cp;
      continue;
    }
    if (!cache_->request(cp)) {
      reqs[kept++] = cp;
      continue;
    }
    const std::uint64_t rev = cache_->revision(cp);
    peer.session->send(build_region_hash(RegionHashMsg{cp, rev, chunk_hash(cp)}));
  }
  reqs.resize(kept);
}

}  // namespace terrane
