// Integer and float 3-vectors, coordinate conversions between voxel and chunk
// spaces (floor division, so negative coordinates work), and half-open boxes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <functional>

namespace terrane {

struct Vec3i {
  std::int32_t x = 0, y = 0, z = 0;

  friend constexpr bool operator==(Vec3i, Vec3i) = default;
  friend constexpr Vec3i operator+(Vec3i a, Vec3i b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
  friend constexpr Vec3i operator-(Vec3i a, Vec3i b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
  friend constexpr Vec3i operator*(Vec3i a, std::int32_t s) { return {a.x * s, a.y * s, a.z * s}; }
};

struct Vec3f {
  float x = 0, y = 0, z = 0;

  friend constexpr bool operator==(Vec3f, Vec3f) = default;
  friend constexpr Vec3f operator+(Vec3f a, Vec3f b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
  friend constexpr Vec3f operator-(Vec3f a, Vec3f b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
  friend constexpr Vec3f operator*(Vec3f a, float s) { return {a.x * s, a.y * s, a.z * s}; }
};

// Floor division and its non-negative remainder, for any sign of a.
// Precondition: b > 0.
constexpr std::int32_t floor_div(std::int32_t a, std::int32_t b) {
  const std::int32_t q = a / b;
  return (a % b != 0 && a < 0) ? q - 1 : q;
}
constexpr std::int32_t floor_mod(std::int32_t a, std::int32_t b) { return a - floor_div(a, b) * b; }

constexpr Vec3i floor_div(Vec3i a, std::int32_t b) {
  return {floor_div(a.x, b), floor_div(a.y, b), floor_div(a.z, b)};
}
constexpr Vec3i floor_mod(Vec3i a, std::int32_t b) {
  return {floor_mod(a.x, b), floor_mod(a.y, b), floor_mod(a.z, b)};
}

constexpr Vec3i min3(Vec3i a, Vec3i b) {
  return {a.x < b.x ? a.x : b.x, a.y < b.y ? a.y : b.y, a.z < b.z ? a.z : b.z};
}
constexpr Vec3i max3(Vec3i a, Vec3i b) {
  return {a.x > b.x ? a.x : b.x, a.y > b.y ? a.y : b.y, a.z > b.z ? a.z : b.z};
}

// A half-open box of voxel coordinates: min inclusive, max exclusive.
struct Region {
  Vec3i min;
  Vec3i max;

  friend constexpr bool operator==(const Region&, const Region&) = default;
  constexpr Vec3i size() const { return max - min; }
  constexpr bool empty() const { return max.x <= min.x || max.y <= min.y || max.z <= min.z; }
  constexpr bool contains(Vec3i p) const {
    return p.x >= min.x && p.y >= min.y && p.z >= min.z && p.x < max.x && p.y < max.y && p.z < max.z;
  }
  // Voxel count as 64-bit (a region can be larger than 2^31 voxels),
  // saturating at INT64_MAX for regions too large to count (any span is at
  // most 2^32, so three of them can overflow 64 bits).
  constexpr std::int64_t volume() const {
    if (empty()) return 0;
    const std::int64_t dx = std::int64_t{max.x} - min.x, dy = std::int64_t{max.y} - min.y,
                       dz = std::int64_t{max.z} - min.z;
    std::int64_t xy = 0, xyz = 0;
    if (__builtin_mul_overflow(dx, dy, &xy) || __builtin_mul_overflow(xy, dz, &xyz))
      return std::numeric_limits<std::int64_t>::max();
    return xyz;
  }
  static constexpr Region from_min_size(Vec3i min, Vec3i size) { return {min, min + size}; }
};

constexpr Region intersect(const Region& a, const Region& b) { return {max3(a.min, b.min), min3(a.max, b.max)}; }

struct Vec3iHash {
  std::size_t operator()(Vec3i v) const noexcept {
    // 64-bit mix of the three coordinates (splitmix-style finaliser).
    std::uint64_t h = static_cast<std::uint32_t>(v.x);
    h = h * 0x9E3779B97F4A7C15ull ^ static_cast<std::uint32_t>(v.y);
    h = h * 0xBF58476D1CE4E5B9ull ^ static_cast<std::uint32_t>(v.z);
    h ^= h >> 31;
    h *= 0x94D049BB133111EBull;
    h ^= h >> 29;
    return static_cast<std::size_t>(h);
  }
};

}  // namespace terrane
