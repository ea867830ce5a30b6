// Update batches of the network voxel codec, format version 1 (see
// common/codec/NET_CODEC.md, "Update batches").
#include "common/codec/update_batch.h"

#include <algorithm>

#include "common/codec/bit_io.h"
#include "common/voxel/chunk.h"

namespace terrane {
namespace {

// Reads a LEB128 varint of at most 5 bytes that fits 32 bits.
Status get_varint32(std::span<const std::uint8_t> bytes, std::size_t& pos, std::uint32_t& v) {
  std::uint64_t x = 0;
  const VarintRead r = get_varint(bytes, pos, 5, x);
  if (r == VarintRead::kTruncated) return DecodeError{DecodeErrorCode::kTruncated, pos, "varint cut short"};
  // Reported at the fifth byte: it has the top bit or bits above the 32nd set.
  if (r == VarintRead::kTooLong || x > 0xFFFFFFFFu) {
    return DecodeError{DecodeErrorCode::kInvalidValue, pos - 1, "varint over 32 bits"};
  }
  v = static_cast<std::uint32_t>(x);
  return Ok{};
}

}  // namespace

bool update_batch_order(const UnitUpdate& a, const UnitUpdate& b) {
  if (a.chunk_pos.y != b.chunk_pos.y) return a.chunk_pos.y < b.chunk_pos.y;
  if (a.chunk_pos.z != b.chunk_pos.z) return a.chunk_pos.z < b.chunk_pos.z;
  if (a.chunk_pos.x != b.chunk_pos.x) return a.chunk_pos.x < b.chunk_pos.x;
  return a.unit_index < b.unit_index;
}

void net_codec_put_update_coords(Vec3i chunk_pos, int unit_index, Vec3i prev_chunk, int prev_unit,
                                 std::vector<std::uint8_t>& out) {
  if (chunk_pos == prev_chunk && unit_index > prev_unit) {
    put_varint((static_cast<std::uint32_t>(unit_index - prev_unit - 1) << 1) | 1u, out);
    return;
  }
  put_varint(static_cast<std::uint32_t>(unit_index) << 1, out);
  // Deltas wrap modulo 2^32 so any pair of int32 coordinates round-trips.
  auto delta = [](std::int32_t a, std::int32_t b) {
    return static_cast<std::int32_t>(static_cast<std::uint32_t>(a) - static_cast<std::uint32_t>(b));
  };
  put_varint(zigzag(delta(chunk_pos.x, prev_chunk.x)), out);
  put_varint(zigzag(delta(chunk_pos.y, prev_chunk.y)), out);
  put_varint(zigzag(delta(chunk_pos.z, prev_chunk.z)), out);
}

void net_codec_encode_update_batch(std::span<const UnitUpdate> updates, std::vector<std::uint8_t>& out,
                                   std::uint8_t codec_version) {
  std::vector<const UnitUpdate*> sorted;
  sorted.reserve(updates.size());
  for (const UnitUpdate& u : updates) sorted.push_back(&u);
  std::stable_sort(sorted.begin(), sorted.end(), [](const UnitUpdate* a, const UnitUpdate* b) { return update_batch_order(*a, *b); });
  out.push_back(kUpdateBatchVersion);
  put_varint(static_cast<std::uint32_t>(sorted.size()), out);
  Vec3i prev_chunk{};
  int prev_unit = -1;
  for (const UnitUpdate* u : sorted) {
    net_codec_put_update_coords(u->chunk_pos, u->unit_index, prev_chunk, prev_unit, out);
    net_codec_encode(kUpdateUnitSize, u->voxels, out, codec_version);
    prev_chunk = u->chunk_pos;
    prev_unit = u->unit_index;
  }
}

UpdatePiece net_codec_encode_update_piece(std::span<const UnitUpdate> units, std::uint8_t codec_version) {
  std::vector<const UnitUpdate*> sorted;
  sorted.reserve(units.size());
  for (const UnitUpdate& u : units) sorted.push_back(&u);
  std::sort(sorted.begin(), sorted.end(),
            [](const UnitUpdate* a, const UnitUpdate* b) { return a->unit_index < b->unit_index; });
  UpdatePiece p;
  p.chunk_pos = sorted.front()->chunk_pos;
  p.first_unit = sorted.front()->unit_index;
  p.count = static_cast<std::uint32_t>(sorted.size());
  int prev = -1;
  for (const UnitUpdate* u : sorted) {
    if (prev >= 0) net_codec_put_update_coords(p.chunk_pos, u->unit_index, p.chunk_pos, prev, p.rest);
    net_codec_encode(kUpdateUnitSize, u->voxels, p.rest, codec_version);
    prev = u->unit_index;
  }
  return p;
}

void net_codec_join_update_pieces(std::span<const UpdatePiece* const> pieces, std::vector<std::uint8_t>& out) {
  net_codec_join_update_pieces(pieces, out, [&](std::size_t, std::span<const std::uint8_t> rest) {
    out.insert(out.end(), rest.begin(), rest.end());
  });
}

Result<std::size_t> net_codec_decode_update_batch(std::span<const std::uint8_t> bytes, std::span<UnitUpdate> out) {
  if (bytes.empty()) return DecodeError{DecodeErrorCode::kTruncated, 0, "empty batch"};
  if (bytes[0] != kUpdateBatchVersion) return DecodeError{DecodeErrorCode::kBadVersion, 0, "unknown batch version"};
  std::size_t pos = 1;
  std::uint32_t count = 0;
  if (auto s = get_varint32(bytes, pos, count); !s) return s.error();
  if (count > out.size()) return DecodeError{DecodeErrorCode::kOverLimit, 1, "more updates than the caller allows"};
  Vec3i prev_chunk{};
  int prev_unit = -1;
  for (std::uint32_t e = 0; e < count; ++e) {
    UnitUpdate& u = out[e];
    const std::size_t entry_pos = pos;
    std::uint32_t tag = 0;
    if (auto s = get_varint32(bytes, pos, tag); !s) return s.error();
    std::uint32_t unit = 0;
    if (tag & 1) {
      unit = static_cast<std::uint32_t>(prev_unit + 1) + (tag >> 1);
      if ((tag >> 1) >= kUpdateUnitsPerChunk || unit >= kUpdateUnitsPerChunk) {
        return DecodeError{DecodeErrorCode::kInvalidValue, entry_pos, "unit index >= 512"};
      }
      u.chunk_pos = prev_chunk;
    } else {
      unit = tag >> 1;
      if (unit >= kUpdateUnitsPerChunk) return DecodeError{DecodeErrorCode::kInvalidValue, entry_pos, "unit index >= 512"};
      std::array<std::uint32_t, 3> d{};
      for (auto& c : d) {
        if (auto s = get_varint32(bytes, pos, c); !s) return s.error();
      }
      auto add = [](std::int32_t a, std::uint32_t z) {
        return static_cast<std::int32_t>(static_cast<std::uint32_t>(a) + static_cast<std::uint32_t>(unzigzag(z)));
      };
      u.chunk_pos = {add(prev_chunk.x, d[0]), add(prev_chunk.y, d[1]), add(prev_chunk.z, d[2])};
    }
    u.unit_index = static_cast<std::uint16_t>(unit);
    auto used = net_codec_decode_prefix(kUpdateUnitSize, bytes.subspan(pos), u.voxels);
    if (!used) {
      DecodeError err = used.error();
      err.offset += pos;
      return err;
    }
    pos += *used;
    prev_chunk = u.chunk_pos;
    prev_unit = static_cast<int>(unit);
  }
  if (pos != bytes.size()) return DecodeError{DecodeErrorCode::kTrailingBytes, pos, "bytes after the batch"};
  return std::size_t{count};
}

bool ChunkUnits::add(const UnitUpdate& u) {
  const UnitUpdate*& slot = by_index_[u.unit_index];
  const bool fresh = slot == nullptr;
  slot = &u;
  if (!fresh) return false;
  const int idx = u.unit_index;
  const Vec3i base = Vec3i{idx % 8, idx / 64, (idx / 8) % 8} * kUpdateUnitSize;
  lo_ = min3(lo_, base);
  hi_ = max3(hi_, base + Vec3i{kUpdateUnitSize, kUpdateUnitSize, kUpdateUnitSize});
  return true;
}

Result<std::bitset<kUpdateUnitsPerChunk>> apply_chunk_update_batch(std::span<const std::uint8_t> batch, Vec3i pos,
                                                                   Chunk& chunk, std::vector<UnitUpdate>& scratch) {
  scratch.resize(kUpdateUnitsPerChunk);
  auto n = net_codec_decode_update_batch(batch, scratch);
  if (!n) return n.error();
  if (*n == 0) return DecodeError{DecodeErrorCode::kInvalidValue, 0, "a chunk's units: none"};
  std::bitset<kUpdateUnitsPerChunk> written;
  ChunkUnits units;
  for (std::size_t i = 0; i < *n; ++i) {
    const UnitUpdate& u = scratch[i];
    if (u.chunk_pos != pos) return DecodeError{DecodeErrorCode::kInvalidValue, 0, "a chunk's units: a unit of another chunk"};
    if (!units.add(u)) return DecodeError{DecodeErrorCode::kInvalidValue, 0, "a chunk's units: a unit twice"};
    written.set(u.unit_index);
  }
  chunk.modify(units.box(), [&](Vec3i p, Voxel old) { return units.at(p, old); });
  return written;
}

void ChunkUnits::clear() {
  by_index_.fill(nullptr);
  constexpr int kSide = kUpdateUnitSize * 8;
  lo_ = Vec3i{kSide, kSide, kSide};
  hi_ = Vec3i{0, 0, 0};
}

}  // namespace terrane
