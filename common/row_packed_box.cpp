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

namespace {
// Stores palette index j of voxel x in the index bytes (zeroed beforehand).
void put_index(std::uint8_t* idx, int n, int bits, int x, int j) {
  // 1 bit: plain bit order; 2 and 4 bits: voxel x in byte x % G at bit
  // b·(x / G); 3 bits: the low two as 2 bits, then bit 2 as 1 bit.
  if (bits == 3) {
    const int g2 = (2 * n + 7) / 8;
    idx[x % g2] = static_cast<std::uint8_t>(idx[x % g2] | ((j & 3) << (2 * (x / g2))));
    idx[g2 + x / 8] = static_cast<std::uint8_t>(idx[g2 + x / 8] | ((j >> 2) << (x % 8)));
    return;
  }
  const int groups = (n * bits + 7) / 8;
  const int byte = bits == 1 ? x / 8 : x % groups;
  const int shift = bits == 1 ? x % 8 : bits * (x / groups);
  idx[byte] = static_cast<std::uint8_t>(idx[byte] | (j << shift));
}
}  // namespace

bool encode_with_entry(const Voxel* row, int n, const std::uint8_t* entry, std::uint8_t* idx) {
  const unsigned info = entry[0];
  const int p = static_cast<int>(info & 15) + 1;
  const bool occ = (info & kTagOccupancy) != 0;
  const int bits = index_bits(info);
  std::memset(idx, 0, static_cast<std::size_t>(index_bytes(info, n)));
  for (int x = 0; x < n; ++x) {
    const Voxel v = row[x];
    if (!occ && !has_default_occupancy(v)) return false;
    int j = 0;
    while (j < p && !(entry[1 + j] == v.material && (!occ || entry[1 + p + j] == v.occupancy))) ++j;
    if (j == p) return false;
    put_index(idx, n, bits, x, j);
  }
  return true;
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

  // Distinct voxel values, sorted (material, then occupancy) so that rows
  // with the same set share one table entry; more than 16: raw.
  Voxel palette[kMaxPalette];
  int p = 0;
  for (int x = 0; x < n; ++x) {
    const Voxel v = row[x];
    int j = 0;
    while (j < p && (palette[j].material < v.material ||
                     (palette[j].material == v.material && palette[j].occupancy < v.occupancy)))
      ++j;
    if (j < p && palette[j] == v) continue;
    if (p == kMaxPalette) {
      std::memcpy(out, row, sizeof(Voxel) * static_cast<std::size_t>(n));
      return 2 * n;
    }
    for (int k = p; k > j; --k) palette[k] = palette[k - 1];
    palette[j] = v;
    ++p;
  }
  const int bits = p <= 2 ? 1 : p <= 4 ? 2 : p <= 8 ? 3 : 4;
  const int groups = (n * bits + 7) / 8;
  const int entry = 1 + p * (all_default ? 1 : 2);
  const int size = entry + groups;
  if (size >= 2 * n) {
    std::memcpy(out, row, sizeof(Voxel) * static_cast<std::size_t>(n));
    return 2 * n;
  }
  const int code = bits >= 3 ? 3 : bits;
  out[0] = static_cast<std::uint8_t>((code << 6) | (all_default ? 0 : kTagOccupancy) | (bits == 3 ? kTagThreeBits : 0) |
                                     (p - 1));
  for (int j = 0; j < p; ++j) {
    out[1 + j] = palette[j].material;
    if (!all_default) out[1 + p + j] = palette[j].occupancy;
  }
  std::uint8_t* idx = out + entry;
  std::memset(idx, 0, static_cast<std::size_t>(groups));
  for (int x = 0; x < n; ++x) {
    int j = 0;
    while (!(palette[j] == row[x])) ++j;
    put_index(idx, n, bits, x, j);
  }
  return size;
}

void decode_palette_scalar(const std::uint8_t* entry, const std::uint8_t* idx, Voxel* out, int n) {
  for (int x = 0; x < n; ++x) out[x] = palette_voxel(entry, idx, n, x);
}

#if defined(__x86_64__) || defined(__i386__)
const bool kHaveSsse3 = detect_ssse3();
#endif

}  // namespace terrane::row_packed_detail

namespace terrane {
template class RowPackedBox<4>;
template class RowPackedBox<8>;
template class RowPackedBox<16>;
template class RowPackedBox<32>;
}  // namespace terrane
