// Network voxel codec units, format version 1 (see common/codec/NET_CODEC.md);
// update batches are in update_batch.cpp.
#include "common/codec/net_codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>

#include "common/codec/bit_io.h"

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
unsigned token_table_id(int prev, int id) {
  return static_cast<unsigned>(prev == kLit ? id : 12 + (prev - 1) * 3 + id);
}

unsigned length_order(TokenType type, int n);

void build_token_table(int prev, const TypeCode& code, int n, TokenEntry* t) {
  const int ranks = prev == kLit ? 4 : 3;
  for (unsigned x = 0; x < kTokenTableSize; ++x) {
    for (int r = 0; r < ranks; ++r) {
      const CodeWord w = code_word(prev, r);
      if ((x & ((1u << w.length) - 1)) != w.bits) continue;
      const TokenType type = code.rank[static_cast<std::size_t>(r)];
      unsigned bits = w.length;
      unsigned length = type == kLit ? 1 : 0;
      if (type != kLit) {
        const unsigned rest = x >> w.length;
        const unsigned avail = kPeekBits - w.length;
        const unsigned order = length_order(type, n);
        if (rest != 0) {
          const auto lg = static_cast<unsigned>(std::countr_zero(rest));
          if (2 * lg + 1 + order <= avail) {
            const unsigned wv = (1u << lg) | ((rest >> (lg + 1)) & ((1u << lg) - 1));
            const unsigned low = (rest >> (2 * lg + 1)) & ((1u << order) - 1);
            length = (((wv - 1) << order) | low) + 1;
            bits = w.length + 2 * lg + 1 + order;
          }
        }
      }
      t[x] = TokenEntry::make(type, bits, length);
      break;
    }
  }
}

template <int n>
const TokenEntry* token_tables() {
  static const TokenTables* tables = [] {
    auto* t = new TokenTables;
    for (int p = 0; p < 4; ++p) {
      for (int id = 0; id < (p == kLit ? 12 : 3); ++id) {
        build_token_table(p, code_from_id(p, id), n, t->data() + token_table_id(p, id) * kTokenTableSize);
      }
    }
    return t;
  }();
  return tables->data();
}

// Per table id: the table id | the length of the code for Lit << 5 (the
// decoder's context byte); and the table of each context's default ranking.
struct ContextTables {
  std::array<std::uint8_t, kTokenTableCount> info;
  std::array<std::uint8_t, 4> default_table;
};
const ContextTables& context_tables() {
  static const ContextTables tables = [] {
    ContextTables t{};
    for (int p = 0; p < 4; ++p) {
      for (int id = 0; id < (p == kLit ? 12 : 3); ++id) {
        const TypeCode code = code_from_id(p, id);
        unsigned lit_code_length = 0;
        for (int rank = 0; rank < (p == kLit ? 4 : 3); ++rank) {
          if (code.rank[static_cast<std::size_t>(rank)] == kLit) lit_code_length = code_word(p, rank).length;
        }
        const unsigned table = token_table_id(p, id);
        t.info[table] = static_cast<std::uint8_t>(table | (lit_code_length << 5));
      }
      t.default_table[static_cast<std::size_t>(p)] =
          static_cast<std::uint8_t>(token_table_id(p, ranking_id(p, kDefaultTypeCodes[static_cast<std::size_t>(p)])));
    }
    return t;
  }();
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

// A voxel as the 16-bit word it is in memory, and back.
inline std::uint16_t voxel_bits(Voxel v) {
  std::uint16_t w;
  std::memcpy(&w, &v, 2);
  return w;
}
inline Voxel bits_voxel(std::uint32_t w) {
  const auto w16 = static_cast<std::uint16_t>(w);
  Voxel v;
  std::memcpy(&v, &w16, 2);
  return v;
}
// Copies 8 voxels with one 16-byte load and store.
inline void copy8_voxels(Voxel* dst, const Voxel* src) {
  std::uint8_t t[16];
  std::memcpy(t, src, 16);
  std::memcpy(dst, t, 16);
}

// Plain members only, so the encoder's token array is not zero-filled.
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

// Builds the error for a failure inside a bit stream: anything noticed after
// the reader fed zeros past the end is truncation. The reader comes by value
// so that the decoder's own reader never has its address taken and stays in
// registers.
[[gnu::noinline, gnu::cold]] DecodeError stream_error(BitReader r, std::size_t size, DecodeErrorCode code,
                                                      const char* detail) {
  if (r.overran()) return DecodeError{DecodeErrorCode::kTruncated, size, "unit cut short"};
  return DecodeError{code, 1 + r.bit_position() / 8, detail};
}

// A literal's body read with one lookup of the next kLiteralPeekBits bits.
// Non-partial units code the palette index over the palette minus the
// previous voxel's index; the payload is the code's value. Partial units
// code it over the whole palette, then a solid material has an occupancy
// flag bit (and 8 bits of occupancy when it is set); the payload is the
// voxel (at default occupancy, or 0 when an occupancy follows). The table
// repeats every 2^(code length) entries, so the decoder masks with a
// constant; fields are whole bytes so the bit count loads on its own.
constexpr unsigned kLiteralPeekBits = 7;  // 6-bit index + occupancy flag
struct LiteralEntry {
  std::uint16_t payload;
  std::uint8_t bits;       // bits used, including flag and occupancy
  std::uint8_t occupancy;  // where the occupancy starts, | 0x80 when there is one
};
struct LiteralCode {
  std::array<LiteralEntry, 1u << kLiteralPeekBits> entries;  // NOLINT: filled by the constructor

  LiteralCode(bool partial, const Palette& palette) {
    const int count = partial ? palette.count : std::max(palette.count - 1, 1);
    const TruncatedBinary code(static_cast<unsigned>(count));
    const unsigned peek_bits = code.bits + (partial ? 1 : 0);
    const unsigned short_bits = code.bits == 0 ? 0 : code.bits - 1;
    for (std::uint32_t x = 0; x < (std::uint32_t{1} << peek_bits); ++x) {
      const std::uint32_t head = x & ((std::uint32_t{1} << short_bits) - 1);
      std::uint32_t value = 0;
      unsigned used = 0;
      if (code.bits != 0) {
        const bool is_short = head < code.short_count;
        value = is_short ? head : ((head << 1) | ((x >> short_bits) & 1)) - code.short_count;
        used = is_short ? short_bits : code.bits;
      }
      LiteralEntry entry{static_cast<std::uint16_t>(value), static_cast<std::uint8_t>(used), 0};
      if (partial) {
        const Material m = palette.materials[value];
        const std::uint32_t flag = m != kAir ? (x >> used) & 1 : 0;
        const Voxel base{m, flag != 0 ? std::uint8_t{0} : default_occupancy(m)};  // occupancy or-ed in when flagged
        entry.payload = voxel_bits(base);
        entry.bits = static_cast<std::uint8_t>(used + (m != kAir ? 1 + 8 * flag : 0));
        entry.occupancy = static_cast<std::uint8_t>((used + 1) | (flag << 7));
      }
      entries[x] = entry;
    }
    for (std::size_t filled = std::size_t{1} << peek_bits; filled < entries.size(); filled *= 2) {
      std::memcpy(entries.data() + filled, entries.data(), filled * sizeof(LiteralEntry));
    }
  }
  const LiteralEntry& lookup(std::uint64_t bits) const { return entries[bits & (entries.size() - 1)]; }
};

constexpr const char* kLengthCodeTooLong = "run length code too long";

// Token streams of kind-3 units, after the header and the first voxel (which
// is written): decode_tokens_solid for units without partial occupancies,
// decode_tokens_partial for the others. They return nullptr, or the detail
// of a kInvalidValue error (reported at the reader's position, or as
// truncation if the reader has overrun).
//
// Both read the type table and the literal table in parallel (a literal's
// body starts right after the context's code for Lit, whose length the
// context knows). Runs and copies are written alike, 8 voxels at a time: a
// copy from `offset` voxels back (>= 8, so each step reads voxels already
// written), or for runs and literals a 16-byte fill followed by copies of
// the step before. Bounds are checked once per token: while its whole
// length plus 16 voxels fit before the end of the unit, these wide stores
// (which later tokens overwrite) stay inside it; near the end tokens are
// checked and written exactly. 4^3 units always take the exact path (their
// row copy is only 4 voxels behind).

// Where a token of each type reads its first 8 voxels and its later steps,
// 16 bits per type.
template <int n>
constexpr std::uint64_t kFirstFrom = (std::uint64_t{n} << 32) | (std::uint64_t{n * n} << 48);
template <int n>
constexpr std::uint64_t kRestFrom = 8u | (8u << 16) | (std::uint64_t{n} << 32) | (std::uint64_t{n * n} << 48);

// Reads an Exp-Golomb length that did not fit the table's window (the
// reader is just past the type code). Returns 0 for a code over 12 zeros.
// Refills first, so callers need only have had the window's 10 bits.
template <int n>
[[gnu::always_inline]] inline std::uint32_t read_long_length(BitReader& r, unsigned type) {
  constexpr unsigned order_z = n == 4 ? 1u : 2u;  // length_order(kCopyZ, n)
  constexpr unsigned order_y = 2;                 // length_order(kCopyY, n)
  const unsigned order = type == kRun ? 0u : (type == kCopyZ ? order_z : order_y);
  r.refill();
  const unsigned lg = r.trailing_zeros();
  if (lg > kMaxLengthLog) return 0;
  r.skip(lg + 1);
  const std::uint32_t w = (std::uint32_t{1} << lg) | r.get(lg);
  return (((w - 1) << order) | r.get(order)) + 1;
}

// Writes a run or copy of len voxels at dst + i with 16-byte steps; fill is
// the run's voxel repeated four times. Precondition: len + 16 <= volume - i,
// i >= the copy's offset.
template <int n>
[[gnu::always_inline]] inline void write_wide(Voxel* out, unsigned type, int len, std::uint64_t fill) {
  const auto first_from = static_cast<int>((kFirstFrom<n> >> (16 * type)) & 0xFFFF);
  const auto rest_from = static_cast<int>((kRestFrom<n> >> (16 * type)) & 0xFFFF);
  const std::uint64_t fill2[2] = {fill, fill};
  std::memcpy(out, fill2, 16);
  copy8_voxels(out, out - first_from);
  copy8_voxels(out + 8, out + 8 - rest_from);
  for (int k = 16; k < len; k += 8) copy8_voxels(out + k, out + k - rest_from);
}

// Units without partial occupancies: every voxel is a palette material at
// its default occupancy, so the previous voxel is known by its palette index
// p_idx. Tokens are decoded without a branch on their type (these units mix
// the four types so evenly that such a branch would often mispredict):
// masks select between the literal and the other tokens.
template <int n>
const char* decode_tokens_solid(BitReader& r, const Palette& palette, std::uint32_t ctx_info, std::uint32_t first_idx,
                                Voxel* dst) {
  constexpr int volume = n * n * n;
  const TokenEntry* const tables = token_tables<n>();
  // Palette voxels at default occupancy, alone and four in a row.
  std::array<Voxel, kMaterialCount> voxels;        // NOLINT: the first palette.count are filled
  std::array<std::uint64_t, kMaterialCount> fills;  // NOLINT: likewise
  for (int k = 0; k < palette.count; ++k) {
    const Material m = palette.materials[static_cast<std::size_t>(k)];
    voxels[static_cast<std::size_t>(k)] = Voxel{m, default_occupancy(m)};
    fills[static_cast<std::size_t>(k)] = voxel_bits(voxels[static_cast<std::size_t>(k)]) * 0x0001000100010001ull;
  }
  const LiteralCode lit(false, palette);
  // A literal must differ from the previous voxel, so a one-material unit
  // has no literals after the first voxel.
  const bool no_literals = palette.count == 1;

  // Per token type: the context that follows it (table start, Lit code length).
  std::array<std::uint32_t, 4> table_after;
  std::array<std::uint32_t, 4> lit_shift_after;
  for (unsigned t = 0; t < 4; ++t) {
    table_after[t] = ((ctx_info >> (8 * t)) & 31) << kPeekBits;
    lit_shift_after[t] = (ctx_info >> (8 * t + 5)) & 7;
  }
  std::uint32_t p_idx = first_idx;  // palette index of voxel i - 1
  std::uint32_t table = table_after[kLit];
  std::uint32_t lit_shift = lit_shift_after[kLit];
  // Tokens take at most 10 bits here (long lengths refill on their own and
  // then ask for a refill before the next token), so one refill of 56 bits
  // serves four tokens.
  unsigned until_refill = 0;
  int i = 1;
  while (i < volume) {
    if (until_refill == 0) {
      r.refill();
      until_refill = 4;
    }
    --until_refill;
    const std::uint64_t b = r.bits();
    const TokenEntry e = tables[table | static_cast<unsigned>(b & (kTokenTableSize - 1))];
    const LiteralEntry lc = lit.lookup(b >> lit_shift);
    const unsigned type = e.type();
    const unsigned this_lit_shift = lit_shift;
    table = table_after[type];
    lit_shift = lit_shift_after[type];
    const std::uint32_t lit_mask = 0u - static_cast<std::uint32_t>(type == kLit);
    const std::uint32_t copy_mask = 0u - static_cast<std::uint32_t>(type >= kCopyZ);
    const std::uint32_t j = lc.payload;
    const std::uint32_t idx = j + (j >= p_idx);  // the literal's index, if it is one
    r.skip(((this_lit_shift + lc.bits) & lit_mask) | (e.bits() & ~lit_mask));
    if (lit_mask & no_literals) return "palette index out of range";

    std::uint32_t length = e.length();  // 1 for literals
    if (length == 0) [[unlikely]] {
      length = read_long_length<n>(r, type);
      if (length == 0) return kLengthCodeTooLong;
      until_refill = 0;
    }
    const int len = static_cast<int>(length);
    const auto offset = static_cast<int>((kFirstFrom<n> >> (16 * type)) & 0xFFFF);
    const std::uint32_t fill_idx = (idx & lit_mask) | (p_idx & ~lit_mask);
    if (n >= 8 && length + 16 <= static_cast<std::uint32_t>(volume - i)) [[likely]] {
      if (i < offset) return "copy from before the unit start";
      write_wide<n>(dst + i, type, len, fills[fill_idx]);
    } else {
      if (length > static_cast<std::uint32_t>(volume - i)) return "run past the end of the unit";
      if (i < offset) return "copy from before the unit start";
      if (type <= kRun) {
        fill_voxels(dst + i, voxels[fill_idx], len);
      } else {
        copy_back(dst + i, offset, len);
      }
    }
    // A copy's last voxel comes from its source (usually written by earlier
    // tokens, so this does not wait on the stores just made); other tokens
    // read voxel 0 and discard it.
    const int tail_at = (i + len - 1 - offset) & static_cast<int>(copy_mask);
    const auto tail_idx = static_cast<std::uint32_t>(palette.index[dst[tail_at].material]);
    p_idx = (tail_idx & copy_mask) | (fill_idx & ~copy_mask);
    i += len;
  }
  return nullptr;
}

// Units with partial occupancies: mostly literals (smooth surfaces), often
// several in a row, so literals take a branch of their own.
template <int n>
const char* decode_tokens_partial(BitReader& r, const Palette& palette, std::uint32_t ctx_info, Voxel* dst) {
  constexpr int volume = n * n * n;
  const TokenEntry* const tables = token_tables<n>();
  const LiteralCode lit(true, palette);
  // Per token type: the context that follows it (table start, Lit code length).
  std::array<std::uint32_t, 4> table_after;
  std::array<std::uint32_t, 4> lit_shift_after;
  for (unsigned t = 0; t < 4; ++t) {
    table_after[t] = ((ctx_info >> (8 * t)) & 31) << kPeekBits;
    lit_shift_after[t] = (ctx_info >> (8 * t + 5)) & 7;
  }

  // The voxel of a literal whose body starts lit_shift bits into b.
  auto literal = [](std::uint64_t b, LiteralEntry lc, unsigned lit_shift) -> std::uint32_t {
    const std::uint32_t occupancy = static_cast<std::uint32_t>(b >> (lit_shift + (lc.occupancy & 15u))) & 0xFF;
    return lc.payload | ((occupancy << 8) & (0u - (lc.occupancy >> 7)));
  };
  const std::uint32_t lit_table = table_after[kLit];
  const std::uint32_t lit_lit_shift = lit_shift_after[kLit];

  std::uint32_t last = voxel_bits(dst[0]);  // voxel i - 1
  std::uint32_t table = lit_table;
  std::uint32_t lit_shift = lit_lit_shift;
  // A literal takes at most 18 bits and any token needs at most 18 at its
  // start (10 through the table; long lengths refill on their own and then
  // ask for a refill before the next token), so one refill of 56 bits serves
  // three tokens.
  unsigned until_refill = 0;
  int i = 1;
  while (i < volume) {
    if (until_refill == 0) {
      r.refill();
      until_refill = 3;
    }
    --until_refill;
    const std::uint64_t b = r.bits();
    const TokenEntry e = tables[table | static_cast<unsigned>(b & (kTokenTableSize - 1))];
    const LiteralEntry lc = lit.lookup(b >> lit_shift);
    if (e.type() == kLit) {
      last = literal(b, lc, lit_shift);
      r.skip(lit_shift + lc.bits);
      dst[i++] = bits_voxel(last);
      table = lit_table;
      lit_shift = lit_lit_shift;
      continue;
    }
    const unsigned type = e.type();
    r.skip(e.bits());
    table = table_after[type];
    lit_shift = lit_shift_after[type];
    std::uint32_t length = e.length();
    if (length == 0) [[unlikely]] {
      length = read_long_length<n>(r, type);
      if (length == 0) return kLengthCodeTooLong;
      until_refill = 0;
    }
    const int len = static_cast<int>(length);
    const auto offset = static_cast<int>((kFirstFrom<n> >> (16 * type)) & 0xFFFF);
    if (n >= 8 && length + 16 <= static_cast<std::uint32_t>(volume - i)) [[likely]] {
      if (i < offset) return "copy from before the unit start";
      write_wide<n>(dst + i, type, len, last * 0x0001000100010001ull);
    } else {
      if (length > static_cast<std::uint32_t>(volume - i)) return "run past the end of the unit";
      if (i < offset) return "copy from before the unit start";
      if (type == kRun) {
        fill_voxels(dst + i, bits_voxel(last), len);
      } else {
        copy_back(dst + i, offset, len);
      }
    }
    const std::uint32_t copy_mask = 0u - static_cast<std::uint32_t>(type >= kCopyZ);
    const int tail_at = (i + len - 1 - offset) & static_cast<int>(copy_mask);
    last = (voxel_bits(dst[tail_at]) & copy_mask) | (last & ~copy_mask);
    i += len;
  }
  return nullptr;
}

template <int n>
Result<std::size_t> decode_unit(std::span<const std::uint8_t> bytes, std::span<Voxel> out) {
  constexpr int volume = n * n * n;
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
  const std::size_t size = bytes.size();

  r.refill();
  Palette palette;
  palette.index.fill(-1);
  palette.count = static_cast<int>(r.get(6)) + 1;
  for (int i = 0; i < palette.count; ++i) {
    r.refill();
    const auto m = static_cast<Material>(r.get(6));
    if (palette.index[m] >= 0) return stream_error(r, size, DecodeErrorCode::kInvalidValue, "duplicate palette material");
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
      if (idx >= static_cast<std::uint32_t>(palette.count)) {
        return stream_error(r, size, DecodeErrorCode::kInvalidValue, "palette index out of range");
      }
      const Material m = palette.materials[idx];
      dst[i] = Voxel{m, default_occupancy(m)};
      if (partial && m != kAir) dst[i].occupancy = static_cast<std::uint8_t>(r.get(8));
    }
  } else {
    r.refill();
    const bool custom = r.get(1) != 0;
    // Per context, 8 bits in token type order: its table id, and the length
    // of its code for Lit << 5.
    std::uint32_t ctx_info = 0;
    for (int p = 0; p < 4; ++p) {
      unsigned table = context_tables().default_table[static_cast<std::size_t>(p)];
      if (custom) {
        if (p == kLit) {
          const unsigned first = r.get(2);
          const unsigned second_idx = r.get(2);
          if (second_idx == 3) return stream_error(r, size, DecodeErrorCode::kInvalidValue, "bad type ranking");
          table = first * 3 + second_idx;
        } else {
          const unsigned id = r.get(2);
          if (id == 3) return stream_error(r, size, DecodeErrorCode::kInvalidValue, "bad type ranking");
          table = token_table_id(p, static_cast<int>(id));
        }
      }
      ctx_info |= std::uint32_t{context_tables().info[table]} << (8 * p);
    }
    // The first voxel is an implicit literal over the whole palette.
    const TruncatedBinary full_code(static_cast<unsigned>(palette.count));
    const std::uint32_t first_idx = full_code.get(r);
    if (first_idx >= static_cast<std::uint32_t>(palette.count)) {
      return stream_error(r, size, DecodeErrorCode::kInvalidValue, "palette index out of range");
    }
    {
      const Material m = palette.materials[first_idx];
      Voxel x{m, default_occupancy(m)};
      if (partial && m != kAir && r.get(1) != 0) x.occupancy = static_cast<std::uint8_t>(r.get(8));
      dst[0] = x;
    }
    const char* invalid = partial ? decode_tokens_partial<n>(r, palette, ctx_info, dst)
                                  : decode_tokens_solid<n>(r, palette, ctx_info, first_idx, dst);
    if (invalid != nullptr) {
      // An over-long length code: the zeros ran past the end when no one
      // bit follows before it (the reader fed them), else z > 12.
      if (invalid == kLengthCodeTooLong && !r.one_bit_ahead()) {
        return DecodeError{DecodeErrorCode::kTruncated, size, "unit cut short"};
      }
      return stream_error(r, size, DecodeErrorCode::kInvalidValue, invalid);
    }
  }

  if (r.overran()) return DecodeError{DecodeErrorCode::kTruncated, size, "unit cut short"};
  const std::size_t pos = r.bit_position();
  const unsigned pad = static_cast<unsigned>((8 - pos % 8) % 8);
  r.refill();
  if (r.get(pad) != 0) return stream_error(r, size, DecodeErrorCode::kInvalidValue, "non-zero padding bits");
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

}  // namespace terrane
