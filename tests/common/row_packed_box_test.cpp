#include "common/row_packed_box.h"

#include <gtest/gtest.h>

#include <random>

#include "common/box.h"

namespace terrane {
namespace {

template <int N>
void expect_equal(const RowPackedBox<N>& packed, const Box& ref, const char* when) {
  typename RowPackedBox<N>::Row scratch;
  for (int y = 0; y < N; ++y) {
    for (int z = 0; z < N; ++z) {
      const Voxel* row = packed.read_row(y, z, scratch);
      for (int x = 0; x < N; ++x) {
        ASSERT_EQ(row[x], ref.get(x, y, z)) << when << " at " << x << "," << y << "," << z;
        ASSERT_EQ(packed.get(x, y, z), ref.get(x, y, z)) << when;
      }
    }
  }
}

// Content generators for a write: uniform solid, uniform Air, block-world
// materials at default occupancy, smooth partial occupancy, random garbage.
Voxel random_voxel(std::mt19937& rng, int style) {
  std::uniform_int_distribution<int> mat(0, 63), few(1, 4), occ(0, 255);
  switch (style) {
    case 0: return solid(static_cast<Material>(few(rng)));
    case 1: return Voxel{};
    case 2: return solid(static_cast<Material>(few(rng) % 3));
    case 3: return make_voxel(static_cast<Material>(few(rng)), static_cast<std::uint8_t>(occ(rng)));
    default: return make_voxel(static_cast<Material>(mat(rng)), static_cast<std::uint8_t>(occ(rng)));
  }
}

template <class T>
class RowPackedBoxTest : public ::testing::Test {};
using Sizes = ::testing::Types<std::integral_constant<int, 4>, std::integral_constant<int, 8>,
                               std::integral_constant<int, 16>, std::integral_constant<int, 32>>;
TYPED_TEST_SUITE(RowPackedBoxTest, Sizes);

TYPED_TEST(RowPackedBoxTest, EqualsUnpackedReferenceUnderRandomWrites) {
  constexpr int N = TypeParam::value;
  std::mt19937 rng(1234 + N);
  RowPackedBox<N> packed;
  Box ref({N, N, N});
  std::uniform_int_distribution<int> coord(0, N - 1), kind(0, 5), style(0, 4);
  for (int step = 0; step < 400; ++step) {
    const int k = kind(rng);
    const int st = style(rng);
    if (k == 0) {
      const int x = coord(rng), y = coord(rng), z = coord(rng);
      const Voxel v = random_voxel(rng, st);
      packed.set(x, y, z, v);
      ref.set(x, y, z, v);
    } else {
      int y0 = coord(rng), y1 = coord(rng), z0 = coord(rng), z1 = coord(rng), x0 = coord(rng), x1 = coord(rng);
      if (k == 5) {  // whole box
        x0 = y0 = z0 = 0;
        x1 = y1 = z1 = N - 1;
      }
      if (y0 > y1) std::swap(y0, y1);
      if (z0 > z1) std::swap(z0, z1);
      if (x0 > x1) std::swap(x0, x1);
      const bool uniform_fill = k <= 2;
      const Voxel fill = random_voxel(rng, st);
      packed.modify_rows(y0, y1 + 1, z0, z1 + 1, [&](int y, int z, Voxel* row) {
        for (int x = x0; x <= x1; ++x) {
          const Voxel v = uniform_fill ? fill : random_voxel(rng, st);
          row[x] = v;
          ref.set(x, y, z, v);
        }
      });
    }
    expect_equal(packed, ref, "after write");
    if (::testing::Test::HasFatalFailure()) return;
    const RowPackedStats s = packed.stats();
    ASSERT_EQ(s.uniform_rows + s.raw_rows + s.byte_rows, static_cast<std::size_t>(N * N));
    if (step % 50 == 49) {
      packed.compact();
      expect_equal(packed, ref, "after compact");
    }
  }
}

TEST(RowPackedBox, UniformBoxOwnsNoMemory) {
  RowPackedBox<32> box(materials::kRock);
  EXPECT_TRUE(box.is_uniform());
  EXPECT_EQ(box.heap_bytes(), 0u);
  EXPECT_EQ(box.get(3, 4, 5), solid(materials::kRock));
}

TEST(RowPackedBox, UniformRowsCostOnlyHeaders) {
  RowPackedBox<32> box(materials::kRock);
  // A layer of grass on top: every row still uniform.
  box.modify_rows(31, 32, 0, 32, [](int, int, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = solid(materials::kGrass);
  });
  EXPECT_FALSE(box.is_uniform());
  EXPECT_EQ(box.heap_bytes(), 32u * 32u * 2u);
  EXPECT_EQ(box.stats().raw_rows, 0u);
  EXPECT_EQ(box.stats().byte_rows, 0u);
}

TEST(RowPackedBox, DefaultOccupancyRowsKeepOneBytePerVoxel) {
  RowPackedBox<32> box(materials::kRock);
  box.set(7, 3, 4, solid(materials::kBasalt));  // an ore in one row
  EXPECT_EQ(box.stats().byte_rows, 1u);
  EXPECT_EQ(box.stats().raw_rows, 0u);
  EXPECT_EQ(box.heap_bytes(), 32u * 32u * 2u + 32u);
  box.set(8, 3, 4, make_voxel(materials::kBasalt, 100));  // partial occupancy: raw
  EXPECT_EQ(box.stats().byte_rows, 0u);
  EXPECT_EQ(box.stats().raw_rows, 1u);
  EXPECT_EQ(box.heap_bytes(), 32u * 32u * 2u + 64u);
}

TEST(RowPackedBox, BoxReturnsToUniformWhenContentDoes) {
  RowPackedBox<16> box(kAir);
  box.set(1, 2, 3, solid(materials::kSand));
  EXPECT_FALSE(box.is_uniform());
  box.set(1, 2, 3, Voxel{});
  EXPECT_TRUE(box.is_uniform());
  EXPECT_EQ(box.uniform_material(), kAir);
  EXPECT_EQ(box.heap_bytes(), 0u);
}

TEST(RowPackedBox, RepeatedTinyWritesUnpackInsteadOfRepackingForever) {
  RowPackedBox<32> box(materials::kRock);
  Box ref({32, 32, 32}, solid(materials::kRock));
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> c(0, 31), occ(0, 254);
  for (int i = 0; i < 200; ++i) {
    const int x = c(rng), y = c(rng), z = c(rng);
    // Alternate classes so every write would otherwise repack.
    const Voxel v = i % 2 ? make_voxel(materials::kMud, static_cast<std::uint8_t>(occ(rng))) : solid(materials::kRock);
    box.set(x, y, z, v);
    ref.set(x, y, z, v);
  }
  EXPECT_TRUE(box.unpacked());
  EXPECT_EQ(box.stats().raw_rows, 1024u);
  expect_equal(box, ref, "unpacked");
  box.compact();
  EXPECT_FALSE(box.unpacked());
  EXPECT_LT(box.heap_bytes(), 32u * 32u * 64u);
  expect_equal(box, ref, "compacted");
}

TEST(RowPackedBox, AirWithOccupancyIsNormalised) {
  RowPackedBox<8> box(materials::kRock);
  box.modify_rows(0, 1, 0, 1, [](int, int, Voxel* row) { row[2] = Voxel{kAir, 77}; });
  EXPECT_EQ(box.get(2, 0, 0), Voxel{});
}

TEST(RowPackedBox, CloneIsIndependent) {
  RowPackedBox<8> box(materials::kRock);
  box.set(1, 1, 1, make_voxel(materials::kSand, 9));
  RowPackedBox<8> copy = box.clone();
  box.set(1, 1, 1, solid(materials::kRock));
  EXPECT_EQ(copy.get(1, 1, 1), make_voxel(materials::kSand, 9));
  EXPECT_EQ(box.get(1, 1, 1), solid(materials::kRock));
}

}  // namespace
}  // namespace terrane

namespace terrane {
namespace {
TEST(RowPackedBox, SimdWideningMatchesScalarReference) {
  std::uint8_t materials[32];
  for (int trial = 0; trial < 64; ++trial) {
    for (int i = 0; i < 32; ++i) materials[i] = static_cast<std::uint8_t>((i * 7 + trial * 13) % 64 * ((i + trial) % 3 != 0));
    Voxel scalar[32], simd[32];
    row_packed_detail::widen_scalar(materials, scalar, 32);
#if defined(__SSE2__)
    row_packed_detail::widen_sse2(materials, simd, 32);
#else
    row_packed_detail::widen_scalar(materials, simd, 32);
#endif
    for (int i = 0; i < 32; ++i) ASSERT_EQ(simd[i], scalar[i]) << i;
  }
}
}  // namespace
}  // namespace terrane
