#include "common/world/terrain_field.h"

#include <cmath>

#include "common/world/noise.h"

namespace terrane {

namespace {

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

// Steps h into plateaus `step` high joined by cliffs; `sharp` is the half
// width of the cliff as a fraction of a step (smaller = steeper).
float terrace(float h, float step, float sharp) {
  const float t = h / step;
  const float fl = std::floor(t);
  return (fl + smoothstep(0.5f - sharp, 0.5f + sharp, t - fl)) * step;
}

}  // namespace

TerrainField::TerrainField(const GeneratorParams& params) : params_(clamped(params)) {
  inv_scale_ = 1.0 / static_cast<double>(params_.terrain_scale);
  for (std::uint32_t i = 0; i < 16; ++i) seeds_[i] = derive_seed(params_.seed, i);
}

std::uint32_t TerrainField::strata_seed() const { return seeds_[kStrata]; }

// The height of a column from continents, hills, mountains, highlands,
// deserts, rivers and swamps (everything but lakes). px, pz are world
// coordinates divided by terrain_scale. Fills *s when not null.
float TerrainField::raw_height(double px, double pz, Surface* s) const {
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
    h = lerp(h, terrace(h, 9.0f, 0.08f), highland);
  }

  const float temperature = 2.0f * fbm2(px / 800.0, pz / 800.0, seeds_[kTemperature], 2);
  const float humidity = 2.0f * fbm2(px / 650.0, pz / 650.0, seeds_[kHumidity], 2);
  const float desert = smoothstep(0.0f, 0.25f, temperature) * smoothstep(0.05f, -0.15f, humidity) * land;
  if (desert > 0.0f) h = lerp(h, terrace(h, 14.0f, 0.04f), desert * 0.85f);

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
      h = lerp(h, bed, lerp(smooth, stepped, desert));
    }
  }

  const float swamp = smoothstep(0.1f, 0.3f, humidity) * (1.0f - smoothstep(sea + 6.0f, sea + 22.0f, h)) * land *
                      (1.0f - desert);
  if (swamp > 0.0f) {
    h = lerp(h, sea + 0.4f + 6.0f * fbm2(px / 30.0, pz / 30.0, seeds_[kSwampDetail], 2), swamp);
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

TerrainField::Surface TerrainField::surface(std::int32_t x, std::int32_t z) const {
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
        h = lerp(h, level + 2.0f, ring);
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

void TerrainField::lattice_sample(std::int32_t lx, std::int32_t ly, std::int32_t lz, float out[kFieldCount]) const {
  fields_at(static_cast<double>(lx) * kLatticeStep, static_cast<double>(ly) * kLatticeStep,
            static_cast<double>(lz) * kLatticeStep, out);
}

void TerrainField::fields_at(double x, double y, double z, float out[kFieldCount], bool overhang) const {
  out[0] = overhang ? clampf(2.0f * fbm3(x / 26.0, y / 20.0, z / 26.0, seeds_[kOverhang], 2), -1.0f, 1.0f) : 0.0f;
  if (params_.caves) {
    out[1] = gradient_noise3(x / 64.0, y / 40.0, z / 64.0, seeds_[kWormA]);
    out[2] = gradient_noise3(x / 64.0, y / 40.0, z / 64.0, seeds_[kWormB]);
    out[3] = fbm3(x / 110.0, y / 60.0, z / 110.0, seeds_[kCavern], 2);
  } else {
    out[1] = out[2] = out[3] = 0.0f;
  }
}

}  // namespace terrane
