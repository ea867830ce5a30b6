// Small, seedable gradient noise for the terrain generator.
//
// Everything here is a pure function of its arguments: lattice corners are
// picked by an integer hash of (cell coordinates, seed), so the same inputs
// give the same bits on every machine. Only +, -, *, / and floor are used on
// floating point values (all exactly rounded under IEEE-754), never libm
// transcendentals whose last bits differ between C libraries.
//
// Coordinates come in as doubles already divided by the feature period, so a
// far-away voxel (|x| ~ 1e8) still gets a precise fractional part; the cell
// index wraps modulo 2^32, which only repeats the pattern after 4 billion
// periods.
#pragma once

#include <cmath>
#include <cstdint>

namespace terrane {

// splitmix64 finaliser: a bijective 64-bit mix.
constexpr std::uint64_t mix64(std::uint64_t z) {
  z ^= z >> 30;
  z *= 0xBF58476D1CE4E5B9ull;
  z ^= z >> 27;
  z *= 0x94D049BB133111EBull;
  z ^= z >> 31;
  return z;
}

// An independent 32-bit seed for noise stream `stream` of a world seed, so
// each field (height, caves, ...) gets its own uncorrelated pattern.
constexpr std::uint32_t derive_seed(std::uint64_t world_seed, std::uint32_t stream) {
  return static_cast<std::uint32_t>(mix64(world_seed * 0x9E3779B97F4A7C15ull + stream + 1) >> 32);
}

// Integer hashes of lattice coordinates (lowbias32 finaliser after a
// multiply-xor combine). Well distributed in every bit.
constexpr std::uint32_t hash_u32(std::uint32_t h) {
  h ^= h >> 16;
  h *= 0x7FEB352Du;
  h ^= h >> 15;
  h *= 0x846CA68Bu;
  h ^= h >> 16;
  return h;
}
constexpr std::uint32_t hash2(std::int32_t x, std::int32_t z, std::uint32_t seed) {
  return hash_u32(seed ^ (static_cast<std::uint32_t>(x) * 0x8DA6B343u) ^
                  (static_cast<std::uint32_t>(z) * 0xCB1AB31Fu));
}
constexpr std::uint32_t hash3(std::int32_t x, std::int32_t y, std::int32_t z, std::uint32_t seed) {
  return hash_u32(seed ^ (static_cast<std::uint32_t>(x) * 0x8DA6B343u) ^
                  (static_cast<std::uint32_t>(y) * 0xD8163841u) ^
                  (static_cast<std::uint32_t>(z) * 0xCB1AB31Fu));
}

// A hash mapped to [0, 1) with 24 bits (exact in a float).
constexpr float hash_unit(std::uint32_t h) { return static_cast<float>(h >> 8) * (1.0f / 16777216.0f); }

// Linear interpolation from a (t = 0) to b (t = 1), as the noise and the
// terrain built on it compute it.
constexpr float lerp(float a, float b, float t) { return a + (b - a) * t; }

namespace noise_detail {

// Quintic fade 6t^5 - 15t^4 + 10t^3: C2-continuous, so interpolated noise has
// no visible creases.
constexpr float fade(float t) { return t * t * t * (t * (t * 6.0f - 15.0f) + 10.0f); }

// Splits a coordinate into a wrapped 32-bit cell index and the fraction in it.
inline void split(double v, std::int32_t& cell, float& frac) {
  const double f = std::floor(v);
  cell = static_cast<std::int32_t>(static_cast<std::int64_t>(f));  // modular since C++20
  frac = static_cast<float>(v - f);
}

// 8 gradient directions for 2D: axes and diagonals, dotted with the offset.
constexpr float grad2(std::uint32_t h, float x, float z) {
  switch (h & 7u) {
    case 0: return x + z;
    case 1: return -x + z;
    case 2: return x - z;
    case 3: return -x - z;
    case 4: return x * 1.41421356f;
    case 5: return -x * 1.41421356f;
    case 6: return z * 1.41421356f;
    default: return -z * 1.41421356f;
  }
}

// Perlin's 12 cube-edge gradients (16 entries with 4 repeated).
constexpr float grad3(std::uint32_t h, float x, float y, float z) {
  switch (h & 15u) {
    case 0: case 12: return x + y;
    case 1: case 13: return -x + y;
    case 2: return x - y;
    case 3: return -x - y;
    case 4: return x + z;
    case 5: return -x + z;
    case 6: return x - z;
    case 7: return -x - z;
    case 8: return y + z;
    case 9: case 14: return -y + z;
    case 10: return y - z;
    default: return -y - z;  // 11, 15
  }
}

}  // namespace noise_detail

// 2D gradient noise at (x, z) in cell units. Zero at every lattice point,
// range within about [-1, 1]; the typical magnitude is about 0.25.
inline float gradient_noise2(double x, double z, std::uint32_t seed) {
  using namespace noise_detail;
  std::int32_t ix, iz;
  float fx, fz;
  split(x, ix, fx);
  split(z, iz, fz);
  const float n00 = grad2(hash2(ix, iz, seed), fx, fz);
  const float n10 = grad2(hash2(ix + 1, iz, seed), fx - 1.0f, fz);
  const float n01 = grad2(hash2(ix, iz + 1, seed), fx, fz - 1.0f);
  const float n11 = grad2(hash2(ix + 1, iz + 1, seed), fx - 1.0f, fz - 1.0f);
  const float u = fade(fx), w = fade(fz);
  return lerp(lerp(n00, n10, u), lerp(n01, n11, u), w) * 0.7071f;
}

// 3D gradient noise (improved Perlin) in cell units, range within about
// [-1, 1], typical magnitude about 0.25.
inline float gradient_noise3(double x, double y, double z, std::uint32_t seed) {
  using namespace noise_detail;
  std::int32_t ix, iy, iz;
  float fx, fy, fz;
  split(x, ix, fx);
  split(y, iy, fy);
  split(z, iz, fz);
  const float u = fade(fx), v = fade(fy), w = fade(fz);
  const float n000 = grad3(hash3(ix, iy, iz, seed), fx, fy, fz);
  const float n100 = grad3(hash3(ix + 1, iy, iz, seed), fx - 1.0f, fy, fz);
  const float n010 = grad3(hash3(ix, iy + 1, iz, seed), fx, fy - 1.0f, fz);
  const float n110 = grad3(hash3(ix + 1, iy + 1, iz, seed), fx - 1.0f, fy - 1.0f, fz);
  const float n001 = grad3(hash3(ix, iy, iz + 1, seed), fx, fy, fz - 1.0f);
  const float n101 = grad3(hash3(ix + 1, iy, iz + 1, seed), fx - 1.0f, fy, fz - 1.0f);
  const float n011 = grad3(hash3(ix, iy + 1, iz + 1, seed), fx, fy - 1.0f, fz - 1.0f);
  const float n111 = grad3(hash3(ix + 1, iy + 1, iz + 1, seed), fx - 1.0f, fy - 1.0f, fz - 1.0f);
  const float y0 = lerp(lerp(n000, n100, u), lerp(n010, n110, u), v);
  const float y1 = lerp(lerp(n001, n101, u), lerp(n011, n111, u), v);
  return lerp(y0, y1, w);
}

// Fractal sums: `octaves` layers, each at twice the frequency and half the
// amplitude of the previous one, normalised by the total amplitude so the
// result stays within about [-1, 1]. Each octave uses its own seed so
// octaves do not line up at the origin. Precondition: 1 <= octaves <= 16.
float fbm2(double x, double z, std::uint32_t seed, int octaves);
float fbm3(double x, double y, double z, std::uint32_t seed, int octaves);

// Ridged fractal in [0, 1]: sum of (1 - |n|)^2, sharp crests where the noise
// crosses zero and smooth valleys in between, weighted so that rough detail
// follows the crests (each octave is scaled by the previous one's value).
float ridged2(double x, double z, std::uint32_t seed, int octaves);

// Hermite smoothstep of x between edges e0 < e1, clamped to [0, 1].
constexpr float smoothstep(float e0, float e1, float x) {
  float t = (x - e0) / (e1 - e0);
  t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
  return t * t * (3.0f - 2.0f * t);
}

constexpr float clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }

}  // namespace terrane
