// The fixed code tables of the network voxel codec (format versions 1 and 2,
// common/codec/NET_CODEC.md), read by both its unit encoder
// (net_codec_encoder.h) and its unit decoder (net_codec_decoder.h): unit
// kinds, token types and their Exp-Golomb orders, the per-context type-code
// rankings and code words, the decoder's token lookup tables, truncated
// binary codes, and the per-unit palette both sides build.
//
// Everything here is immutable. The token and context tables are built once,
// on first use, by whichever thread asks first (function-local statics), and
// only read afterwards, so any thread may use them. The small functions stay
// inline in this header because the encoder and decoder call them per unit or
// per token.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>

#include "common/codec/bit_io.h"
#include "common/voxel/voxel.h"

namespace terrane::net_codec_detail {

// Unit kinds: the high nibble of the first byte (the low nibble is the version).
enum UnitKind : std::uint8_t {
  kKindAir = 0,         // every voxel Air: 1 byte
  kKindUniform = 1,     // one solid material, full occupancy: 2 bytes
  kKindUniformOcc = 2,  // one solid material, one occupancy byte: 3 bytes
  kKindTokens = 3,      // palette + run/copy token stream
  kKindPacked = 4,      // palette + fixed-width indices (bounds the worst case)
  kKindRaw = 5,         // N^3 x (material, occupancy) bytes (bounds tiny units)
};

// Token types. The first voxel is always an implicit literal.
enum TokenType : std::uint8_t {
  kLit = 0,   // one new voxel: palette index (+ occupancy)
  kRun = 1,   // repeat the previous voxel (offset 1)
  kCopyZ = 2, // copy from the row behind (offset N)
  kCopyY = 3, // copy from the layer below (offset N^2)
};

constexpr int kMaxVolume = 16 * 16 * 16;
constexpr unsigned kMaxLengthLog = 12;  // run lengths are <= 4096 = 2^12

// Exp-Golomb order per token type. Measured on the Minecraft and generated
// worlds: runs are mostly 1-3 voxels (order 0), copies cluster around the
// row length (order 2, order 1 for 4^3 rows).
inline unsigned length_order(TokenType type, int n) {
  if (type == kRun) return 0;
  if (type == kCopyZ) return n == 4 ? 1u : 2u;
  return 2;
}

// Default type-code rankings (rank 0 gets the 1-bit code), used when the
// encoder does not send its own: the most frequent successors measured on
// Minecraft terrain. The next type always differs from the previous one
// except after a literal, so non-literal contexts rank 3 types.
// Code words, LSB-first: rank0 "0", rank1 "10", rank2 "11" (3 types) or
// rank1 "10", rank2 "110", rank3 "111" (4 types).
struct TypeCode {
  std::array<TokenType, 4> rank;  // symbols by rank (3 used for non-literal contexts)
};
constexpr std::array<TypeCode, 4> kDefaultTypeCodes = {{
    {{kRun, kCopyZ, kLit, kCopyY}},    // after a literal (ranks 2 and 3 ascending)
    {{kCopyZ, kLit, kCopyY, kLit}},    // after a run
    {{kLit, kRun, kCopyY, kLit}},      // after a row copy
    {{kCopyZ, kLit, kRun, kLit}},      // after a layer copy
}};

// The number of ranked types in context prev: 4 after a literal, else 3.
constexpr int context_ranks(int prev) { return prev == kLit ? 4 : 3; }
// The number of rankings a context can send: 12 after a literal, else 3.
constexpr int context_rankings(int prev) { return prev == kLit ? 12 : 3; }

// The non-rank-0 symbols of a context are in ascending order except after a
// literal, where rank 1 is sent too. These helpers build a full ranking.
inline TypeCode make_code(int prev, int first, int second) {
  TypeCode code{};
  code.rank[0] = static_cast<TokenType>(first);
  int r = 1;
  if (prev == kLit) {
    code.rank[1] = static_cast<TokenType>(second);
    r = 2;
  }
  for (int s = 0; s < 4; ++s) {
    if (s == first || (prev == kLit && s == second) || (prev != kLit && s == prev)) continue;
    code.rank[static_cast<std::size_t>(r++)] = static_cast<TokenType>(s);
  }
  return code;
}

// The code word of a rank in context prev, LSB-first.
struct CodeWord {
  std::uint8_t bits;
  std::uint8_t length;
};
inline CodeWord code_word(int prev, int rank) {
  if (rank == 0) return {0, 1};
  if (prev != kLit) return {static_cast<std::uint8_t>(rank == 1 ? 0b01 : 0b11), 2};
  if (rank == 1) return {0b01, 2};
  return {static_cast<std::uint8_t>(rank == 2 ? 0b011 : 0b111), 3};
}

// The ranking of a context as sent in the unit: for non-literal contexts the
// index of rank 0 among the three allowed types (0..2); after a literal,
// rank0 * 3 + (index of rank 1 among the other three) (0..11).
inline int ranking_id(int prev, const TypeCode& c) {
  if (prev == kLit) {
    int idx = 0;
    for (int s = 0; s < c.rank[1]; ++s) idx += s != c.rank[0];
    return c.rank[0] * 3 + idx;
  }
  int idx = 0;
  for (int s = 0; s < c.rank[0]; ++s) idx += s != prev;
  return idx;
}
// The ranking with that id (the inverse of ranking_id).
// Precondition: 0 <= id < context_rankings(prev).
inline TypeCode code_from_id(int prev, int id) {
  if (prev == kLit) {
    const int first = id / 3;
    int second = -1;
    for (int s = 0, k = 0; s < 4; ++s) {
      if (s == first) continue;
      if (k++ == id % 3) second = s;
    }
    return make_code(prev, first, second);
  }
  int first = -1;
  for (int s = 0, k = 0; s < 4; ++s) {
    if (s == prev) continue;
    if (k++ == id) first = s;
  }
  return make_code(prev, first, -1);
}

// Decode tables: for each context and ranking, 10 peeked bits give the token
// type and, when the whole Exp-Golomb length fits in those bits, the length
// too (length 0: decode it the slow way after skipping `bits`). All 21
// tables (12 rankings after a literal, 3 after each of Run, CopyZ, CopyY)
// sit in one array, so a context is an offset into it.
constexpr unsigned kPeekBits = 10;
constexpr unsigned kTokenTableSize = 1u << kPeekBits;
constexpr int kTokenTableCount = 21;
// Packed in 16 bits so that the 21 tables of a unit size take 42 KiB (the
// tables a unit uses, 8 KiB, stay in L1 beside its output): bits 0-1 the
// type, 2-5 the bits to skip, 6-15 the length (1 for literals, 0 for lengths
// longer than the window; the window holds lengths up to 64).
struct TokenEntry {
  std::uint16_t packed;

  static TokenEntry make(TokenType type, unsigned bits, unsigned length) {
    return {static_cast<std::uint16_t>(type | (bits << 2) | (length << 6))};
  }
  unsigned type() const { return packed & 3u; }
  unsigned bits() const { return (packed >> 2) & 15u; }
  unsigned length() const { return packed >> 6; }
};
using TokenTables = std::array<TokenEntry, kTokenTableCount * kTokenTableSize>;

// Which of the 21 tables serves context `prev` with ranking `id`.
inline unsigned token_table_id(int prev, int id) {
  return static_cast<unsigned>(prev == kLit ? id : 12 + (prev - 1) * 3 + id);
}

// Builds the 21 token tables of unit size n (net_codec_tables.cpp).
// Precondition: n is 4, 8 or 16. The caller owns the result.
const TokenTables* build_token_tables(int n);

// The token tables of unit size n, table id t at t * kTokenTableSize; built
// on first use and never freed (they outlive every decoder).
template <int n>
const TokenEntry* token_tables() {
  static const TokenTables* const tables = build_token_tables(n);
  return tables->data();
}

// Per table id: the table id | the length of the code for Lit << 5 (the
// decoder's context byte); and the table of each context's default ranking.
struct ContextTables {
  std::array<std::uint8_t, kTokenTableCount> info;
  std::array<std::uint8_t, 4> default_table;
};
ContextTables build_context_tables();

// The context tables, built on first use.
inline const ContextTables& context_tables() {
  static const ContextTables tables = build_context_tables();
  return tables;
}

// Truncated binary code over `count` choices (count >= 1).
struct TruncatedBinary {
  unsigned bits = 0;       // long code length; short codes have bits - 1
  std::uint32_t short_count = 0;
  explicit TruncatedBinary(unsigned count) {
    bits = count <= 1 ? 0u : static_cast<unsigned>(std::bit_width(count - 1));
    short_count = (std::uint32_t{1} << bits) - count;
  }
  // Writes the high bits first so the reader can tell short from long codes.
  void put(BitWriter& w, std::uint32_t v) const {
    if (bits == 0) return;
    if (v < short_count) {
      w.put(v, bits - 1);
    } else {
      const std::uint32_t x = v + short_count;
      w.put(x >> 1, bits - 1);
      w.put(x & 1, 1);
    }
  }
  std::uint32_t get(BitReader& r) const {
    if (bits == 0) return 0;
    const std::uint32_t x = r.get(bits - 1);
    if (x < short_count) return x;
    return ((x << 1) | r.get(1)) - short_count;
  }
};

// Palette: materials in code order, and each material's index (-1 if absent).
// The encoder builds one per unit from its literals, the decoder reads it
// from the unit's header.
struct Palette {
  std::array<Material, kMaterialCount> materials{};
  std::array<std::int8_t, kMaterialCount> index{};
  int count = 0;
};

// Format version 2: a literal's occupancy predicted from the voxels of the
// unit before it (NET_CODEC.md, "Version 2: predicted occupancies"). Voxel
// i = (y*n + z)*n + x of the unit at `unit`; every voxel below index i is
// read, none at or after it. A neighbour counts in steps 1 and 2 only when
// its occupancy is partial (1..254): a plane through partial neighbours
// (steps 1: the three pairs of axes; 2: a line along each axis) continues
// smooth terrain, where clamped ones (0, 255) would bend it.
// `left` is the occupancy of voxel i - 1 (the decoder has it in a register;
// read from memory it would wait on the store just made).
template <int n>
inline int predict_occupancy(const Voxel* unit, int i, int left) {
  // A neighbour outside the unit reads as a voxel of occupancy 0, which is
  // never partial, and counts only in step 3's existence flags.
  static constexpr Voxel kOutside{};
  constexpr int shift = n == 4 ? 2 : (n == 8 ? 3 : 4);
  constexpr int X = 1, Z = n, Y = n * n;
  const int x = i & (n - 1), z = (i >> shift) & (n - 1), y = i >> (2 * shift);
  const auto at = [&](bool inside, int back) -> int {
    return (inside ? unit + (i - back) : &kOutside)->occupancy;
  };
  const auto partial = [](int o) { return static_cast<int>(static_cast<unsigned>(o - 1) < 254u); };
  // floor(sum / count) for count 1..3, clamped to 0..255: sums are at least
  // -756 (three predictions of 1 + 1 - 254), so sum + 256 * count is not
  // negative, and below 2^15, where t * 21846 >> 16 is t / 3.
  const auto mean = [](int sum, int count) {
    static constexpr std::uint32_t kReciprocal[4] = {0, 65536, 32768, 21846};
    const auto t = static_cast<std::uint32_t>(sum + 256 * count);
    return std::clamp(static_cast<int>((t * kReciprocal[count]) >> 16) - 256, 0, 255);
  };
  const int l = x > 0 ? left : 0, b = at(z > 0, Z), d = at(y > 0, Y);
  const int pl = partial(l), pb = partial(b), pd = partial(d);
  // Step 1: a + b - ab over the pairs (x, y), (z, y), (x, z).
  const int ld = at(x > 0 && y > 0, X + Y), bd = at(z > 0 && y > 0, Z + Y), lb = at(x > 0 && z > 0, X + Z);
  const int v1 = pl & pd & partial(ld), v2 = pb & pd & partial(bd), v3 = pl & pb & partial(lb);
  const int plane_count = v1 + v2 + v3;
  if (plane_count > 0) [[likely]] {
    return mean((v1 ? l + d - ld : 0) + (v2 ? b + d - bd : 0) + (v3 ? l + b - lb : 0), plane_count);
  }
  // Step 2: 2a - aa along x, y, z.
  const int ll = at(x > 1, 2 * X), dd = at(y > 1, 2 * Y), bb = at(z > 1, 2 * Z);
  const int w1 = pl & partial(ll), w2 = pd & partial(dd), w3 = pb & partial(bb);
  const int line_count = w1 + w2 + w3;
  if (line_count > 0) return mean((w1 ? 2 * l - ll : 0) + (w2 ? 2 * d - dd : 0) + (w3 ? 2 * b - bb : 0), line_count);
  // Step 3: the mean of the neighbours at x - 1, y - 1, z - 1, whatever
  // their occupancies; 128 for voxel 0.
  const int near_count = (x > 0) + (y > 0) + (z > 0);
  return near_count > 0 ? mean(l + b + d, near_count) : 128;
}

template <int n>
inline int predict_occupancy(const Voxel* unit, int i) {
  return predict_occupancy<n>(unit, i, i > 0 ? unit[i - 1].occupancy : 0);
}

// The signed difference between an occupancy and its prediction, as the
// unsigned value version 2 codes: r in -128..127 (occupancy = (prediction +
// r) mod 256) zigzagged to 0..255 (0, -1, 1, -2, ... become 0, 1, 2, 3, ...).
inline std::uint32_t occupancy_residual(int occupancy, int prediction) {
  const int r = ((occupancy - prediction + 128) & 255) - 128;
  return r >= 0 ? static_cast<std::uint32_t>(2 * r) : static_cast<std::uint32_t>(-2 * r - 1);
}
inline std::uint8_t occupancy_from_residual(int prediction, std::uint32_t u) {
  const int r = (u & 1) != 0 ? -static_cast<int>((u + 1) >> 1) : static_cast<int>(u >> 1);
  return static_cast<std::uint8_t>((prediction + r) & 255);
}
// The largest residual value and Exp-Golomb order a unit may use.
constexpr std::uint32_t kMaxResidual = 255;
constexpr unsigned kMaxResidualOrder = 3;
constexpr unsigned kMaxResidualZeros = 8;

// The width of a palette index in packed units: ceil(log2(count)).
inline unsigned packed_index_bits(int palette_count) {
  return palette_count <= 1 ? 0u : static_cast<unsigned>(std::bit_width(static_cast<unsigned>(palette_count - 1)));
}

}  // namespace terrane::net_codec_detail
