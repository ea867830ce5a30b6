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

// A 32-bit bitmap (its bytes 0..3 in the low dword of b) as one byte per
// bit, 0xFF where set: bits 0..15 in lo, 16..31 in hi.
__attribute__((target("ssse3"))) inline void bitmap_lanes(__m128i b, __m128i& lo, __m128i& hi) {
  const __m128i bit = _mm_set1_epi64x(static_cast<long long>(0x8040201008040201ull));
  lo = _mm_cmpeq_epi8(_mm_and_si128(_mm_shuffle_epi8(b, _mm_set_epi8(1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0)), bit), bit);
  hi = _mm_cmpeq_epi8(_mm_and_si128(_mm_shuffle_epi8(b, _mm_set_epi8(3, 3, 3, 3, 3, 3, 3, 3, 2, 2, 2, 2, 2, 2, 2, 2)), bit), bit);
}

// Lanes of 0 or 0xFF (-1) over 32 lanes -> in each lane, minus the count of
// set lanes at or before it (prefix sums, lo then hi).
__attribute__((target("ssse3"))) inline void prefix_counts(__m128i& lo, __m128i& hi) {
  lo = _mm_add_epi8(lo, _mm_slli_si128(lo, 1));
  hi = _mm_add_epi8(hi, _mm_slli_si128(hi, 1));
  lo = _mm_add_epi8(lo, _mm_slli_si128(lo, 2));
  hi = _mm_add_epi8(hi, _mm_slli_si128(hi, 2));
  lo = _mm_add_epi8(lo, _mm_slli_si128(lo, 4));
  hi = _mm_add_epi8(hi, _mm_slli_si128(hi, 4));
  lo = _mm_add_epi8(lo, _mm_slli_si128(lo, 8));
  hi = _mm_add_epi8(hi, _mm_slli_si128(hi, 8));
  hi = _mm_add_epi8(hi, _mm_shuffle_epi8(lo, _mm_set1_epi8(15)));
}

// Entries of a 32-entry table (entries 0..15 in low, 16..31 in high)
// picked by lanes of indices 0..31. (Where every index is below 16, one
// pshufb of low does.)
__attribute__((target("ssse3"))) inline __m128i pick32(__m128i low, __m128i high, __m128i index) {
  const __m128i upper = _mm_cmpgt_epi8(index, _mm_set1_epi8(15));
  return _mm_or_si128(_mm_and_si128(upper, _mm_shuffle_epi8(high, index)),  // (pshufb takes the low 4 bits)
                      _mm_andnot_si128(upper, _mm_shuffle_epi8(low, index)));
}

// Indices of voxels 0..15 and 16..31 (one per byte) for every index width at
// once, then the row's own picked by kIndexSelect. 1 bit: each index byte is
// broadcast over 8 lanes and tested against its bit; 2 and 4 bits: voxel x is
// in index byte x % G at bit b·(x / G), so whole-register 16-bit shifts line
// the groups up (bits crossing into a neighbouring byte are masked off).
// Runs: a bitmap of run starts, summed along the row into run numbers.
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
    // Runs: a bit per run start (runs 1..R-1; run 0 starts at 0), spread
    // to one byte per voxel as for 1-bit indices, then summed along the row
    // into each voxel's run number, which picks its run's palette index.
    // The bitmap of runs 1..15 without a loop: each run's bit (1 << first x
    // % 8) summed per bitmap byte (first x / 8) by psadbw; the first x are
    // distinct, so the sums are the bits' union. (The body is followed by
    // at least 16 readable bytes.)
    const unsigned runs = (body[0] & 31) + 1;  // the first run's byte holds R - 1
    const __m128i zero = _mm_setzero_si128();
    const __m128i iota_lo = _mm_setr_epi8(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const __m128i body_lo = _mm_loadu_si128(reinterpret_cast<const __m128i*>(body));
    const __m128i first_x = _mm_and_si128(body_lo, _mm_set1_epi8(31));
    const __m128i counted = _mm_andnot_si128(_mm_cmpeq_epi8(iota_lo, zero),
                                             _mm_cmpgt_epi8(_mm_set1_epi8(static_cast<char>(runs)), iota_lo));
    const __m128i run_bit = _mm_and_si128(
        _mm_shuffle_epi8(_mm_setr_epi8(1, 2, 4, 8, 16, 32, 64, -128, 1, 2, 4, 8, 16, 32, 64, -128), first_x), counted);
    const __m128i bitmap_byte = _mm_and_si128(_mm_srli_epi16(first_x, 3), _mm_set1_epi8(3));
    const auto byte_sum = [&](int k) {
      return _mm_sad_epu8(_mm_and_si128(_mm_cmpeq_epi8(bitmap_byte, _mm_set1_epi8(static_cast<char>(k))), run_bit), zero);
    };
    __m128i s = _mm_or_si128(_mm_or_si128(byte_sum(0), _mm_slli_epi64(byte_sum(1), 8)),
                             _mm_or_si128(_mm_slli_epi64(byte_sum(2), 16), _mm_slli_epi64(byte_sum(3), 24)));
    s = _mm_add_epi64(s, _mm_unpackhi_epi64(s, s));
    if (runs > 16) {
      std::uint32_t more = 0;
      for (unsigned r = 16; r < runs; ++r) more |= 1u << (body[r] & 31);
      s = _mm_or_si128(s, _mm_cvtsi32_si128(static_cast<int>(more)));
    }
    // 0xFF (-1) where a run starts; prefix counts give minus the run number.
    __m128i n_lo, n_hi;
    bitmap_lanes(s, n_lo, n_hi);
    prefix_counts(n_lo, n_hi);
    const __m128i run_lo = _mm_sub_epi8(zero, n_lo);  // 0..15
    const __m128i run_hi = _mm_sub_epi8(zero, n_hi);  // 0..R-1
    // Each run's palette index (its byte >> 5), for runs 0..15 and 16..31.
    const __m128i sevens = _mm_set1_epi8(7);
    const __m128i index0 = _mm_and_si128(_mm_srli_epi16(body_lo, 5), sevens);
    lo = _mm_shuffle_epi8(index0, run_lo);
    hi = runs <= 16 ? _mm_shuffle_epi8(index0, run_hi)
                    : pick32(index0, _mm_and_si128(_mm_srli_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(body + 16)), 5), sevens),
                             run_hi);
    end = body + runs;
  } else {
    const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(body));
    __m128i lo1, hi1;
    bitmap_lanes(v, lo1, hi1);  // 1 bit: the first 4 bytes as a bitmap
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
  __m128i o_lo = _mm_xor_si128(_mm_cmpeq_epi8(m_lo, zero), ones);
  __m128i o_hi = _mm_xor_si128(_mm_cmpeq_epi8(m_hi, zero), ones);
  if (tag & 0x20) {
    // The section's bytes go, in order, to the voxels its bitmap names:
    // voxel x takes byte (set bits at or before x) - 1, without a loop.
    std::uint32_t bits;
    std::memcpy(&bits, end, 4);
    const std::uint8_t* occ = end + 4;
    __m128i set_lo, set_hi;
    bitmap_lanes(_mm_cvtsi32_si128(static_cast<int>(bits)), set_lo, set_hi);
    __m128i at_lo = set_lo, at_hi = set_hi;
    prefix_counts(at_lo, at_hi);  // -(count), so the byte's index is ~at
    const __m128i occ_lo = _mm_loadu_si128(reinterpret_cast<const __m128i*>(occ));
    const __m128i v_lo = _mm_shuffle_epi8(occ_lo, _mm_xor_si128(at_lo, ones));  // indices 0..15 where set
    const __m128i index_hi = _mm_and_si128(_mm_xor_si128(at_hi, ones), _mm_set1_epi8(31));
    const __m128i v_hi = std::popcount(bits) <= 16
                             ? _mm_shuffle_epi8(occ_lo, index_hi)
                             : pick32(occ_lo, _mm_loadu_si128(reinterpret_cast<const __m128i*>(occ + 16)), index_hi);
    o_lo = _mm_or_si128(_mm_and_si128(set_lo, v_lo), _mm_andnot_si128(set_lo, o_lo));
    o_hi = _mm_or_si128(_mm_and_si128(set_hi, v_hi), _mm_andnot_si128(set_hi, o_hi));
  }
  auto* dst = reinterpret_cast<__m128i*>(out);
  _mm_storeu_si128(dst + 0, _mm_unpacklo_epi8(m_lo, o_lo));
  _mm_storeu_si128(dst + 1, _mm_unpackhi_epi8(m_lo, o_lo));
  _mm_storeu_si128(dst + 2, _mm_unpacklo_epi8(m_hi, o_hi));
  _mm_storeu_si128(dst + 3, _mm_unpackhi_epi8(m_hi, o_hi));
}

}  // namespace terrane::row_packed_detail
#endif
