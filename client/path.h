// Path search over the voxel surface for walking clients (bots, scripts).
//
// A walker is body_height voxels tall and stands in a place: the voxel
// its feet are in (x, y, z) and the one(s) above are Air, and the voxel
// below (x, y - 1, z) is not. Every voxel a place or a move looks at must
// be held at full resolution (World::resolution_at == 0): what the replica
// knows only as a mip, or not at all, is never walked through — the search
// stays inside the full-resolution region.
//
// Moves go to the 8 neighbouring columns: up at most max_climb voxels
// (with head room above the walker for the climb), down at most max_drop
// (with the landing column clear down from head height). A diagonal move
// needs both columns beside it clear at the higher of the two feet
// heights, so a walker never cuts a corner. A* with the octile distance;
// cost 1 per straight step, sqrt 2 per diagonal, plus climb_cost per voxel
// climbed.
//
// World is anything with `Voxel get(Vec3i) const` and
// `int resolution_at(Vec3i) const` (the Replica; a Grid wrapper in tests).
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <optional>
#include <queue>
#include <string>
#include <unordered_map>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/voxel/voxel.h"

namespace terrane {

struct PathOptions {
  int body_height = 2;
  int max_climb = 1;
  int max_drop = 3;
  float climb_cost = 0.5f;
  // Places expanded at most before the search gives up, and when it gives
  // up at the latest (checked every 256 places).
  std::size_t max_nodes = 200000;
  std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
};

struct PathResult {
  // The places walked through after the start, ending at the goal; empty
  // when found is false (or when start is the goal).
  std::vector<Vec3i> steps;
  bool found = false;
  std::size_t explored = 0;
  bool timed_out = false;  // the deadline passed
  std::string error;       // why not found
};

template <class World>
bool is_place(const World& w, Vec3i p, const PathOptions& o) {
  const Vec3i below{p.x, p.y - 1, p.z};
  if (w.resolution_at(below) != 0 || w.get(below).material == kAir) return false;
  for (int k = 0; k < o.body_height; ++k) {
    const Vec3i b{p.x, p.y + k, p.z};
    if (w.resolution_at(b) != 0 || w.get(b).material != kAir) return false;
  }
  return true;
}

// Air (and known) at column (x, z) for y in [y0, y1).
template <class World>
bool is_clear(const World& w, std::int32_t x, std::int32_t z, std::int32_t y0, std::int32_t y1) {
  for (std::int32_t y = y0; y < y1; ++y) {
    const Vec3i v{x, y, z};
    if (w.resolution_at(v) != 0 || w.get(v).material != kAir) return false;
  }
  return true;
}

// The place in column (x, z) whose feet are nearest near_y, within
// +-range; nullopt if none (or nothing there is held at full resolution).
template <class World>
std::optional<Vec3i> place_near(const World& w, std::int32_t x, std::int32_t z, std::int32_t near_y, int range,
                                 const PathOptions& o) {
  for (int d = 0; d <= range; ++d)
    for (const int s : {0, 1}) {
      if (d == 0 && s == 1) continue;
      const Vec3i p{x, s == 0 ? near_y - d : near_y + d, z};
      if (is_place(w, p, o)) return p;
    }
  return std::nullopt;
}

template <class World>
PathResult find_path(const World& w, Vec3i start, Vec3i goal, const PathOptions& o = {}) {
  PathResult r;
  if (!is_place(w, start, o)) {
    r.error = "the start is not a place to stand (ground below, room above, held at full resolution)";
    return r;
  }
  if (!is_place(w, goal, o)) {
    r.error = "the goal is not a place to stand (ground below, room above, held at full resolution)";
    return r;
  }
  if (start == goal) {
    r.found = true;
    return r;
  }
  struct Node {
    float g = 0;
    Vec3i parent;
    bool closed = false;
  };
  struct Open {
    float f;
    float g;
    Vec3i p;
    bool operator<(const Open& b) const { return f > b.f; }  // min-heap
  };
  const auto h = [&](Vec3i p) {
    const float dx = static_cast<float>(std::abs(p.x - goal.x)), dz = static_cast<float>(std::abs(p.z - goal.z));
    return std::max(dx, dz) + (std::sqrt(2.0f) - 1.0f) * std::min(dx, dz);
  };
  std::unordered_map<Vec3i, Node, Vec3iHash> nodes;
  std::priority_queue<Open> open;
  nodes[start] = Node{0, start, false};
  open.push({h(start), 0, start});
  std::vector<Vec3i> next;
  while (!open.empty()) {
    const Open cur = open.top();
    open.pop();
    Node& n = nodes[cur.p];
    if (n.closed || cur.g > n.g) continue;
    n.closed = true;
    if (cur.p == goal) {
      for (Vec3i p = goal; p != start; p = nodes[p].parent) r.steps.push_back(p);
      std::reverse(r.steps.begin(), r.steps.end());
      r.found = true;
      r.explored = nodes.size();
      return r;
    }
    if (++r.explored > o.max_nodes) {
      r.error = "no path found within " + std::to_string(o.max_nodes) + " places searched";
      return r;
    }
    if (r.explored % 256 == 0 && std::chrono::steady_clock::now() > o.deadline) {
      r.timed_out = true;
      r.error = "the search ran out of time after " + std::to_string(r.explored) + " places";
      return r;
    }
    const Vec3i p = cur.p;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dx = -1; dx <= 1; ++dx) {
        if (dx == 0 && dz == 0) continue;
        next.clear();
        for (int dy = o.max_climb; dy >= -o.max_drop; --dy) {
          const Vec3i q{p.x + dx, p.y + dy, p.z + dz};
          if (!is_place(w, q, o)) continue;
          // Climbing: head room above the walker; dropping: the landing
          // column clear from head height down.
          if (dy > 0 && !is_clear(w, p.x, p.z, p.y + o.body_height, q.y + o.body_height)) continue;
          if (dy < 0 && !is_clear(w, q.x, q.z, q.y + o.body_height, p.y + o.body_height)) continue;
          if (dx != 0 && dz != 0) {
            const std::int32_t lo = std::max(p.y, q.y);
            if (!is_clear(w, p.x + dx, p.z, lo, lo + o.body_height) ||
                !is_clear(w, p.x, p.z + dz, lo, lo + o.body_height))
              continue;
          }
          next.push_back(q);
        }
        for (const Vec3i q : next) {
          const float step = (dx != 0 && dz != 0 ? std::sqrt(2.0f) : 1.0f) +
                             o.climb_cost * static_cast<float>(std::max(0, q.y - p.y));
          const float g = cur.g + step;
          auto [it, fresh] = nodes.try_emplace(q, Node{g, p, false});
          if (!fresh) {
            if (it->second.closed || it->second.g <= g) continue;
            it->second = Node{g, p, false};
          }
          open.push({g + h(q), g, q});
        }
      }
  }
  r.error = "the goal cannot be reached from the start (" + std::to_string(r.explored) + " places searched)";
  return r;
}

}  // namespace terrane
