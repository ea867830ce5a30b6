#include "common/world/terrain_generator.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <deque>
#include <limits>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "common/voxel/chunk.h"
#include "common/world/noise.h"

namespace terrane {

namespace {

namespace m = materials;

// Lattice spacing of the 3D fields. They are smooth at this scale (their
// shortest period is 10+ voxels), so trilinear interpolation of the lattice is
// indistinguishable from evaluating every voxel at 1/64 of the cost.
constexpr std::int32_t kStep = 4;
constexpr float kInvStep = 0.25f;
constexpr int kFields = 4;  // overhang, worm a, worm b, cavern

// Caves are carved only in [kCaveMinY, surface); below kBedrockY everything is
// solid Basalt; cave air below kLavaY is CrackedLava.
constexpr std::int32_t kCaveMinY = kWorldMinY + 4;
constexpr std::int32_t kBedrockY = kWorldMinY + 4;
constexpr std::int32_t kLavaY = kWorldMinY + 14;

// Noise streams (indices into seeds_).
enum Stream : std::uint32_t {
  kContinent,
  kHills,
  kMountainMask,
  kRidges,
  kHighlandMask,
  kTemperature,
  kHumidity,
  kRiver,
  kSwampDetail,
  kEntrance,
  kCaveAmount,
  kStrata,
  kOverhang,
  kWormA,
  kWormB,
  kCavern,
};

constexpr float lerpf(float a, float b, float t) { return a + (b - a) * t; }

// Steps h into plateaus `step` high joined by cliffs; `sharp` is the half
// width of the cliff as a fraction of a step (smaller = steeper).
float terrace(float h, float step, float sharp) {
  const float t = h / step;
  const float fl = std::floor(t);
  return (fl + smoothstep(0.5f - sharp, 0.5f + sharp, t - fl)) * step;
}

// Trilinear interpolation of the 8 lattice corners c[(dy * 2 + dz) * 2 + dx].
// The single formula both generate() and voxel_at() use, so their bits agree.
float trilerp(const float* c, float fx, float fy, float fz) {
  const float a = lerpf(lerpf(c[0], c[1], fx), lerpf(c[2], c[3], fx), fz);
  const float b = lerpf(lerpf(c[4], c[5], fx), lerpf(c[6], c[7], fx), fz);
  return lerpf(a, b, fy);
}

std::int32_t floor_to_int(float v) {
  return static_cast<std::int32_t>(std::floor(clampf(v, -1.0e8f, 1.0e8f)));
}

// Rock strata: bands 7 voxels thick (wobbling with a 2D warp), each band's
// material picked by hashing its index, the same everywhere in the world so
// layers line up across canyon walls.
constexpr std::array<Material, 8> kStrataRock = {m::kRock, m::kLimestone, m::kSlate, m::kRock,
                                             m::kLimestone, m::kRock, m::kSlate, m::kRock};
constexpr std::array<Material, 8> kStrataDesert = {m::kSandstone, m::kSandstone, m::kLimestone, m::kSandstone,
                                                   m::kSandstone, m::kRock, m::kSandstone, m::kLimestone};
constexpr std::array<Material, 8> kStrataDeep = {m::kRock, m::kSlate, m::kBasalt, m::kRock,
                                                 m::kSlate, m::kRock, m::kBasalt, m::kRock};

}  // namespace

// 2D fields of one column, before its neighbours are known.
struct TerrainGenerator::Surface {
  float height = 0;  // final surface height
  float cont = 0, mountain = 0, highland = 0, desert = 0, swamp = 0, lake = 0;
  float temperature = 0, humidity = 0;
  float strata_warp = 0, entrance = 0, cave_amount = 0;
  std::int32_t water_level = 0;
};

// Everything the voxel loop needs about one column.
struct TerrainGenerator::Column {
  float height;         // surface height
  float inv_len;        // 1 / sqrt(1 + |grad h|^2): vertical distance -> true distance
  float slope;          // |grad h|
  float overhang;        // vertical displacement amplitude of the surface, voxels
  float normal_overhang; // displacement along the surface normal, voxels
  std::int32_t top_y;   // y >= top_y: terrain density <= -1 (no 3D work)
  std::int32_t bot_y;   // y <= bot_y: terrain density >= 1 before caves
  std::int32_t lattice_lo, lattice_hi;  // y range that reads the 3D lattice
  std::int32_t water_level;
  float strata_warp;
  float cave_guard;     // caves fade out within this depth of the surface
  float worm_radius;
  float soil_factor;    // 1 on flats, 0 on cliffs
  float top_depth, sub_depth;
  Material top_mat, sub_mat;
  float desert_depth;   // sandstone strata reach this deep (deserts)
  Biome biome;
  bool cold;
};

const char* to_string(Biome biome) {
  switch (biome) {
    case Biome::kOcean: return "ocean";
    case Biome::kBeach: return "beach";
    case Biome::kPlains: return "plains";
    case Biome::kMeadow: return "meadow";
    case Biome::kDesert: return "desert";
    case Biome::kSwamp: return "swamp";
    case Biome::kHighlands: return "highlands";
    case Biome::kSnowyMountains: return "snowy_mountains";
  }
  return "unknown";
}

std::string validate(const GeneratorParams& p) {
  auto in = [](float v, float lo, float hi) { return std::isfinite(v) && v >= lo && v <= hi; };
  if (p.sea_level < -100 || p.sea_level > 400) return "sea_level out of range [-100, 400]";
  if (!in(p.terrain_scale, 0.25f, 8.0f)) return "terrain_scale out of range [0.25, 8]";
  if (!in(p.mountain_height, 0.0f, 400.0f)) return "mountain_height out of range [0, 400]";
  if (!in(p.hill_height, 0.0f, 64.0f)) return "hill_height out of range [0, 64]";
  if (!in(p.overhang_strength, 0.0f, 16.0f)) return "overhang_strength out of range [0, 16]";
  return {};
}

TerrainGenerator::TerrainGenerator(GeneratorParams params) : params_(params) {
  // Clamp into the documented ranges (NaN becomes the default) so that even
  // a caller that skipped validate() gets bounded work per voxel.
  auto fix = [](float v, float lo, float hi, float def) { return std::isfinite(v) ? clampf(v, lo, hi) : def; };
  const GeneratorParams d;
  params_.sea_level = std::clamp(params_.sea_level, -100, 400);
  params_.terrain_scale = fix(params_.terrain_scale, 0.25f, 8.0f, d.terrain_scale);
  params_.mountain_height = fix(params_.mountain_height, 0.0f, 400.0f, d.mountain_height);
  params_.hill_height = fix(params_.hill_height, 0.0f, 64.0f, d.hill_height);
  params_.overhang_strength = fix(params_.overhang_strength, 0.0f, 16.0f, d.overhang_strength);
  inv_scale_ = 1.0 / static_cast<double>(params_.terrain_scale);
  for (std::uint32_t i = 0; i < 16; ++i) seeds_[i] = derive_seed(params_.seed, i);
  cache_ = std::make_shared<ColumnCache>(kColumnCacheSize);
  coarse_cache_ = std::make_shared<ColumnCache>(kCoarseColumnCacheSize);
}

// The height of a column from continents, hills, mountains, highlands,
// deserts, rivers and swamps (everything but lakes). px, pz are world
// coordinates divided by terrain_scale. Fills *s when not null.
float TerrainGenerator::raw_height(double px, double pz, Surface* s) const {
  const auto sea = static_cast<float>(params_.sea_level);
  const float cont = 2.0f * fbm2(px / 600.0, pz / 600.0, seeds_[kContinent], 4);
  const float land = smoothstep(-0.3f, 0.05f, cont);
  float h = sea + 8.0f + 40.0f * cont;
  h += params_.hill_height * 2.0f * fbm2(px / 140.0, pz / 140.0, seeds_[kHills], 3) * (0.3f + 0.7f * land);

  const float mountain =
      smoothstep(-0.05f, 0.4f, 2.0f * fbm2(px / 400.0, pz / 400.0, seeds_[kMountainMask], 2) + 0.3f * cont) * land;
  if (mountain > 0.0f) {
    const float ridge = ridged2(px / 260.0, pz / 260.0, seeds_[kRidges], 5);
    h += params_.mountain_height * mountain * smoothstep(0.25f, 0.9f, ridge);
  }

  const float highland =
      smoothstep(0.15f, 0.45f, 2.0f * fbm2(px / 380.0, pz / 380.0, seeds_[kHighlandMask], 2)) * land *
      (1.0f - mountain);
  if (highland > 0.0f) {
    h += 38.0f * highland;
    h = lerpf(h, terrace(h, 9.0f, 0.08f), highland);
  }

  const float temperature = 2.0f * fbm2(px / 800.0, pz / 800.0, seeds_[kTemperature], 2);
  const float humidity = 2.0f * fbm2(px / 650.0, pz / 650.0, seeds_[kHumidity], 2);
  const float desert = smoothstep(0.0f, 0.25f, temperature) * smoothstep(0.05f, -0.15f, humidity) * land;
  if (desert > 0.0f) h = lerpf(h, terrace(h, 14.0f, 0.04f), desert * 0.85f);

  // Rivers and canyons follow the zero lines of a noise: |n| small is the
  // valley. The bed sits below sea level so rivers fill with sea water; in
  // deserts the valley is wider and stepped (canyon walls).
  const float river = 2.0f * fbm2(px / 420.0 + 0.37, pz / 420.0 - 0.21, seeds_[kRiver], 3);
  const float width = 0.05f * (1.0f + 1.5f * desert);
  const float valley = 1.0f - smoothstep(0.0f, width, river < 0.0f ? -river : river);
  if (valley > 0.0f) {
    const float bed = sea - 2.0f - 3.0f * valley;
    if (h > bed) {
      const float smooth = valley * valley * (3.0f - 2.0f * valley);
      const float stepped = terrace(valley * 3.0f, 1.0f, 0.1f) * (1.0f / 3.0f);
      h = lerpf(h, bed, lerpf(smooth, stepped, desert));
    }
  }

  const float swamp = smoothstep(0.1f, 0.3f, humidity) * (1.0f - smoothstep(sea + 6.0f, sea + 22.0f, h)) * land *
                      (1.0f - desert);
  if (swamp > 0.0f) {
    h = lerpf(h, sea + 0.4f + 6.0f * fbm2(px / 30.0, pz / 30.0, seeds_[kSwampDetail], 2), swamp);
  }

  if (s != nullptr) {
    s->cont = cont;
    s->mountain = mountain;
    s->highland = highland;
    s->desert = desert;
    s->swamp = swamp;
    s->temperature = temperature;
    s->humidity = humidity;
  }
  return h;
}

TerrainGenerator::Surface TerrainGenerator::surface(std::int32_t x, std::int32_t z) const {
  Surface s;
  const double px = static_cast<double>(x) * inv_scale_;
  const double pz = static_cast<double>(z) * inv_scale_;
  float h = raw_height(px, pz, &s);
  s.water_level = params_.sea_level;

  // Lakes: at most one per 256x256 cell (in scaled units), centred in the
  // cell's middle half so its 1.8 R influence never leaves the cell. The
  // water level comes from the height at the centre, so every column of a
  // lake agrees on it; the terrain is flattened to just above that level
  // around the lake and dug into a bowl inside, so the water is contained.
  constexpr double kCell = 256.0;
  const auto cx = static_cast<std::int32_t>(std::floor(px / kCell));
  const auto cz = static_cast<std::int32_t>(std::floor(pz / kCell));
  const std::uint32_t lh = hash2(cx, cz, seeds_[kSwampDetail] ^ 0x1A4Eu);
  if ((lh & 3u) != 0) {  // 3 cells in 4 may hold a lake
    const double lcx = (cx + 0.25 + 0.5 * hash_unit(hash_u32(lh + 1))) * kCell;
    const double lcz = (cz + 0.25 + 0.5 * hash_unit(hash_u32(lh + 2))) * kCell;
    const float radius = 18.0f + 16.0f * hash_unit(hash_u32(lh + 3));
    const auto dx = static_cast<float>(px - lcx), dz = static_cast<float>(pz - lcz);
    // The shore wobbles by a third of the radius so lakes are not discs.
    const float dist = std::sqrt(dx * dx + dz * dz) *
                       (1.0f + 0.7f * gradient_noise2(px / 24.0, pz / 24.0, seeds_[kSwampDetail] + 1));
    if (dist < radius * 1.8f) {
      Surface c;
      const float hc = raw_height(lcx, lcz, &c);
      const auto sea = static_cast<float>(params_.sea_level);
      if (hc > sea + 3.0f && hc < sea + 60.0f && c.mountain < 0.2f && c.desert < 0.5f && c.swamp < 0.3f) {
        const float level = std::floor(hc) - 1.0f;
        const float ring = 1.0f - smoothstep(radius, radius * 1.8f, dist);
        h = lerpf(h, level + 2.0f, ring);
        if (dist < radius) {
          const float r = dist / radius;
          h -= 10.0f * (1.0f - r * r);
          s.water_level = static_cast<std::int32_t>(level);
        }
        s.lake = ring;
      }
    }
  }

  s.height = h;
  s.strata_warp = 12.0f * fbm2(px / 90.0, pz / 90.0, seeds_[kStrata], 2);
  if (params_.caves) {
    s.entrance = smoothstep(0.4f, 0.6f, 2.0f * gradient_noise2(px / 200.0, pz / 200.0, seeds_[kEntrance]));
    s.cave_amount = smoothstep(-0.4f, 0.3f, 2.0f * fbm2(px / 300.0, pz / 300.0, seeds_[kCaveAmount], 2));
  }
  return s;
}

TerrainGenerator::Column TerrainGenerator::column(const Surface& s, float h_xm, float h_xp, float h_zm,
                                                  float h_zp) const {
  Column c{};
  const auto sea = static_cast<float>(params_.sea_level);
  const float h = s.height;
  c.height = h;
  const float gx = (h_xp - h_xm) * 0.5f, gz = (h_zp - h_zm) * 0.5f;
  const float g2 = gx * gx + gz * gz;
  c.slope = std::sqrt(g2);
  // Density is (h - y) / len: close to a signed distance on slopes, so the
  // occupancy ramp is about two voxels wide across the surface, not along y.
  // Capped so that cliffs keep a bounded vertical band of 3D work.
  const float len = std::min(std::sqrt(1.0f + g2), 6.0f);
  c.inv_len = 1.0f / len;
  c.water_level = s.water_level;
  const bool underwater = h < static_cast<float>(s.water_level);

  const float rugged = std::max(std::max(s.mountain, s.highland), std::max(s.desert * 0.6f, smoothstep(0.8f, 2.5f, c.slope)));
  float a = params_.overhang_strength * (0.12f + 0.88f * rugged) * (1.0f - s.lake);
  if (underwater) a = std::min(a, 1.0f);
  c.overhang = a;
  // Part of the perturbation acts along the true normal (so cliff faces get
  // bulges and hollows), bounded so the band above a steep column stays small.
  c.normal_overhang = std::min(a, 2.0f) * rugged;
  const float band = a + (1.0f + c.normal_overhang) * len + 0.5f;
  c.top_y = floor_to_int(h + band) + 1;
  c.bot_y = floor_to_int(h - band);
  c.lattice_hi = c.top_y - 1;
  c.lattice_lo = params_.caves ? std::min(kCaveMinY, c.bot_y + 1) : c.bot_y + 1;

  c.strata_warp = s.strata_warp;
  c.worm_radius = 0.03f + 0.08f * s.cave_amount;
  const bool near_water = h < static_cast<float>(s.water_level) + 4.0f;
  c.cave_guard = near_water ? 18.0f : lerpf(7.0f, -8.0f, s.entrance);
  c.soil_factor = clampf(1.6f - 0.6f * c.slope, 0.0f, 1.0f);

  // Biome.
  const float temp = s.temperature - std::max(0.0f, h - sea) * (1.0f / 180.0f);
  c.cold = temp < -0.55f;
  const float snow_line = 130.0f + 45.0f * s.temperature + s.strata_warp;
  if (underwater) {
    c.biome = Biome::kOcean;
  } else if (h > snow_line || c.cold) {
    c.biome = Biome::kSnowyMountains;
  } else if (s.highland > 0.5f || (s.mountain > 0.4f && h > sea + 60.0f)) {
    c.biome = Biome::kHighlands;
  } else if (s.swamp > 0.5f) {
    c.biome = Biome::kSwamp;
  } else if (s.desert > 0.4f) {
    c.biome = Biome::kDesert;
  } else if (h < sea + 3.0f && s.cont < 0.1f && s.water_level == params_.sea_level) {
    c.biome = Biome::kBeach;
  } else if (s.humidity > 0.1f) {
    c.biome = Biome::kMeadow;
  } else {
    c.biome = Biome::kPlains;
  }

  switch (c.biome) {
    case Biome::kOcean:
      if (h > static_cast<float>(s.water_level) - 10.0f) {
        c.top_mat = m::kSand, c.top_depth = 3.0f, c.sub_mat = m::kSandstone, c.sub_depth = 7.0f;
      } else {
        c.top_mat = m::kMud, c.top_depth = 2.0f, c.sub_mat = m::kGround, c.sub_depth = 5.0f;
      }
      if (c.cold) c.top_mat = m::kGround;
      break;
    case Biome::kBeach:
      c.top_mat = m::kSand, c.top_depth = 4.0f, c.sub_mat = m::kSandstone, c.sub_depth = 8.0f;
      break;
    case Biome::kPlains:
      c.top_mat = m::kGrass, c.top_depth = 1.2f, c.sub_mat = m::kGround, c.sub_depth = 5.0f;
      break;
    case Biome::kMeadow:
      c.top_mat = m::kLeafyGrass, c.top_depth = 1.2f, c.sub_mat = m::kGround, c.sub_depth = 5.0f;
      break;
    case Biome::kDesert:
      c.top_mat = m::kSand, c.top_depth = 4.0f, c.sub_mat = m::kSandstone, c.sub_depth = 30.0f;
      break;
    case Biome::kSwamp:
      c.top_mat = m::kMud, c.top_depth = 3.0f, c.sub_mat = m::kGround, c.sub_depth = 7.0f;
      break;
    case Biome::kHighlands:
      c.top_mat = m::kGrass, c.top_depth = 1.0f, c.sub_mat = m::kGround, c.sub_depth = 2.5f;
      break;
    case Biome::kSnowyMountains:
      c.top_mat = m::kSnow, c.top_depth = 2.5f;
      c.sub_mat = h > sea + 140.0f ? m::kGlacier : m::kGround;
      c.sub_depth = h > sea + 140.0f ? 6.0f : 4.0f;
      // Snow clings to steeper slopes than soil does.
      c.soil_factor = clampf(2.2f - 0.6f * c.slope, 0.0f, 1.0f);
      break;
  }
  c.desert_depth = 45.0f * smoothstep(0.2f, 0.6f, s.desert);
  return c;
}

void TerrainGenerator::lattice_sample(std::int32_t lx, std::int32_t ly, std::int32_t lz, float out[4]) const {
  fields_at(static_cast<double>(lx) * kStep, static_cast<double>(ly) * kStep, static_cast<double>(lz) * kStep, out);
}

void TerrainGenerator::fields_at(double x, double y, double z, float out[4], bool overhang) const {
  out[0] = overhang ? clampf(2.0f * fbm3(x / 26.0, y / 20.0, z / 26.0, seeds_[kOverhang], 2), -1.0f, 1.0f) : 0.0f;
  if (params_.caves) {
    out[1] = gradient_noise3(x / 64.0, y / 40.0, z / 64.0, seeds_[kWormA]);
    out[2] = gradient_noise3(x / 64.0, y / 40.0, z / 64.0, seeds_[kWormB]);
    out[3] = fbm3(x / 110.0, y / 60.0, z / 110.0, seeds_[kCavern], 2);
  } else {
    out[1] = out[2] = out[3] = 0.0f;
  }
}

// The voxel at (x, y, z) of a column. `corners` holds the 8 lattice corners of
// each field (corners[f * 8 + i]); it is read only for y in
// [lattice_lo, lattice_hi] and may be null elsewhere.
Voxel TerrainGenerator::shade(const Column& col, std::int32_t x, std::int32_t y, std::int32_t z,
                              const float* corners, float sharpness) const {
  if (y < kBedrockY) return solid(m::kBasalt);
  const auto fy = static_cast<float>(y);
  float d = 1.0f;
  if (y >= col.top_y) {
    d = -1.0f;
  } else {
    const float fx = static_cast<float>(floor_mod(x, kStep)) * kInvStep;
    const float fyl = static_cast<float>(floor_mod(y, kStep)) * kInvStep;
    const float fz = static_cast<float>(floor_mod(z, kStep)) * kInvStep;
    if (y > col.bot_y) {
      const float ov = trilerp(corners, fx, fyl, fz);
      d = clampf(((col.height + col.overhang * ov - fy) * col.inv_len + col.normal_overhang * ov) * sharpness, -1.0f,
                 1.0f);
    }
    if (params_.caves && y >= kCaveMinY && d > -1.0f) {
      const float a = trilerp(corners + 8, fx, fyl, fz);
      const float b = trilerp(corners + 16, fx, fyl, fz);
      const float cav = trilerp(corners + 24, fx, fyl, fz);
      // Worms: where two independent noises are both near zero, a tube.
      // 30 converts noise units to voxels (the noise changes ~1/30 per voxel).
      float dc = (std::sqrt(a * a + b * b) - col.worm_radius) * 30.0f;
      // Caverns: big chambers where a low-frequency noise peaks, only deep.
      const float threshold = 0.26f + 0.5f * smoothstep(-70.0f, 10.0f, fy);
      dc = std::min(dc, (threshold - cav) * 60.0f);
      // Fade caves out near the surface (except at cave entrances) and well
      // below water, so the sea never pours into an air pocket.
      const float depth = col.height - fy;
      if (depth < col.cave_guard) dc += col.cave_guard - depth;
      d = std::min(d, clampf(dc * sharpness, -1.0f, 1.0f));
    }
  }

  const float f = d * 0.5f + 0.5f;
  if (f * 256.0f < 0.5f) {
    if (y < kLavaY) return solid(m::kCrackedLava);  // deep caves hold lava
    if (y < col.water_level && y > col.bot_y) {
      return solid(col.cold && y == col.water_level - 1 ? m::kIce : m::kWater);
    }
    return Voxel{};
  }
  const std::uint8_t occ = occupancy_byte(f);

  const float depth = col.height - fy;
  Material mat;
  const float deep_line = -40.0f + col.strata_warp;
  if (fy < -100.0f + col.strata_warp * 0.5f) {
    mat = m::kBasalt;
  } else if (depth < col.top_depth * col.soil_factor && depth > -2.0f) {
    mat = col.top_mat;
  } else if (depth < col.sub_depth * col.soil_factor && depth > -2.0f) {
    mat = col.sub_mat;
  } else {
    const std::int32_t band = floor_to_int((fy + col.strata_warp) * (1.0f / 7.0f));
    const std::uint32_t pick = hash2(band, 0, seeds_[kStrata]) & 7u;
    if (fy < deep_line) {
      mat = kStrataDeep[pick];
    } else if (depth < col.desert_depth) {
      mat = kStrataDesert[pick];
    } else {
      mat = kStrataRock[pick];
    }
  }
  return make_voxel(mat, occ);
}

float TerrainGenerator::surface_height(std::int32_t x, std::int32_t z) const { return surface(x, z).height; }

std::int32_t TerrainGenerator::water_level(std::int32_t x, std::int32_t z) const {
  return surface(x, z).water_level;
}

Biome TerrainGenerator::biome_at(std::int32_t x, std::int32_t z) const {
  const Surface s = surface(x, z);
  return column(s, surface(x - 1, z).height, surface(x + 1, z).height, surface(x, z - 1).height,
                surface(x, z + 1).height)
      .biome;
}

Voxel TerrainGenerator::voxel_at(Vec3i p) const {
  const Surface s = surface(p.x, p.z);
  const Column col = column(s, surface(p.x - 1, p.z).height, surface(p.x + 1, p.z).height,
                            surface(p.x, p.z - 1).height, surface(p.x, p.z + 1).height);
  float corners[kFields * 8];
  const float* cp = nullptr;
  if (p.y >= col.lattice_lo && p.y <= col.lattice_hi) {
    const Vec3i l = floor_div(p, kStep);
    for (int i = 0; i < 8; ++i) {
      float v[kFields];
      lattice_sample(l.x + (i & 1), l.y + (i >> 2), l.z + ((i >> 1) & 1), v);
      for (int f = 0; f < kFields; ++f) corners[f * 8 + i] = v[f];
    }
    cp = corners;
  }
  return shade(col, p.x, p.y, p.z, cp);
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

std::vector<TerrainGenerator::Column> TerrainGenerator::columns(std::int32_t x0, std::int32_t z0, int sx,
                                                                int sz) const {
  // 2D fields with a one-voxel margin (for the slope).
  const int mx = sx + 2;
  std::vector<Surface> surf(static_cast<std::size_t>(mx) * (sz + 2));
  for (int z = 0; z < sz + 2; ++z) {
    for (int x = 0; x < mx; ++x) {
      surf[static_cast<std::size_t>(z) * mx + x] = surface(x0 + x - 1, z0 + z - 1);
    }
  }
  std::vector<Column> cols(static_cast<std::size_t>(sx) * sz);
  for (int z = 0; z < sz; ++z) {
    for (int x = 0; x < sx; ++x) {
      auto at = [&](int dx, int dz) -> const Surface& {
        return surf[static_cast<std::size_t>(z + 1 + dz) * mx + (x + 1 + dx)];
      };
      cols[static_cast<std::size_t>(z) * sx + x] = column(at(0, 0),
                                                          at(-1, 0).height, at(1, 0).height, at(0, -1).height,
                                                          at(0, 1).height);
    }
  }
  return cols;
}

std::shared_ptr<const std::vector<TerrainGenerator::Column>> TerrainGenerator::chunk_columns(std::int32_t x0,
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
        lattice_sample(l0.x + lx, l0.y + ly, l0.z + lz,
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
        row[x] = shade(c, wx, wy, wz, cp);
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
  const auto make_columns = [&] {
    std::vector<Column> made(static_cast<std::size_t>(nx) * nz);
    for (int z = 0; z < nz; ++z) {
      for (int x = 0; x < nx; ++x) {
        const std::int32_t wx = at(x, origin.x), wz = at(z, origin.z);
        Column c = column(surface(wx, wz), surface(wx - 1, wz).height, surface(wx + 1, wz).height,
                          surface(wx, wz - 1).height, surface(wx, wz + 1).height);
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
          fields_at(static_cast<double>(wx), static_cast<double>(wy), static_cast<double>(wz), v, wy > c.bot_y);
          for (int f = 0; f < kFields; ++f) std::fill_n(corners + f * 8, 8, v[f]);
          cp = corners;
        }
        row[x] = shade(c, wx, wy, wz, cp, sharpness);
      }
    }
  }
}

// ---------------------------------------------------------------------------
// Metadata

namespace {

constexpr std::string_view kGeneratorName = "terrane.density";

template <class T>
void append_kv(std::string& s, std::string_view key, T value) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), value);
  s += key;
  s += '=';
  s += std::string_view(buf, static_cast<std::size_t>(r.ptr - buf));
  s += '\n';
}

template <class T>
bool parse_number(std::string_view v, T& out) {
  if (v.empty()) return false;
  const auto r = std::from_chars(v.data(), v.data() + v.size(), out);
  return r.ec == std::errc{} && r.ptr == v.data() + v.size();
}

}  // namespace

std::string TerrainGenerator::to_metadata() const {
  std::string s;
  s.append("generator=").append(kGeneratorName).push_back('\n');
  append_kv(s, "version", kGeneratorVersion);
  append_kv(s, "seed", params_.seed);
  append_kv(s, "sea_level", params_.sea_level);
  append_kv(s, "terrain_scale", params_.terrain_scale);
  append_kv(s, "mountain_height", params_.mountain_height);
  append_kv(s, "hill_height", params_.hill_height);
  append_kv(s, "overhang_strength", params_.overhang_strength);
  s.append("caves=").append(params_.caves ? "true" : "false").push_back('\n');
  return s;
}

Result<TerrainGenerator> TerrainGenerator::from_metadata(std::string_view text, std::string* message) {
  enum Key { kKeyName, kKeyVersion, kKeySeed, kKeySea, kKeyScale, kKeyMountain, kKeyHill, kKeyOverhang, kKeyCaves, kKeyCount };
  static constexpr std::array<std::string_view, kKeyCount> kKeys = {
      "generator", "version", "seed", "sea_level", "terrain_scale", "mountain_height", "hill_height",
      "overhang_strength", "caves"};
  std::array<bool, kKeyCount> seen{};
  GeneratorParams p;
  std::size_t line_no = 0;

  auto fail = [&](DecodeErrorCode code, std::size_t offset, const char* detail, const std::string& msg) {
    if (message != nullptr) *message = msg;
    return Result<TerrainGenerator>(DecodeError{code, offset, detail});
  };

  std::size_t pos = 0;
  while (pos < text.size()) {
    const std::size_t line_start = pos;
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line.empty()) continue;
    const std::string where = "line " + std::to_string(line_no);
    const std::size_t eq = line.find('=');
    if (eq == std::string_view::npos) {
      return fail(DecodeErrorCode::kInvalidValue, line_start, "expected key=value",
                  where + ": expected key=value, got '" + std::string(line) + "'");
    }
    const std::string_view key = line.substr(0, eq), value = line.substr(eq + 1);
    const std::string what = where + " (" + std::string(key) + ")";
    int k = 0;
    while (k < kKeyCount && kKeys[k] != key) ++k;
    if (k == kKeyCount) {
      return fail(DecodeErrorCode::kInvalidValue, line_start, "unknown key", what + ": unknown key");
    }
    if (seen[k]) return fail(DecodeErrorCode::kInvalidValue, line_start, "duplicate key", what + ": duplicate key");
    seen[k] = true;
    bool ok = true;
    switch (static_cast<Key>(k)) {
      case kKeyName:
        if (value != kGeneratorName) {
          return fail(DecodeErrorCode::kBadMagic, line_start, "not a terrane.density generator",
                      what + ": unknown generator '" + std::string(value) + "'");
        }
        break;
      case kKeyVersion: {
        std::uint32_t v = 0;
        if (!parse_number(value, v)) {
          ok = false;
        } else if (v != kGeneratorVersion) {
          return fail(DecodeErrorCode::kBadVersion, line_start, "unsupported generator version",
                      what + ": version " + std::string(value) + " is not " + std::to_string(kGeneratorVersion));
        }
        break;
      }
      case kKeySeed: ok = parse_number(value, p.seed); break;
      case kKeySea: ok = parse_number(value, p.sea_level); break;
      case kKeyScale: ok = parse_number(value, p.terrain_scale); break;
      case kKeyMountain: ok = parse_number(value, p.mountain_height); break;
      case kKeyHill: ok = parse_number(value, p.hill_height); break;
      case kKeyOverhang: ok = parse_number(value, p.overhang_strength); break;
      case kKeyCaves:
        if (value == "true") {
          p.caves = true;
        } else if (value == "false") {
          p.caves = false;
        } else {
          ok = false;
        }
        break;
      case kKeyCount: break;
    }
    if (!ok) {
      return fail(DecodeErrorCode::kInvalidValue, line_start, "malformed value",
                  what + ": malformed value '" + std::string(value) + "'");
    }
  }
  for (int k = 0; k < kKeyCount; ++k) {
    if (!seen[k]) {
      return fail(DecodeErrorCode::kTruncated, text.size(), "missing key",
                  "missing key '" + std::string(kKeys[k]) + "'");
    }
  }
  if (std::string err = validate(p); !err.empty()) {
    return fail(DecodeErrorCode::kInvalidValue, 0, "parameter out of range", err);
  }
  return TerrainGenerator(p);
}

}  // namespace terrane
