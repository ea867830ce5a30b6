#include "protocol/chunk_hash.h"

#include <cstring>

namespace terrane {

namespace {

using namespace chunk_hash_detail;

// FNV-1a over one row's 64 bytes, byte by byte (the definition).
std::uint64_t hash_bytes(std::uint64_t h, const Voxel* row) {
  for (int x = 0; x < kChunkSize; ++x) {
    h ^= row[x].material;
    h *= kFnvPrime;
    h ^= row[x].occupancy;
    h *= kFnvPrime;
  }
  return h;
}

// A row of one voxel, hashed in one multiplication once seen.
//
// FNV-1a is affine in all but the hash's low byte: with h = H + l (l = h &
// 0xff) and a byte b, h ^ b = H + (l ^ b), so (h ^ b) * p = H * p + (l ^ b)
// * p, and H * p is a multiple of 256 again. The low byte's path through a
// row depends on l and the bytes alone, and over the row's 64 bytes
//   hash_row(h) = (h - l) * p^64 + hash_row(l)   (mod 2^64).
// So a row of voxel v needs hash_row(l) of v's row once per low byte l: a
// thread keeps those of a few voxels, each value filled when first needed
// (at the cost of hashing that row once, as without the table), so no input
// costs more than byte-by-byte hashing plus a lookup.
struct UniformRows {
  static constexpr int kVoxels = 8;
  static constexpr std::uint32_t kNone = 0xffffffffu;
  std::uint32_t keys[kVoxels] = {kNone, kNone, kNone, kNone, kNone, kNone, kNone, kNone};
  struct Table {
    std::uint64_t known[4] = {};  // bit l: value[l] is filled
    std::uint64_t value[256];
  } tables[kVoxels];
  int next = 0;  // the table given to the next voxel not kept (round robin)

  Table& of(std::uint32_t key) {
    for (int i = 0; i < kVoxels; ++i)
      if (keys[i] == key) return tables[i];
    const int i = next;
    next = (next + 1) % kVoxels;
    keys[i] = key;
    std::memset(tables[i].known, 0, sizeof tables[i].known);
    return tables[i];
  }
};

}  // namespace

std::uint64_t hash_row(std::uint64_t h, const Voxel* row) {
  static_assert(sizeof(Voxel) == 2 && kChunkSize % 4 == 0);
  // Whether every voxel is the first, eight bytes (four voxels) at a time.
  std::uint64_t words[kChunkSize / 4];
  std::memcpy(words, row, sizeof words);
  std::uint64_t differ = 0;
  for (const std::uint64_t w : words) differ |= w ^ words[0];
  const std::uint16_t first = static_cast<std::uint16_t>(words[0]);
  differ |= (words[0] ^ (words[0] >> 16)) & 0xffffffffffffull;
  if (differ != 0) return hash_bytes(h, row);
  if (first == 0) return h * kAirRowFactor;  // Air: both bytes zero, only multiplications
  thread_local UniformRows rows;
  UniformRows::Table& t = rows.of(first);
  const std::uint64_t l = h & 0xff;
  const std::uint64_t bit = std::uint64_t{1} << (l & 63);
  if ((t.known[l >> 6] & bit) == 0) {
    t.value[l] = hash_bytes(l, row);
    t.known[l >> 6] |= bit;
  }
  return (h - l) * kAirRowFactor + t.value[l];  // p^64: a row's 64 bytes (zeros only multiply)
}

}  // namespace terrane
