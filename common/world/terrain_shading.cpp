#include "common/world/terrain_shading.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "common/voxel/chunk.h"
#include "common/world/noise.h"

namespace terrane {

namespace {

namespace m = materials;

constexpr std::int32_t kStep = TerrainField::kLatticeStep;
constexpr float kInvStep = 1.0f / static_cast<float>(kStep);

// Trilinear interpolation of the 8 lattice corners c[(dy * 2 + dz) * 2 + dx].
// The single formula both generate() and voxel_at() use, so their bits agree.
float trilerp(const float* c, float fx, float fy, float fz) {
  const float a = lerp(lerp(c[0], c[1], fx), lerp(c[2], c[3], fx), fz);
  const float b = lerp(lerp(c[4], c[5], fx), lerp(c[6], c[7], fx), fz);
  return lerp(a, b, fy);
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

TerrainShading::TerrainShading(const TerrainField& field)
    : sea_level_(field.params().sea_level),
      overhang_strength_(field.params().overhang_strength),
      caves_(field.params().caves),
      strata_seed_(field.strata_seed()) {}

TerrainShading::Column TerrainShading::column(const TerrainField::Surface& s, float h_xm, float h_xp, float h_zm,
                                              float h_zp) const {
  Column c{};
  const auto sea = static_cast<float>(sea_level_);
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
  float a = overhang_strength_ * (0.12f + 0.88f * rugged) * (1.0f - s.lake);
  if (underwater) a = std::min(a, 1.0f);
  c.overhang = a;
  // Part of the perturbation acts along the true normal (so cliff faces get
  // bulges and hollows), bounded so the band above a steep column stays small.
  c.normal_overhang = std::min(a, 2.0f) * rugged;
  const float band = a + (1.0f + c.normal_overhang) * len + 0.5f;
  c.top_y = floor_to_int(h + band) + 1;
  c.bot_y = floor_to_int(h - band);
  c.lattice_hi = c.top_y - 1;
  c.lattice_lo = caves_ ? std::min(kCaveMinY, c.bot_y + 1) : c.bot_y + 1;

  c.strata_warp = s.strata_warp;
  c.worm_radius = 0.03f + 0.08f * s.cave_amount;
  const bool near_water = h < static_cast<float>(s.water_level) + 4.0f;
  c.cave_guard = near_water ? 18.0f : lerp(7.0f, -8.0f, s.entrance);
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
  } else if (h < sea + 3.0f && s.cont < 0.1f && s.water_level == sea_level_) {
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

Voxel TerrainShading::shade(const Column& col, std::int32_t x, std::int32_t y, std::int32_t z,
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
    if (caves_ && y >= kCaveMinY && d > -1.0f) {
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
    const std::uint32_t pick = hash2(band, 0, strata_seed_) & 7u;
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

}  // namespace terrane
