// The network voxel codec's unit encoder (see net_codec_encoder.h).
#include "common/codec/net_codec_encoder.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>

#include "common/codec/bit_io.h"
#include "common/codec/net_codec.h"
#include "common/codec/net_codec_tables.h"

namespace terrane::net_codec_detail {
namespace {

// Writes a run or copy length (>= 1) as an Exp-Golomb code of that order.
void eg_put(BitWriter& out, std::uint32_t length, unsigned order) {
  const std::uint32_t v = length - 1;
  const std::uint32_t w = (v >> order) + 1;
  const unsigned lg = static_cast<unsigned>(std::bit_width(w)) - 1;
  const std::uint32_t code = (std::uint32_t{1} << lg) | ((w ^ (std::uint32_t{1} << lg)) << (lg + 1)) |
                             ((v & ((std::uint32_t{1} << order) - 1)) << (2 * lg + 1));
  out.put(code, 2 * lg + 1 + order);
}

// The length of eg_put's code.
unsigned eg_bits(std::uint32_t length, unsigned order) {
  const std::uint32_t w = ((length - 1) >> order) + 1;
  return 2 * (static_cast<unsigned>(std::bit_width(w)) - 1) + 1 + order;
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
struct Token {
  TokenType type;
  std::uint16_t length;  // voxels covered (1 for literals)
  Material material;     // literals only
  std::uint8_t occupancy;
  std::uint8_t residual;  // version 2: the literal's occupancy residual (occupancy_residual)
};

// The palette header shared by token and packed units, then the partial flag.
void put_palette(BitWriter& w, const Palette& p, bool partial) {
  w.put(static_cast<std::uint32_t>(p.count - 1), 6);
  for (int i = 0; i < p.count; ++i) w.put(p.materials[static_cast<std::size_t>(i)], 6);
  w.put(partial ? 1u : 0u, 1);
}

// Writes a packed unit (kind 4) to dst; returns its size in bytes.
std::size_t write_packed(int n, const Voxel* v, const Palette& p, bool partial, std::uint8_t* dst) {
  const int volume = n * n * n;
  dst[0] = static_cast<std::uint8_t>(kNetCodecVersion1 | (kKindPacked << 4));
  BitWriter w(dst + 1);
  put_palette(w, p, partial);
  const unsigned bits = packed_index_bits(p.count);
  for (int i = 0; i < volume; ++i) {
    w.put(static_cast<std::uint32_t>(p.index[v[i].material]), bits);
    if (partial && v[i].material != kAir) w.put(v[i].occupancy, 8);
  }
  return 1 + w.finish();
}

// The size of a packed unit in bits, without its first byte.
std::size_t packed_bits(int n, int palette_count, int solid_count, bool partial) {
  const std::size_t volume = static_cast<std::size_t>(n) * n * n;
  const unsigned bits = packed_index_bits(palette_count);
  return 6 + 6 * static_cast<std::size_t>(palette_count) + 1 + volume * bits +
         (partial ? 8 * static_cast<std::size_t>(solid_count) : 0);
}

}  // namespace

// Greedy parse, then the smallest of the encodings (see net_codec_encoder.h).
template <int n>
void encode_unit(const Voxel* v, std::vector<std::uint8_t>& out, std::uint8_t version) {
  constexpr int volume = n * n * n;
  // Version 2 differs from version 1 only in a token unit with predicted
  // occupancies: every other unit is written as version 1, which readers of
  // either version read.
  const bool may_predict = version == kNetCodecVersion2;
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
  tokens[0] = {kLit, 1, first.material, first.occupancy, 0};
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
      tokens[static_cast<std::size_t>(token_count++)] = {kLit, 1, x.material, x.occupancy, 0};
      ++literal_freq[x.material];
      present |= std::uint64_t{1} << x.material;
      partial |= x.material != kAir && x.occupancy != kFullOccupancy;
      type = kLit;
      best = 1;
    } else {
      tokens[static_cast<std::size_t>(token_count++)] = {static_cast<TokenType>(type), static_cast<std::uint16_t>(best), 0, 0, 0};
    }
    ++transitions[static_cast<std::size_t>(prev)][static_cast<std::size_t>(type)];
    prev = type;
    i += best;
  }

  if (token_count == 2 && tokens[1].type == kRun) {  // uniform unit
    if (first.material == kAir) {
      out.push_back(static_cast<std::uint8_t>(kNetCodecVersion1 | (kKindAir << 4)));
    } else if (first.occupancy == kFullOccupancy) {
      out.push_back(static_cast<std::uint8_t>(kNetCodecVersion1 | (kKindUniform << 4)));
      out.push_back(first.material);
    } else {
      out.push_back(static_cast<std::uint8_t>(kNetCodecVersion1 | (kKindUniformOcc << 4)));
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
    const int ranks = context_ranks(p);
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
    const int ranks = context_ranks(p);
    for (int r = 0; r < ranks; ++r) {
      encode_words[static_cast<std::size_t>(p)][codes[static_cast<std::size_t>(p)].rank[static_cast<std::size_t>(r)]] = code_word(p, r);
    }
  }

  // Version 2: each solid literal's occupancy as its residual from the
  // prediction, in the Exp-Golomb order that makes them shortest.
  // Where the occupancies are not smooth (a surface one voxel thick, whose
  // neighbours are Air or full), version 1's flag and byte may be shorter:
  // then the unit stays version 1.
  bool predicted = may_predict && partial;
  unsigned residual_order = 0;
  if (predicted) {
    std::array<std::size_t, kMaxResidualOrder + 1> order_bits{};
    std::size_t flagged_bits = 0;  // version 1's flags and bytes
    int at = 0;
    for (int t = 0; t < token_count; ++t) {
      Token& tok = tokens[static_cast<std::size_t>(t)];
      if (tok.type == kLit && tok.material != kAir) {
        const std::uint32_t u = occupancy_residual(tok.occupancy, predict_occupancy<n>(v, at));
        tok.residual = static_cast<std::uint8_t>(u);
        for (unsigned k = 0; k <= kMaxResidualOrder; ++k) order_bits[k] += eg_bits(u + 1, k);
        flagged_bits += tok.occupancy == kFullOccupancy ? 1 : 9;
      }
      at += tok.length;
    }
    residual_order = static_cast<unsigned>(std::min_element(order_bits.begin(), order_bits.end()) - order_bits.begin());
    predicted = order_bits[residual_order] + 2 < flagged_bits;
  }

  std::array<std::uint8_t, net_codec_max_encoded_size(16) + 64> scratch;  // NOLINT: written before read
  // The token stream must beat both fallbacks (packed, and raw for tiny units).
  const std::size_t packed_limit = packed_bits(n, palette.count, solid_count, partial);
  const std::size_t raw_limit = 16 * static_cast<std::size_t>(volume);
  const std::size_t limit_bits = std::min(packed_limit, raw_limit);
  // Token streams never need more than 18 bits per voxel; stop as soon as
  // the packed form would be smaller (it bounds the worst case).
  std::array<std::uint8_t, 3 * kMaxVolume + 64> token_buf;  // NOLINT: written before read
  token_buf[0] = static_cast<std::uint8_t>((predicted ? kNetCodecVersion2 : kNetCodecVersion1) | (kKindTokens << 4));
  BitWriter w(token_buf.data() + 1);
  put_palette(w, palette, partial);
  if (predicted) w.put(residual_order, 2);
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
      if (predicted) {
        full_code.put(w, idx);
        if (tok.material != kAir) eg_put(w, std::uint32_t{tok.residual} + 1, residual_order);
      } else if (partial) {
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
    out.push_back(static_cast<std::uint8_t>(kNetCodecVersion1 | (kKindRaw << 4)));
    for (int i = 0; i < volume; ++i) {
      out.push_back(v[i].material);
      out.push_back(v[i].occupancy);
    }
    return;
  }
  const std::size_t size = write_packed(n, v, palette, partial, scratch.data());
  out.insert(out.end(), scratch.data(), scratch.data() + size);
}

template void encode_unit<4>(const Voxel* v, std::vector<std::uint8_t>& out, std::uint8_t version);
template void encode_unit<8>(const Voxel* v, std::vector<std::uint8_t>& out, std::uint8_t version);
template void encode_unit<16>(const Voxel* v, std::vector<std::uint8_t>& out, std::uint8_t version);

}  // namespace terrane::net_codec_detail
