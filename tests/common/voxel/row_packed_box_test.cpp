#include "common/voxel/row_packed_box.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "common/voxel/box.h"

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
// materials at default occupancy, smooth partial occupancy, random garbage,
// then rows drawing from 2, 3, 5, 9 or 17 materials (every palette width and
// the raw fallback), and few materials with a few occupancy values (palette
// records that store occupancies).
constexpr int kStyles = 11;
Voxel random_voxel(std::mt19937& rng, int style) {
  std::uniform_int_distribution<int> mat(0, 63), few(1, 4), occ(0, 255), pick(0, 1 << 20);
  constexpr int kDistinct[] = {2, 3, 5, 9, 17};
  switch (style) {
    case 0: return solid(static_cast<Material>(few(rng)));
    case 1: return Voxel{};
    case 2: return solid(static_cast<Material>(few(rng) % 3));
    case 3: return make_voxel(static_cast<Material>(few(rng)), static_cast<std::uint8_t>(occ(rng)));
    case 4: return make_voxel(static_cast<Material>(mat(rng)), static_cast<std::uint8_t>(occ(rng)));
    case 5: case 6: case 7: case 8: case 9:
      return solid(static_cast<Material>(20 + pick(rng) % kDistinct[style - 5]));
    default:
      return make_voxel(static_cast<Material>(pick(rng) % 3), static_cast<std::uint8_t>(64 * (pick(rng) % 3) + 63));
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
  std::uniform_int_distribution<int> coord(0, N - 1), kind(0, 5), style(0, kStyles - 1);
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
    ASSERT_LE(s.palette_rows + s.shared_rows, s.raw_rows + s.byte_rows + s.shared_rows);
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

// Padding after the records of a 32³ box (SSSE3 over-read), in bytes.
constexpr std::size_t kPad32 = 2 * RowPackedBox<32>::kPadUnits;

TEST(RowPackedBox, OreRowsUsePaletteRecords) {
  RowPackedBox<32> box(materials::kRock);
  box.set(7, 3, 4, solid(materials::kBasalt));  // an ore in one row
  EXPECT_EQ(box.stats().byte_rows, 1u);
  EXPECT_EQ(box.stats().palette_rows, 1u);
  EXPECT_EQ(box.stats().raw_rows, 0u);
  // tag + 2 materials + 4 bytes of 1-bit indices, padded to 8.
  EXPECT_EQ(box.heap_bytes(), 32u * 32u * 2u + 8u + kPad32);
  box.set(8, 3, 4, make_voxel(materials::kBasalt, 100));  // partial occupancy: occupancies stored
  EXPECT_EQ(box.stats().byte_rows, 0u);
  EXPECT_EQ(box.stats().raw_rows, 1u);
  EXPECT_EQ(box.stats().palette_rows, 1u);
  // tag + 3 materials + 3 occupancies + 8 bytes of 2-bit indices, padded to 16.
  EXPECT_EQ(box.heap_bytes(), 32u * 32u * 2u + 16u + kPad32);
  EXPECT_EQ(box.get(7, 3, 4), solid(materials::kBasalt));
  EXPECT_EQ(box.get(8, 3, 4), make_voxel(materials::kBasalt, 100));
  EXPECT_EQ(box.get(9, 3, 4), solid(materials::kRock));
}

// Record size per number of distinct materials in a row of 32 (default
// occupancy): 1, 2 and 4-bit palettes, then raw beyond 16 entries.
TEST(RowPackedBox, PaletteWidthFollowsDistinctMaterials) {
  const struct {
    int distinct;
    std::size_t record_bytes;
    bool palette;
  } cases[] = {{2, 8, true}, {3, 12, true}, {4, 14, true}, {5, 22, true}, {9, 26, true}, {16, 34, true}, {17, 64, false}};
  for (const auto& c : cases) {
    RowPackedBox<32> box(kAir);
    Box ref({32, 32, 32});
    box.modify_rows(5, 6, 9, 10, [&](int, int, Voxel* row) {
      for (int x = 0; x < 32; ++x) row[x] = solid(static_cast<Material>(1 + x % c.distinct));
    });
    for (int x = 0; x < 32; ++x) ref.set(x, 5, 9, solid(static_cast<Material>(1 + x % c.distinct)));
    EXPECT_EQ(box.stats().palette_rows, c.palette ? 1u : 0u) << c.distinct;
    EXPECT_EQ(box.heap_bytes(), 32u * 32u * 2u + c.record_bytes + kPad32) << c.distinct;
    expect_equal(box, ref, "palette width");
  }
}

TEST(RowPackedBox, IdenticalRowsShareOneRecord) {
  RowPackedBox<32> box(materials::kRock);
  Box ref({32, 32, 32}, solid(materials::kRock));
  auto pattern = [](int x) { return x % 5 == 0 ? solid(materials::kSand) : solid(materials::kRock); };
  box.modify_rows(0, 4, 0, 32, [&](int y, int z, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = pattern(x);
    for (int x = 0; x < 32; ++x) ref.set(x, y, z, pattern(x));
  });
  EXPECT_EQ(box.stats().palette_rows, 128u);
  EXPECT_EQ(box.stats().shared_rows, 127u);
  EXPECT_EQ(box.heap_bytes(), 32u * 32u * 2u + 8u + kPad32);
  // Writing one of the sharing rows must not change the others.
  box.set(1, 2, 3, solid(materials::kSand));
  ref.set(1, 2, 3, solid(materials::kSand));
  expect_equal(box, ref, "after write to a shared row");
  EXPECT_EQ(box.stats().shared_rows, 126u);
}

TEST(RowPackedBox, SameSizeWritesStayInPlace) {
  RowPackedBox<32> box(materials::kRock);
  box.set(0, 0, 0, solid(materials::kSand));
  box.set(0, 0, 1, solid(materials::kMud));
  const std::size_t bytes = box.heap_bytes();
  // Same record size (2 palette entries, sand kept at x = 0), different
  // content: no rebuild, so repeated writes never reach the unpack budget.
  for (int i = 0; i < 3 * RowPackedBox<32>::kRepackBudget; ++i)
    box.set(1 + i % 31, 0, 0, solid(i % 2 ? materials::kSand : materials::kRock));
  EXPECT_FALSE(box.unpacked());
  EXPECT_EQ(box.heap_bytes(), bytes);
  EXPECT_EQ(box.get(0, 0, 1), solid(materials::kMud));
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
TEST(RowPackedBox, SimdDecoderMatchesScalarReference) {
  std::mt19937 rng(99);
  std::uniform_int_distribution<int> occ(0, 255), count(1, 16), flip(0, 3);
  int palette_records = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    // A palette of 1..16 voxel values, with or without partial occupancy.
    const int k = count(rng);
    const bool partial = flip(rng) == 0;
    Voxel palette[16];
    for (int j = 0; j < k; ++j)
      palette[j] = partial ? make_voxel(static_cast<Material>(j * 3 % 64), static_cast<std::uint8_t>(occ(rng)))
                           : solid(static_cast<Material>((j * 7 + trial) % 64));
    Voxel row[32];
    std::uniform_int_distribution<int> pick(0, k - 1);
    for (auto& v : row) v = palette[pick(rng)];
    // Record at the end of a buffer with exactly the decoder's padding after it.
    std::uint8_t buf[64 + kPad32];
    std::memset(buf, 0xAB, sizeof(buf));
    const int size = row_packed_detail::encode_row(row, 32, buf);
    if (size == 0 || buf[0] < row_packed_detail::kPaletteTag) continue;
    ++palette_records;
    std::uint8_t tail[64 + kPad32];
    std::memset(tail, 0xCD, sizeof(tail));
    std::memcpy(tail + sizeof(tail) - kPad32 - size, buf, static_cast<std::size_t>(size));
    const std::uint8_t* rec = tail + sizeof(tail) - kPad32 - size;
    ASSERT_EQ(row_packed_detail::record_bytes(rec, 32), size);
    Voxel scalar[32];
    row_packed_detail::decode_palette_scalar(rec, scalar, 32);
    for (int x = 0; x < 32; ++x) ASSERT_EQ(scalar[x], row[x]) << "scalar, trial " << trial << " x " << x;
#if defined(__x86_64__) || defined(__i386__)
    if (row_packed_detail::kHaveSsse3) {
      Voxel simd[32];
      row_packed_detail::decode_palette32_ssse3(rec, simd);
      for (int x = 0; x < 32; ++x) ASSERT_EQ(simd[x], scalar[x]) << "ssse3, trial " << trial << " x " << x;
    }
#endif
  }
  EXPECT_GT(palette_records, 1000);
}
}  // namespace
}  // namespace terrane

namespace terrane {
namespace {
TEST(RowPackedBox, MovedFromBoxIsUniformAirAndUsable) {
  RowPackedBox<32> a(materials::kRock);
  a.set(1, 2, 3, make_voxel(materials::kSand, 7));
  RowPackedBox<32> b(std::move(a));
  EXPECT_EQ(b.get(1, 2, 3), make_voxel(materials::kSand, 7));
  EXPECT_TRUE(a.is_uniform());  // NOLINT(bugprone-use-after-move): documented state
  EXPECT_EQ(a.get(1, 2, 3), Voxel{});
  a.set(4, 4, 4, solid(materials::kMud));
  EXPECT_EQ(a.get(4, 4, 4), solid(materials::kMud));
}
}  // namespace
}  // namespace terrane
