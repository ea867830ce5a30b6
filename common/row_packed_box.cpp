#include "common/row_packed_box.h"

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

}  // namespace terrane::row_packed_detail

namespace terrane {
template class RowPackedBox<4>;
template class RowPackedBox<8>;
template class RowPackedBox<16>;
template class RowPackedBox<32>;
}  // namespace terrane
