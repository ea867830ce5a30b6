#include "client/view/mesher.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "client/view/materials.h"

namespace terrane::view {
namespace {

constexpr float kLevel = 0.5f;  // the surface: occupancy 0.5
constexpr std::uint32_t kNoVertex = 0xFFFFFFFFu;
// Sharp materials pull their vertex this share of the way to the cell
// centre (terraces and flat faces) ...
constexpr float kSharpPull = 0.35f;
// ... and jitter it by up to this many cells (broken, rocky facets).
constexpr float kSharpJitter = 0.2f;
// Colour variation between neighbouring cells (+-), so large flat areas
// read as a surface rather than a flat fill.
constexpr float kColourNoise = 0.07f;

std::uint32_t hash3(std::int64_t x, std::int64_t y, std::int64_t z) {
  std::uint64_t h = static_cast<std::uint64_t>(x) * 0x9E3779B97F4A7C15ull;
  h ^= static_cast<std::uint64_t>(y) * 0xC2B2AE3D27D4EB4Full + (h >> 29);
  h ^= static_cast<std::uint64_t>(z) * 0x165667B19E3779F9ull + (h >> 32);
  h ^= h >> 31;
  h *= 0x94D049BB133111EBull;
  h ^= h >> 29;
  return static_cast<std::uint32_t>(h);
}
float unit_hash(std::uint32_t h, int shift) { return static_cast<float>((h >> shift) & 0xFF) / 255.0f; }

std::uint8_t to_byte(float v) { return static_cast<std::uint8_t>(std::clamp(v, 0.0f, 255.0f) + 0.5f); }

}  // namespace

SampleGrid::SampleGrid(Vec3i d, Vec3f o, float s)
    : dims(d),
      origin(o),
      spacing(s),
      occupancy(static_cast<std::size_t>(d.x) * static_cast<std::size_t>(d.y) * static_cast<std::size_t>(d.z), 0.0f),
      material(occupancy.size(), kAir) {}

std::size_t SampleGrid::solid_count() const {
  return static_cast<std::size_t>(std::count_if(occupancy.begin(), occupancy.end(), [](float v) { return v >= kLevel; }));
}

void mesh_samples(const SampleGrid& grid, Mesh& out, const MesherOptions& options) {
  out.vertices.clear();
  out.indices.clear();
  const Vec3i d = grid.dims;
  if (d.x <= 0 || d.y <= 0 || d.z <= 0) return;

  // Padded copy: one ring of Air around the grid, so every lookup is in range.
  const int px = d.x + 2, py = d.y + 2, pz = d.z + 2;
  auto pidx = [&](int x, int y, int z) {  // padded coordinates
    return (static_cast<std::size_t>(z) * static_cast<std::size_t>(py) + static_cast<std::size_t>(y)) *
               static_cast<std::size_t>(px) +
           static_cast<std::size_t>(x);
  };
  std::vector<float> occ(static_cast<std::size_t>(px) * static_cast<std::size_t>(py) * static_cast<std::size_t>(pz), 0.0f);
  std::vector<Material> mat(occ.size(), kAir);
  const bool lit = !grid.light.empty();
  std::vector<std::uint8_t> light(lit ? occ.size() : 0, 255);
  for (int z = 0; z < d.z; ++z)
    for (int y = 0; y < d.y; ++y)
      for (int x = 0; x < d.x; ++x) {
        occ[pidx(x + 1, y + 1, z + 1)] = grid.occupancy[grid.index(x, y, z)];
        mat[pidx(x + 1, y + 1, z + 1)] = grid.material[grid.index(x, y, z)];
        if (lit) light[pidx(x + 1, y + 1, z + 1)] = grid.light[grid.index(x, y, z)];
      }

  // Cells: between padded samples c and c + 1, c in [0, p - 1): a cell's
  // index is that of its min corner in padded coordinates.
  std::vector<std::uint32_t> cell_vertex(occ.size(), kNoVertex);
  static constexpr std::array<std::array<int, 3>, 8> kCorner = {
      {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0, 0, 1}, {1, 0, 1}, {0, 1, 1}, {1, 1, 1}}};
  static constexpr std::array<std::array<int, 2>, 12> kEdges = {
      {{0, 1}, {2, 3}, {4, 5}, {6, 7}, {0, 2}, {1, 3}, {4, 6}, {5, 7}, {0, 4}, {1, 5}, {2, 6}, {3, 7}}};
  // World integer key of a cell for hashing: the same cell of two
  // overlapping grids with equal spacing gets the same jitter and tint.
  const float inv = 1.0f / grid.spacing;
  const auto key = [&](float o, int c) {
    return static_cast<std::int64_t>(std::lround(static_cast<double>(o * inv) * 2.0)) + 2 * static_cast<std::int64_t>(c);
  };
  std::vector<std::uint8_t> has_normal;

  for (int z = 0; z + 1 < pz; ++z)
    for (int y = 0; y + 1 < py; ++y)
      for (int x = 0; x + 1 < px; ++x) {
        float v[8];
        int mask = 0;
        for (int i = 0; i < 8; ++i) {
          v[i] = occ[pidx(x + kCorner[i][0], y + kCorner[i][1], z + kCorner[i][2])];
          if (v[i] >= kLevel) mask |= 1 << i;
        }
        if (mask == 0 || mask == 0xFF) continue;
        // Vertex: mean of the level crossings on the cell's edges.
        float sx = 0, sy = 0, sz = 0;
        int n = 0;
        for (const auto& e : kEdges) {
          const bool s0 = (mask >> e[0]) & 1, s1 = (mask >> e[1]) & 1;
          if (s0 == s1) continue;
          const float t = (kLevel - v[e[0]]) / (v[e[1]] - v[e[0]]);
          sx += static_cast<float>(kCorner[e[0]][0]) + t * static_cast<float>(kCorner[e[1]][0] - kCorner[e[0]][0]);
          sy += static_cast<float>(kCorner[e[0]][1]) + t * static_cast<float>(kCorner[e[1]][1] - kCorner[e[0]][1]);
          sz += static_cast<float>(kCorner[e[0]][2]) + t * static_cast<float>(kCorner[e[1]][2] - kCorner[e[0]][2]);
          ++n;
        }
        const float fn = static_cast<float>(n);
        float lx = sx / fn, ly = sy / fn, lz = sz / fn;
        // Material: the fullest solid corner (first on ties).
        int best = -1;
        for (int i = 0; i < 8; ++i)
          if (((mask >> i) & 1) && (best < 0 || v[i] > v[best])) best = i;
        const Material m = mat[pidx(x + kCorner[best][0], y + kCorner[best][1], z + kCorner[best][2])];
        const MaterialStyle& style = material_style(m);
        // Padded cell x spans grid samples x - 1 .. x.
        const std::uint32_t h = hash3(key(grid.origin.x, x - 1), key(grid.origin.y, y - 1), key(grid.origin.z, z - 1));
        if (options.material_shaping && style.sharpness > 0) {
          const float pull = kSharpPull * style.sharpness, jit = kSharpJitter * style.sharpness;
          lx += (0.5f - lx) * pull + (unit_hash(h, 0) - 0.5f) * 2.0f * jit;
          ly += (0.5f - ly) * pull + (unit_hash(h, 8) - 0.5f) * 2.0f * jit;
          lz += (0.5f - lz) * pull + (unit_hash(h, 16) - 0.5f) * 2.0f * jit;
          lx = std::clamp(lx, 0.0f, 1.0f);
          ly = std::clamp(ly, 0.0f, 1.0f);
          lz = std::clamp(lz, 0.0f, 1.0f);
        }
        MeshVertex vert{};
        vert.pos[0] = grid.origin.x + (static_cast<float>(x - 1) + lx) * grid.spacing;
        vert.pos[1] = grid.origin.y + (static_cast<float>(y - 1) + ly) * grid.spacing;
        vert.pos[2] = grid.origin.z + (static_cast<float>(z - 1) + lz) * grid.spacing;
        // Normal: minus the occupancy gradient over the cell.
        const float gx = (v[1] + v[3] + v[5] + v[7]) - (v[0] + v[2] + v[4] + v[6]);
        const float gy = (v[2] + v[3] + v[6] + v[7]) - (v[0] + v[1] + v[4] + v[5]);
        const float gz = (v[4] + v[5] + v[6] + v[7]) - (v[0] + v[1] + v[2] + v[3]);
        const float len = std::sqrt(gx * gx + gy * gy + gz * gz);
        const bool ok = len > 1e-4f;
        if (ok) {
          vert.normal[0] = -gx / len;
          vert.normal[1] = -gy / len;
          vert.normal[2] = -gz / len;
        }
        float tint = 1.0f + (unit_hash(h, 24) - 0.5f) * 2.0f * kColourNoise;
        if (lit) {
          // The brightest solid corner: the light of the surface fragment
          // the vertex shows (buried corners carry 0).
          std::uint8_t l = 0;
          for (int i = 0; i < 8; ++i)
            if ((mask >> i) & 1) l = std::max(l, light[pidx(x + kCorner[i][0], y + kCorner[i][1], z + kCorner[i][2])]);
          // Only diagonal contact with Air: no lit fragment, half light.
          tint *= static_cast<float>(l == 0 ? 128 : l) / 255.0f;
        }
        vert.rgba[0] = to_byte(static_cast<float>(style.r) * tint);
        vert.rgba[1] = to_byte(static_cast<float>(style.g) * tint);
        vert.rgba[2] = to_byte(static_cast<float>(style.b) * tint);
        vert.rgba[3] = to_byte(style.sharpness * 255.0f);
        cell_vertex[pidx(x, y, z)] = static_cast<std::uint32_t>(out.vertices.size());
        out.vertices.push_back(vert);
        has_normal.push_back(ok ? 1 : 0);
      }

  // Quads: one per sample edge the level crosses, joining the four cells
  // around the edge. Axis a with (u, w) the next two axes in cyclic order,
  // so the listed order is counter-clockwise seen from +a.
  auto emit = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c, std::uint32_t e, bool flip) {
    const std::uint32_t q[4] = {a, b, c, e};
    const auto dist2 = [&](std::uint32_t i, std::uint32_t j) {
      const MeshVertex &p = out.vertices[q[i]], &r = out.vertices[q[j]];
      const float dx = p.pos[0] - r.pos[0], dy = p.pos[1] - r.pos[1], dz = p.pos[2] - r.pos[2];
      return dx * dx + dy * dy + dz * dz;
    };
    // Split along the shorter diagonal (a deterministic choice, so two
    // grids meshing the same cells give the same triangles).
    const bool diag02 = dist2(0, 2) <= dist2(1, 3);
    const std::uint32_t t[6] = {diag02 ? q[0] : q[1], diag02 ? q[1] : q[2], diag02 ? q[2] : q[3],
                                diag02 ? q[0] : q[1], diag02 ? q[2] : q[3], diag02 ? q[3] : q[0]};
    for (int k = 0; k < 2; ++k) {
      out.indices.push_back(t[k * 3]);
      if (flip) {
        out.indices.push_back(t[k * 3 + 2]);
        out.indices.push_back(t[k * 3 + 1]);
      } else {
        out.indices.push_back(t[k * 3 + 1]);
        out.indices.push_back(t[k * 3 + 2]);
      }
    }
  };
  for (int z = 0; z < pz; ++z)
    for (int y = 0; y < py; ++y)
      for (int x = 0; x < px; ++x) {
        const bool s0 = occ[pidx(x, y, z)] >= kLevel;
        // +x edge: cells (x, y-1..y, z-1..z); (u, w) = (y, z).
        if (x + 1 < px && y > 0 && z > 0 && s0 != (occ[pidx(x + 1, y, z)] >= kLevel))
          emit(cell_vertex[pidx(x, y - 1, z - 1)], cell_vertex[pidx(x, y, z - 1)], cell_vertex[pidx(x, y, z)],
               cell_vertex[pidx(x, y - 1, z)], !s0);
        // +y edge: (u, w) = (z, x).
        if (y + 1 < py && z > 0 && x > 0 && s0 != (occ[pidx(x, y + 1, z)] >= kLevel))
          emit(cell_vertex[pidx(x - 1, y, z - 1)], cell_vertex[pidx(x - 1, y, z)], cell_vertex[pidx(x, y, z)],
               cell_vertex[pidx(x, y, z - 1)], !s0);
        // +z edge: (u, w) = (x, y).
        if (z + 1 < pz && x > 0 && y > 0 && s0 != (occ[pidx(x, y, z + 1)] >= kLevel))
          emit(cell_vertex[pidx(x - 1, y - 1, z)], cell_vertex[pidx(x, y - 1, z)], cell_vertex[pidx(x, y, z)],
               cell_vertex[pidx(x - 1, y, z)], !s0);
      }

  // Vertices whose cell gradient vanished (thin features): area-weighted
  // normals of their triangles.
  std::vector<float> acc;
  for (std::size_t i = 0; i < has_normal.size(); ++i) {
    if (has_normal[i]) continue;
    if (acc.empty()) acc.assign(out.vertices.size() * 3, 0.0f);
  }
  if (!acc.empty()) {
    for (std::size_t t = 0; t + 2 < out.indices.size(); t += 3) {
      const float* a = out.vertices[out.indices[t]].pos;
      const float* b = out.vertices[out.indices[t + 1]].pos;
      const float* c = out.vertices[out.indices[t + 2]].pos;
      const float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
      const float e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
      const float nrm[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
      for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j) acc[out.indices[t + static_cast<std::size_t>(k)] * 3 + static_cast<std::size_t>(j)] += nrm[j];
    }
    for (std::size_t i = 0; i < out.vertices.size(); ++i) {
      if (has_normal[i]) continue;
      const float* a = &acc[i * 3];
      const float len = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
      MeshVertex& vert = out.vertices[i];
      if (len > 0) {
        vert.normal[0] = a[0] / len;
        vert.normal[1] = a[1] / len;
        vert.normal[2] = a[2] / len;
      } else {
        vert.normal[1] = 1.0f;
      }
    }
  }
}

}  // namespace terrane::view
