// SSSE3 decoder of 32-wide index and run records, inline so that builds with
// SSSE3 enabled (the default x86-64-v2 level, see TERRANE_X86_LEVEL) read
// rows without a call; other builds reach it through a runtime check.
// Included by row_packed_box.h only, after the record constants.
#pragma once

#if defined(__x86_64__) || defined(__i386__)
#include <tmmintrin.h>

#include <bit>
#include <cstdint>
#include <cstring>

#include "common/voxel/voxel.h"

namespace terrane::row_packed_detail {

struct alignas(16) IndexSelect {
  std::uint8_t bits1[16], bits2[16], bits4[16];
};
inline constexpr IndexSelect make_select(int bits) {
  IndexSelect s{};
  for (int i = 0; i < 16; ++i) {
    s.bits1[i] = bits == 1 ? 0x01 : 0;
    s.bits2[i] = bits == 2 ? 0x03 : 0;
    s.bits4[i] = bits == 4 ? 0x0F : 0;
  }
  return s;
}
// By palette size P - 1 (0..15): the masks of that index width.
inline constexpr IndexSelect kIndexSelect[16] = {
    make_select(1), make_select(1), make_select(2), make_select(2), make_select(4), make_select(4),
    make_select(4), make_select(4), make_select(4), make_select(4), make_select(4), make_select(4),
    make_select(4), make_select(4), make_select(4), make_select(4)};

// Indices of voxels 0..15 and 16..31 (one per byte) for every index width at
// once, then the row's own picked by kIndexSelect. 1 bit: each index byte is
// broadcast over 8 lanes and tested against its bit; 2 and 4 bits: voxel x is
// in index byte x % G at bit b·(x / G), so whole-register 16-bit shifts line
// the groups up (bits crossing into a neighbouring byte are masked off).
// Runs: each run's index is blended into the lanes at or after its first x.
// Occupancy: the material's default (255 unless Air), then the section's
// bytes at the voxels its bitmap names.
__attribute__((target("ssse3"))) inline void decode_record32_ssse3(const std::uint8_t* rec, const std::uint8_t* table,
                                                                   Voxel* out) {
  const unsigned tag = rec[0];
  const bool inline_palette = (tag & 31) == 31;
  const std::uint8_t* pal = inline_palette ? rec + 1 : table + table[1 + (tag & 31)];
  const unsigned p1 = pal[0];  // P - 1
  const std::uint8_t* body = inline_palette ? rec + 3 + p1 : rec + 1;
  const __m128i pal_m = _mm_loadu_si128(reinterpret_cast<const __m128i*>(pal + 1));
  __m128i lo, hi;
  const std::uint8_t* end;
  if ((tag & 0xC0) == 0x80) {
    const unsigned runs = (body[0] & 31) + 1;  // the first run's byte holds R - 1
    const __m128i iota_lo = _mm_setr_epi8(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const __m128i iota_hi = _mm_add_epi8(iota_lo, _mm_set1_epi8(16));
    lo = _mm_set1_epi8(static_cast<char>(body[0] >> 5));
    hi = lo;
    for (unsigned r = 1; r < runs; ++r) {
      const unsigned b = body[r];
      const __m128i start = _mm_set1_epi8(static_cast<char>((b & 31) - 1));
      const __m128i idx = _mm_set1_epi8(static_cast<char>(b >> 5));
      const __m128i in_lo = _mm_cmpgt_epi8(iota_lo, start);
      const __m128i in_hi = _mm_cmpgt_epi8(iota_hi, start);
      lo = _mm_or_si128(_mm_and_si128(in_lo, idx), _mm_andnot_si128(in_lo, lo));
      hi = _mm_or_si128(_mm_and_si128(in_hi, idx), _mm_andnot_si128(in_hi, hi));
    }
    end = body + runs;
  } else {
    const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(body));
    const __m128i bit = _mm_set1_epi64x(static_cast<long long>(0x8040201008040201ull));
    const __m128i lo1 = _mm_cmpeq_epi8(_mm_and_si128(_mm_shuffle_epi8(v, _mm_set_epi8(1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0)), bit), bit);
    const __m128i hi1 = _mm_cmpeq_epi8(_mm_and_si128(_mm_shuffle_epi8(v, _mm_set_epi8(3, 3, 3, 3, 3, 3, 3, 3, 2, 2, 2, 2, 2, 2, 2, 2)), bit), bit);
    const __m128i s2 = _mm_srli_epi16(v, 2);
    const __m128i s4 = _mm_srli_epi16(v, 4);
    const __m128i s6 = _mm_srli_epi16(v, 6);
    const __m128i lo2 = _mm_unpacklo_epi64(v, s2);
    const __m128i hi2 = _mm_unpacklo_epi64(s4, s6);
    const IndexSelect& sel = kIndexSelect[p1 & 15];
    const __m128i m1 = _mm_load_si128(reinterpret_cast<const __m128i*>(sel.bits1));
    const __m128i m2 = _mm_load_si128(reinterpret_cast<const __m128i*>(sel.bits2));
    const __m128i m4 = _mm_load_si128(reinterpret_cast<const __m128i*>(sel.bits4));
    lo = _mm_or_si128(_mm_or_si128(_mm_and_si128(lo1, m1), _mm_and_si128(lo2, m2)), _mm_and_si128(v, m4));
    hi = _mm_or_si128(_mm_or_si128(_mm_and_si128(hi1, m1), _mm_and_si128(hi2, m2)), _mm_and_si128(s4, m4));
    end = body + (p1 < 2 ? 4 : p1 < 4 ? 8 : 16);
  }
  const __m128i m_lo = _mm_shuffle_epi8(pal_m, lo);
  const __m128i m_hi = _mm_shuffle_epi8(pal_m, hi);
  const __m128i ones = _mm_set1_epi8(-1);
  const __m128i zero = _mm_setzero_si128();
  const __m128i o_lo = _mm_xor_si128(_mm_cmpeq_epi8(m_lo, zero), ones);
  const __m128i o_hi = _mm_xor_si128(_mm_cmpeq_epi8(m_hi, zero), ones);
  auto* dst = reinterpret_cast<__m128i*>(out);
  _mm_storeu_si128(dst + 0, _mm_unpacklo_epi8(m_lo, o_lo));
  _mm_storeu_si128(dst + 1, _mm_unpackhi_epi8(m_lo, o_lo));
  _mm_storeu_si128(dst + 2, _mm_unpacklo_epi8(m_hi, o_hi));
  _mm_storeu_si128(dst + 3, _mm_unpackhi_epi8(m_hi, o_hi));
  if (tag & 0x20) {
    std::uint32_t bits;
    std::memcpy(&bits, end, 4);
    const std::uint8_t* occ = end + 4;
    while (bits != 0) {
      out[std::countr_zero(bits)].occupancy = *occ++;
      bits &= bits - 1;
    }
  }
}

}  // namespace terrane::row_packed_detail
#endif
