#include "common/world/terrain_generator.h"

#include <algorithm>
#include <deque>
#include <limits>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "common/voxel/chunk.h"

namespace terrane {

namespace {

constexpr std::int32_t kStep = TerrainField::kLatticeStep;
constexpr int kFields = TerrainField::kFieldCount;
constexpr std::int32_t kBedrockY = TerrainShading::kBedrockY;
constexpr std::int32_t kLavaY = TerrainShading::kLavaY;

}  // namespace

TerrainGenerator::TerrainGenerator(GeneratorParams params)
    : field_(params),
      shading_(field_),
      cache_(std::make_shared<ColumnCache>(kColumnCacheSize)),
      coarse_cache_(std::make_shared<ColumnCache>(kCoarseColumnCacheSize)) {}

TerrainGenerator::Column TerrainGenerator::column_at(std::int32_t x, std::int32_t z) const {
  return shading_.column(field_.surface(x, z), field_.surface(x - 1, z).height, field_.surface(x + 1, z).height,
                         field_.surface(x, z - 1).height, field_.surface(x, z + 1).height);
}

float TerrainGenerator::surface_height(std::int32_t x, std::int32_t z) const { return field_.surface(x, z).height; }

std::int32_t TerrainGenerator::water_level(std::int32_t x, std::int32_t z) const {
  return field_.surface(x, z).water_level;
}

Biome TerrainGenerator::biome_at(std::int32_t x, std::int32_t z) const { return column_at(x, z).biome; }

Voxel TerrainGenerator::voxel_at(Vec3i p) const {
  const Column col = column_at(p.x, p.z);
  float corners[kFields * 8];
  const float* cp = nullptr;
  if (p.y >= col.lattice_lo && p.y <= col.lattice_hi) {
    const Vec3i l = floor_div(p, kStep);
    for (int i = 0; i < 8; ++i) {
      float v[kFields];
      field_.lattice_sample(l.x + (i & 1), l.y + (i >> 2), l.z + ((i >> 1) & 1), v);
      for (int f = 0; f < kFields; ++f) corners[f * 8 + i] = v[f];
    }
    cp = corners;
  }
  return shading_.shade(col, p.x, p.y, p.z, cp);
}

struct TerrainGenerator::ColumnCache {
  explicit ColumnCache(std::size_t cap) : capacity(cap) {}

  // The columns of the footprint at (x0, z0): kept ones, or make() kept as
  // the newest (the oldest going beyond capacity). make() runs outside the
  // lock: two threads may make the same columns, which are the same.
  template <class Make>
  std::shared_ptr<const std::vector<Column>> get(std::int32_t x0, std::int32_t z0, Make&& make) {
    const std::uint64_t key = (static_cast<std::uint64_t>(static_cast<std::uint32_t>(x0)) << 32) |
                              static_cast<std::uint32_t>(z0);
    {
      std::lock_guard lock(mutex);
      if (auto it = entries.find(key); it != entries.end()) return it->second;
    }
    auto made = std::make_shared<const std::vector<Column>>(make());
    std::lock_guard lock(mutex);
    if (entries.emplace(key, made).second) {
      order.push_back(key);
      if (order.size() > capacity) {
        entries.erase(order.front());
        order.pop_front();
      }
    }
    return made;
  }

  const std::size_t capacity;
  std::mutex mutex;
  std::unordered_map<std::uint64_t, std::shared_ptr<const std::vector<Column>>> entries;
  std::deque<std::uint64_t> order;  // oldest first
};

std::vector<TerrainShading::Column> TerrainGenerator::columns(std::int32_t x0, std::int32_t z0, int sx,
                                                              int sz) const {
  // 2D fields with a one-voxel margin (for the slope).
  const int mx = sx + 2;
  std::vector<TerrainField::Surface> surf(static_cast<std::size_t>(mx) * (sz + 2));
  for (int z = 0; z < sz + 2; ++z) {
    for (int x = 0; x < mx; ++x) {
      surf[static_cast<std::size_t>(z) * mx + x] = field_.surface(x0 + x - 1, z0 + z - 1);
    }
  }
  std::vector<Column> cols(static_cast<std::size_t>(sx) * sz);
  for (int z = 0; z < sz; ++z) {
    for (int x = 0; x < sx; ++x) {
      auto at = [&](int dx, int dz) -> const TerrainField::Surface& {
        return surf[static_cast<std::size_t>(z + 1 + dz) * mx + (x + 1 + dx)];
      };
      cols[static_cast<std::size_t>(z) * sx + x] =
          shading_.column(at(0, 0), at(-1, 0).height, at(1, 0).height, at(0, -1).height, at(0, 1).height);
    }
  }
  return cols;
}

std::shared_ptr<const std::vector<TerrainShading::Column>> TerrainGenerator::chunk_columns(std::int32_t x0,
                                                                                          std::int32_t z0) const {
  return cache_->get(x0, z0, [&] { return columns(x0, z0, kChunkSize, kChunkSize); });
}

bool TerrainGenerator::all_air(const Region& region) const {
  if (region.empty()) return true;
  if (region.min.y < kBedrockY || region.min.y < kLavaY) return false;  // before any column is made
  const Vec3i size = region.size();
  const bool chunk_footprint = size.x == kChunkSize && size.z == kChunkSize && floor_mod(region.min.x, kChunkSize) == 0 &&
                               floor_mod(region.min.z, kChunkSize) == 0;
  std::shared_ptr<const std::vector<Column>> cached;
  std::vector<Column> own;
  if (chunk_footprint)
    cached = chunk_columns(region.min.x, region.min.z);
  else
    own = columns(region.min.x, region.min.z, size.x, size.z);
  const std::vector<Column>& cols = chunk_footprint ? *cached : own;
  // shade(): at y >= top_y the density is -1, so the voxel is Air unless
  // y < kBedrockY (Basalt), y < kLavaY (lava) or y < water_level (water).
  const std::int32_t y = region.min.y;
  for (const Column& c : cols)
    if (y < c.top_y || y < c.water_level) return false;
  return true;
}

void TerrainGenerator::generate(const Region& region, Box& out) const {
  if (region.empty()) {
    out.resize({0, 0, 0});
    return;
  }
  const Vec3i size = region.size();
  out.resize(size);
  const int sx = size.x, sy = size.y, sz = size.z;

  // 1. The columns' 2D fields (shared by a chunk's column stack).
  std::shared_ptr<const std::vector<Column>> cached;
  std::vector<Column> own;
  const bool chunk_footprint = sx == kChunkSize && sz == kChunkSize && floor_mod(region.min.x, kChunkSize) == 0 &&
                               floor_mod(region.min.z, kChunkSize) == 0;
  if (chunk_footprint)
    cached = chunk_columns(region.min.x, region.min.z);
  else
    own = columns(region.min.x, region.min.z, sx, sz);
  const std::vector<Column>& cols = chunk_footprint ? *cached : own;

  // 2. Which lattice points are read: per lattice column, the hull of the
  // lattice y indices needed by the voxel columns of the cells around it.
  const Vec3i l0 = floor_div(region.min, kStep);
  const Vec3i l1 = floor_div(region.max - Vec3i{1, 1, 1}, kStep) + Vec3i{1, 1, 1};  // inclusive
  const int nlx = l1.x - l0.x + 1, nly = l1.y - l0.y + 1, nlz = l1.z - l0.z + 1;
  std::vector<std::int32_t> need_lo(static_cast<std::size_t>(nlx) * nlz, std::numeric_limits<std::int32_t>::max());
  std::vector<std::int32_t> need_hi(need_lo.size(), std::numeric_limits<std::int32_t>::min());
  for (int z = 0; z < sz; ++z) {
    for (int x = 0; x < sx; ++x) {
      const Column& c = cols[static_cast<std::size_t>(z) * sx + x];
      const std::int32_t lo = std::max(c.lattice_lo, region.min.y);
      const std::int32_t hi = std::min(c.lattice_hi, region.max.y - 1);
      if (lo > hi) continue;
      const std::int32_t ylo = floor_div(lo, kStep) - l0.y, yhi = floor_div(hi, kStep) + 1 - l0.y;
      const int cx = floor_div(region.min.x + x, kStep) - l0.x, cz = floor_div(region.min.z + z, kStep) - l0.z;
      for (int i = 0; i < 4; ++i) {
        const std::size_t k = static_cast<std::size_t>(cz + (i >> 1)) * nlx + (cx + (i & 1));
        need_lo[k] = std::min(need_lo[k], ylo);
        need_hi[k] = std::max(need_hi[k], yhi);
      }
    }
  }
  // lattice[((ly * nlz + lz) * nlx + lx) * kFields + f]
  std::vector<float> lattice(static_cast<std::size_t>(nlx) * nly * nlz * kFields, 0.0f);
  for (int lz = 0; lz < nlz; ++lz) {
    for (int lx = 0; lx < nlx; ++lx) {
      const std::size_t k = static_cast<std::size_t>(lz) * nlx + lx;
      for (int ly = need_lo[k]; ly <= need_hi[k]; ++ly) {
        field_.lattice_sample(l0.x + lx, l0.y + ly, l0.z + lz,
                       &lattice[((static_cast<std::size_t>(ly) * nlz + lz) * nlx + lx) * kFields]);
      }
    }
  }

  // 3. Voxels.
  float corners[kFields * 8];
  for (int y = 0; y < sy; ++y) {
    const std::int32_t wy = region.min.y + y;
    const int ly = floor_div(wy, kStep) - l0.y;
    for (int z = 0; z < sz; ++z) {
      const std::int32_t wz = region.min.z + z;
      const int lz = floor_div(wz, kStep) - l0.z;
      Voxel* row = out.write_row(y, z);
      const Column* crow = &cols[static_cast<std::size_t>(z) * sx];
      for (int x = 0; x < sx; ++x) {
        const Column& c = crow[x];
        const std::int32_t wx = region.min.x + x;
        const float* cp = nullptr;
        if (wy >= c.lattice_lo && wy <= c.lattice_hi) {
          const int lx = floor_div(wx, kStep) - l0.x;
          for (int i = 0; i < 8; ++i) {
            const float* v = &lattice[((static_cast<std::size_t>(ly + (i >> 2)) * nlz + (lz + ((i >> 1) & 1))) * nlx +
                                       (lx + (i & 1))) *
                                      kFields];
            for (int f = 0; f < kFields; ++f) corners[f * 8 + i] = v[f];
          }
          cp = corners;
        }
        row[x] = shading_.shade(c, wx, wy, wz, cp);
      }
    }
  }
}

void TerrainGenerator::coarse_sample(Vec3i origin, int cell, Vec3i count, Box& out) const {
  out.resize(count);
  if (count.x <= 0 || count.y <= 0 || count.z <= 0) return;
  cell = std::max(cell, 1);
  const std::int32_t half = cell / 2;
  // The surface ramp (and the caves' walls) widened from about two voxels to
  // about two cells: a cell's occupancy approximates its voxels' mean.
  const float sharpness = 2.0f / static_cast<float>(std::max(cell, 2));
  const int nx = count.x, ny = count.y, nz = count.z;
  const auto at = [&](int i, std::int32_t o) { return o + static_cast<std::int32_t>(cell) * i + half; };
  // The columns at the cells' centres, their bands widened by the wider
  // ramp (a cell whose centre is above the band may still reach into it).
  // A chunk's column stack is often sampled in parts (the regions above
  // and below one another): the latest footprints are kept.
  // From cells of half a chunk up, a column's slope is taken between its
  // neighbouring cells' centres (the cell's mean slope), so a column costs
  // one surface evaluation and the ring around them one more each, not five
  // (column_at's neighbours one voxel away).
  const bool grid_slopes = cell >= kChunkSize / 2;
  const auto make_columns = [&] {
    std::vector<Column> made(static_cast<std::size_t>(nx) * nz);
    std::vector<TerrainField::Surface> surfaces;
    std::vector<float> heights;  // (nx + 2) x (nz + 2), the ring's corners unused
    const auto hi = [&](int x, int z) -> float& {
      return heights[static_cast<std::size_t>(z + 1) * static_cast<std::size_t>(nx + 2) + static_cast<std::size_t>(x + 1)];
    };
    if (grid_slopes) {
      surfaces.resize(static_cast<std::size_t>(nx) * nz);
      heights.assign(static_cast<std::size_t>(nx + 2) * static_cast<std::size_t>(nz + 2), 0.0f);
      for (int z = -1; z <= nz; ++z)
        for (int x = -1; x <= nx; ++x) {
          const bool ring_x = x < 0 || x >= nx, ring_z = z < 0 || z >= nz;
          if (ring_x && ring_z) continue;  // a corner
          const bool inner = !ring_x && !ring_z;
          const TerrainField::Surface sf = field_.surface(at(x, origin.x), at(z, origin.z));
          hi(x, z) = sf.height;
          if (inner) surfaces[static_cast<std::size_t>(z) * nx + x] = sf;
        }
    }
    for (int z = 0; z < nz; ++z) {
      for (int x = 0; x < nx; ++x) {
        const std::int32_t wx = at(x, origin.x), wz = at(z, origin.z);
        Column c;
        if (grid_slopes) {
          // The gradient per voxel, as column_at's neighbours give it.
          const float h = hi(x, z), step = 2.0f * static_cast<float>(cell);
          const float gx = (hi(x + 1, z) - hi(x - 1, z)) / step, gz = (hi(x, z + 1) - hi(x, z - 1)) / step;
          c = shading_.column(surfaces[static_cast<std::size_t>(z) * nx + x], h - gx, h + gx, h - gz, h + gz);
        } else {
          c = column_at(wx, wz);
        }
        // (The ramp is len voxels wide per voxel along y: cell * len here.)
        const auto widen = static_cast<std::int32_t>(std::ceil(static_cast<float>(half) / c.inv_len));
        c.top_y += widen;
        c.bot_y -= widen;
        // The cell's centre lies half a voxel below the voxel evaluated (at
        // an even cell): the surface is raised by as much instead.
        if (cell % 2 == 0) c.height += 0.5f;
        made[static_cast<std::size_t>(z) * nx + x] = c;
      }
    }
    return made;
  };
  std::shared_ptr<const std::vector<Column>> kept;
  std::vector<Column> own;
  const bool chunk_stack = cell == kChunkSize / 4 && nx == 4 && nz == 4 && floor_mod(origin.x, kChunkSize) == 0 &&
                           floor_mod(origin.z, kChunkSize) == 0;
  if (chunk_stack)
    kept = coarse_cache_->get(origin.x, origin.z, make_columns);
  else
    own = make_columns();
  const std::vector<Column>& cols = kept ? *kept : own;
  // The 3D fields are evaluated at each centre (not interpolated from the
  // lattice generate() uses: one evaluation per cell, not per lattice point).
  float corners[kFields * 8];
  for (int y = 0; y < ny; ++y) {
    const std::int32_t wy = at(y, origin.y);
    for (int z = 0; z < nz; ++z) {
      const std::int32_t wz = at(z, origin.z);
      Voxel* row = out.write_row(y, z);
      for (int x = 0; x < nx; ++x) {
        const Column& c = cols[static_cast<std::size_t>(z) * nx + x];
        const std::int32_t wx = at(x, origin.x);
        const float* cp = nullptr;
        if (wy < c.top_y && wy >= kBedrockY) {
          float v[kFields];
          // shade() reads the overhang only above the band's bottom.
          field_.fields_at(static_cast<double>(wx), static_cast<double>(wy), static_cast<double>(wz), v, wy > c.bot_y);
          for (int f = 0; f < kFields; ++f) std::fill_n(corners + f * 8, 8, v[f]);
          cp = corners;
        }
        row[x] = shading_.shade(c, wx, wy, wz, cp, sharpness);
      }
    }
  }
}

std::string TerrainGenerator::to_metadata() const { return terrane::to_metadata(params()); }

Result<TerrainGenerator> TerrainGenerator::from_metadata(std::string_view text, std::string* message) {
  Result<GeneratorParams> params = params_from_metadata(text, message);
  if (!params.ok()) return params.error();
  return TerrainGenerator(*params);
}

}  // namespace terrane
