#include "common/world/view.h"

#include <algorithm>
#include <limits>
#include <tuple>

namespace terrane {

namespace {

// The offsets within radius whose y is in [y_lo, y_hi], nearest first.
// The order's key is the centre-to-centre distance, 1024 (x^2 + y^2 + z^2),
// then (y, z, x): a counting sort on s = x^2 + y^2 + z^2 over offsets made
// in (y, z, x) order keeps that order within each s, so the whole order
// costs two passes over the cube, not a comparison sort (1.1 million
// offsets at view 2,048: 190 ms sorted by comparisons).
std::vector<Vec3i> offsets_nearest_first(std::int32_t radius, std::int32_t y_lo, std::int32_t y_hi) {
  const std::int32_t n = (std::max(radius, 0) + kChunkSize / 2) / kChunkSize;
  y_lo = std::max(y_lo, -n);
  y_hi = std::min(y_hi, n);
  if (y_lo > y_hi) return {};
  const std::size_t nn = static_cast<std::size_t>(n);
  std::vector<std::size_t> first(3 * nn * nn + 2, 0);
  auto each = [&](auto&& fn) {
    for (std::int32_t y = y_lo; y <= y_hi; ++y)
      for (std::int32_t z = -n; z <= n; ++z)
        for (std::int32_t x = -n; x <= n; ++x)
          if (offset_within({x, y, z}, radius))
            fn(Vec3i{x, y, z}, static_cast<std::size_t>(std::int64_t{x} * x + std::int64_t{y} * y + std::int64_t{z} * z));
  };
  each([&](Vec3i, std::size_t s) { ++first[s + 1]; });
  for (std::size_t s = 1; s < first.size(); ++s) first[s] += first[s - 1];
  std::vector<Vec3i> out(first.back());
  each([&](Vec3i o, std::size_t s) { out[first[s]++] = o; });
  return out;
}

}  // namespace

std::vector<Vec3i> view_offsets(std::int32_t radius) {
  return offsets_nearest_first(radius, std::numeric_limits<std::int32_t>::min(), std::numeric_limits<std::int32_t>::max());
}

std::vector<Vec3i> chunks_in_view(Vec3f position, std::int32_t radius, const WorldBounds& bounds) {
  const Vec3i c = view_chunk(position);
  // Only the layers of chunks within the world's vertical range.
  const std::int32_t lo = floor_div(bounds.min_y, kChunkSize) - c.y;
  const std::int32_t hi = floor_div(bounds.max_y - 1, kChunkSize) - c.y;
  std::vector<Vec3i> out;
  for (const Vec3i o : offsets_nearest_first(radius, lo, hi)) {
    const Vec3i cp = c + o;
    if (bounds.touches_chunk(cp)) out.push_back(cp);
  }
  return out;
}

}  // namespace terrane
