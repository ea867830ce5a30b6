#include "server/tools/world_stats.h"

#include <chrono>
#include <cstdio>
#include <sstream>

#include "common/codec/byte_rle.h"
#include "common/codec/lz4_block.h"
#include "common/codec/net_codec.h"
#include "common/voxel/grid.h"
#include "server/base/chunk_version.h"

namespace terrane {

namespace {

using Clock = std::chrono::steady_clock;

// Cuts content into n³ units (Air-padded at the far edges).
std::vector<Box> cut_units(const Box& content, int n) {
  const Vec3i s = content.size();
  std::vector<Box> units;
  for (int y0 = 0; y0 < s.y; y0 += n)
    for (int z0 = 0; z0 < s.z; z0 += n)
      for (int x0 = 0; x0 < s.x; x0 += n) {
        Box u({n, n, n});
        const int nx = std::min(n, s.x - x0), ny = std::min(n, s.y - y0), nz = std::min(n, s.z - z0);
        for (int y = 0; y < ny; ++y)
          for (int z = 0; z < nz; ++z) std::copy_n(content.read_row(y0 + y, z0 + z) + x0, nx, u.write_row(y, z));
        units.push_back(std::move(u));
      }
  return units;
}

template <class Encode, class Decode>
CodecFigures measure_codec(const std::string& name, const std::vector<Box>& units, Encode&& encode,
                           Decode&& decode) {
  CodecFigures f;
  f.name = name;
  f.units = units.size();
  std::vector<std::vector<std::uint8_t>> encoded(units.size());
  std::uint64_t raw_bytes = 0;
  const auto t0 = Clock::now();
  for (std::size_t i = 0; i < units.size(); ++i) {
    encode(units[i], encoded[i]);
    raw_bytes += units[i].voxel_count() * sizeof(Voxel);
  }
  const auto t1 = Clock::now();
  for (const auto& e : encoded) f.bytes += e.size();
  Box out;
  bool ok = true;
  const auto t2 = Clock::now();
  for (std::size_t i = 0; i < units.size(); ++i) {
    out.resize(units[i].size());
    ok &= decode(encoded[i], out);
  }
  const auto t3 = Clock::now();
  // Check the round trip outside the timed loop.
  for (std::size_t i = 0; ok && i < units.size(); i += 97) {
    out.resize(units[i].size());
    ok &= decode(encoded[i], out) && out == units[i];
  }
  if (!ok) std::fprintf(stderr, "stats: codec %s failed to round-trip\n", name.c_str());
  const double mb = static_cast<double>(raw_bytes) / 1e6;
  f.encode_mb_s = mb / std::max(1e-9, std::chrono::duration<double>(t1 - t0).count());
  f.decode_mb_s = mb / std::max(1e-9, std::chrono::duration<double>(t3 - t2).count());
  return f;
}

}  // namespace

BoxStats measure_box(const Region& box, const Box& content) {
  BoxStats s;
  s.box = box;
  s.voxels = content.voxel_count();
  bool seen[kMaterialCount] = {};
  for (const Voxel v : content.voxels()) {
    if (v.material == kAir) continue;
    ++s.non_empty_voxels;
    s.partial_occupancy_voxels += v.occupancy != kFullOccupancy;
    seen[v.material] = true;
  }
  for (bool b : seen) s.materials += b;

  {
    const std::vector<Box> chunks = cut_units(content, 32);
    s.codecs.push_back(measure_codec(
        "disk_rle", chunks, [](const Box& u, std::vector<std::uint8_t>& e) { byte_rle_encode(u.voxels(), e); },
        [](const std::vector<std::uint8_t>& e, Box& o) { return byte_rle_decode(e, o.voxels()).ok(); }));
    s.codecs.push_back(measure_codec(
        "disk_rle_lz4", chunks,
        [](const Box& u, std::vector<std::uint8_t>& e) { byte_rle_lz4_encode(u.voxels(), e); },
        [](const std::vector<std::uint8_t>& e, Box& o) { return byte_rle_lz4_decode(e, o.voxels()).ok(); }));
  }
  for (int n : {16, 4}) {
    const std::vector<Box> units = cut_units(content, n);
    s.codecs.push_back(measure_codec(
        "network_" + std::to_string(n), units,
        // What the server sends a client that reads version 2.
        [n](const Box& u, std::vector<std::uint8_t>& e) { net_codec_encode(n, u.voxels(), e, kServedCodecVersion); },
        [n](const std::vector<std::uint8_t>& e, Box& o) { return net_codec_decode(n, e, o.voxels()).ok(); }));
  }

  // Memory: the content in a grid at its world position (chunk-aligned).
  Grid grid;
  grid.write_box(box.min, content);
  grid.compact();
  const GridMemory m = grid.memory();
  constexpr std::size_t kUnpackedChunk = 2 * (32 * 32 * 32 + 16 * 16 * 16 + 8 * 8 * 8 + 4 * 4 * 4);
  CodecFigures unpacked{"memory_unpacked", m.map_bytes + m.object_bytes + m.chunks * kUnpackedChunk, 0, 0, 0, false};
  CodecFigures packed{"memory_row_packed", m.total(), 0, 0, 0, false};
  s.codecs.push_back(unpacked);
  s.codecs.push_back(packed);
  return s;
}

namespace {
double per(std::uint64_t bytes, std::uint64_t n) { return n ? static_cast<double>(bytes) / static_cast<double>(n) : 0.0; }
}  // namespace

std::string stats_table(const BoxStats& s) {
  std::ostringstream o;
  char line[256];
  std::snprintf(line, sizeof line, "box %d,%d,%d .. %d,%d,%d\n", s.box.min.x, s.box.min.y, s.box.min.z, s.box.max.x,
                s.box.max.y, s.box.max.z);
  o << line;
  std::snprintf(line, sizeof line, "voxels               %14llu\n", static_cast<unsigned long long>(s.voxels));
  o << line;
  std::snprintf(line, sizeof line, "non-empty voxels     %14llu  (%.1f%%)\n",
                static_cast<unsigned long long>(s.non_empty_voxels), 100.0 * per(s.non_empty_voxels, s.voxels));
  o << line;
  std::snprintf(line, sizeof line, "partial occupancy    %14.1f%% of non-empty\n",
                100.0 * per(s.partial_occupancy_voxels, s.non_empty_voxels));
  o << line;
  std::snprintf(line, sizeof line, "materials            %14d\n\n", s.materials);
  o << line;
  std::snprintf(line, sizeof line, "%-20s %14s %10s %12s %10s %10s\n", "storage", "bytes", "B/voxel",
                "B/non-empty", "enc MB/s", "dec MB/s");
  o << line;
  for (const CodecFigures& c : s.codecs) {
    if (c.is_codec) {
      std::snprintf(line, sizeof line, "%-20s %14llu %10.4f %12.4f %10.0f %10.0f\n", c.name.c_str(),
                    static_cast<unsigned long long>(c.bytes), per(c.bytes, s.voxels), per(c.bytes, s.non_empty_voxels),
                    c.encode_mb_s, c.decode_mb_s);
    } else {
      std::snprintf(line, sizeof line, "%-20s %14llu %10.4f %12.4f %10s %10s\n", c.name.c_str(),
                    static_cast<unsigned long long>(c.bytes), per(c.bytes, s.voxels), per(c.bytes, s.non_empty_voxels),
                    "-", "-");
    }
    o << line;
  }
  return o.str();
}

std::string stats_json(const BoxStats& s) {
  std::ostringstream o;
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "{\"box\": [%d, %d, %d, %d, %d, %d], \"voxels\": %llu, \"non_empty_voxels\": %llu, "
                "\"partial_occupancy_voxels\": %llu, \"partial_occupancy_share\": %.6f, \"materials\": %d, "
                "\"codecs\": {",
                s.box.min.x, s.box.min.y, s.box.min.z, s.box.max.x, s.box.max.y, s.box.max.z,
                static_cast<unsigned long long>(s.voxels), static_cast<unsigned long long>(s.non_empty_voxels),
                static_cast<unsigned long long>(s.partial_occupancy_voxels),
                per(s.partial_occupancy_voxels, s.non_empty_voxels), s.materials);
  o << buf;
  for (std::size_t i = 0; i < s.codecs.size(); ++i) {
    const CodecFigures& c = s.codecs[i];
    std::snprintf(buf, sizeof buf, "%s\"%s\": {\"bytes\": %llu, \"bytes_per_voxel\": %.6f, \"bytes_per_non_empty_voxel\": %.6f",
                  i ? ", " : "", c.name.c_str(), static_cast<unsigned long long>(c.bytes), per(c.bytes, s.voxels),
                  per(c.bytes, s.non_empty_voxels));
    o << buf;
    if (c.is_codec) {
      std::snprintf(buf, sizeof buf, ", \"encode_mb_s\": %.1f, \"decode_mb_s\": %.1f, \"units\": %llu", c.encode_mb_s,
                    c.decode_mb_s, static_cast<unsigned long long>(c.units));
      o << buf;
    }
    o << "}";
  }
  o << "}}\n";
  return o.str();
}

}  // namespace terrane
