// Update batches of Terrane's network voxel codec: the 4^3 units that changed
// in one tick, each with its chunk coordinate and unit index, delta-coded and
// followed by its unit (common/codec/net_codec.h). Format version 1 is
// specified in common/codec/NET_CODEC.md, "Update batches".
//
// Like the unit decoder, the batch decoder never trusts its input: errors
// come back as a DecodeError and the output buffer is the caller's.
#pragma once

#include <array>
#include <bitset>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "common/codec/bit_io.h"
#include "common/codec/decode_error.h"
#include "common/codec/net_codec.h"
#include "common/voxel/vec3.h"
#include "common/voxel/voxel.h"

namespace terrane {

inline constexpr int kUpdateUnitSize = 4;
inline constexpr int kUpdateUnitVoxels = 64;
// Units of 4^3 in a 32^3 chunk, indexed (uy*8+uz)*8+ux.
inline constexpr int kUpdateUnitsPerChunk = 512;
inline constexpr std::uint8_t kUpdateBatchVersion = 1;

struct UnitUpdate {
  Vec3i chunk_pos;               // signed coordinate of the 32^3 chunk
  std::uint16_t unit_index = 0;  // 0..511: (uy*8+uz)*8+ux within the chunk
  std::array<Voxel, kUpdateUnitVoxels> voxels{};

  friend bool operator==(const UnitUpdate&, const UnitUpdate&) = default;
};

// Orders updates the way a batch stores them: by chunk (y, z, x), then unit.
bool update_batch_order(const UnitUpdate& a, const UnitUpdate& b);

// Appends a batch holding the given updates. The batch is a set: entries are
// written sorted by update_batch_order (so coordinates delta-code well) and
// decode in that order. Preconditions: unit_index < 512, voxels valid.
// Units in network codec format codec_version (net_codec_encode's).
void net_codec_encode_update_batch(std::span<const UnitUpdate> updates, std::vector<std::uint8_t>& out,
                                   std::uint8_t codec_version = kNetCodecVersion);

// Decodes a whole batch into out, returning the number of updates. Errors as
// net_codec_decode, plus kOverLimit when the batch holds more than out.size()
// updates and kInvalidValue for a unit index >= 512 or an over-long varint.
Result<std::size_t> net_codec_decode_update_batch(std::span<const std::uint8_t> bytes, std::span<UnitUpdate> out);

// One chunk's units of a batch, encoded once and joined into batches that
// differ per receiver (a server sends each client the chunks it holds):
// joining writes each piece's first coordinates and copies the rest, so a
// batch costs its receiver one copy of the shared bytes. Joining pieces in
// update_batch_order of their chunks gives the bytes
// net_codec_encode_update_batch makes of the same units.
struct UpdatePiece {
  Vec3i chunk_pos;
  int first_unit = 0;
  std::uint32_t count = 0;
  std::vector<std::uint8_t> rest;  // the first unit, then the other entries
};
// Precondition: units is non-empty, every unit of chunk_pos, distinct indices.
UpdatePiece net_codec_encode_update_piece(std::span<const UnitUpdate> units,
                                          std::uint8_t codec_version = kNetCodecVersion);
// Appends one batch of the pieces (distinct chunks), in the order given.
void net_codec_join_update_pieces(std::span<const UpdatePiece* const> pieces, std::vector<std::uint8_t>& out);
// The same batch, but each piece's rest is handed to put_rest(i, rest) (i
// its index in pieces) instead of copied into out: a writer that sends
// the batch as segments keeps the pieces' bytes shared. put_rest must
// append rest where out's next byte would go.
template <class PutRest>
void net_codec_join_update_pieces(std::span<const UpdatePiece* const> pieces, std::vector<std::uint8_t>& out,
                                  PutRest&& put_rest);

// One chunk's units of a batch, by index, to write into the chunk's voxels
// in one pass over the box that holds them (a replica's, or a server's copy
// of a chunk another server changed).
class ChunkUnits {
 public:
  ChunkUnits() { clear(); }
  // Adds u (kept by reference until clear), in place of a unit of the same
  // index added before; false if there was one.
  bool add(const UnitUpdate& u);
  bool empty() const { return lo_.x >= hi_.x; }
  // The chunk-local box holding every unit added (empty when none).
  Region box() const { return empty() ? Region{} : Region{lo_, hi_}; }
  // The voxel at chunk-local p: the added unit's there, else old.
  Voxel at(Vec3i local, Voxel old) const {
    const Vec3i uc{local.x / kUpdateUnitSize, local.y / kUpdateUnitSize, local.z / kUpdateUnitSize};
    const UnitUpdate* u = by_index_[static_cast<std::size_t>((uc.y * 8 + uc.z) * 8 + uc.x)];
    if (u == nullptr) return old;
    const Vec3i w = local - uc * kUpdateUnitSize;
    return u->voxels[static_cast<std::size_t>((w.y * kUpdateUnitSize + w.z) * kUpdateUnitSize + w.x)];
  }
  void clear();

 private:
  std::array<const UnitUpdate*, kUpdateUnitsPerChunk> by_index_{};
  Vec3i lo_, hi_;
};

class Chunk;

// Writes one batch holding units of the chunk at pos only into chunk, in one
// pass over the box of its units (rows repacked and mips updated once), and
// returns the indices of the units written (bit i: unit i). Checked before
// anything is written: the batch decodes, holds at least one unit, none of
// another chunk and none twice. scratch is the caller's buffer.
Result<std::bitset<kUpdateUnitsPerChunk>> apply_chunk_update_batch(std::span<const std::uint8_t> batch, Vec3i pos,
                                                                   Chunk& chunk, std::vector<UnitUpdate>& scratch);

// The coordinate part of one batch entry, exposed so benchmarks can put the
// same coordinates in front of other unit codecs. prev_* is the previous
// entry's chunk and unit (start: chunk (0,0,0), unit -1).
void net_codec_put_update_coords(Vec3i chunk_pos, int unit_index, Vec3i prev_chunk, int prev_unit,
                                 std::vector<std::uint8_t>& out);

template <class PutRest>
void net_codec_join_update_pieces(std::span<const UpdatePiece* const> pieces, std::vector<std::uint8_t>& out,
                                  PutRest&& put_rest) {
  std::uint32_t count = 0;
  for (const UpdatePiece* p : pieces) count += p->count;
  out.push_back(kUpdateBatchVersion);
  put_varint(count, out);
  Vec3i prev_chunk{};
  int prev_unit = -1;
  for (std::size_t i = 0; i < pieces.size(); ++i) {
    const UpdatePiece* p = pieces[i];
    net_codec_put_update_coords(p->chunk_pos, p->first_unit, prev_chunk, prev_unit, out);
    put_rest(i, std::span<const std::uint8_t>(p->rest));
    prev_chunk = p->chunk_pos;
    prev_unit = kUpdateUnitsPerChunk;  // pieces are distinct chunks
  }
}

}  // namespace terrane
