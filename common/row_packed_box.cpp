#include "common/row_packed_box.h"

#include <cstring>

#if defined(__x86_64__) || defined(__i386__)
#include <tmmintrin.h>
#endif

namespace terrane::row_packed_detail {
namespace {

constexpr int kMaxRow = 32;

constexpr auto make_uniform_rows() {
  std::array<std::array<Voxel, kMaxRow>, kMaterialCount> rows{};
  for (int m = 0; m < kMaterialCount; ++m)
    for (auto& v : rows[m]) v = solid(static_cast<Material>(m));
  return rows;
}

template <int N>
constexpr auto make_uniform_headers() {
  std::array<std::array<std::uint16_t, N * N>, kMaterialCount> headers{};
  for (int m = 0; m < kMaterialCount; ++m)
    for (auto& h : headers[m]) h = static_cast<std::uint16_t>(m);
  return headers;
}

constexpr auto kHeaders4 = make_uniform_headers<4>();
constexpr auto kHeaders8 = make_uniform_headers<8>();
constexpr auto kHeaders16 = make_uniform_headers<16>();
constexpr auto kHeaders32 = make_uniform_headers<32>();

#if defined(__x86_64__) || defined(__i386__)
bool detect_ssse3() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("ssse3");
}
#endif

}  // namespace

constinit const std::array<std::array<Voxel, 32>, kMaterialCount> kUniformRows = make_uniform_rows();

const std::uint16_t* uniform_headers(int size, Material material) {
  const int m = material & 63;
  switch (size) {
    case 4: return kHeaders4[m].data();
    case 8: return kHeaders8[m].data();
    case 16: return kHeaders16[m].data();
    default: return kHeaders32[m].data();
  }
}

int encode_row(const Voxel* row, int n, std::uint8_t* out) {
  const Voxel first = row[0];
  bool uniform = true;
  bool all_default = true;
  for (int i = 0; i < n; ++i) {
    uniform &= row[i] == first;
    all_default &= has_default_occupancy(row[i]);
  }
  if (uniform && all_default) return 0;

  // Palette in order of first appearance; more than 16 voxel values: raw.
  Voxel palette[kMaxPalette];
  std::uint8_t index[kMaxRow];
  int p = 0;
  for (int x = 0; x < n; ++x) {
    int j = 0;
    while (j < p && !(palette[j] == row[x])) ++j;
    if (j == p) {
      if (p == kMaxPalette) {
        std::memcpy(out, row, sizeof(Voxel) * static_cast<std::size_t>(n));
        return 2 * n;
      }
      palette[p++] = row[x];
    }
    index[x] = static_cast<std::uint8_t>(j);
  }
  const int bits = p <= 2 ? 1 : p <= 4 ? 2 : 4;
  const int groups = (n * bits + 7) / 8;
  const int entry_bytes = all_default ? 1 : 2;
  const int size = 1 + p * entry_bytes + groups;
  const int padded = (size + 1) & ~1;
  if (padded >= 2 * n) {
    std::memcpy(out, row, sizeof(Voxel) * static_cast<std::size_t>(n));
    return 2 * n;
  }
  const int code = bits == 4 ? 3 : bits;
  out[0] = static_cast<std::uint8_t>((code << 6) | (all_default ? 0 : kTagOccupancy) | (p - 1));
  for (int j = 0; j < p; ++j) {
    out[1 + j] = palette[j].material;
    if (!all_default) out[1 + p + j] = palette[j].occupancy;
  }
  std::uint8_t* idx = out + 1 + p * entry_bytes;
  std::memset(idx, 0, static_cast<std::size_t>(padded - (1 + p * entry_bytes)));  // indices and pad byte
  for (int x = 0; x < n; ++x) {
    // 1 bit: plain bit order; 2 and 4 bits: voxel x in byte x % G at bit b·(x / G).
    const int byte = bits == 1 ? x / 8 : x % groups;
    const int shift = bits == 1 ? x % 8 : bits * (x / groups);
    idx[byte] = static_cast<std::uint8_t>(idx[byte] | (index[x] << shift));
  }
  return padded;
}

void decode_palette_scalar(const std::uint8_t* rec, Voxel* out, int n) {
  for (int x = 0; x < n; ++x) out[x] = palette_voxel(rec, n, x);
}

#if defined(__x86_64__) || defined(__i386__)
const bool kHaveSsse3 = detect_ssse3();

// Selection masks per index width (tag >> 6): each row form's candidate
// indices are masked with its entry, so the decoder has no data-dependent
// branch (the three forms are mixed unpredictably along a chunk).
struct alignas(16) IndexSelect {
  std::uint8_t bits1[16], bits2[16], bits4[16];
};
constexpr IndexSelect make_select(int code) {
  IndexSelect s{};
  for (int i = 0; i < 16; ++i) {
    s.bits1[i] = code == 1 ? 0x01 : 0;
    s.bits2[i] = code == 2 ? 0x03 : 0;
    s.bits4[i] = code == 3 ? 0x0F : 0;
  }
  return s;
}
constexpr IndexSelect kIndexSelect[4] = {make_select(0), make_select(1), make_select(2), make_select(3)};

// Indices of voxels 0..15 and 16..31 (one per byte) for every index width at
// once, then the row's own picked by kIndexSelect. 1 bit: each index byte is
// broadcast over 8 lanes and tested against its bit; 2 and 4 bits: voxel x is
// in index byte x % G at bit b·(x / G), so whole-register 16-bit shifts line
// the groups up (bits crossing into a neighbouring byte are masked off).
__attribute__((target("ssse3"))) void decode_palette32_ssse3(const std::uint8_t* rec, Voxel* out) {
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
#endif

}  // namespace terrane::row_packed_detail

namespace terrane {
template class RowPackedBox<4>;
template class RowPackedBox<8>;
template class RowPackedBox<16>;
template class RowPackedBox<32>;
}  // namespace terrane
