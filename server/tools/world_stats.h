// The world tool's `stats`: the storage article's results table for a box of
// a world — voxels, non-empty voxels, share of non-empty voxels with partial
// occupancy, materials — then, for every codec and memory format, total
// bytes and bytes per voxel and per non-empty voxel, plus codec speeds.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/voxel/box.h"
#include "common/voxel/vec3.h"

namespace terrane {

struct CodecFigures {
  std::string name;
  std::uint64_t bytes = 0;
  double encode_mb_s = 0;  // MB of raw voxels (2 bytes each) per second; 0 for memory formats
  double decode_mb_s = 0;
  std::uint64_t units = 0;  // units encoded (0 for memory formats)
  bool is_codec = true;
};

struct BoxStats {
  Region box;
  std::uint64_t voxels = 0;
  std::uint64_t non_empty_voxels = 0;
  std::uint64_t partial_occupancy_voxels = 0;
  int materials = 0;
  std::vector<CodecFigures> codecs;
};

// Measures `content` (the voxels of `box`). Units tile the box from its min
// corner; units that stick out past the box are padded with Air (the padding
// is not counted in voxels). Every unit counts what its codec really
// spends, all-Air units included.
BoxStats measure_box(const Region& box, const Box& content);

std::string stats_table(const BoxStats& s);
std::string stats_json(const BoxStats& s);

}  // namespace terrane
