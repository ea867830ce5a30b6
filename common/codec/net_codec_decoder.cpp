// The network voxel codec's unit decoder (see net_codec_decoder.h).
#include "common/codec/net_codec_decoder.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>

#include "common/codec/bit_io.h"
#include "common/codec/net_codec.h"
#include "common/codec/net_codec_tables.h"

namespace terrane::net_codec_detail {
namespace {

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
// voxel (at default occupancy, or 0 when an occupancy follows). Only the
// 2^(peek bits) entries the code can reach are filled, and the lookup masks
// with that size (filling all 128 entries was a large share of decoding a
// unit of 4³ voxels); fields are whole bytes so the bit count loads on its
// own.
constexpr unsigned kLiteralPeekBits = 7;  // 6-bit index + occupancy flag
struct LiteralEntry {
  std::uint16_t payload;
  std::uint8_t bits;       // bits used, including flag and occupancy
  std::uint8_t occupancy;  // where the occupancy starts, | 0x80 when there is one
};
struct LiteralCode {
  std::array<LiteralEntry, 1u << kLiteralPeekBits> entries;  // NOLINT: the first mask + 1 filled by the constructor
  std::uint32_t mask = 0;

  // flagged: a partial unit of version 1 (a flag bit, then 8 bits of
  // occupancy when set); a partial unit of version 2 has neither (its
  // occupancies come as residuals after the entry's bits): entries mark a
  // solid material with 0x80 in `occupancy` and give it occupancy 0.
  LiteralCode(bool partial, const Palette& palette, bool flagged = true) {
    const int count = partial ? palette.count : std::max(palette.count - 1, 1);
    const TruncatedBinary code(static_cast<unsigned>(count));
    const unsigned peek_bits = code.bits + (partial && flagged ? 1 : 0);
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
      if (partial && !flagged) {
        const Material m = palette.materials[value];
        entry.payload = voxel_bits(Voxel{m, 0});
        entry.occupancy = m != kAir ? 0x80 : 0;
      } else if (partial) {
        const Material m = palette.materials[value];
        const std::uint32_t flag = m != kAir ? (x >> used) & 1 : 0;
        const Voxel base{m, flag != 0 ? std::uint8_t{0} : default_occupancy(m)};  // occupancy or-ed in when flagged
        entry.payload = voxel_bits(base);
        entry.bits = static_cast<std::uint8_t>(used + (m != kAir ? 1 + 8 * flag : 0));
        entry.occupancy = static_cast<std::uint8_t>((used + 1) | (flag << 7));
      }
      entries[x] = entry;
    }
    mask = (std::uint32_t{1} << peek_bits) - 1;
  }
  const LiteralEntry& lookup(std::uint64_t bits) const { return entries[bits & mask]; }
};

constexpr const char* kLengthCodeTooLong = "run length code too long";
constexpr const char* kResidualCodeTooLong = "occupancy residual code too long";
constexpr const char* kResidualOutOfRange = "occupancy residual over 255";

// Residual codes of up to kResidualPeekBits bits, per order: the bits a
// code takes (0: longer, read it the slow way) and its residual.
constexpr unsigned kResidualPeekBits = 10;
struct ResidualEntry {
  std::uint8_t bits;
  std::uint8_t value;
};
using ResidualTable = std::array<ResidualEntry, 1u << kResidualPeekBits>;
const ResidualTable& residual_table(unsigned order) {
  static const std::array<ResidualTable, kMaxResidualOrder + 1> tables = [] {
    std::array<ResidualTable, kMaxResidualOrder + 1> t{};
    for (unsigned k = 0; k <= kMaxResidualOrder; ++k) {
      for (std::uint32_t x = 0; x < (1u << kResidualPeekBits); ++x) {
        const auto lg = static_cast<unsigned>(std::countr_zero(x | (1u << kResidualPeekBits)));
        const unsigned bits = 2 * lg + 1 + k;
        if (lg > kMaxResidualZeros || bits > kResidualPeekBits) continue;
        const std::uint32_t w = (1u << lg) | ((x >> (lg + 1)) & ((1u << lg) - 1));
        const std::uint32_t u = ((w - 1) << k) | ((x >> (2 * lg + 1)) & ((1u << k) - 1));
        if (u > kMaxResidual) continue;
        t[k][x] = {static_cast<std::uint8_t>(bits), static_cast<std::uint8_t>(u)};
      }
    }
    return t;
  }();
  return tables[order];
}
// Reads a version-2 occupancy residual (an Exp-Golomb code of `order` for
// the residual + 1) into u, refilling first; returns nullptr, or why it is
// invalid (more than 8 zeros, or over 255).
inline const char* read_residual(BitReader& r, unsigned order, std::uint32_t& u) {
  r.refill();
  const unsigned lg = r.trailing_zeros();
  if (lg > kMaxResidualZeros) return kResidualCodeTooLong;
  r.skip(lg + 1);
  const std::uint32_t w = (std::uint32_t{1} << lg) | r.get(lg);
  u = ((w - 1) << order) | r.get(order);
  return u > kMaxResidual ? kResidualOutOfRange : nullptr;
}

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
// several in a row, so literals take a branch of their own. In version 2
// (predicted) a solid literal's occupancy is its residual, of Exp-Golomb
// order `order`, from predict_occupancy.
template <int n, bool predicted>
const char* decode_tokens_partial(BitReader& r, const Palette& palette, std::uint32_t ctx_info, unsigned order,
                                  Voxel* dst) {
  constexpr int volume = n * n * n;
  const TokenEntry* const tables = token_tables<n>();
  const LiteralCode lit(true, palette, !predicted);
  const ResidualEntry* const residuals = predicted ? residual_table(order).data() : nullptr;
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
      if constexpr (predicted) {
        const auto left = static_cast<int>(last >> 8);
        last = lc.payload;
        r.skip(lit_shift + lc.bits);
        if (lc.occupancy & 0x80) {
          r.refill();
          const ResidualEntry re = residuals[r.bits() & ((1u << kResidualPeekBits) - 1)];
          std::uint32_t u = re.value;
          if (re.bits != 0) [[likely]] {
            r.skip(re.bits);
          } else if (const char* invalid = read_residual(r, order, u)) {
            return invalid;
          }
          last |= std::uint32_t{occupancy_from_residual(predict_occupancy<n>(dst, i, left), u)} << 8;
          // The refill above left at least 56 bits, the residual took at
          // most 20 (the slow path refills on its own): two more tokens fit.
          until_refill = 2;
        }
      } else {
        last = literal(b, lc, lit_shift);
        r.skip(lit_shift + lc.bits);
      }
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

}  // namespace

// The unit's first byte picks its kind; palette kinds then read their bit stream.
template <int n>
Result<std::size_t> decode_unit(std::span<const std::uint8_t> bytes, std::span<Voxel> out) {
  constexpr int volume = n * n * n;
  const std::uint8_t head = bytes[0];
  const unsigned version = head & 0x0F;
  if (version != kNetCodecVersion1 && version != kNetCodecVersion2) {
    return DecodeError{DecodeErrorCode::kBadVersion, 0, "unknown unit format version"};
  }
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
    const unsigned bits = packed_index_bits(palette.count);
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
    const bool predicted = partial && version == kNetCodecVersion2;
    const unsigned order = predicted ? r.get(2) : 0;
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
    const char* invalid = nullptr;
    {
      const Material m = palette.materials[first_idx];
      Voxel x{m, default_occupancy(m)};
      if (predicted && m != kAir) {
        std::uint32_t u = 0;
        invalid = read_residual(r, order, u);
        x.occupancy = occupancy_from_residual(predict_occupancy<n>(dst, 0), u);
      } else if (partial && m != kAir && r.get(1) != 0) {  // version 1
        x.occupancy = static_cast<std::uint8_t>(r.get(8));
      }
      dst[0] = x;
    }
    if (invalid == nullptr) {
      invalid = predicted ? decode_tokens_partial<n, true>(r, palette, ctx_info, order, dst)
                : partial ? decode_tokens_partial<n, false>(r, palette, ctx_info, 0, dst)
                          : decode_tokens_solid<n>(r, palette, ctx_info, first_idx, dst);
    }
    if (invalid != nullptr) {
      // An over-long length or residual code: the zeros ran past the end
      // when no one bit follows before it (the reader fed them), else z > 12
      // (8 for a residual).
      if ((invalid == kLengthCodeTooLong || invalid == kResidualCodeTooLong) && !r.one_bit_ahead()) {
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

template Result<std::size_t> decode_unit<4>(std::span<const std::uint8_t> bytes, std::span<Voxel> out);
template Result<std::size_t> decode_unit<8>(std::span<const std::uint8_t> bytes, std::span<Voxel> out);
template Result<std::size_t> decode_unit<16>(std::span<const std::uint8_t> bytes, std::span<Voxel> out);

}  // namespace terrane::net_codec_detail
