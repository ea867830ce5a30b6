// VXRAW reader and writer (format: common/vxraw/VXRAW.md), plain or gzip-compressed.
//
// Readers detect gzip by its magic (1f 8b) and inflate as a stream, never
// producing more than the header promises plus one byte (to notice trailing
// data), so a small hostile file cannot expand into a large allocation. The
// Box is allocated only after the header passed every check, including the
// caller's voxel limit.
//
// Validation: a material byte >= 64 rejects the file (kInvalidValue, offset
// of the first such byte); Air with a non-zero occupancy is normalized to 0
// and counted in VxrawFile::repaired_air. Bytes after the voxels (or after the
// gzip member) are kTrailingBytes.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/box.h"
#include "common/voxel/vec3.h"

namespace terrane {

inline constexpr std::size_t kVxrawHeaderSize = 32;

struct VxrawLimits {
  std::int64_t max_voxels = std::int64_t{1} << 31;  // sizeX * sizeY * sizeZ must not exceed it
};

struct VxrawFile {
  Vec3i origin;                   // world voxel coordinate of box voxel (0, 0, 0)
  Box box;
  std::uint64_t repaired_air = 0; // Air voxels whose non-zero occupancy was reset to 0
};

// Decodes a VXRAW image held in memory (plain or gzip). DecodeError::offset
// is in the plain VXRAW stream for content errors (magic, sizes, materials,
// truncation, trailing bytes) and in the compressed bytes for gzip errors
// ("gzip data damaged"; a gzip stream that stops early is kTruncated).
Result<VxrawFile> vxraw_decode(std::span<const std::uint8_t> bytes, const VxrawLimits& limits);

// The plain VXRAW image of `box`. Air is written with occupancy 0.
// Precondition: every material < kMaterialCount.
std::vector<std::uint8_t> vxraw_encode(const Box& box, Vec3i origin);


// Reads a VXRAW file (plain or gzip), streaming it straight into the Box.
FileResult<VxrawFile> vxraw_read_file(const std::string& path, const VxrawLimits& limits);

// Writes `box` to `path`, gzip-compressed if `gzip`. The data goes to a
// temporary file in the same directory, is flushed to disk, then renamed over
// `path`, so a crash leaves either the old file or the complete new one.
FileStatus vxraw_write_file(const std::string& path, const Box& box, Vec3i origin, bool gzip);

}  // namespace terrane
