// The reference point for network bytes: a Minecraft-style paletted section
// of voxels, as the chunk packets of Minecraft-like servers carry them.
//
//   [palette count u16][palette entries: material, occupancy]
//   [indices at max(4, ceil(log2 count)) bits in 64-bit words, no index
//    spanning two words]; a single-value unit has no indices.
//
// The benchmarks compress the whole section with zlib level 6.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "common/voxel/voxel.h"

namespace terrane {

// Writes the section of v into out (cleared first).
inline void paletted_section(std::span<const Voxel> v, std::vector<std::uint8_t>& out) {
  std::array<int, 65536> index;  // NOLINT: only entries of seen keys are read
  std::vector<std::uint16_t> pal;
  std::vector<std::uint16_t> idx(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) {
    const auto key = static_cast<std::uint16_t>(v[i].material | (v[i].occupancy << 8));
    bool found = false;
    for (const std::uint16_t p : pal) {
      if (p == key) {
        found = true;
        break;
      }
    }
    if (!found) {
      index[key] = static_cast<int>(pal.size());
      pal.push_back(key);
    }
    idx[i] = static_cast<std::uint16_t>(index[key]);
  }
  out.clear();
  out.push_back(static_cast<std::uint8_t>(pal.size() & 0xFF));
  out.push_back(static_cast<std::uint8_t>(pal.size() >> 8));
  for (const std::uint16_t p : pal) {
    out.push_back(static_cast<std::uint8_t>(p & 0xFF));
    out.push_back(static_cast<std::uint8_t>(p >> 8));
  }
  if (pal.size() <= 1) return;
  int bits = 4;
  while ((std::size_t{1} << bits) < pal.size()) ++bits;
  const int per_word = 64 / bits;
  for (std::size_t i = 0; i < idx.size(); i += static_cast<std::size_t>(per_word)) {
    std::uint64_t w = 0;
    for (int k = 0; k < per_word && i + static_cast<std::size_t>(k) < idx.size(); ++k)
      w |= std::uint64_t{idx[i + static_cast<std::size_t>(k)]} << (k * bits);
    for (int b = 0; b < 8; ++b) out.push_back(static_cast<std::uint8_t>(w >> (8 * b)));
  }
}

}  // namespace terrane
