#include "common/voxel/row_packed_box.h"

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
#endif

}  // namespace terrane::row_packed_detail

namespace terrane {
template class RowPackedBox<4>;
template class RowPackedBox<8>;
template class RowPackedBox<16>;
template class RowPackedBox<32>;
}  // namespace terrane
