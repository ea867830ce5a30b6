#include "common/enhance/lighting.h"

#include <cassert>
#include <cmath>

#include "common/enhance/enhance.h"
#include "common/world/noise.h"

namespace terrane {
namespace {

// Occupancy of the box, one byte per fragment, for the particle walks.
struct SolidGrid {
  Vec3i size;
  std::vector<std::uint8_t> solid;

  explicit SolidGrid(const Box& fine) : size(fine.size()), solid(fine.voxel_count()) {
    const auto v = fine.voxels();
    for (std::size_t i = 0; i < v.size(); ++i) solid[i] = enhance_solid(v[i]);
  }
  // Box-local; outside the box is empty.
  bool at(Vec3i p) const {
    if (p.x < 0 || p.y < 0 || p.z < 0 || p.x >= size.x || p.y >= size.y || p.z >= size.z) return false;
    return solid[(static_cast<std::size_t>(p.y) * static_cast<std::size_t>(size.z) + static_cast<std::size_t>(p.z)) *
                     static_cast<std::size_t>(size.x) +
                 static_cast<std::size_t>(p.x)] != 0;
  }
  bool surface(Vec3i p) const {
    return at(p) && (!at(p + Vec3i{1, 0, 0}) || !at(p - Vec3i{1, 0, 0}) || !at(p + Vec3i{0, 1, 0}) ||
                     !at(p - Vec3i{0, 1, 0}) || !at(p + Vec3i{0, 0, 1}) || !at(p - Vec3i{0, 0, 1}));
  }
};

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    state_ += 0x9E3779B97F4A7C15ull;
    return mix64(state_);
  }
  // Uniform in [0, 1) from the top 24 bits of r.
  static float unit24(std::uint64_t r) { return static_cast<float>(r >> 40) * (1.0f / 16777216.0f); }

 private:
  std::uint64_t state_;
};

constexpr Vec3i kFaces[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};

// A particle's drift: cumulative probabilities of its three axes and the
// unit step along each (towards the sign of the direction).
struct Drift {
  float cum_x = 0, cum_y = 0;
  Vec3i step_x, step_y, step_z;
};

Drift make_drift(Vec3f d) {
  const float ax = std::fabs(d.x), ay = std::fabs(d.y), az = std::fabs(d.z);
  const float sum = ax + ay + az;
  Drift r;
  r.cum_x = ax / sum;
  r.cum_y = (ax + ay) / sum;
  r.step_x = {d.x < 0 ? -1 : 1, 0, 0};
  r.step_y = {0, d.y < 0 ? -1 : 1, 0};
  r.step_z = {0, 0, d.z < 0 ? -1 : 1};
  return r;
}

// Walks one particle from the open cell `start` (box-local) for `steps`
// steps; true if it never enters a solid fragment.
bool walk(const SolidGrid& g, Vec3i start, const Drift& drift, float follow, int steps, Rng& rng) {
  Vec3i p = start;
  for (int s = 0; s < steps; ++s) {
    const std::uint64_t r = rng.next();
    const float u = Rng::unit24(r);
    if (u < follow) {
      const float a = static_cast<float>((r >> 8) & 0xFFFFFF) * (1.0f / 16777216.0f);
      p = p + (a < drift.cum_x ? drift.step_x : (a < drift.cum_y ? drift.step_y : drift.step_z));
    } else {
      p = p + kFaces[(r & 0xFF) % 6];
    }
    if (g.at(p)) return false;
  }
  return true;
}

// A direction uniform on the sphere by rejection from the cube (no
// transcendental functions, so the same on every C library).
Vec3f random_direction(Rng& rng) {
  for (;;) {
    const std::uint64_t a = rng.next(), b = rng.next();
    const float x = Rng::unit24(a) * 2.0f - 1.0f;
    const float y = static_cast<float>((a >> 8) & 0xFFFFFF) * (2.0f / 16777216.0f) - 1.0f;
    const float z = Rng::unit24(b) * 2.0f - 1.0f;
    const float n = x * x + y * y + z * z;
    if (n > 1e-6f && n <= 1.0f) return {x, y, z};
  }
}

std::uint8_t light_of(const SolidGrid& g, Vec3i local, Vec3i world, const LightingParams& params, const Drift& sun) {
  // Particles are released into the open cells beside the fragment, each
  // from one of its exposed faces picked at random.
  Vec3i exposed[6];
  std::uint64_t n_exposed = 0;
  for (const Vec3i f : kFaces) {
    if (!g.at(local + f)) exposed[n_exposed++] = local + f;
  }
  const std::uint64_t base =
      mix64(params.seed ^ (static_cast<std::uint64_t>(Vec3iHash{}(world)) * 0x9E3779B97F4A7C15ull));
  int sun_escaped = 0, sky_escaped = 0;
  for (int i = 0; i < params.sun_particles; ++i) {
    Rng rng(base + static_cast<std::uint64_t>(i) * 0xD1B54A32D192ED03ull);
    const Vec3i start = exposed[rng.next() % n_exposed];
    sun_escaped += walk(g, start, sun, params.follow, params.steps - 1, rng);
  }
  for (int i = 0; i < params.sky_particles; ++i) {
    Rng rng(~base + static_cast<std::uint64_t>(i) * 0xD1B54A32D192ED03ull);
    const Vec3i start = exposed[rng.next() % n_exposed];
    const Drift sky = make_drift(random_direction(rng));
    sky_escaped += walk(g, start, sky, params.follow, params.steps - 1, rng);
  }
  const double value = params.sun_weight * (static_cast<double>(sun_escaped) / params.sun_particles) +
                       (1.0 - params.sun_weight) * (static_cast<double>(sky_escaped) / params.sky_particles);
  return static_cast<std::uint8_t>(std::lround(value * 255.0));
}

}  // namespace

std::string validate(const LightingParams& params) {
  const Vec3f d = params.sun_direction;
  if (!(std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z)) || (d.x == 0.0f && d.y == 0.0f && d.z == 0.0f))
    return "sun_direction must be finite and non-zero";
  if (params.sun_particles < 1 || params.sun_particles > 4096) return "sun_particles must be in [1, 4096]";
  if (params.sky_particles < 1 || params.sky_particles > 4096) return "sky_particles must be in [1, 4096]";
  if (params.steps < 1 || params.steps > 256) return "steps must be in [1, 256]";
  if (!(params.follow >= 0.0f && params.follow <= 1.0f)) return "follow must be in [0, 1]";
  if (!(params.sun_weight >= 0.0f && params.sun_weight <= 1.0f)) return "sun_weight must be in [0, 1]";
  return {};
}

std::uint8_t LightMap::at(Vec3i p) const {
  assert(region.contains(p));
  const Vec3i l = p - region.min;
  const Vec3i s = region.size();
  return light[(static_cast<std::size_t>(l.y) * static_cast<std::size_t>(s.z) + static_cast<std::size_t>(l.z)) *
                   static_cast<std::size_t>(s.x) +
               static_cast<std::size_t>(l.x)];
}

bool is_surface_fragment(const Box& fine, Vec3i local) {
  const Vec3i s = fine.size();
  const auto solid_at = [&](Vec3i p) {
    return p.x >= 0 && p.y >= 0 && p.z >= 0 && p.x < s.x && p.y < s.y && p.z < s.z && enhance_solid(fine.get(p));
  };
  if (!solid_at(local)) return false;
  for (const Vec3i f : kFaces) {
    if (!solid_at(local + f)) return true;
  }
  return false;
}

namespace {

void light_into(const SolidGrid& g, Vec3i origin, const LightingParams& params, const Region& region, LightMap& map,
                const LightProgress& progress) {
  const Region r = intersect(region, map.region);
  if (r.empty()) return;
  const Drift sun = make_drift(params.sun_direction);
  const Vec3i ms = map.region.size();
  const std::uint64_t total = static_cast<std::uint64_t>(r.volume());
  std::uint64_t done = 0;
  for (std::int32_t y = r.min.y; y < r.max.y; ++y) {
    for (std::int32_t z = r.min.z; z < r.max.z; ++z) {
      std::uint8_t* row =
          map.light.data() + (static_cast<std::size_t>(y - map.region.min.y) * static_cast<std::size_t>(ms.z) +
                              static_cast<std::size_t>(z - map.region.min.z)) *
                                 static_cast<std::size_t>(ms.x);
      for (std::int32_t x = r.min.x; x < r.max.x; ++x) {
        const Vec3i world{x, y, z};
        const Vec3i local = world - origin;
        row[x - map.region.min.x] = g.surface(local) ? light_of(g, local, world, params, sun) : 0;
      }
      done += static_cast<std::uint64_t>(r.max.x - r.min.x);
    }
    if (progress) progress(done, total);
  }
}

}  // namespace

LightMap compute_lighting(const Box& fine, Vec3i origin, const LightingParams& params, const LightProgress& progress) {
  assert(validate(params).empty());
  LightMap map;
  map.region = Region::from_min_size(origin, fine.size());
  map.light.assign(fine.voxel_count(), 0);
  const SolidGrid g(fine);
  light_into(g, origin, params, map.region, map, progress);
  return map;
}

void light_region(const Box& fine, Vec3i origin, const LightingParams& params, const Region& region, LightMap& map) {
  assert(validate(params).empty());
  const SolidGrid g(fine);
  light_into(g, origin, params, region, map, {});
}

Region lighting_affected_region(const Region& changed, const LightingParams& params) {
  const Vec3i n{params.steps, params.steps, params.steps};
  return {changed.min - n, changed.max + n};
}

Region relight(const Box& fine, Vec3i origin, const LightingParams& params, const Region& changed, LightMap& map) {
  const Region r = intersect(lighting_affected_region(changed, params), map.region);
  if (!r.empty()) light_region(fine, origin, params, r, map);
  return r;
}

}  // namespace terrane
