#include "common/voxel/row_packed_box.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <random>
#include <string>
#include <utility>
#include <vector>

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
      // A part of the row, as Chunk::read_box copies it.
      const int x0 = (y * 7 + z) % N, n = (y + 3 * z) % (N - x0 + 1);
      std::array<Voxel, N + 1> part;
      part[static_cast<std::size_t>(n)] = make_voxel(63, 7);  // must stay
      packed.read_row_part(y, z, x0, n, part.data(), scratch);
      for (int x = 0; x < n; ++x) ASSERT_EQ(part[static_cast<std::size_t>(x)], ref.get(x0 + x, y, z)) << when;
      ASSERT_EQ(part[static_cast<std::size_t>(n)], make_voxel(63, 7)) << when << ": read past the part";
      // Whether the part holds a voxel solid enough, for a few thresholds,
      // as a loop over the reference row answers.
      for (const int min_occupancy : {0, 1, 100, 255}) {
        bool expected = false;
        for (int x = x0; x < x0 + n; ++x)
          expected |= solid_enough(ref.get(x, y, z), static_cast<std::uint8_t>(min_occupancy));
        ASSERT_EQ(packed.box_has_solid(x0, x0 + n, y, y + 1, z, z + 1, static_cast<std::uint8_t>(min_occupancy)), expected)
            << when << " row " << y << "," << z << " [" << x0 << ", " << x0 + n << ") min " << min_occupancy;
      }
      // And over a box of up to 3 layers and 4 rows from this row.
      const int y1 = std::min(N, y + 1 + z % 3), z1 = std::min(N, z + 1 + y % 4);
      for (const int min_occupancy : {0, 200}) {
        bool expected = false;
        for (int by = y; by < y1; ++by)
          for (int bz = z; bz < z1; ++bz)
            for (int x = x0; x < x0 + n; ++x)
              expected |= solid_enough(ref.get(x, by, bz), static_cast<std::uint8_t>(min_occupancy));
        ASSERT_EQ(packed.box_has_solid(x0, x0 + n, y, y1, z, z1, static_cast<std::uint8_t>(min_occupancy)), expected)
            << when << " box from row " << y << "," << z;
      }
    }
  }
  // Every row's part read together (rows sharing a header copy the row
  // before), nothing written past a part.
  for (const auto& [x0, n] : {std::pair{0, N}, std::pair{1, N - 2}, std::pair{N / 2, N / 2}}) {
    std::vector<Voxel> all(std::size_t{N} * N * N, make_voxel(63, 7));
    packed.read_rows_part(0, N, 0, N, x0, n, [&](int y, int z) { return all.data() + (std::size_t(y) * N + z) * N; });
    for (int y = 0; y < N; ++y)
      for (int z = 0; z < N; ++z) {
        const Voxel* row = all.data() + (std::size_t(y) * N + z) * N;
        for (int x = 0; x < n; ++x) ASSERT_EQ(row[x], ref.get(x0 + x, y, z)) << when << ": rows read together";
        for (int x = n; x < N; ++x) ASSERT_EQ(row[x], make_voxel(63, 7)) << when << ": rows read together, past the part";
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
    ASSERT_EQ(s.uniform_rows + s.raw_rows + s.index_rows + s.run_rows, static_cast<std::size_t>(N * N));
    ASSERT_LE(s.shared_rows, s.raw_rows + s.index_rows + s.run_rows);
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

// Headers of a 32³ box that owns them: the layer map, then for each layer
// whose rows are not all uniform with one material either one unit (narrow:
// two base offsets and 32 one-byte offsets) or two (wide: 32 two-byte
// headers, in two units of 36 bytes).
constexpr std::size_t headers32(std::size_t narrow, std::size_t wide = 0) { return 32 + narrow * 36 + wide * 72; }

TEST(RowPackedBox, UniformLayersCostOnlyTheLayerMap) {
  RowPackedBox<32> box(materials::kRock);
  // A layer of grass on top: every layer still uniform with one material.
  box.modify_rows(31, 32, 0, 32, [](int, int, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = solid(materials::kGrass);
  });
  EXPECT_FALSE(box.is_uniform());
  EXPECT_EQ(box.heap_bytes(), headers32(0));
  EXPECT_EQ(box.stats().uniform_rows, 1024u);
  EXPECT_EQ(box.get(5, 31, 7), solid(materials::kGrass));
  EXPECT_EQ(box.get(5, 30, 7), solid(materials::kRock));
  // Half of a layer of sand: that layer's rows are uniform but not alike,
  // so it keeps its 32 headers.
  box.modify_rows(10, 11, 0, 16, [](int, int, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = solid(materials::kSand);
  });
  EXPECT_EQ(box.heap_bytes(), headers32(1));
  EXPECT_EQ(box.get(0, 10, 15), solid(materials::kSand));
  EXPECT_EQ(box.get(0, 10, 16), solid(materials::kRock));
  // The other half too: alike again.
  box.modify_rows(10, 11, 16, 32, [](int, int, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = solid(materials::kSand);
  });
  EXPECT_EQ(box.heap_bytes(), headers32(0));
  EXPECT_EQ(box.get(0, 10, 16), solid(materials::kSand));
  RowPackedBox<32> copy = box.clone();
  EXPECT_EQ(copy.heap_bytes(), headers32(0));
  EXPECT_EQ(copy.get(0, 31, 0), solid(materials::kGrass));
}

constexpr std::size_t kPad32 = RowPackedBox<32>::kPadBytes;
// A palette table of palettes with these sizes: count, offsets, palettes.
std::size_t table_bytes(std::initializer_list<int> sizes) {
  std::size_t bytes = 1;
  for (int p : sizes) bytes += 1 + 1 + static_cast<std::size_t>(p);
  return bytes;
}

TEST(RowPackedBox, OreRowUsesARecordOverTheTable) {
  RowPackedBox<32> box(materials::kRock);
  box.set(7, 3, 4, solid(materials::kBasalt));  // an ore in one row
  EXPECT_EQ(box.stats().index_rows + box.stats().run_rows, 1u);
  EXPECT_EQ(box.stats().raw_rows, 0u);
  // The palette {rock, basalt} joins the table; the record is its tag and
  // three runs, the first holding the count (1-bit indices would take 4
  // bytes); the layer is narrow.
  EXPECT_EQ(box.stats().table_bytes, table_bytes({2}));
  EXPECT_EQ(box.stats().narrow_layers, 1u);
  EXPECT_EQ(box.stats().run_rows, 1u);
  EXPECT_EQ(box.heap_bytes(), headers32(1) + table_bytes({2}) + 4u + kPad32);
  box.set(8, 3, 4, make_voxel(materials::kBasalt, 100));  // partial occupancy: an occupancy section
  EXPECT_EQ(box.stats().occupancy_rows, 1u);
  // + 4 bytes of bitmap and the one occupancy byte.
  EXPECT_EQ(box.heap_bytes(), headers32(1) + table_bytes({2}) + 9u + kPad32);
  EXPECT_EQ(box.get(7, 3, 4), solid(materials::kBasalt));
  EXPECT_EQ(box.get(8, 3, 4), make_voxel(materials::kBasalt, 100));
  EXPECT_EQ(box.get(9, 3, 4), solid(materials::kRock));
}

// Record size per number of distinct materials in a row of 32 that changes
// material at every voxel (default occupancy): 1, 2 and 4-bit indices over a
// table palette, raw beyond 16 materials.
TEST(RowPackedBox, IndexWidthFollowsDistinctMaterials) {
  const struct {
    int distinct;
    std::size_t record_bytes;
    bool raw;
  } cases[] = {{2, 5, false}, {3, 9, false}, {4, 9, false}, {5, 17, false}, {9, 17, false}, {16, 17, false}, {17, 64, true}};
  for (const auto& c : cases) {
    RowPackedBox<32> box(kAir);
    Box ref({32, 32, 32});
    box.modify_rows(5, 6, 9, 10, [&](int, int, Voxel* row) {
      for (int x = 0; x < 32; ++x) row[x] = solid(static_cast<Material>(1 + x % c.distinct));
    });
    for (int x = 0; x < 32; ++x) ref.set(x, 5, 9, solid(static_cast<Material>(1 + x % c.distinct)));
    EXPECT_EQ(box.stats().raw_rows, c.raw ? 1u : 0u) << c.distinct;
    EXPECT_EQ(box.stats().index_rows, c.raw ? 0u : 1u) << c.distinct;
    const std::size_t table = c.raw ? 1u : table_bytes({c.distinct});
    EXPECT_EQ(box.heap_bytes(), headers32(1) + table + c.record_bytes + kPad32) << c.distinct;
    expect_equal(box, ref, "index width");
  }
}

TEST(RowPackedBox, FewRunsUseARunRecord) {
  RowPackedBox<32> box(kAir);
  Box ref({32, 32, 32});
  auto material = [](int x) { return x < 10 ? materials::kRock : x < 20 ? materials::kSand : materials::kMud; };
  box.modify_rows(0, 1, 0, 1, [&](int, int, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = solid(material(x));
  });
  for (int x = 0; x < 32; ++x) ref.set(x, 0, 0, solid(material(x)));
  EXPECT_EQ(box.stats().run_rows, 1u);
  // tag and three runs, the first holding the run count (2-bit indices
  // would take 1 + 8).
  EXPECT_EQ(box.heap_bytes(), headers32(1) + table_bytes({3}) + 4u + kPad32);
  expect_equal(box, ref, "runs");
  // Occupancy on top of runs: the section follows the runs.
  box.set(15, 0, 0, make_voxel(materials::kSand, 3));
  ref.set(15, 0, 0, make_voxel(materials::kSand, 3));
  EXPECT_EQ(box.stats().run_rows, 1u);
  EXPECT_EQ(box.stats().occupancy_rows, 1u);
  expect_equal(box, ref, "runs with occupancy");
}

TEST(RowPackedBox, PalettesBeyondTheTableGoInline) {
  // 40 rows, each over its own pair of materials, in one write: 31 pairs
  // fit the table, the rest carry their palette in the record; compact()
  // keeps the same content.
  RowPackedBox<32> box(kAir);
  Box ref({32, 32, 32});
  box.modify_rows(0, 2, 0, 32, [&](int y, int z, Voxel* row) {
    const int r = y * 32 + z;
    if (r >= 40) return;
    const Material a = static_cast<Material>(1 + r % 63), b = static_cast<Material>(1 + (r + 20) % 63);
    for (int x = 0; x < 32; ++x) {
      row[x] = solid(x % 3 ? a : b);
      ref.set(x, y, z, row[x]);
    }
  });
  EXPECT_GT(box.stats().table_bytes, 1u);
  int inline_records = 0;
  for (int r = 0; r < 40; ++r) {
    // A record names its palette in its tag: 31 is inline.
    if ((box.record_tag(r / 32, r % 32) & row_packed_detail::kPaletteMask) == row_packed_detail::kInlinePalette)
      ++inline_records;
  }
  EXPECT_EQ(inline_records, 40 - row_packed_detail::kMaxTablePalettes);
  EXPECT_EQ(box.stats().index_rows, 40u);
  expect_equal(box, ref, "inline palettes");
  box.compact();
  expect_equal(box, ref, "compacted");
  // Each pair is used once, so compact() keeps every palette inline.
  EXPECT_EQ(box.stats().table_bytes, 1u);
}

// Rows of two runs over every pair of 6 materials, each pair in two rows:
// compact() gives the table one palette of all 6 (the first pair's, grown a
// material at a time) rather than 15 palettes of two or 15 inline ones, as a
// run record costs the same with any palette of up to 8 materials; a later
// write of another pair of them uses it too.
TEST(RowPackedBox, RunRowsShareATablePaletteHoldingTheirMaterials) {
  RowPackedBox<32> box(kAir);
  Box ref({32, 32, 32});
  std::vector<std::pair<Material, Material>> pairs;
  for (int a = 1; a <= 6; ++a)
    for (int b = a + 1; b <= 6; ++b) pairs.emplace_back(static_cast<Material>(a), static_cast<Material>(b));
  ASSERT_EQ(pairs.size(), 15u);
  box.modify_rows(0, 1, 0, 30, [&](int y, int z, Voxel* row) {
    const auto [a, b] = pairs[static_cast<std::size_t>(z / 2)];
    for (int x = 0; x < 32; ++x) {
      row[x] = solid(x < 13 ? a : b);
      ref.set(x, y, z, row[x]);
    }
  });
  box.compact();
  expect_equal(box, ref, "compacted");
  EXPECT_EQ(box.stats().table_bytes, table_bytes({6}));
  EXPECT_EQ(box.stats().run_rows, 30u);
  EXPECT_EQ(box.stats().inline_palette_bytes, 0u);
  for (int z = 0; z < 30; ++z) EXPECT_EQ(box.record_tag(0, z), row_packed_detail::kKindRuns | 0) << z;
  // 15 distinct records of a tag and two runs.
  EXPECT_EQ(box.heap_bytes(), headers32(1) + table_bytes({6}) + 15u * 3u + kPad32);
  box.modify_rows(3, 4, 7, 8, [&](int, int, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = solid(static_cast<Material>(x < 20 ? 5 : 2));
  });
  for (int x = 0; x < 32; ++x) ref.set(x, 3, 7, solid(static_cast<Material>(x < 20 ? 5 : 2)));
  expect_equal(box, ref, "a later row");
  EXPECT_EQ(box.stats().table_bytes, table_bytes({6}));
  EXPECT_EQ(box.record_tag(3, 7), row_packed_detail::kKindRuns | 0);
  // A row alternating two of them takes an index record (1-bit indices, 4
  // bytes, against 32 runs): the palette of 6 (4-bit indices) does not
  // serve it, so it gets a palette of its own in the table.
  box.modify_rows(4, 5, 9, 10, [&](int, int, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = solid(static_cast<Material>(x % 2 ? 2 : 5));
  });
  for (int x = 0; x < 32; ++x) ref.set(x, 4, 9, solid(static_cast<Material>(x % 2 ? 2 : 5)));
  expect_equal(box, ref, "an index row");
  EXPECT_EQ(box.stats().table_bytes, table_bytes({6, 2}));
  EXPECT_EQ(box.record_tag(4, 9), row_packed_detail::kKindIndex | 1);
}

// Rows that take index records keep palettes of their own index width: two
// materials alternating (1-bit indices, 4 bytes, against 32 runs) are not
// served by a palette of three (2-bit indices, 8 bytes).
TEST(RowPackedBox, IndexRowsKeepPalettesOfTheirIndexWidth) {
  RowPackedBox<32> box(kAir);
  Box ref({32, 32, 32});
  box.modify_rows(0, 1, 0, 8, [&](int y, int z, Voxel* row) {
    for (int x = 0; x < 32; ++x) {
      // Rows 0-3 over {1, 2, 3}, rows 4-7 over {1, 2}.
      row[x] = solid(static_cast<Material>(1 + x % (z < 4 ? 3 : 2)));
      ref.set(x, y, z, row[x]);
    }
  });
  box.compact();
  expect_equal(box, ref, "compacted");
  EXPECT_EQ(box.stats().index_rows, 8u);
  EXPECT_EQ(box.stats().table_bytes, table_bytes({3, 2}));
  EXPECT_EQ(box.heap_bytes(), headers32(1) + table_bytes({3, 2}) + (1u + 8u) + (1u + 4u) + kPad32);
}

TEST(RowPackedBox, IdenticalRowsShareOneRecord) {
  RowPackedBox<32> box(materials::kRock);
  Box ref({32, 32, 32}, solid(materials::kRock));
  auto pattern = [](int x) { return x % 5 == 0 ? solid(materials::kSand) : solid(materials::kRock); };
  box.modify_rows(0, 4, 0, 32, [&](int y, int z, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = pattern(x);
    for (int x = 0; x < 32; ++x) ref.set(x, y, z, pattern(x));
  });
  EXPECT_EQ(box.stats().index_rows, 128u);
  EXPECT_EQ(box.stats().shared_rows, 127u);
  EXPECT_EQ(box.heap_bytes(), headers32(4) + table_bytes({2}) + 5u + kPad32);
  // Writing one of the sharing rows must not change the others.
  box.set(1, 2, 3, solid(materials::kSand));
  ref.set(1, 2, 3, solid(materials::kSand));
  expect_equal(box, ref, "after write to a shared row");
  EXPECT_EQ(box.stats().shared_rows, 126u);
}

TEST(RowPackedBox, WritesThatDoNotGrowARecordStayInPlace) {
  RowPackedBox<32> box(materials::kRock);
  // Rows alternating sand and rock: index records of 5 bytes.
  box.modify_rows(0, 1, 0, 2, [&](int, int z, Voxel* row) {
    for (int x = 0; x < 32; ++x) row[x] = solid(x % 2 ? materials::kRock : z ? materials::kMud : materials::kSand);
  });
  const std::size_t bytes = box.heap_bytes();
  // Flipping voxels keeps the record at most as long: no rebuild, so
  // repeated writes never reach the unpack budget.
  for (int i = 0; i < 3 * RowPackedBox<32>::kRepackBudget; ++i)
    box.set(1 + i % 31, 0, 0, solid(i % 2 ? materials::kRock : materials::kSand));
  EXPECT_FALSE(box.unpacked());
  EXPECT_EQ(box.heap_bytes(), bytes);
  EXPECT_EQ(box.get(0, 0, 1), solid(materials::kMud));
  for (int x = 0; x < 32; ++x) {
    // The last write to each x (i = x - 1 + 31k) decides it; x = 0 kept sand.
    const int last = x == 0 ? -1 : x - 1 + 31 * ((3 * RowPackedBox<32>::kRepackBudget - x) / 31);
    const Material want = x == 0 ? materials::kSand : last % 2 ? materials::kRock : materials::kSand;
    EXPECT_EQ(box.get(x, 0, 0), solid(want)) << x;
  }
}

TEST(RowPackedBox, RecordsBeyondFifteenBitOffsetsStayUnpacked) {
  // 513 distinct rows of 17+ materials (raw, 64 bytes each) pass 32 KiB of
  // records: the box falls back to unpacked mode and reads back exactly.
  RowPackedBox<32> box(kAir);
  Box ref({32, 32, 32});
  box.modify_rows(0, 17, 0, 32, [&](int y, int z, Voxel* row) {
    const int r = y * 32 + z;
    if (r >= 513) return;
    for (int x = 0; x < 32; ++x) {
      row[x] = make_voxel(static_cast<Material>(1 + (x + r) % 40), static_cast<std::uint8_t>(r));
      ref.set(x, y, z, row[x]);
    }
  });
  EXPECT_TRUE(box.unpacked());
  expect_equal(box, ref, "past 32 KiB");
  box.compact();
  EXPECT_TRUE(box.unpacked());
  expect_equal(box, ref, "compacted past 32 KiB");
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
  EXPECT_EQ(box.heap_bytes(), headers32(0, 32) + 32u * 32u * 64u + kPad32);  // unpacked: every layer wide
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
// A 32-wide index or run record (its table palettes in tbl) decodes to
// `expected` through the scalar reference and, where the CPU has it, SSSE3.
void expect_decoded(const std::uint8_t* rec, const std::uint8_t* tbl, const Voxel* expected, const std::string& what) {
  Voxel scalar[32];
  row_packed_detail::decode_record_scalar(rec, tbl, scalar, 32);
  for (int x = 0; x < 32; ++x) ASSERT_EQ(scalar[x], expected[x]) << "scalar, " << what << ", x " << x;
#if defined(__x86_64__) || defined(__i386__)
  if (row_packed_detail::kHaveSsse3) {
    Voxel simd[32];
    row_packed_detail::decode_record32_ssse3(rec, tbl, simd);
    for (int x = 0; x < 32; ++x) ASSERT_EQ(simd[x], expected[x]) << "ssse3, " << what << ", x " << x;
  }
#endif
}

TEST(RowPackedBox, SimdDecoderMatchesScalarReference) {
  std::mt19937 rng(99);
  std::uniform_int_distribution<int> occ(0, 255), count(1, 16), flip(0, 3), runs(1, 12), coin(0, 1);
  int records = 0, run_records = 0, occupancy_records = 0, long_occupancy_records = 0, table_records = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    // 1..16 materials; runs or scattered voxels; some partial occupancy.
    const int k = count(rng);
    Material mats[16];
    for (int j = 0; j < k; ++j) mats[j] = static_cast<Material>((j * 7 + trial) % 64);
    std::uniform_int_distribution<int> pick(0, k - 1);
    Voxel row[32];
    if (coin(rng)) {
      for (auto& v : row) v = solid(mats[pick(rng)]);
    } else {
      const int n_runs = runs(rng);
      for (int x = 0; x < 32; ++x) row[x] = solid(mats[(x * n_runs / 32) % k]);
    }
    // A few voxels of partial occupancy, or from 17 to 32 of them (an
    // occupancy section longer than one register).
    if (flip(rng) == 0)
      for (int i = 0; i < 1 + flip(rng) * 4; ++i) {
        Voxel& v = row[occ(rng) % 32];
        v = make_voxel(v.material, static_cast<std::uint8_t>(occ(rng)));
      }
    else if (flip(rng) == 0)
      for (int x = 0, partial = 0, want = 17 + occ(rng) % 16; x < 32 && partial < want; ++x)
        if (row[x].material != kAir && (occ(rng) & 3) != 0) {
          row[x] = make_voxel(row[x].material, static_cast<std::uint8_t>(1 + occ(rng) % 254));
          ++partial;
        }
    // A table holding this row's palette half of the time, laid out as in a
    // box: table, then the record, then exactly the decoder's padding.
    row_packed_detail::PaletteTable table;
    const row_packed_detail::RowSummary s = row_packed_detail::summarize_row(row, 32);
    if (coin(rng) && s.p <= 16) table.add(s.materials, s.p);
    std::uint8_t buf[256 + 64 + kPad32];
    std::memset(buf, 0xCD, sizeof(buf));
    table.write(buf);
    std::uint8_t* rec = buf + table.bytes();
    const int size = row_packed_detail::encode_row(row, 32, table, rec);
    if (size == 0 || rec[0] < row_packed_detail::kKindIndex) continue;
    std::memmove(buf + sizeof(buf) - kPad32 - size - table.bytes(), buf, static_cast<std::size_t>(table.bytes() + size));
    const std::uint8_t* tbl = buf + sizeof(buf) - kPad32 - size - table.bytes();
    rec = buf + sizeof(buf) - kPad32 - size;
    ++records;
    run_records += (rec[0] & row_packed_detail::kKindMask) == row_packed_detail::kKindRuns;
    occupancy_records += (rec[0] & row_packed_detail::kTagOccupancy) != 0;
    long_occupancy_records += std::count_if(row, row + 32, [](Voxel v) { return !has_default_occupancy(v); }) > 16;
    table_records += (rec[0] & row_packed_detail::kPaletteMask) != row_packed_detail::kInlinePalette;
    ASSERT_EQ(row_packed_detail::record_bytes(rec, tbl, 32), size);
    ASSERT_NO_FATAL_FAILURE(expect_decoded(rec, tbl, row, "trial " + std::to_string(trial)));
    for (int x = 0; x < 32; ++x)
      ASSERT_EQ(row_packed_detail::record_voxel(rec, tbl, 32, x), row[x]) << "voxel, trial " << trial << " x " << x;
  }
  EXPECT_GT(records, 2000);
  EXPECT_GT(run_records, 200);
  EXPECT_GT(occupancy_records, 200);
  EXPECT_GT(long_occupancy_records, 50);
  EXPECT_GT(table_records, 200);
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

namespace terrane {
namespace {

// A row of each form: uniform, runs (first run byte holding the count),
// index, raw, and any of them with partial occupancy.
Voxel form_voxel(int form, int x, int salt) {
  const Material a = static_cast<Material>(1 + salt % 60);
  switch (form) {
    case 0: return solid(a);                                                          // uniform
    case 1: return solid(static_cast<Material>(a + (x < 5 ? 0 : x < 20 ? 1 : 2)));    // 3 runs
    case 2: return solid(static_cast<Material>(1 + (x * 5 + salt) % 7));              // index, 7 materials
    case 3: return solid(static_cast<Material>((x * 2 + salt) % 64));                 // raw: > 16 materials, Air among them
    default: return make_voxel(static_cast<Material>(a + x % 2), static_cast<std::uint8_t>(x * 8 + salt));
  }
}

TEST(RowPackedBox, RowsSwitchBetweenFormsInANarrowLayer) {
  RowPackedBox<32> box(materials::kRock);
  Box ref({32, 32, 32}, solid(materials::kRock));
  // A layer with a few run records: narrow.
  for (int z = 0; z < 32; z += 4) {
    box.modify_rows(5, 6, z, z + 1, [&](int, int, Voxel* row) {
      for (int x = 0; x < 32; ++x) ref.set(x, 5, z, row[x] = form_voxel(1, x, z));
    });
  }
  EXPECT_EQ(box.stats().narrow_layers, 1u);
  expect_equal(box, ref, "runs");
  // One row through every form and back, the others kept.
  for (int form : {2, 3, 4, 1, 0, 3, 0, 4, 2, 1}) {
    box.modify_rows(5, 6, 9, 10, [&](int, int, Voxel* row) {
      for (int x = 0; x < 32; ++x) row[x] = form_voxel(form, x, 9);
    });
    for (int x = 0; x < 32; ++x) {
      const Voxel v = form_voxel(form, x, 9);
      ref.set(x, 5, 9, make_voxel(v.material, v.occupancy));
    }
    expect_equal(box, ref, "form switch");
    RowPackedBox<32> copy = box.clone();
    copy.compact();
    expect_equal(copy, ref, "form switch, compacted");
  }
  // A uniform row changing material while records stay (the headers are
  // laid out again): the narrow layer's uniform rows say the new material.
  box.modify_rows(5, 6, 1, 2, [&](int, int, Voxel* row) {
    for (int x = 0; x < 32; ++x) ref.set(x, 5, 1, row[x] = solid(materials::kSand));
  });
  expect_equal(box, ref, "uniform row changed");
  EXPECT_GE(box.stats().narrow_layers, 1u);
}

TEST(RowPackedBox, LayerTurnsWideWhenItsRecordsReachPastAByteAndBack) {
  RowPackedBox<32> box(kAir);
  Box ref({32, 32, 32});
  // Sixteen raw rows of one half-layer: 16 × 64 bytes, beyond one byte.
  box.modify_rows(7, 8, 0, 16, [&](int, int z, Voxel* row) {
    for (int x = 0; x < 32; ++x) ref.set(x, 7, z, row[x] = form_voxel(3, x, z));
  });
  EXPECT_EQ(box.stats().wide_layers, 1u);
  EXPECT_EQ(box.stats().narrow_layers, 0u);
  expect_equal(box, ref, "wide");
  // Back to small records: narrow again once repacked.
  box.modify_rows(7, 8, 0, 16, [&](int, int z, Voxel* row) {
    for (int x = 0; x < 32; ++x) ref.set(x, 7, z, row[x] = form_voxel(1, x, z));
  });
  box.compact();
  EXPECT_EQ(box.stats().wide_layers, 0u);
  EXPECT_EQ(box.stats().narrow_layers, 1u);
  expect_equal(box, ref, "narrow again");
}

// Every N: random rectangles written with rows of every form, every
// material 0..63 (far more palettes than the table's 31: the rest inline)
// and every occupancy byte (Air's normalised to 0), against a dense box,
// through repacks, in-place writes, compact() and clone().
template <int N>
void every_material_and_occupancy(unsigned seed) {
  RowPackedBox<N> box(kAir);
  Box ref({N, N, N});
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> coord(0, N - 1), form(0, 4), salt(0, 255), small(0, 7);
  for (int step = 0; step < 300; ++step) {
    int y0 = coord(rng), y1 = coord(rng), z0 = coord(rng), z1 = coord(rng);
    if (y0 > y1) std::swap(y0, y1);
    if (z0 > z1) std::swap(z0, z1);
    if (small(rng) != 0) y1 = y0, z1 = std::min(z0 + small(rng), N - 1);  // mostly small writes
    const int f = form(rng), s = salt(rng);
    box.modify_rows(y0, y1 + 1, z0, z1 + 1, [&](int y, int z, Voxel* row) {
      for (int x = 0; x < N; ++x) {
        Voxel v = form_voxel(f, x, s + y * 3 + z);
        if (f == 4 || (f == 3 && x % 5 == 0)) v.occupancy = static_cast<std::uint8_t>(s + 37 * x + 11 * z);
        if (f == 3) v.material = static_cast<Material>((s + x + 7 * z) % 64);
        row[x] = v;
        const Voxel stored = make_voxel(v.material, v.occupancy);
        ref.set(x, y, z, stored);
      }
    });
    if (step % 50 == 49) {
      expect_equal(box, ref, "random writes");
      RowPackedBox<N> copy = box.clone();
      copy.compact();
      expect_equal(copy, ref, "compacted clone");
    }
  }
  // Every occupancy byte with every material (Air's normalised), one voxel
  // at a time over the random content.
  for (int v = 0; v < 256; ++v) {
    const Voxel w = make_voxel(static_cast<Material>(v % 64), static_cast<std::uint8_t>(v));
    const int x = v % N, y = (v / N) % N, z = (v / N / N + v) % N;
    box.set(x, y, z, Voxel{w.material, static_cast<std::uint8_t>(v)});  // set() normalises Air
    ref.set(x, y, z, w);
    ASSERT_EQ(box.get(x, y, z), w) << N << " value " << v;
  }
  expect_equal(box, ref, "every occupancy");
  box.compact();
  expect_equal(box, ref, "compacted");
}

TEST(RowPackedBox, EveryMaterialAndOccupancyRoundTripsAtEverySize) {
  for (unsigned seed = 1; seed <= 4; ++seed) {
    every_material_and_occupancy<4>(seed);
    every_material_and_occupancy<8>(seed);
    every_material_and_occupancy<16>(seed);
    every_material_and_occupancy<32>(seed);
  }
}

}  // namespace
}  // namespace terrane

namespace terrane {
namespace {
// The encoder takes runs over indices only below 16 runs, but the format
// allows 32: a hand-made run record of every count from 2 to 32, with an
// inline palette of up to 8 materials, decodes alike in both decoders.
TEST(RowPackedBox, SimdDecoderReadsRunRecordsOfUpTo32Runs) {
  std::mt19937 rng(5);
  for (int runs = 2; runs <= 32; ++runs) {
    for (int trial = 0; trial < 20; ++trial) {
      // Distinct starts, ascending from 0.
      std::vector<int> starts{0};
      std::vector<int> rest(31);
      for (int i = 0; i < 31; ++i) rest[static_cast<std::size_t>(i)] = i + 1;
      std::shuffle(rest.begin(), rest.end(), rng);
      starts.insert(starts.end(), rest.begin(), rest.begin() + (runs - 1));
      std::sort(starts.begin(), starts.end());
      const int p = 1 + static_cast<int>(rng() % 8);
      std::uint8_t buf[3 + 8 + 32 + 16 + 16] = {};
      buf[0] = row_packed_detail::kKindRuns | row_packed_detail::kInlinePalette;
      buf[1] = static_cast<std::uint8_t>(p - 1);
      for (int i = 0; i < p; ++i) buf[2 + i] = static_cast<std::uint8_t>(3 * i + 1);
      std::uint8_t* body = buf + 2 + p;
      Voxel expected[32];
      for (int r = 0; r < runs; ++r) {
        const unsigned index = static_cast<unsigned>(rng() % static_cast<unsigned>(p));
        body[r] = static_cast<std::uint8_t>(index << 5 | static_cast<unsigned>(r == 0 ? runs - 1 : starts[static_cast<std::size_t>(r)]));
        const int end = r + 1 < runs ? starts[static_cast<std::size_t>(r) + 1] : 32;
        for (int x = starts[static_cast<std::size_t>(r)]; x < end; ++x) expected[x] = solid(buf[2 + index]);
      }
      ASSERT_NO_FATAL_FAILURE(expect_decoded(buf, nullptr, expected, std::to_string(runs) + " runs"));
    }
  }
}
}  // namespace
}  // namespace terrane
