#include "common/enhance/enhance.h"

#include <algorithm>
#include <cassert>
#include <cmath>

#include "common/world/noise.h"

namespace terrane {
namespace {

// One level of an enhancement in flight: a dense grid over `region` (world
// coordinates at that level) holding 0 for empty cells and the material of
// solid ones. Fragments are full or Air, so a material says everything.
struct MatGrid {
  Region region;
  Vec3i size;
  std::vector<std::uint8_t> mat;

  explicit MatGrid(const Region& r) : region(r), size(r.size()), mat(static_cast<std::size_t>(r.volume()), 0) {}
  std::size_t index(Vec3i p) const {
    const Vec3i l = p - region.min;
    assert(region.contains(p));
    return (static_cast<std::size_t>(l.y) * static_cast<std::size_t>(size.z) + static_cast<std::size_t>(l.z)) *
               static_cast<std::size_t>(size.x) +
           static_cast<std::size_t>(l.x);
  }
};

std::int32_t clamp_i(std::int32_t v, std::int32_t lo, std::int32_t hi) { return v < lo ? lo : (v > hi ? hi : v); }

// The coarse map over `region` (world coordinates), extended beyond the box
// by repeating its border voxels.
MatGrid coarse_grid(const Box& coarse, Vec3i origin, const Region& region) {
  MatGrid g(region);
  const Vec3i s = coarse.size();
  std::size_t i = 0;
  for (std::int32_t y = region.min.y; y < region.max.y; ++y) {
    const std::int32_t ly = clamp_i(y - origin.y, 0, s.y - 1);
    for (std::int32_t z = region.min.z; z < region.max.z; ++z) {
      const std::int32_t lz = clamp_i(z - origin.z, 0, s.z - 1);
      const Voxel* row = coarse.read_row(ly, lz);
      for (std::int32_t x = region.min.x; x < region.max.x; ++x) {
        const Voxel v = row[clamp_i(x - origin.x, 0, s.x - 1)];
        g.mat[i++] = enhance_solid(v) ? v.material : kAir;
      }
    }
  }
  return g;
}

void grid_to_box(const MatGrid& g, Box& out) {
  out.resize(g.size);
  auto voxels = out.voxels();
  for (std::size_t i = 0; i < g.mat.size(); ++i) voxels[i] = g.mat[i] ? solid(g.mat[i]) : Voxel{kAir, 0};
}

// The most common material among the solid ones of a, b, c (0 = empty);
// ties go to the first in a, b, c order.
std::uint8_t pick_material(std::uint8_t a, std::uint8_t b, std::uint8_t c) {
  if (a && (a == b || a == c)) return a;
  if (b && b == c) return b;
  return a ? a : (b ? b : c);
}

// Half-open region grown by n on every side.
Region dilate(const Region& r, std::int32_t n) { return {r.min - Vec3i{n, n, n}, r.max + Vec3i{n, n, n}}; }

// Copies `src` (covering region src_region) into `dst` (covering dst_region)
// where they overlap.
void paste(const Box& src, const Region& src_region, Box& dst, const Region& dst_region) {
  const Region r = intersect(src_region, dst_region);
  if (r.empty()) return;
  for (std::int32_t y = r.min.y; y < r.max.y; ++y) {
    for (std::int32_t z = r.min.z; z < r.max.z; ++z) {
      const Voxel* s = src.read_row(y - src_region.min.y, z - src_region.min.z) + (r.min.x - src_region.min.x);
      Voxel* d = dst.write_row(y - dst_region.min.y, z - dst_region.min.z) + (r.min.x - dst_region.min.x);
      std::copy(s, s + (r.max.x - r.min.x), d);
    }
  }
}

// One subdivision level: the fragments of `next.region` from `prev`, which
// must cover their source voxels and every face neighbour of those.
void subdivide_level(const MatGrid& prev, MatGrid& next, const SubdivisionThreshold& thr, std::int64_t scale,
                     EnhanceStats* stats) {
  const Vec3i smin = floor_div(next.region.min, 2);
  const Vec3i smax = floor_div(next.region.max - Vec3i{1, 1, 1}, 2);  // inclusive
  assert(prev.region.contains(smin - Vec3i{1, 1, 1}) && prev.region.contains(smax + Vec3i{1, 1, 1}));
  const std::size_t sx = 1, sy = static_cast<std::size_t>(prev.size.x) * static_cast<std::size_t>(prev.size.z),
                    sz = static_cast<std::size_t>(prev.size.x);
  std::uint64_t evaluated = 0, skipped = 0;
  for (std::int32_t y = smin.y; y <= smax.y; ++y) {
    const std::int32_t fy0 = std::max(2 * y, next.region.min.y), fy1 = std::min(2 * y + 1, next.region.max.y - 1);
    for (std::int32_t z = smin.z; z <= smax.z; ++z) {
      const std::int32_t fz0 = std::max(2 * z, next.region.min.z), fz1 = std::min(2 * z + 1, next.region.max.z - 1);
      std::size_t i = prev.index({smin.x, y, z});
      for (std::int32_t x = smin.x; x <= smax.x; ++x, ++i) {
        const std::uint8_t* m = prev.mat.data() + i;
        const std::uint8_t c = m[0];
        const std::uint8_t nxm = *(m - sx), nxp = m[sx], nym = *(m - sy), nyp = m[sy], nzm = *(m - sz), nzp = m[sz];
        const unsigned cfg = (c != 0) << kCfgCentre | (nxm != 0) << kCfgMinusX | (nxp != 0) << kCfgPlusX |
                             (nym != 0) << kCfgMinusY | (nyp != 0) << kCfgPlusY | (nzm != 0) << kCfgMinusZ |
                             (nzp != 0) << kCfgPlusZ;
        if (cfg == 0) {  // all empty: the fragments stay empty
          ++skipped;
          continue;
        }
        const std::int32_t fx0 = std::max(2 * x, next.region.min.x), fx1 = std::min(2 * x + 1, next.region.max.x - 1);
        if (cfg == kSubdivisionConfigs - 1) {  // all solid: every fragment solid
          ++skipped;
          for (std::int32_t fy = fy0; fy <= fy1; ++fy)
            for (std::int32_t fz = fz0; fz <= fz1; ++fz)
              for (std::int32_t fx = fx0; fx <= fx1; ++fx) next.mat[next.index({fx, fy, fz})] = c;
          continue;
        }
        ++evaluated;
        for (std::int32_t fy = fy0; fy <= fy1; ++fy) {
          const int dy = fy - 2 * y;
          const int t = thr.at(fy, scale);
          const std::uint8_t mask = kSubdivisionTable[static_cast<std::size_t>(t - 1)][cfg];
          const std::uint8_t my = dy ? nyp : nym;
          for (std::int32_t fz = fz0; fz <= fz1; ++fz) {
            const int dz = fz - 2 * z;
            const std::uint8_t mz = dz ? nzp : nzm;
            for (std::int32_t fx = fx0; fx <= fx1; ++fx) {
              const int dx = fx - 2 * x;
              const int o = dx | dy << 1 | dz << 2;
              if (!((mask >> o) & 1)) continue;
              next.mat[next.index({fx, fy, fz})] = c ? c : pick_material(dx ? nxp : nxm, my, mz);
            }
          }
        }
      }
    }
  }
  if (stats) {
    stats->voxels_evaluated += evaluated;
    stats->voxels_skipped += skipped;
  }
}

std::uint64_t next_random(std::uint64_t& state) {
  state += 0x9E3779B97F4A7C15ull;
  return mix64(state);
}

}  // namespace

std::string validate(const SubdivisionParams& params) {
  if (params.levels < 1 || params.levels > kMaxSubdivisionLevels) return "levels must be in [1, 6]";
  const SubdivisionThreshold& t = params.threshold;
  for (const int v : {t.below, t.above_even, t.above_odd}) {
    if (v < kMinSubdivisionThreshold || v > kMaxSubdivisionThreshold) return "threshold must be in [1, 4]";
  }
  return {};
}

Region fine_region_of(const Box& coarse, Vec3i origin, int factor) {
  return {origin * factor, (origin + coarse.size()) * factor};
}

void subdivide_region(const Box& coarse, Vec3i origin, const SubdivisionParams& params, const Region& fine_region,
                      Box& out, EnhanceStats* stats) {
  assert(validate(params).empty() && !coarse.empty());
  if (fine_region.empty()) {
    out.resize({0, 0, 0});
    return;
  }
  // Regions needed at each level, top down: the sources of a level's cells
  // plus one voxel on every side for the face neighbours.
  std::vector<Region> need(static_cast<std::size_t>(params.levels) + 1);
  need[static_cast<std::size_t>(params.levels)] = fine_region;
  for (int k = params.levels; k > 0; --k) {
    const Region& r = need[static_cast<std::size_t>(k)];
    need[static_cast<std::size_t>(k - 1)] = {floor_div(r.min, 2) - Vec3i{1, 1, 1},
                                             floor_div(r.max - Vec3i{1, 1, 1}, 2) + Vec3i{2, 2, 2}};
  }
  MatGrid prev = coarse_grid(coarse, origin, need[0]);
  for (int k = 1; k <= params.levels; ++k) {
    MatGrid next(need[static_cast<std::size_t>(k)]);
    subdivide_level(prev, next, params.threshold, std::int64_t{1} << k, stats);
    prev = std::move(next);
  }
  grid_to_box(prev, out);
  if (stats) stats->solid_fragments += count_solid(out);
}

Box subdivide(const Box& coarse, Vec3i origin, const SubdivisionParams& params, EnhanceStats* stats) {
  Box out;
  subdivide_region(coarse, origin, params, fine_region_of(coarse, origin, 1 << params.levels), out, stats);
  return out;
}

Region subdivision_affected_region(const Region& changed, const SubdivisionParams& params) {
  // A fragment p depends on the voxels floor((p - 1) / 2) .. floor((p + 1) / 2)
  // of the level below, so inclusive [a, b] there reaches [2a - 1, 2b + 2].
  Region r = changed;
  for (int k = 0; k < params.levels; ++k) {
    r = {r.min * 2 - Vec3i{1, 1, 1}, r.max * 2 + Vec3i{1, 1, 1}};
  }
  return r;
}

Region subdivide_update(const Box& coarse, Vec3i origin, const SubdivisionParams& params, const Region& changed,
                        Box& fine, EnhanceStats* stats) {
  const Region whole = fine_region_of(coarse, origin, 1 << params.levels);
  const Region r = intersect(subdivision_affected_region(changed, params), whole);
  if (r.empty()) return r;
  Box part;
  subdivide_region(coarse, origin, params, r, part, stats);
  paste(part, r, fine, whole);
  return r;
}

// ---------------------------------------------------------------------------

std::string validate(const ResampleParams& params) {
  if (params.factor < 1 || params.factor > 32) return "factor must be in [1, 32]";
  if (params.probes < 1 || params.probes > 4096) return "probes must be in [1, 4096]";
  if (!(params.spread > 0.0f && params.spread <= 4.0f)) return "spread must be in (0, 4]";
  if (!(params.threshold >= 0.0f && params.threshold < 1.0f)) return "threshold must be in [0, 1)";
  return {};
}

std::size_t Resampler::KeyHash::operator()(const std::vector<std::uint64_t>& key) const noexcept {
  std::uint64_t h = 0x243F6A8885A308D3ull;
  for (const std::uint64_t w : key) h = mix64(h ^ w) + 0x9E3779B97F4A7C15ull;
  return static_cast<std::size_t>(h);
}

Resampler::Resampler(const ResampleParams& params) : params_(params) {
  assert(validate(params).empty());
  const int f = params.factor;
  const int n = params.probes;
  std::uint64_t state = params.seed;
  const auto unit = [&state] { return static_cast<double>(next_random(state) >> 11) * (1.0 / 9007199254740992.0); };
  pattern_.reserve(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    const double s = params.spread;
    const auto ox = static_cast<float>((2.0 * unit() - 1.0) * s);
    const auto oy = static_cast<float>((2.0 * unit() - 1.0) * s);
    const auto oz = static_cast<float>((2.0 * unit() - 1.0) * s);
    pattern_.push_back({ox, oy, oz});
  }
  // Cell offsets per axis: probe k of a fragment at local index i along an
  // axis lands in voxel floor((i + 0.5) / f + offset) relative to its source.
  const std::size_t fn = static_cast<std::size_t>(f) * static_cast<std::size_t>(n);
  std::vector<int> cx(fn), cy(fn), cz(fn);
  reach_ = 0;
  for (int i = 0; i < f; ++i) {
    const double centre = (i + 0.5) / f;
    for (int k = 0; k < n; ++k) {
      const Vec3f o = pattern_[static_cast<std::size_t>(k)];
      const std::size_t j = static_cast<std::size_t>(i) * static_cast<std::size_t>(n) + static_cast<std::size_t>(k);
      cx[j] = static_cast<int>(std::floor(centre + static_cast<double>(o.x)));
      cy[j] = static_cast<int>(std::floor(centre + static_cast<double>(o.y)));
      cz[j] = static_cast<int>(std::floor(centre + static_cast<double>(o.z)));
      reach_ = std::max({reach_, std::abs(cx[j]), std::abs(cy[j]), std::abs(cz[j])});
    }
  }
  side_ = 2 * reach_ + 1;
  const int w = side_ * side_ * side_;
  min_solid_ = static_cast<int>(std::floor(static_cast<double>(params.threshold) * n)) + 1;
  // Probe histograms per fragment, in window index order.
  std::vector<std::uint16_t> counts(static_cast<std::size_t>(w), 0);
  hist_begin_.reserve(static_cast<std::size_t>(f) * static_cast<std::size_t>(f) * static_cast<std::size_t>(f) + 1);
  hist_begin_.push_back(0);
  for (int iy = 0; iy < f; ++iy) {
    for (int iz = 0; iz < f; ++iz) {
      for (int ix = 0; ix < f; ++ix) {
        for (int k = 0; k < n; ++k) {
          const auto at = [n, k](int i) {
            return static_cast<std::size_t>(i) * static_cast<std::size_t>(n) + static_cast<std::size_t>(k);
          };
          const int wi = ((cy[at(iy)] + reach_) * side_ + (cz[at(iz)] + reach_)) * side_ + (cx[at(ix)] + reach_);
          ++counts[static_cast<std::size_t>(wi)];
        }
        for (int wi = 0; wi < w; ++wi) {
          std::uint16_t& c = counts[static_cast<std::size_t>(wi)];
          if (!c) continue;
          hist_index_.push_back(static_cast<std::uint16_t>(wi));
          hist_count_.push_back(c);
          c = 0;
        }
        hist_begin_.push_back(static_cast<std::uint32_t>(hist_index_.size()));
      }
    }
  }
}

const Resampler::FragmentSet& Resampler::fragments_for(const std::vector<std::uint64_t>& key,
                                                       const std::uint8_t* window_solid, EnhanceStats* stats) {
  if (auto it = cache_.find(key); it != cache_.end()) {
    if (stats) ++stats->cache_hits;
    return it->second;
  }
  if (stats) ++stats->cache_misses;
  const std::size_t fragments = hist_begin_.size() - 1;
  const int centre = (side_ * side_ * side_) / 2;
  const bool centre_solid = window_solid[centre] != 0;
  FragmentSet set(fragments, kEmptyFragment);
  for (std::size_t i = 0; i < fragments; ++i) {
    int total = 0, best = -1, best_count = 0;
    for (std::uint32_t e = hist_begin_[i]; e < hist_begin_[i + 1]; ++e) {
      if (!window_solid[hist_index_[e]]) continue;
      const int c = hist_count_[e];
      total += c;
      if (c > best_count) {
        best_count = c;
        best = hist_index_[e];
      }
    }
    if (total >= min_solid_) set[i] = static_cast<std::uint16_t>(centre_solid ? centre : best);
  }
  const std::size_t bytes = set.size() * sizeof(std::uint16_t) + key.size() * sizeof(std::uint64_t) + 64;
  if (cache_bytes_ + bytes > kMaxCacheBytes) clear_cache();
  cache_bytes_ += bytes;
  return cache_.emplace(key, std::move(set)).first->second;
}

void Resampler::resample_region(const Box& coarse, Vec3i origin, const Region& fine_region, Box& out,
                                EnhanceStats* stats) {
  assert(!coarse.empty());
  out.resize(fine_region.empty() ? Vec3i{0, 0, 0} : fine_region.size());
  if (fine_region.empty()) return;
  const std::int32_t f = params_.factor;
  const Region src{floor_div(fine_region.min, f), floor_div(fine_region.max - Vec3i{1, 1, 1}, f) + Vec3i{1, 1, 1}};
  const MatGrid grid = coarse_grid(coarse, origin, dilate(src, reach_));
  const int w = side_ * side_ * side_;
  std::vector<std::uint8_t> window_mat(static_cast<std::size_t>(w)), window_solid(static_cast<std::size_t>(w));
  std::vector<std::uint64_t> key(static_cast<std::size_t>((w + 63) / 64));
  const std::size_t row_stride = static_cast<std::size_t>(grid.size.x);
  const std::size_t layer_stride = row_stride * static_cast<std::size_t>(grid.size.z);
  const int centre = w / 2;
  std::uint64_t evaluated = 0, skipped = 0;
  for (std::int32_t y = src.min.y; y < src.max.y; ++y) {
    for (std::int32_t z = src.min.z; z < src.max.z; ++z) {
      for (std::int32_t x = src.min.x; x < src.max.x; ++x) {
        // The window, in Box order, and its occupancy key.
        std::fill(key.begin(), key.end(), 0);
        int solid_count = 0, wi = 0;
        const std::size_t base = grid.index({x - reach_, y - reach_, z - reach_});
        for (int dy = 0; dy < side_; ++dy) {
          for (int dz = 0; dz < side_; ++dz) {
            const std::uint8_t* row = grid.mat.data() + base + static_cast<std::size_t>(dy) * layer_stride +
                                      static_cast<std::size_t>(dz) * row_stride;
            for (int dx = 0; dx < side_; ++dx, ++wi) {
              const std::uint8_t m = row[dx];
              window_mat[static_cast<std::size_t>(wi)] = m;
              window_solid[static_cast<std::size_t>(wi)] = m != 0;
              if (m) {
                ++solid_count;
                key[static_cast<std::size_t>(wi >> 6)] |= std::uint64_t{1} << (wi & 63);
              }
            }
          }
        }
        const Vec3i lo = max3(Vec3i{x, y, z} * f, fine_region.min);
        const Vec3i hi = min3(Vec3i{x + 1, y + 1, z + 1} * f, fine_region.max);
        if (solid_count == 0) {  // every probe empty: nothing to write
          ++skipped;
          continue;
        }
        if (solid_count == w) {  // every probe solid: fill with the source material
          ++skipped;
          const Voxel v = solid(window_mat[static_cast<std::size_t>(centre)]);
          for (std::int32_t fy = lo.y; fy < hi.y; ++fy)
            for (std::int32_t fz = lo.z; fz < hi.z; ++fz) {
              Voxel* row = out.write_row(fy - fine_region.min.y, fz - fine_region.min.z);
              std::fill(row + (lo.x - fine_region.min.x), row + (hi.x - fine_region.min.x), v);
            }
          continue;
        }
        ++evaluated;
        const FragmentSet& set = fragments_for(key, window_solid.data(), stats);
        for (std::int32_t fy = lo.y; fy < hi.y; ++fy) {
          for (std::int32_t fz = lo.z; fz < hi.z; ++fz) {
            Voxel* row = out.write_row(fy - fine_region.min.y, fz - fine_region.min.z);
            const std::size_t local = (static_cast<std::size_t>(fy - y * f) * static_cast<std::size_t>(f) +
                                       static_cast<std::size_t>(fz - z * f)) *
                                      static_cast<std::size_t>(f);
            for (std::int32_t fx = lo.x; fx < hi.x; ++fx) {
              const std::uint16_t s = set[local + static_cast<std::size_t>(fx - x * f)];
              if (s != kEmptyFragment) row[fx - fine_region.min.x] = solid(window_mat[s]);
            }
          }
        }
      }
    }
  }
  if (stats) {
    stats->voxels_evaluated += evaluated;
    stats->voxels_skipped += skipped;
    stats->solid_fragments += count_solid(out);
  }
}

Box Resampler::resample(const Box& coarse, Vec3i origin, EnhanceStats* stats) {
  Box out;
  resample_region(coarse, origin, fine_region_of(coarse, origin, params_.factor), out, stats);
  return out;
}

Region Resampler::affected_region(const Region& changed) const {
  return {(changed.min - Vec3i{reach_, reach_, reach_}) * params_.factor,
          (changed.max + Vec3i{reach_, reach_, reach_}) * params_.factor};
}

Region Resampler::update(const Box& coarse, Vec3i origin, const Region& changed, Box& fine, EnhanceStats* stats) {
  const Region whole = fine_region_of(coarse, origin, params_.factor);
  const Region r = intersect(affected_region(changed), whole);
  if (r.empty()) return r;
  Box part;
  resample_region(coarse, origin, r, part, stats);
  paste(part, r, fine, whole);
  return r;
}

// ---------------------------------------------------------------------------

std::uint64_t count_solid(const Box& box) {
  std::uint64_t n = 0;
  for (const Voxel v : box.voxels()) n += enhance_solid(v);
  return n;
}

std::uint64_t count_surface(const Box& box) {
  const Vec3i s = box.size();
  std::uint64_t n = 0;
  for (int y = 0; y < s.y; ++y) {
    for (int z = 0; z < s.z; ++z) {
      for (int x = 0; x < s.x; ++x) {
        if (!enhance_solid(box.get(x, y, z))) continue;
        const bool open =
            (x > 0 && !enhance_solid(box.get(x - 1, y, z))) || (x + 1 < s.x && !enhance_solid(box.get(x + 1, y, z))) ||
            (y > 0 && !enhance_solid(box.get(x, y - 1, z))) || (y + 1 < s.y && !enhance_solid(box.get(x, y + 1, z))) ||
            (z > 0 && !enhance_solid(box.get(x, y, z - 1))) || (z + 1 < s.z && !enhance_solid(box.get(x, y, z + 1)));
        n += open;
      }
    }
  }
  return n;
}

}  // namespace terrane
