// Network voxel codec, format version 1 (see common/NET_CODEC.md).
#include "common/net_codec.h"

#include <algorithm>
#include <bit>
#include <cstring>

#include "common/bit_io.h"

namespace terrane {
namespace {

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
unsigned length_order(TokenType type, int n) {
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

// The non-rank-0 symbols of a context are in ascending order except after a
// literal, where rank 1 is sent too. These helpers build a full ranking.
TypeCode make_code(int prev, int first, int second) {
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

struct CodeWord {
  std::uint8_t bits;
  std::uint8_t length;
};
CodeWord code_word(int prev, int rank) {
  if (rank == 0) return {0, 1};
  if (prev != kLit) return {static_cast<std::uint8_t>(rank == 1 ? 0b01 : 0b11), 2};
  if (rank == 1) return {0b01, 2};
  return {static_cast<std::uint8_t>(rank == 2 ? 0b011 : 0b111), 3};
}

// The ranking of a context as sent in the unit: for non-literal contexts the
// index of rank 0 among the three allowed types (0..2); after a literal,
// rank0 * 3 + (index of rank 1 among the other three) (0..11).
int ranking_id(int prev, const TypeCode& c) {
  if (prev == kLit) {
    int idx = 0;
    for (int s = 0; s < c.rank[1]; ++s) idx += s != c.rank[0];
    return c.rank[0] * 3 + idx;
  }
  int idx = 0;
  for (int s = 0; s < c.rank[0]; ++s) idx += s != prev;
  return idx;
}
TypeCode code_from_id(int prev, int id) {
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
// too (length 0: decode it the slow way after skipping `bits`).
constexpr unsigned kPeekBits = 10;
struct TokenEntry {
  TokenType type;
  std::uint8_t bits;     // bits to skip
  std::uint16_t length;  // 0 for literals and long lengths
};
using TokenTable = std::array<TokenEntry, 1u << kPeekBits>;
struct TokenTables {
  std::array<TokenTable, 12> after_literal;
  std::array<std::array<TokenTable, 3>, 3> after_copy;  // [prev - 1][ranking]
  const TokenTable& get(int prev, int id) const {
    return prev == kLit ? after_literal[static_cast<std::size_t>(id)]
                        : after_copy[static_cast<std::size_t>(prev - 1)][static_cast<std::size_t>(id)];
  }
};

unsigned length_order(TokenType type, int n);

void build_token_table(int prev, const TypeCode& code, int n, TokenTable& t) {
  const int ranks = prev == kLit ? 4 : 3;
  for (unsigned x = 0; x < t.size(); ++x) {
    for (int r = 0; r < ranks; ++r) {
      const CodeWord w = code_word(prev, r);
      if ((x & ((1u << w.length) - 1)) != w.bits) continue;
      const TokenType type = code.rank[static_cast<std::size_t>(r)];
      TokenEntry e{type, w.length, 0};
      if (type != kLit) {
        const unsigned rest = x >> w.length;
        const unsigned avail = kPeekBits - w.length;
        const unsigned order = length_order(type, n);
        if (rest != 0) {
          const auto lg = static_cast<unsigned>(std::countr_zero(rest));
          if (2 * lg + 1 + order <= avail) {
            const unsigned wv = (1u << lg) | ((rest >> (lg + 1)) & ((1u << lg) - 1));
            const unsigned low = (rest >> (2 * lg + 1)) & ((1u << order) - 1);
            e.length = static_cast<std::uint16_t>((((wv - 1) << order) | low) + 1);
            e.bits = static_cast<std::uint8_t>(w.length + 2 * lg + 1 + order);
          }
        }
      }
      t[x] = e;
      break;
    }
  }
}

template <int n>
const TokenTables& token_tables() {
  static const TokenTables* tables = [] {
    auto* t = new TokenTables;
    for (int id = 0; id < 12; ++id) build_token_table(kLit, code_from_id(kLit, id), n, t->after_literal[static_cast<std::size_t>(id)]);
    for (int p = 1; p < 4; ++p) {
      for (int id = 0; id < 3; ++id) {
        build_token_table(p, code_from_id(p, id), n, t->after_copy[static_cast<std::size_t>(p - 1)][static_cast<std::size_t>(id)]);
      }
    }
    return t;
  }();
  return *tables;
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

void eg_put(BitWriter& out, std::uint32_t length, unsigned order) {
  const std::uint32_t v = length - 1;
  const std::uint32_t w = (v >> order) + 1;
  const unsigned lg = static_cast<unsigned>(std::bit_width(w)) - 1;
  const std::uint32_t code = (std::uint32_t{1} << lg) | ((w ^ (std::uint32_t{1} << lg)) << (lg + 1)) |
                             ((v & ((std::uint32_t{1} << order) - 1)) << (2 * lg + 1));
  out.put(code, 2 * lg + 1 + order);
}

// Voxels equal from a and b onward, at most max.
int match_length(const Voxel* a, const Voxel* b, int max) {
  int l = 0;
  while (l + 4 <= max) {
    std::uint64_t x, y;
    std::memcpy(&x, a + l, 8);
    std::memcpy(&y, b + l, 8);
    if (const std::uint64_t d = x ^ y; d != 0) {
      if constexpr (std::endian::native == std::endian::little) {
        return l + std::countr_zero(d) / 16;
      } else {
        return l + std::countl_zero(d) / 16;
      }
    }
    l += 4;
  }
  while (l < max && a[l] == b[l]) ++l;
  return l;
}

// Plain members only, so the encoder's token array is not zero-filled.
// Fills len voxels with v, four at a time.
inline void fill_voxels(Voxel* dst, Voxel v, int len) {
  std::uint16_t w16;
  std::memcpy(&w16, &v, 2);
  const std::uint64_t w64 = w16 * 0x0001000100010001ull;
  int k = 0;
  for (; k + 4 <= len; k += 4) std::memcpy(dst + k, &w64, 8);
  for (; k < len; ++k) dst[k] = v;
}

// Copies len voxels from offset voxels back, forward, four at a time: safe
// for overlapping ranges because offset >= 4 (the smallest unit row).
inline void copy_back(Voxel* dst, int offset, int len) {
  const Voxel* src = dst - offset;
  int k = 0;
  for (; k + 4 <= len; k += 4) {
    std::uint64_t t;
    std::memcpy(&t, src + k, 8);
    std::memcpy(dst + k, &t, 8);
  }
  for (; k < len; ++k) dst[k] = src[k];
}

// Fast forms that may write up to 7 voxels past len (into voxels later
// tokens overwrite); callers use them only when that stays inside the unit.
inline void fill_voxels_wild(Voxel* dst, Voxel v, int len) {
  std::uint16_t w16;
  std::memcpy(&w16, &v, 2);
  const std::uint64_t w64 = w16 * 0x0001000100010001ull;
  for (int k = 0; k < len; k += 8) {
    std::memcpy(dst + k, &w64, 8);
    std::memcpy(dst + k + 4, &w64, 8);
  }
}
// Step of 4 voxels for offset >= 4, 8 voxels for offset >= 8: each step
// reads only voxels written before it.
template <int kStep>
inline void copy_back_wild(Voxel* dst, int offset, int len) {
  const Voxel* src = dst - offset;
  for (int k = 0; k < len; k += kStep) {
    std::uint8_t t[kStep * 2];
    std::memcpy(t, src + k, sizeof t);
    std::memcpy(dst + k, t, sizeof t);
  }
}

struct Token {
  TokenType type;
  std::uint16_t length;  // voxels covered (1 for literals)
  Material material;     // literals only
  std::uint8_t occupancy;
};

// Palette: materials in code order, and each material's index (-1 if absent).
struct Palette {
  std::array<Material, kMaterialCount> materials{};
  std::array<std::int8_t, kMaterialCount> index{};
  int count = 0;
};

void put_palette(BitWriter& w, const Palette& p, bool partial) {
  w.put(static_cast<std::uint32_t>(p.count - 1), 6);
  for (int i = 0; i < p.count; ++i) w.put(p.materials[static_cast<std::size_t>(i)], 6);
  w.put(partial ? 1u : 0u, 1);
}

std::size_t write_packed(int n, const Voxel* v, const Palette& p, bool partial, std::uint8_t* dst) {
  const int volume = n * n * n;
  dst[0] = static_cast<std::uint8_t>(kNetCodecVersion | (kKindPacked << 4));
  BitWriter w(dst + 1);
  put_palette(w, p, partial);
  const unsigned bits = p.count <= 1 ? 0u : static_cast<unsigned>(std::bit_width(static_cast<unsigned>(p.count - 1)));
  for (int i = 0; i < volume; ++i) {
    w.put(static_cast<std::uint32_t>(p.index[v[i].material]), bits);
    if (partial && v[i].material != kAir) w.put(v[i].occupancy, 8);
  }
  return 1 + w.finish();
}

std::size_t packed_bits(int n, int palette_count, int solid_count, bool partial) {
  const std::size_t volume = static_cast<std::size_t>(n) * n * n;
  const unsigned bits = palette_count <= 1 ? 0u : static_cast<unsigned>(std::bit_width(static_cast<unsigned>(palette_count - 1)));
  return 6 + 6 * static_cast<std::size_t>(palette_count) + 1 + volume * bits +
         (partial ? 8 * static_cast<std::size_t>(solid_count) : 0);
}

// ---------------------------------------------------------------------------
// Varints for the update batch.

void put_varint(std::uint32_t v, std::vector<std::uint8_t>& out) {
  while (v >= 0x80) {
    out.push_back(static_cast<std::uint8_t>(v | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<std::uint8_t>(v));
}

std::uint32_t zigzag(std::int32_t v) {
  const auto u = static_cast<std::uint32_t>(v);
  return (u << 1) ^ static_cast<std::uint32_t>(-static_cast<std::int32_t>(u >> 31));
}
std::int32_t unzigzag(std::uint32_t z) {
  return static_cast<std::int32_t>((z >> 1) ^ (0u - (z & 1)));
}

// Reads a LEB128 varint of at most 5 bytes that fits 32 bits.
Status get_varint(std::span<const std::uint8_t> bytes, std::size_t& pos, std::uint32_t& v) {
  v = 0;
  for (unsigned shift = 0; shift < 35; shift += 7) {
    if (pos >= bytes.size()) return DecodeError{DecodeErrorCode::kTruncated, pos, "varint cut short"};
    const std::uint8_t b = bytes[pos++];
    if (shift == 28 && (b & 0xF0) != 0) return DecodeError{DecodeErrorCode::kInvalidValue, pos - 1, "varint over 32 bits"};
    v |= std::uint32_t{b & 0x7Fu} << shift;
    if ((b & 0x80) == 0) return Ok{};
  }
  return DecodeError{DecodeErrorCode::kInvalidValue, pos, "varint over 32 bits"};
}

// ---------------------------------------------------------------------------
// Encoder

template <int n>
void encode_unit(const Voxel* v, std::vector<std::uint8_t>& out) {
  constexpr int volume = n * n * n;
  constexpr int layer = n * n;

  // Greedy parse: at each voxel the longest of run / row copy / layer copy,
  // a literal when none matches. Every distinct voxel value of the unit
  // appears in some literal, so literals alone give the palette and whether
  // any occupancy is not the default.
  std::array<Token, kMaxVolume> tokens;  // NOLINT: filled below
  int token_count = 0;
  std::array<std::uint32_t, kMaterialCount> literal_freq{};
  std::array<std::array<std::uint32_t, 4>, 4> transitions{};
  const Voxel first = v[0];
  tokens[0] = {kLit, 1, first.material, first.occupancy};
  token_count = 1;
  ++literal_freq[first.material];
  std::uint64_t present = std::uint64_t{1} << first.material;
  bool partial = first.material != kAir && first.occupancy != kFullOccupancy;
  int prev = kLit;
  for (int i = 1; i < volume;) {
    const int max = volume - i;
    int best = match_length(v + i, v + i - 1, max);
    int type = kRun;
    if (i >= n && best < max) {
      const int l = match_length(v + i, v + i - n, max);
      if (l > best) best = l, type = kCopyZ;
    }
    if (i >= layer && best < max) {
      const int l = match_length(v + i, v + i - layer, max);
      if (l > best) best = l, type = kCopyY;
    }
    if (best == 0) {
      const Voxel x = v[i];
      tokens[static_cast<std::size_t>(token_count++)] = {kLit, 1, x.material, x.occupancy};
      ++literal_freq[x.material];
      present |= std::uint64_t{1} << x.material;
      partial |= x.material != kAir && x.occupancy != kFullOccupancy;
      type = kLit;
      best = 1;
    } else {
      tokens[static_cast<std::size_t>(token_count++)] = {static_cast<TokenType>(type), static_cast<std::uint16_t>(best), 0, 0};
    }
    ++transitions[static_cast<std::size_t>(prev)][static_cast<std::size_t>(type)];
    prev = type;
    i += best;
  }

  if (token_count == 2 && tokens[1].type == kRun) {  // uniform unit
    if (first.material == kAir) {
      out.push_back(static_cast<std::uint8_t>(kNetCodecVersion | (kKindAir << 4)));
    } else if (first.occupancy == kFullOccupancy) {
      out.push_back(static_cast<std::uint8_t>(kNetCodecVersion | (kKindUniform << 4)));
      out.push_back(first.material);
    } else {
      out.push_back(static_cast<std::uint8_t>(kNetCodecVersion | (kKindUniformOcc << 4)));
      out.push_back(first.material);
      out.push_back(first.occupancy);
    }
    return;
  }
  // Occupancy bytes in the packed form (only needed when some are partial).
  int solid_count = 0;
  if (partial) {
    for (int i = 0; i < volume; ++i) solid_count += v[i].material != kAir;
  }

  // Palette in descending literal frequency (short truncated-binary codes first).
  Palette palette;
  palette.index.fill(-1);
  for (std::uint64_t bits = present; bits != 0; bits &= bits - 1) {
    palette.materials[static_cast<std::size_t>(palette.count++)] = static_cast<Material>(std::countr_zero(bits));
  }
  std::stable_sort(palette.materials.begin(), palette.materials.begin() + palette.count,
                   [&](Material a, Material b) { return literal_freq[a] > literal_freq[b]; });
  for (int i = 0; i < palette.count; ++i) palette.index[palette.materials[static_cast<std::size_t>(i)]] = static_cast<std::int8_t>(i);

  // Type codes: the ranking that fits this unit's transitions, sent when it
  // saves more than the 10 bits it costs.
  std::array<TypeCode, 4> codes = kDefaultTypeCodes;
  std::array<TypeCode, 4> custom{};
  std::size_t default_bits = 0, custom_bits = 10;
  for (int p = 0; p < 4; ++p) {
    const auto& t = transitions[static_cast<std::size_t>(p)];
    std::array<int, 4> order = {0, 1, 2, 3};
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
      const bool a_ok = p == kLit || a != p, b_ok = p == kLit || b != p;
      if (a_ok != b_ok) return a_ok;
      return t[static_cast<std::size_t>(a)] > t[static_cast<std::size_t>(b)];
    });
    custom[static_cast<std::size_t>(p)] = make_code(p, order[0], order[1]);
    const int ranks = p == kLit ? 4 : 3;
    for (int r = 0; r < ranks; ++r) {
      const auto len = code_word(p, r).length;
      default_bits += std::size_t{len} * t[kDefaultTypeCodes[static_cast<std::size_t>(p)].rank[static_cast<std::size_t>(r)]];
      custom_bits += std::size_t{len} * t[custom[static_cast<std::size_t>(p)].rank[static_cast<std::size_t>(r)]];
    }
  }
  const bool use_custom = custom_bits < default_bits;
  if (use_custom) codes = custom;
  std::array<std::array<CodeWord, 4>, 4> encode_words{};
  for (int p = 0; p < 4; ++p) {
    const int ranks = p == kLit ? 4 : 3;
    for (int r = 0; r < ranks; ++r) {
      encode_words[static_cast<std::size_t>(p)][codes[static_cast<std::size_t>(p)].rank[static_cast<std::size_t>(r)]] = code_word(p, r);
    }
  }

  std::array<std::uint8_t, net_codec_max_encoded_size(16) + 64> scratch;  // NOLINT: written before read
  // The token stream must beat both fallbacks (packed, and raw for tiny units).
  const std::size_t packed_limit = packed_bits(n, palette.count, solid_count, partial);
  const std::size_t raw_limit = 16 * static_cast<std::size_t>(volume);
  const std::size_t limit_bits = std::min(packed_limit, raw_limit);
  // Token streams never need more than 18 bits per voxel; stop as soon as
  // the packed form would be smaller (it bounds the worst case).
  std::array<std::uint8_t, 3 * kMaxVolume + 64> token_buf;  // NOLINT: written before read
  token_buf[0] = static_cast<std::uint8_t>(kNetCodecVersion | (kKindTokens << 4));
  BitWriter w(token_buf.data() + 1);
  put_palette(w, palette, partial);
  w.put(use_custom ? 1u : 0u, 1);
  if (use_custom) {
    for (int p = 0; p < 4; ++p) {
      const int id = ranking_id(p, codes[static_cast<std::size_t>(p)]);
      if (p == kLit) {
        w.put(static_cast<std::uint32_t>(id / 3), 2);
        w.put(static_cast<std::uint32_t>(id % 3), 2);
      } else {
        w.put(static_cast<std::uint32_t>(id), 2);
      }
    }
  }
  const TruncatedBinary full_code(static_cast<unsigned>(palette.count));
  const TruncatedBinary excl_code(static_cast<unsigned>(palette.count > 1 ? palette.count - 1 : 1));
  bool fits = true;
  int pos = 0;
  prev = -1;
  for (int t = 0; t < token_count; ++t) {
    const Token& tok = tokens[static_cast<std::size_t>(t)];
    if (prev >= 0) {
      const CodeWord cw = encode_words[static_cast<std::size_t>(prev)][tok.type];
      w.put(cw.bits, cw.length);
    }
    if (tok.type == kLit) {
      const auto idx = static_cast<std::uint32_t>(palette.index[tok.material]);
      if (partial) {
        full_code.put(w, idx);
        if (tok.material != kAir) {
          if (tok.occupancy == kFullOccupancy) {
            w.put(0, 1);
          } else {
            w.put(1u | (std::uint32_t{tok.occupancy} << 1), 9);
          }
        }
      } else if (pos == 0) {
        full_code.put(w, idx);
      } else {
        const auto p_idx = static_cast<std::uint32_t>(palette.index[v[pos - 1].material]);
        excl_code.put(w, idx < p_idx ? idx : idx - 1);
      }
    } else {
      eg_put(w, tok.length, length_order(tok.type, n));
    }
    pos += tok.length;
    prev = tok.type;
    if (w.bit_count() > limit_bits) {
      fits = false;
      break;
    }
  }
  if (fits) {
    const std::size_t size = 1 + w.finish();
    out.insert(out.end(), token_buf.data(), token_buf.data() + size);
    return;
  }
  if ((packed_limit + 7) / 8 > 2 * static_cast<std::size_t>(volume)) {
    out.push_back(static_cast<std::uint8_t>(kNetCodecVersion | (kKindRaw << 4)));
    for (int i = 0; i < volume; ++i) {
      out.push_back(v[i].material);
      out.push_back(v[i].occupancy);
    }
    return;
  }
  const std::size_t size = write_packed(n, v, palette, partial, scratch.data());
  out.insert(out.end(), scratch.data(), scratch.data() + size);
}

// ---------------------------------------------------------------------------
// Decoder

template <int n>
Result<std::size_t> decode_unit(std::span<const std::uint8_t> bytes, std::span<Voxel> out) {
  constexpr int volume = n * n * n;
  constexpr int layer = n * n;
  const std::uint8_t head = bytes[0];
  if ((head & 0x0F) != kNetCodecVersion) return DecodeError{DecodeErrorCode::kBadVersion, 0, "unknown unit format version"};
  const int kind = head >> 4;
  Voxel* dst = out.data();
  switch (kind) {
    case kKindAir:
      std::fill(out.begin(), out.end(), Voxel{});
      return std::size_t{1};
    case kKindUniform:
    case kKindUniformOcc: {
      const std::size_t size = kind == kKindUniform ? 2 : 3;
      if (bytes.size() < size) return DecodeError{DecodeErrorCode::kTruncated, bytes.size(), "uniform unit cut short"};
      const Material m = bytes[1];
      if (m == kAir || m >= kMaterialCount) {
        return DecodeError{DecodeErrorCode::kInvalidValue, 1, "uniform unit material not in 1..63"};
      }
      const Voxel x{m, kind == kKindUniform ? kFullOccupancy : bytes[2]};
      std::fill(out.begin(), out.end(), x);
      return size;
    }
    case kKindRaw: {
      const std::size_t size = 1 + 2 * static_cast<std::size_t>(volume);
      if (bytes.size() < size) return DecodeError{DecodeErrorCode::kTruncated, bytes.size(), "raw unit cut short"};
      for (int i = 0; i < volume; ++i) {
        const std::size_t at = 1 + 2 * static_cast<std::size_t>(i);
        const Voxel x{bytes[at], bytes[at + 1]};
        if (x.material >= kMaterialCount) return DecodeError{DecodeErrorCode::kInvalidValue, at, "material >= 64"};
        if (x.material == kAir && x.occupancy != 0) return DecodeError{DecodeErrorCode::kInvalidValue, at + 1, "Air with occupancy"};
        dst[i] = x;
      }
      return size;
    }
    case kKindTokens:
    case kKindPacked:
      break;
    default:
      return DecodeError{DecodeErrorCode::kInvalidValue, 0, "unknown unit kind"};
  }

  BitReader r(bytes.data() + 1, bytes.data() + bytes.size());
  // Errors found after reading past the end are reported as truncation.
  auto fail = [&](DecodeErrorCode code, const char* detail) -> DecodeError {
    if (r.overran()) return DecodeError{DecodeErrorCode::kTruncated, bytes.size(), "unit cut short"};
    return DecodeError{code, 1 + r.bit_position() / 8, detail};
  };

  r.refill();
  Palette palette;
  palette.index.fill(-1);
  palette.count = static_cast<int>(r.get(6)) + 1;
  for (int i = 0; i < palette.count; ++i) {
    r.refill();
    const auto m = static_cast<Material>(r.get(6));
    if (palette.index[m] >= 0) return fail(DecodeErrorCode::kInvalidValue, "duplicate palette material");
    palette.materials[static_cast<std::size_t>(i)] = m;
    palette.index[m] = static_cast<std::int8_t>(i);
  }
  r.refill();
  const bool partial = r.get(1) != 0;

  if (kind == kKindPacked) {
    const unsigned bits = palette.count <= 1 ? 0u : static_cast<unsigned>(std::bit_width(static_cast<unsigned>(palette.count - 1)));
    for (int i = 0; i < volume; ++i) {
      r.refill();
      const std::uint32_t idx = r.get(bits);
      if (idx >= static_cast<std::uint32_t>(palette.count)) return fail(DecodeErrorCode::kInvalidValue, "palette index out of range");
      const Material m = palette.materials[idx];
      dst[i] = Voxel{m, default_occupancy(m)};
      if (partial && m != kAir) dst[i].occupancy = static_cast<std::uint8_t>(r.get(8));
    }
  } else {
    r.refill();
    const TokenTables& all_tables = token_tables<n>();
    std::array<const TokenTable*, 4> tables{};
    const bool custom = r.get(1) != 0;
    for (int p = 0; p < 4; ++p) {
      int id = ranking_id(p, kDefaultTypeCodes[static_cast<std::size_t>(p)]);
      if (custom) {
        if (p == kLit) {
          const int first = static_cast<int>(r.get(2));
          const int second_idx = static_cast<int>(r.get(2));
          if (second_idx == 3) return fail(DecodeErrorCode::kInvalidValue, "bad type ranking");
          id = first * 3 + second_idx;
        } else {
          id = static_cast<int>(r.get(2));
          if (id == 3) return fail(DecodeErrorCode::kInvalidValue, "bad type ranking");
        }
      }
      tables[static_cast<std::size_t>(p)] = &all_tables.get(p, id);
    }
    const TruncatedBinary full_code(static_cast<unsigned>(palette.count));
    const TruncatedBinary excl_code(static_cast<unsigned>(palette.count > 1 ? palette.count - 1 : 1));
    constexpr unsigned order_z = n == 4 ? 1u : 2u;  // length_order(kCopyZ, n)
    constexpr unsigned order_y = 2;                 // length_order(kCopyY, n)
    // The first voxel is an implicit literal over the whole palette.
    {
      const std::uint32_t idx = full_code.get(r);
      if (idx >= static_cast<std::uint32_t>(palette.count)) return fail(DecodeErrorCode::kInvalidValue, "palette index out of range");
      const Material m = palette.materials[idx];
      Voxel x{m, default_occupancy(m)};
      if (partial && m != kAir && r.get(1) != 0) x.occupancy = static_cast<std::uint8_t>(r.get(8));
      dst[0] = x;
    }
    int i = 1;
    int prev = kLit;
    while (i < volume) {
      r.refill();
      const TokenEntry e = (*tables[static_cast<std::size_t>(prev)])[r.peek(kPeekBits)];
      r.skip(e.bits);
      prev = e.type;
      if (e.type == kLit) {
        std::uint32_t idx;
        if (partial) {
          idx = full_code.get(r);
        } else {
          idx = excl_code.get(r);
          const auto p_idx = static_cast<std::uint32_t>(palette.index[dst[i - 1].material]);
          idx += idx >= p_idx;
        }
        if (idx >= static_cast<std::uint32_t>(palette.count)) return fail(DecodeErrorCode::kInvalidValue, "palette index out of range");
        const Material m = palette.materials[idx];
        Voxel x{m, default_occupancy(m)};
        if (partial && m != kAir && r.get(1) != 0) x.occupancy = static_cast<std::uint8_t>(r.get(8));
        dst[i++] = x;
        continue;
      }
      std::uint32_t length = e.length;
      if (length == 0) {  // Exp-Golomb length longer than the peek window
        const unsigned order = e.type == kRun ? 0u : (e.type == kCopyZ ? order_z : order_y);
        const unsigned lg = r.trailing_zeros();
        if (lg > kMaxLengthLog) {
          if (r.bit_position() + lg + 1 > r.bit_size()) {  // zeros fed past the end
            return DecodeError{DecodeErrorCode::kTruncated, bytes.size(), "unit cut short"};
          }
          return fail(DecodeErrorCode::kInvalidValue, "run length code too long");
        }
        r.skip(lg + 1);
        const std::uint32_t w = (std::uint32_t{1} << lg) | r.get(lg);
        length = (((w - 1) << order) | r.get(order)) + 1;
      }
      if (length > static_cast<std::uint32_t>(volume - i)) return fail(DecodeErrorCode::kInvalidValue, "run past the end of the unit");
      const int len = static_cast<int>(length);
      const bool room = len + 8 <= volume - i;  // wild writes stay inside the unit
      if (e.type == kRun) {
        if (room) {
          fill_voxels_wild(dst + i, dst[i - 1], len);
        } else {
          fill_voxels(dst + i, dst[i - 1], len);
        }
      } else {
        const int offset = e.type == kCopyZ ? n : layer;
        if (i < offset) return fail(DecodeErrorCode::kInvalidValue, "copy from before the unit start");
        if (!room) {
          copy_back(dst + i, offset, len);
        } else if (n == 4 && e.type == kCopyZ) {
          copy_back_wild<4>(dst + i, offset, len);
        } else {
          copy_back_wild<8>(dst + i, offset, len);
        }
      }
      i += len;
    }
  }

  if (r.overran()) return DecodeError{DecodeErrorCode::kTruncated, bytes.size(), "unit cut short"};
  const std::size_t pos = r.bit_position();
  const unsigned pad = static_cast<unsigned>((8 - pos % 8) % 8);
  r.refill();
  if (r.get(pad) != 0) return fail(DecodeErrorCode::kInvalidValue, "non-zero padding bits");
  return 1 + (pos + pad) / 8;
}

}  // namespace

void net_codec_encode(int n, std::span<const Voxel> voxels, std::vector<std::uint8_t>& out) {
  switch (n) {
    case 4: return encode_unit<4>(voxels.data(), out);
    case 8: return encode_unit<8>(voxels.data(), out);
    default: return encode_unit<16>(voxels.data(), out);
  }
}

Result<std::size_t> net_codec_decode_prefix(int n, std::span<const std::uint8_t> bytes, std::span<Voxel> out) {
  if (!net_codec_valid_size(n)) return DecodeError{DecodeErrorCode::kOverLimit, 0, "unit size is not 4, 8 or 16"};
  if (out.size() != static_cast<std::size_t>(n) * n * n) {
    return DecodeError{DecodeErrorCode::kOverLimit, 0, "output buffer is not N^3 voxels"};
  }
  if (bytes.empty()) return DecodeError{DecodeErrorCode::kTruncated, 0, "empty unit"};
  switch (n) {
    case 4: return decode_unit<4>(bytes, out);
    case 8: return decode_unit<8>(bytes, out);
    default: return decode_unit<16>(bytes, out);
  }
}

Status net_codec_decode(int n, std::span<const std::uint8_t> bytes, std::span<Voxel> out) {
  auto used = net_codec_decode_prefix(n, bytes, out);
  if (!used) return used.error();
  if (*used != bytes.size()) return DecodeError{DecodeErrorCode::kTrailingBytes, *used, "bytes after the unit"};
  return Ok{};
}

// ---------------------------------------------------------------------------
// Update batches

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

void net_codec_encode_update_batch(std::span<const UnitUpdate> updates, std::vector<std::uint8_t>& out) {
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
    net_codec_encode(kUpdateUnitSize, u->voxels, out);
    prev_chunk = u->chunk_pos;
    prev_unit = u->unit_index;
  }
}

Result<std::size_t> net_codec_decode_update_batch(std::span<const std::uint8_t> bytes, std::span<UnitUpdate> out) {
  if (bytes.empty()) return DecodeError{DecodeErrorCode::kTruncated, 0, "empty batch"};
  if (bytes[0] != kUpdateBatchVersion) return DecodeError{DecodeErrorCode::kBadVersion, 0, "unknown batch version"};
  std::size_t pos = 1;
  std::uint32_t count = 0;
  if (auto s = get_varint(bytes, pos, count); !s) return s.error();
  if (count > out.size()) return DecodeError{DecodeErrorCode::kOverLimit, 1, "more updates than the caller allows"};
  Vec3i prev_chunk{};
  int prev_unit = -1;
  for (std::uint32_t e = 0; e < count; ++e) {
    UnitUpdate& u = out[e];
    const std::size_t entry_pos = pos;
    std::uint32_t tag = 0;
    if (auto s = get_varint(bytes, pos, tag); !s) return s.error();
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
        if (auto s = get_varint(bytes, pos, c); !s) return s.error();
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

}  // namespace terrane
