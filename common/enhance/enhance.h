// Voxel detail enhancement: fine "fragment" maps derived from coarse voxel
// maps, after A. M. Smith, "Two Methods for Voxel Detail Enhancement"
// (PCGames 2011). See common/enhance/ENHANCE.md for the rules, the lookup table
// derivation and the versioning rule.
//
// Two operators:
//  - Recursive subdivision: each voxel becomes 2x2x2 fragments; a fragment is
//    solid when the count of solid voxels among its source voxel and the
//    source's three face neighbours towards the fragment reaches an activation
//    threshold. Applied `levels` times for a 2^levels expansion.
//  - Direct resampling: a stored random pattern of probe offsets is added to
//    each fragment's centre; the fragment is solid when more than a threshold
//    fraction of the probes land in solid voxels. Any integer factor.
//
// Contract shared by both:
//  - Solid means occupancy_fraction(v) >= 0.5. Fragments are written as full
//    voxels (kFullOccupancy) or Air.
//  - A solid fragment whose source voxel is solid takes the source's
//    material; a solid fragment of an empty source voxel takes the material of
//    a solid neighbour (subdivision: the most common material among the solid
//    voxels of its neighbourhood, ties to the first in x, y, z order;
//    resampling: the solid voxel hit by the most probes, ties to the lowest
//    window index).
//  - The coarse map is the given Box placed at `origin` (world voxel
//    coordinates), extended beyond its faces by repeating its border voxels.
//    Fine coordinates are coarse coordinates times the factor, so coarse
//    voxel p covers fine [p * f, p * f + f) and negative coordinates follow
//    floor division.
//  - Deterministic: a fragment depends only on the parameters and the coarse
//    voxels in its dependency window, never on the region requested, so any
//    region computed alone equals the same part of a whole-box enhancement.
//    That is what makes the *_update functions exact.
//  - Surface only: a voxel whose whole dependency window agrees is filled
//    (all solid or all empty) without evaluating its fragments.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "common/voxel/box.h"
#include "common/voxel/vec3.h"
#include "common/voxel/voxel.h"

namespace terrane {

// Bump when any fragment produced for some (params, input) changes.
inline constexpr std::uint32_t kEnhanceVersion = 1;

// The enhancement solid test: occupancy_fraction(v) >= 0.5.
constexpr bool enhance_solid(Voxel v) { return occupancy_fraction(v) >= 0.5f; }

// ---------------------------------------------------------------------------
// Recursive subdivision

// Bits of a subdivision configuration (the paper's 128 configurations):
// bit 0 the source voxel, then its face neighbours -x, +x, -y, +y, -z, +z.
inline constexpr int kCfgCentre = 0, kCfgMinusX = 1, kCfgPlusX = 2, kCfgMinusY = 3, kCfgPlusY = 4, kCfgMinusZ = 5,
                     kCfgPlusZ = 6;
inline constexpr int kSubdivisionConfigs = 128;
inline constexpr int kMinSubdivisionThreshold = 1;
inline constexpr int kMaxSubdivisionThreshold = 4;

// Fragment octant o = dx | dy << 1 | dz << 2 (d = 1: the fragment lies on
// the + side of its source voxel along that axis).
// kSubdivisionTable[t - 1][config] has bit o set when fragment o is solid
// under threshold t: centre + the three neighbours towards o, counted, >= t.
using SubdivisionTable = std::array<std::array<std::uint8_t, kSubdivisionConfigs>, kMaxSubdivisionThreshold>;
constexpr SubdivisionTable make_subdivision_table() {
  SubdivisionTable table{};
  for (int t = kMinSubdivisionThreshold; t <= kMaxSubdivisionThreshold; ++t) {
    for (int cfg = 0; cfg < kSubdivisionConfigs; ++cfg) {
      int mask = 0;
      for (int o = 0; o < 8; ++o) {
        const int bx = (o & 1) ? kCfgPlusX : kCfgMinusX;
        const int by = (o & 2) ? kCfgPlusY : kCfgMinusY;
        const int bz = (o & 4) ? kCfgPlusZ : kCfgMinusZ;
        const int count = ((cfg >> kCfgCentre) & 1) + ((cfg >> bx) & 1) + ((cfg >> by) & 1) + ((cfg >> bz) & 1);
        if (count >= t) mask |= 1 << o;
      }
      table[static_cast<std::size_t>(t - 1)][static_cast<std::size_t>(cfg)] = static_cast<std::uint8_t>(mask);
    }
  }
  return table;
}
inline constexpr SubdivisionTable kSubdivisionTable = make_subdivision_table();

// The activation threshold, constant or varying with altitude as in the
// paper's Figure 1: fragments below split_y (in coarse world voxels) use
// `below`; fragments at or above it alternate on the lowest bit of their
// own y at the level being computed (even: above_even, odd: above_odd).
// Each value is in [1, 4].
struct SubdivisionThreshold {
  int below = 2;
  int above_even = 2;
  int above_odd = 2;
  std::int32_t split_y = 0;

  static constexpr SubdivisionThreshold constant(int t) { return {t, t, t, 0}; }
  // Threshold for a fragment at fine y `y` of a level with `scale` fragments
  // per coarse voxel (2, 4, 8, ...).
  constexpr int at(std::int64_t y, std::int64_t scale) const {
    if (y < std::int64_t{split_y} * scale) return below;
    return (y & 1) ? above_odd : above_even;
  }
  friend constexpr bool operator==(const SubdivisionThreshold&, const SubdivisionThreshold&) = default;
};

struct SubdivisionParams {
  int levels = 1;  // expansion factor 2^levels; [1, kMaxSubdivisionLevels]
  SubdivisionThreshold threshold;
};
inline constexpr int kMaxSubdivisionLevels = 6;  // factor 64

// Empty when valid, else a message naming the bad field.
std::string validate(const SubdivisionParams& params);

struct EnhanceStats {
  std::uint64_t voxels_evaluated = 0;  // source voxels (all levels) whose fragments were computed
  std::uint64_t voxels_skipped = 0;    // source voxels filled without evaluation (uniform window)
  std::uint64_t solid_fragments = 0;   // solid fragments written to the output
  std::uint64_t cache_hits = 0;        // resampling: evaluations answered by the cache
  std::uint64_t cache_misses = 0;
};

// The fine region of a whole coarse box: [origin * f, (origin + size) * f).
Region fine_region_of(const Box& coarse, Vec3i origin, int factor);

// Subdivides the whole box. Preconditions: validate(params) is empty,
// coarse is not empty, and the fine coordinates fit in int32.
Box subdivide(const Box& coarse, Vec3i origin, const SubdivisionParams& params, EnhanceStats* stats = nullptr);

// The fragments of `fine_region` (fine world coordinates, any region, also
// beyond the box: the border extension applies) into `out`, resized to
// fine_region.size(). Same preconditions as subdivide().
void subdivide_region(const Box& coarse, Vec3i origin, const SubdivisionParams& params, const Region& fine_region,
                      Box& out, EnhanceStats* stats = nullptr);

// The fine region whose fragments can change when the coarse voxels of
// `changed` change: per axis [2a - 1, 2b + 2] per level from [a, b], which
// stays within one coarse voxel of `changed` on the low side and two on the
// high side, for any number of levels.
Region subdivision_affected_region(const Region& changed, const SubdivisionParams& params);

// After the coarse voxels of `changed` were edited in `coarse`, rewrites the
// affected part of `fine` (a whole-box subdivision of coarse, as returned by
// subdivide()) and returns the fine region rewritten (box-local fine
// coordinates are that minus fine_region_of(...).min). The result equals a
// full recomputation.
Region subdivide_update(const Box& coarse, Vec3i origin, const SubdivisionParams& params, const Region& changed,
                        Box& fine, EnhanceStats* stats = nullptr);

// ---------------------------------------------------------------------------
// Direct resampling

struct ResampleParams {
  int factor = 16;          // fragments per coarse voxel along each axis; [1, 32]
  int probes = 64;          // probe offsets in the pattern; [1, 4096]
  float spread = 1.0f;      // offsets uniform in [-spread, spread] per axis, coarse voxels; (0, 4]
  float threshold = 0.25f;  // solid when solid probes > threshold * probes; [0, 1)
  std::uint64_t seed = 1;   // pattern seed
};

// Empty when valid, else a message naming the bad field.
std::string validate(const ResampleParams& params);

// A resampling operator: the stored probe pattern, the per-fragment probe
// histograms derived from it, and a lazily filled cache from window
// occupancy configurations to fragment sets (the paper's section 4.2).
// Not thread-safe: resampling fills the cache, so use one Resampler per
// thread. The cache only memoises, so output never depends on its state.
class Resampler {
 public:
  // Precondition: validate(params) is empty.
  explicit Resampler(const ResampleParams& params);

  const ResampleParams& params() const { return params_; }
  // The probe offsets, in coarse voxels, in generation order.
  const std::vector<Vec3f>& pattern() const { return pattern_; }
  // Chebyshev radius, in coarse voxels, of the window a voxel's fragments
  // read: ceil(spread) at most.
  int reach() const { return reach_; }
  // Probes that must land in solid voxels for a solid fragment.
  int min_solid_probes() const { return min_solid_; }

  Box resample(const Box& coarse, Vec3i origin, EnhanceStats* stats = nullptr);
  // As subdivide_region(), for this operator.
  void resample_region(const Box& coarse, Vec3i origin, const Region& fine_region, Box& out,
                       EnhanceStats* stats = nullptr);
  // Fragments of the coarse voxels within reach() of `changed`.
  Region affected_region(const Region& changed) const;
  // As subdivide_update(), for this operator.
  Region update(const Box& coarse, Vec3i origin, const Region& changed, Box& fine, EnhanceStats* stats = nullptr);

  std::size_t cache_entries() const { return cache_.size(); }
  void clear_cache() {
    cache_.clear();
    cache_bytes_ = 0;
  }

 private:
  struct KeyHash {
    std::size_t operator()(const std::vector<std::uint64_t>& key) const noexcept;
  };
  // Per fragment: window index whose material a solid fragment takes, or
  // kEmptyFragment. Indexed like a Box of size factor^3.
  using FragmentSet = std::vector<std::uint16_t>;
  static constexpr std::uint16_t kEmptyFragment = 0xFFFF;
  // The cache is dropped whole when it grows past this (64 MiB of sets).
  static constexpr std::size_t kMaxCacheBytes = std::size_t{64} << 20;

  const FragmentSet& fragments_for(const std::vector<std::uint64_t>& key, const std::uint8_t* window_solid,
                                   EnhanceStats* stats);

  ResampleParams params_;
  std::vector<Vec3f> pattern_;
  int reach_ = 1;
  int side_ = 3;  // window side, 2 * reach + 1
  int min_solid_ = 1;
  // Probe histogram of fragment i: entries [hist_begin_[i], hist_begin_[i+1])
  // of (window index, probe count) pairs.
  std::vector<std::uint32_t> hist_begin_;
  std::vector<std::uint16_t> hist_index_;
  std::vector<std::uint16_t> hist_count_;
  std::unordered_map<std::vector<std::uint64_t>, FragmentSet, KeyHash> cache_;
  std::size_t cache_bytes_ = 0;
};

// ---------------------------------------------------------------------------
// Measures

// Solid voxels (enhance_solid) of a box.
std::uint64_t count_solid(const Box& box);
// Solid voxels with at least one face neighbour inside the box that is not
// solid: the visible surface. Neighbours outside the box do not count.
std::uint64_t count_surface(const Box& box);

}  // namespace terrane
