// SSSE3 decoder of 32-wide palette row records, inline so that builds with
// SSSE3 enabled (the default x86-64-v2 level, see TERRANE_X86_LEVEL) read
// rows without a call; other builds reach it through a runtime check.
// Included by row_packed_box.h only.
#pragma once

#if defined(__x86_64__) || defined(__i386__)
#include <tmmintrin.h>

#include <cstdint>

#include "common/voxel/voxel.h"

namespace terrane::row_packed_detail {

struct alignas(16) IndexSelect {
  std::uint8_t bits1[16], bits2[16], bits4[16];
};
inline constexpr IndexSelect make_select(int code) {
  IndexSelect s{};
  for (int i = 0; i < 16; ++i) {
    s.bits1[i] = code == 1 ? 0x01 : 0;
    s.bits2[i] = code == 2 ? 0x03 : 0;
    s.bits4[i] = code == 3 ? 0x0F : 0;
  }
  return s;
}
inline constexpr IndexSelect kIndexSelect[4] = {make_select(0), make_select(1), make_select(2), make_select(3)};

// Indices of voxels 0..15 and 16..31 (one per byte) for every index width at
// once, then the row's own picked by kIndexSelect. 1 bit: each index byte is
// broadcast over 8 lanes and tested against its bit; 2 and 4 bits: voxel x is
// in index byte x % G at bit b·(x / G), so whole-register 16-bit shifts line
// the groups up (bits crossing into a neighbouring byte are masked off).
__attribute__((target("ssse3"))) inline void decode_palette32_ssse3(const std::uint8_t* rec, Voxel* out) {
  const unsigned tag = rec[0];
  const unsigned p = (tag & 15) + 1;
  const unsigned occ = (tag >> 5) & 1;
  const __m128i pal_m = _mm_loadu_si128(reinterpret_cast<const __m128i*>(rec + 1));
  // Occupancy palette: stored, or the default occupancy of each material
  // (255 unless Air), chosen without a branch.
  const __m128i stored_o = _mm_loadu_si128(reinterpret_cast<const __m128i*>(rec + 1 + p));
  const __m128i default_o = _mm_xor_si128(_mm_cmpeq_epi8(pal_m, _mm_setzero_si128()), _mm_set1_epi8(-1));
  const __m128i use_stored = _mm_set1_epi8(static_cast<char>(-static_cast<int>(occ)));
  const __m128i pal_o = _mm_or_si128(_mm_and_si128(use_stored, stored_o), _mm_andnot_si128(use_stored, default_o));

  const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(rec + 1 + p + p * occ));
  const __m128i bit = _mm_set1_epi64x(static_cast<long long>(0x8040201008040201ull));
  const __m128i lo1 = _mm_cmpeq_epi8(_mm_and_si128(_mm_shuffle_epi8(v, _mm_set_epi8(1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0)), bit), bit);
  const __m128i hi1 = _mm_cmpeq_epi8(_mm_and_si128(_mm_shuffle_epi8(v, _mm_set_epi8(3, 3, 3, 3, 3, 3, 3, 3, 2, 2, 2, 2, 2, 2, 2, 2)), bit), bit);
  const __m128i s2 = _mm_srli_epi16(v, 2);
  const __m128i s4 = _mm_srli_epi16(v, 4);
  const __m128i s6 = _mm_srli_epi16(v, 6);
  const __m128i lo2 = _mm_unpacklo_epi64(v, s2);
  const __m128i hi2 = _mm_unpacklo_epi64(s4, s6);
  const IndexSelect& sel = kIndexSelect[tag >> 6];
  const __m128i m1 = _mm_load_si128(reinterpret_cast<const __m128i*>(sel.bits1));
  const __m128i m2 = _mm_load_si128(reinterpret_cast<const __m128i*>(sel.bits2));
  const __m128i m4 = _mm_load_si128(reinterpret_cast<const __m128i*>(sel.bits4));
  const __m128i lo = _mm_or_si128(_mm_or_si128(_mm_and_si128(lo1, m1), _mm_and_si128(lo2, m2)), _mm_and_si128(v, m4));
  const __m128i hi = _mm_or_si128(_mm_or_si128(_mm_and_si128(hi1, m1), _mm_and_si128(hi2, m2)), _mm_and_si128(s4, m4));
  const __m128i m_lo = _mm_shuffle_epi8(pal_m, lo);
  const __m128i m_hi = _mm_shuffle_epi8(pal_m, hi);
  const __m128i o_lo = _mm_shuffle_epi8(pal_o, lo);
  const __m128i o_hi = _mm_shuffle_epi8(pal_o, hi);
  auto* dst = reinterpret_cast<__m128i*>(out);
  _mm_storeu_si128(dst + 0, _mm_unpacklo_epi8(m_lo, o_lo));
  _mm_storeu_si128(dst + 1, _mm_unpackhi_epi8(m_lo, o_lo));
  _mm_storeu_si128(dst + 2, _mm_unpacklo_epi8(m_hi, o_hi));
  _mm_storeu_si128(dst + 3, _mm_unpackhi_epi8(m_hi, o_hi));
}

}  // namespace terrane::row_packed_detail
#endif
