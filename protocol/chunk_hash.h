// The chunk hash (messages.h chunk_hash) over any chunk-like reader of rows:
// a Chunk on both sides of the protocol and, in the consumers' benchmark
// (tests/bench/consumers_bench.cpp), the same voxels as a plain array, so
// both run exactly this code. C has
// `const Voxel* read_row(int y, int z, std::array<Voxel, 32>& scratch) const`
// (never null).
// 64-bit FNV-1a over the revision (8 bytes little-endian) then the 32^3
// voxels in Box order, two bytes each (material, occupancy). Stateless.
#pragma once

#include <array>
#include <cstdint>

#include "common/voxel/chunk.h"
#include "common/voxel/voxel.h"

namespace terrane {

namespace chunk_hash_detail {
inline constexpr std::uint64_t kFnvOffset = 0xcbf29ce484222325ull, kFnvPrime = 0x100000001b3ull;
// FNV-1a over 2^k zero bytes: x ^ 0 = x, so each only multiplies by the
// prime; the product is the prime squared k times (mod 2^64).
constexpr std::uint64_t fnv_zeros_factor(int k) {
  std::uint64_t p = kFnvPrime;
  for (int i = 0; i < k; ++i) p *= p;
  return p;
}
static_assert(2 * kChunkSize == 1 << 6 && 2 * kChunkSize * kChunkSize * kChunkSize == 1 << 16);
inline constexpr std::uint64_t kAirRowFactor = fnv_zeros_factor(6), kAirChunkFactor = fnv_zeros_factor(16);
}  // namespace chunk_hash_detail

// The hash h carried over one row of kChunkSize voxels: the same value as
// byte by byte, but an all-Air row (both bytes zero) is one multiplication
// and a row of any one voxel a multiplication and a lookup in a table the
// calling thread fills as it meets such rows (chunk_hash.cpp says why that
// is exact). One function, not a template: every reader's rows go through
// the same code.
std::uint64_t hash_row(std::uint64_t h, const Voxel* row);

// A null chunk is all Air.
template <class C>
std::uint64_t chunk_hash_of(const C* chunk, std::uint64_t revision) {
  using namespace chunk_hash_detail;
  std::uint64_t h = kFnvOffset;
  for (int i = 0; i < 8; ++i) {
    h ^= (revision >> (8 * i)) & 0xff;
    h *= kFnvPrime;
  }
  // Air (both bytes zero) is hashed a row or a chunk at a time: the same
  // value as byte by byte, without the pass.
  if (chunk == nullptr) return h * kAirChunkFactor;
  // Each row is read before the previous one is hashed: a decoded row's
  // reading overlaps the hash's chain of multiplies rather than waiting
  // for it.
  constexpr int kRows = kChunkSize * kChunkSize;
  std::array<Voxel, kChunkSize> scratch[2];
  const Voxel* row = chunk->read_row(0, 0, scratch[0]);
  for (int r = 0; r < kRows; ++r) {
    const Voxel* next = r + 1 < kRows ? chunk->read_row((r + 1) / kChunkSize, (r + 1) % kChunkSize, scratch[(r + 1) & 1]) : nullptr;
    h = hash_row(h, row);
    row = next;
  }
  return h;
}

}  // namespace terrane
