#include "common/codec/byte_rle.h"

#include <bit>
#include <cassert>
#include <cstring>

namespace terrane {
namespace {

// A voxel's two bytes as one 16-bit lane, and four lanes as one word: run
// scanning compares four voxels per load, run filling stores four per store.
// Both are built with memcpy of the same bytes, so they are endian-neutral;
// only the "which lane differed first" step below looks at byte order.
std::uint16_t lane_of(Voxel v) {
  std::uint16_t lane;
  std::memcpy(&lane, &v, sizeof lane);
  return lane;
}

std::uint64_t word_of(Voxel v) { return std::uint64_t{lane_of(v)} * 0x0001000100010001ull; }

// Number of voxels equal to the word's lanes at the start of [p, end).
std::size_t run_length(const Voxel* p, const Voxel* end, std::uint64_t pattern) {
  const Voxel* q = p;
  while (end - q >= 4) {
    std::uint64_t w;
    std::memcpy(&w, q, sizeof w);
    const std::uint64_t diff = w ^ pattern;
    if (diff != 0) {
      const int bit = std::endian::native == std::endian::little ? std::countr_zero(diff)
                                                                  : std::countl_zero(diff);
      return static_cast<std::size_t>(q - p) + static_cast<std::size_t>(bit / 16);
    }
    q += 4;
  }
  std::uint16_t lane;
  std::memcpy(&lane, &pattern, sizeof lane);
  while (q != end && lane_of(*q) == lane) ++q;
  return static_cast<std::size_t>(q - p);
}

// Writes `len` copies of the voxel whose lanes fill `pattern`.
void fill_run(Voxel* dst, std::size_t len, std::uint64_t pattern) {
  if (len >= 4) {
    std::size_t i = 0;
    for (; len - i >= 8; i += 8) {
      std::memcpy(dst + i, &pattern, 8);
      std::memcpy(dst + i + 4, &pattern, 8);
    }
    if (len - i >= 4) std::memcpy(dst + i, &pattern, 8);
    std::memcpy(dst + len - 4, &pattern, 8);  // overlapping tail store
    return;
  }
  for (std::size_t i = 0; i < len; ++i) std::memcpy(dst + i, &pattern, 2);
}

// The fixed part of a run of one voxel value in the canonical encoding.
struct RunHeader {
  std::uint8_t lead_base;  // material | occupancy bit
  std::uint8_t occupancy;  // written when the occupancy bit is set
};

RunHeader run_header(Voxel v) {
  assert(v.material < kMaterialCount);
  const auto material = static_cast<std::uint8_t>(v.material & kByteRleMaterialMask);
  const bool has_occupancy = material != kAir && v.occupancy != kFullOccupancy;
  return {static_cast<std::uint8_t>(material | (has_occupancy ? kByteRleOccupancyBit : 0)),
          v.occupancy};
}

// Writes runs of total length `len` (any size) at `o`; returns the new end.
// Needs room for 3 bytes per started 256 voxels.
std::uint8_t* write_runs(std::uint8_t* o, RunHeader h, std::size_t len) {
  const bool has_occupancy = (h.lead_base & kByteRleOccupancyBit) != 0;
  while (len > 0) {
    const std::size_t n = len < kByteRleMaxRun ? len : kByteRleMaxRun;
    len -= n;
    if (n == 1) {
      *o++ = h.lead_base;
      if (has_occupancy) *o++ = h.occupancy;
    } else {
      *o++ = static_cast<std::uint8_t>(h.lead_base | kByteRleCountBit);
      if (has_occupancy) *o++ = h.occupancy;
      *o++ = static_cast<std::uint8_t>(n - 1);
    }
  }
  return o;
}

}  // namespace

std::size_t byte_rle_encode_to(std::span<const Voxel> voxels, std::span<std::uint8_t> out) {
  assert(out.size() >= byte_rle_max_encoded_size(voxels.size()));
  const Voxel* p = voxels.data();
  const Voxel* const end = p + voxels.size();
  std::uint8_t* o = out.data();
  while (p != end) {
    const Voxel v = *p;
    const std::size_t len = 1 + run_length(p + 1, end, word_of(v));
    o = write_runs(o, run_header(v), len);
    p += len;
  }
  return static_cast<std::size_t>(o - out.data());
}

void byte_rle_encode(std::span<const Voxel> voxels, std::vector<std::uint8_t>& out) {
  // Encode through a stack buffer and append in blocks: growing `out` to the
  // worst-case bound first would zero-fill 2 bytes per voxel, which costs more
  // than encoding a typical chunk.
  constexpr std::size_t kBlock = 4096;
  std::uint8_t buf[kBlock];
  std::uint8_t* o = buf;
  const Voxel* p = voxels.data();
  const Voxel* const end = p + voxels.size();
  while (p != end) {
    const Voxel v = *p;
    std::size_t len = 1 + run_length(p + 1, end, word_of(v));
    p += len;
    const RunHeader h = run_header(v);
    while (len > 0) {
      // Up to 3 bytes per 256 voxels; cut the run so its bytes fit.
      std::size_t room = static_cast<std::size_t>(buf + kBlock - o) / 3;
      if (room == 0) {
        out.insert(out.end(), buf, o);
        o = buf;
        room = kBlock / 3;
      }
      const std::size_t take = len < room * kByteRleMaxRun ? len : room * kByteRleMaxRun;
      o = write_runs(o, h, take);
      len -= take;
    }
  }
  out.insert(out.end(), buf, o);
}

Status byte_rle_decode(std::span<const std::uint8_t> in, std::span<Voxel> out) {
  const std::uint8_t* const begin = in.data();
  const std::uint8_t* cur = begin;
  const std::uint8_t* const end = begin + in.size();
  Voxel* o = out.data();
  Voxel* const out_end = o + out.size();
  auto at = [&](const std::uint8_t* p) { return static_cast<std::size_t>(p - begin); };

  // Fast path, while a whole run's bytes (at most 3) are in the input and a
  // whole run (at most 256 voxels) plus its spill fits in the output: read
  // the fields without per-field checks and fill in 16-voxel blocks, letting
  // the last block spill past the run (the next run overwrites the spill).
  // Anything unusual leaves for the checked loop below, which re-reads the
  // run and reports the exact error.
  constexpr std::size_t kFillBlock = 16;
  while (end - cur >= 3 && static_cast<std::size_t>(out_end - o) >= kByteRleMaxRun + kFillBlock) {
    const std::uint8_t lead = cur[0];
    const unsigned has_occupancy = (lead >> 6) & 1u;
    const unsigned has_count = lead >> 7;
    const auto material = static_cast<Material>(lead & kByteRleMaterialMask);
    const std::uint8_t count = cur[1 + has_occupancy];
    if (((has_occupancy & static_cast<unsigned>(material == kAir)) | (has_count & static_cast<unsigned>(count == 0))) != 0) {
      break;
    }
    const std::uint8_t occupancy = has_occupancy != 0 ? cur[1] : default_occupancy(material);
    const std::size_t len = has_count != 0 ? std::size_t{count} + 1 : 1;
    cur += 1 + has_occupancy + has_count;
    const std::uint64_t pattern = word_of(Voxel{material, occupancy});
    const std::uint64_t block[4] = {pattern, pattern, pattern, pattern};
    static_assert(sizeof block == kFillBlock * sizeof(Voxel));
    for (std::size_t i = 0; i < len; i += kFillBlock) std::memcpy(o + i, block, sizeof block);
    o += len;
  }

  while (o != out_end) {
    if (cur == end) return DecodeError{DecodeErrorCode::kTruncated, at(cur), "input ends before the output is full"};
    const std::uint8_t* const run_start = cur;
    const std::uint8_t lead = *cur++;
    const auto material = static_cast<Material>(lead & kByteRleMaterialMask);
    std::uint8_t occupancy = default_occupancy(material);
    if ((lead & kByteRleOccupancyBit) != 0) {
      if (material == kAir) return DecodeError{DecodeErrorCode::kInvalidValue, at(run_start), "Air run with an occupancy byte"};
      if (cur == end) return DecodeError{DecodeErrorCode::kTruncated, at(cur), "missing occupancy byte"};
      occupancy = *cur++;
    }
    std::size_t len = 1;
    if ((lead & kByteRleCountBit) != 0) {
      if (cur == end) return DecodeError{DecodeErrorCode::kTruncated, at(cur), "missing count byte"};
      if (*cur == 0) return DecodeError{DecodeErrorCode::kInvalidValue, at(cur), "count byte 0 is reserved"};
      len = std::size_t{*cur++} + 1;
    }
    if (len > static_cast<std::size_t>(out_end - o)) {
      return DecodeError{DecodeErrorCode::kOverLimit, at(run_start), "run reaches past the end of the output"};
    }
    fill_run(o, len, word_of(Voxel{material, occupancy}));
    o += len;
  }
  if (cur != end) return DecodeError{DecodeErrorCode::kTrailingBytes, at(cur), "bytes after the last voxel"};
  return Ok{};
}

}  // namespace terrane
