// Chunk images (Chunk::write_image / read_image, RowPackedBox's image): every
// chunk of every dataset in tests/data and of the default generated world
// reads back as the same chunk, byte for byte; every truncation is an error;
// a damaged image is an error or a chunk that still reads safely (every row,
// every mip level), never an out-of-bounds read.
#include <gtest/gtest.h>

#include <random>
#include <string>
#include <vector>

#include "common/codec/net_codec.h"
#include "common/voxel/grid.h"
#include "common/vxraw/vxraw.h"
#include "common/world/terrain_generator.h"
#include "common/world/world_store.h"
#include "tests/common/voxel/mips_check.h"

namespace terrane {
namespace {

std::vector<std::uint8_t> image_of(const Chunk& c) {
  std::vector<std::uint8_t> out;
  c.write_image(out);
  return out;
}

Result<Chunk> read_all(std::span<const std::uint8_t> in) {
  std::size_t pos = 0;
  auto c = Chunk::read_image(in, pos);
  if (c && pos != in.size()) return DecodeError{DecodeErrorCode::kInvalidValue, pos, "bytes after the image"};
  return c;
}

void expect_same_chunk(const Chunk& got, const Chunk& want, const std::string& where) {
  Box a, b;
  for (int level = 0; level < kMipLevels; ++level) {
    got.read_level(level, a);
    want.read_level(level, b);
    ASSERT_TRUE(a == b) << where << " level " << level;
  }
  RowPackedBox<32>::Row scratch;
  for (int y = 0; y < 32; ++y)
    for (int z = 0; z < 32; ++z) {
      const Voxel* row = got.read_row(y, z, scratch);
      for (int x = 0; x < 32; ++x) ASSERT_EQ(row[x], want.get(x, y, z)) << where << " at " << x << "," << y << "," << z;
    }
  EXPECT_EQ(got.empty(), want.empty()) << where;
  EXPECT_EQ(got.uniform(), want.uniform()) << where;
  EXPECT_EQ(got.memory().total(), want.memory().total()) << where;
}

// Every row and mip level of a chunk read from untrusted bytes: readable, and
// every voxel a valid one (below material 64, Air only at occupancy 0).
void expect_safe(const Chunk& c) {
  RowPackedBox<32>::Row scratch;
  for (int y = 0; y < 32; ++y)
    for (int z = 0; z < 32; ++z) {
      const Voxel* row = c.read_row(y, z, scratch);
      for (int x = 0; x < 32; ++x) {
        ASSERT_LT(row[x].material, kMaterialCount);
        ASSERT_FALSE(row[x].material == kAir && row[x].occupancy != 0);
        ASSERT_EQ(row[x], c.get(x, y, z));
      }
    }
  Box level;
  for (int l = 1; l < kMipLevels; ++l) c.read_level(l, level);
  for (int y = 0; y < 32; y += 7) EXPECT_EQ(c.box_has_solid({0, y, 0}, {32, y + 1, 32}, 0) ,
                                            [&] {
                                              for (int z = 0; z < 32; ++z)
                                                for (int x = 0; x < 32; ++x)
                                                  if (c.get(x, y, z).material != kAir) return true;
                                              return false;
                                            }());
}

Grid grid_of(const std::string& name) {
  Grid grid;
  if (name == "default world") {
    TerrainGenerator gen(GeneratorParams{});
    const Region r{{-64, -32, -64}, {64, 96, 64}};
    Box box;
    gen.generate(r, box);
    grid.write_box(r.min, box);
  } else {
    const std::string path = std::string(TERRANE_TEST_DATA_DIR) + "/" + name + ".vxraw.gz";
    auto file = vxraw_read_file(path, VxrawLimits{});
    EXPECT_TRUE(file.ok()) << path;
    if (file) grid.write_box(file->origin, file->box);
  }
  grid.compact();
  return grid;
}

void check_dataset(const std::string& name) {
  const Grid grid = grid_of(name);
  std::size_t chunks = 0, packed = 0;
  grid.for_each_chunk([&](Vec3i pos, const Chunk& chunk) {
    if (::testing::Test::HasFatalFailure()) return;
    ++chunks;
    packed += !chunk.uniform();
    const std::string where = name + " chunk " + std::to_string(pos.x) + "," + std::to_string(pos.y) + "," +
                              std::to_string(pos.z);
    const auto image = image_of(chunk);
    auto back = read_all(image);
    ASSERT_TRUE(back.ok()) << where << ": " << back.error().detail << " at " << back.error().offset;
    expect_same_chunk(*back, chunk, where);
    EXPECT_EQ(image_of(*back), image) << where;
    for (int level = 1; level < kMipLevels; ++level) {
      const auto a = back->mip_unit(level), b = chunk.mip_unit(level);
      EXPECT_TRUE(std::equal(a.begin(), a.end(), b.begin(), b.end())) << where << " unit " << level;
    }
    // The mips read are the ones the rule gives for the voxels read.
    Box level0;
    back->read_level(0, level0);
    test_mips::expect_mips_as_rebuilt(*back, Chunk::from_box(level0), where);
  });
  EXPECT_GT(chunks, 10u) << name;
  EXPECT_GT(packed, 5u) << name;
}

TEST(ChunkImage, Mc19ChunksReadBackByteForByte) { check_dataset("mc-1.9"); }
TEST(ChunkImage, Mc116ChunksReadBackByteForByte) { check_dataset("mc-1.16"); }
TEST(ChunkImage, GeneratedWorldChunksReadBackByteForByte) { check_dataset("default world"); }

// A few kinds of chunk: uniform (Air and stone), one voxel, a noisy one with
// raw rows (more than 16 materials in a row) and partial occupancies.
std::vector<Chunk> sample_chunks() {
  std::vector<Chunk> out;
  out.emplace_back(kAir);
  out.emplace_back(materials::kRock);
  Chunk one;
  one.set({3, 4, 5}, make_voxel(materials::kSand, 90));
  one.compact();
  out.push_back(std::move(one));
  Chunk noisy;
  std::mt19937 rng(7);
  noisy.modify(Region{{0, 0, 0}, {32, 32, 32}}, [&](Vec3i p, Voxel) {
    if (p.y > 20) return Voxel{};
    if (p.y == 3) return make_voxel(static_cast<Material>(1 + (p.x + p.z) % 40), 255);
    const auto r = rng();
    return make_voxel(static_cast<Material>(1 + r % 5), static_cast<std::uint8_t>(r % 3 == 0 ? (r >> 8) & 255 : 255));
  });
  noisy.compact();
  out.push_back(std::move(noisy));
  return out;
}

TEST(ChunkImage, EveryTruncationIsAnError) {
  for (const Chunk& c : sample_chunks()) {
    const auto image = image_of(c);
    ASSERT_TRUE(read_all(image).ok());
    for (std::size_t n = 0; n < image.size(); ++n) {
      std::size_t pos = 0;
      auto got = Chunk::read_image(std::span(image.data(), n), pos);
      ASSERT_FALSE(got.ok()) << "prefix " << n << " of " << image.size();
      EXPECT_EQ(got.error().code, DecodeErrorCode::kTruncated) << "prefix " << n;
    }
  }
}

TEST(ChunkImage, DamagedImagesAreErrorsOrChunksThatReadSafely) {
  std::mt19937 rng(11);
  std::size_t errors = 0, read = 0;
  for (const Chunk& c : sample_chunks()) {
    const auto image = image_of(c);
    // Every byte of a small image; of a large one, its first 200 (form,
    // layer map, slots) and 300 others at random.
    std::vector<std::size_t> at;
    for (std::size_t i = 0; i < image.size() && (image.size() <= 500 || i < 200); ++i) at.push_back(i);
    while (at.size() < std::min<std::size_t>(image.size(), 500)) at.push_back(200 + rng() % (image.size() - 200));
    for (const std::size_t i : at) {
      // Each byte set to a few values: the edges of the fields' ranges.
      for (const std::uint8_t v : {std::uint8_t{0}, std::uint8_t{0x40}, std::uint8_t{0xBF}, std::uint8_t{0xFF},
                                   static_cast<std::uint8_t>(image[i] ^ (1u << (rng() % 8)))}) {
        if (v == image[i]) continue;
        auto bad = image;
        bad[i] = v;
        auto got = read_all(bad);
        if (!got) {
          ++errors;
          continue;
        }
        ++read;
        expect_safe(*got);
        if (::testing::Test::HasFatalFailure()) {
          ADD_FAILURE() << "byte " << i << " set to " << int(v);
          return;
        }
        // What was read writes an image that reads back the same.
        auto again = read_all(image_of(*got));
        ASSERT_TRUE(again.ok()) << "byte " << i;
        expect_same_chunk(*again, *got, "byte " + std::to_string(i));
      }
    }
  }
  // Both outcomes happen: checks refuse structure, while a changed material
  // or occupancy byte is still a valid chunk.
  EXPECT_GT(errors, 100u);
  EXPECT_GT(read, 100u);
}

TEST(ChunkImage, UnpackedStorageAndUnpackedMipsWriteTheImageOfThePackedChunk) {
  Chunk c = std::move(sample_chunks()[3]);
  Chunk edited = c.clone();
  // Many small writes: level 0 unpacks itself, and the mips stay unpacked.
  for (int i = 0; i < 200; ++i) edited.set({i % 32, (i * 7) % 20, (i * 13) % 32}, make_voxel(materials::kSand, 200));
  ASSERT_TRUE(edited.level0().unpacked());
  ASSERT_FALSE(edited.mips_packed());
  auto back = read_all(image_of(edited));
  ASSERT_TRUE(back.ok()) << back.error().detail;
  expect_same_chunk(*back, [&] {
    Chunk packed = edited.clone();
    packed.compact();
    return packed;
  }(), "edited");
  EXPECT_FALSE(back->level0().unpacked());
  EXPECT_TRUE(back->mips_packed());
}

TEST(ChunkImage, APackedImageOfOneMaterialIsRefused) {
  // Stone with one layer of sand: a packed box whose layers are all uniform
  // (a layer map and no slots, no data).
  Chunk c(materials::kRock);
  c.modify(Region{{0, 5, 0}, {32, 6, 32}}, [](Vec3i, Voxel) { return solid(materials::kSand); });
  c.compact();
  auto image = image_of(c);
  ASSERT_EQ(image[0], 1);
  ASSERT_EQ(image[1 + 5], 0x80 | materials::kSand);
  ASSERT_EQ(image[1 + 6], 0x80 | materials::kRock);
  EXPECT_EQ(image[33], 0);  // no data
  EXPECT_EQ(image[34], 0);
  ASSERT_TRUE(read_all(image).ok());
  // All stone in a packed image: a reader would take it for a box with
  // rows while uniform() said otherwise.
  image[1 + 5] = 0x80 | materials::kRock;
  auto got = read_all(image);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(got.error().offset, 1u);
}

TEST(ChunkImage, ARecordInsideAnotherIsRefused) {
  // Layer 0 wide (slot units 0 and 1), the others Air. Row 0's record is a
  // 1-bit index record of palette 0 {Air, Rock} at byte 5; row 1's starts
  // at byte 6, inside it, where 64 bytes read as a valid raw record (Rock
  // at occupancy 0). Each is valid alone, but a write in place to row 0
  // would rewrite row 1's first bytes.
  std::vector<std::uint8_t> image{1, 0x40};
  for (int y = 1; y < 32; ++y) image.push_back(0x80);
  const auto word = [&](std::uint16_t w) {
    image.push_back(static_cast<std::uint8_t>(w & 0xFF));
    image.push_back(static_cast<std::uint8_t>(w >> 8));
  };
  std::vector<std::uint8_t> data{1, 2, 1, kAir, materials::kRock, 0x40};
  for (int i = 0; i < 32; ++i) {
    data.push_back(materials::kRock);
    data.push_back(0);
  }
  const auto image_with = [&](std::uint16_t row1) {
    image.resize(33);
    word(0x8005);
    word(row1);
    for (int z = 2; z < 36; ++z) word(0);
    word(static_cast<std::uint16_t>(data.size()));
    image.insert(image.end(), data.begin(), data.end());
    return image;
  };
  std::size_t pos = 0;
  auto got = RowPackedBox<32>::read_image(image_with(0x8006), pos);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_STREQ(got.error().detail, "row-packed image: a record inside another");
  // Row 1 sharing row 0's record instead: valid, and both rows read it.
  pos = 0;
  got = RowPackedBox<32>::read_image(image_with(0x8005), pos);
  ASSERT_TRUE(got.ok()) << got.error().detail;
  EXPECT_EQ(pos, image.size());
  EXPECT_EQ(got->get(3, 0, 1), solid(materials::kRock));
  EXPECT_EQ(got->get(2, 0, 1), Voxel{});
}

TEST(ChunkImage, AChunkWhoseRowsStayUnpackedIsStoredAsCodecOne) {
  // 1,024 distinct raw rows (64 KiB of records, beyond 15-bit offsets): the
  // chunk stays unpacked when packed and has no image.
  Chunk c;
  c.modify(Region{{0, 0, 0}, {32, 32, 32}}, [](Vec3i p, Voxel) {
    const int r = p.y * 32 + p.z;
    return make_voxel(static_cast<Material>(1 + (p.x + r) % 40), static_cast<std::uint8_t>(p.x < 2 ? r >> (8 * p.x) : 7));
  });
  c.compact();
  ASSERT_TRUE(c.level0().unpacked());
  std::vector<std::uint8_t> out;
  EXPECT_FALSE(c.write_image(out));
  EXPECT_TRUE(out.empty());
  const auto blob = encode_chunk_blob(c);
  EXPECT_EQ(blob[1], 1) << "codec 1";
  auto back = decode_chunk_blob(blob);
  ASSERT_TRUE(back.ok());
  expect_same_chunk(*back, c, "unpacked");
}

TEST(ChunkImage, MipsThatCallAChunkEmptyWhileItHoldsVoxelsAreRefused) {
  // A one-voxel chunk's image with the mips of an empty chunk (all Air):
  // the reader would drop the chunk as empty.
  Chunk one;
  one.set({3, 4, 5}, make_voxel(materials::kSand, 90));
  one.compact();
  auto image = image_of(one);
  std::size_t level0_end = 0;
  ASSERT_TRUE(RowPackedBox<32>::read_image(image, level0_end).ok());
  image.resize(level0_end);
  std::vector<std::uint8_t> units;
  for (int level = 1; level < kMipLevels; ++level) {
    const int n = kChunkSize >> level;
    std::vector<Voxel> air(static_cast<std::size_t>(n * n * n));
    units.clear();
    net_codec_encode(n, air, units);
    image.push_back(static_cast<std::uint8_t>(units.size() & 0xFF));
    image.push_back(static_cast<std::uint8_t>(units.size() >> 8));
    image.insert(image.end(), units.begin(), units.end());
  }
  auto got = read_all(image);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, DecodeErrorCode::kInvalidValue);
}

// A chunk encodes its mips in network codec version 1; an image whose mip
// units are of version 2 (as a writer may store them) reads too, keeps its
// units as stored and gives the same mips.
TEST(ChunkImage, AnImageWithVersion2MipUnitsReadsTheSameMips) {
  const Grid grid = grid_of("default world");
  std::size_t version2 = 0, checked = 0;
  grid.for_each_chunk([&](Vec3i, const Chunk& chunk) {
    if (chunk.uniform() || checked >= 200) return;
    auto image = image_of(chunk);
    std::size_t level0_end = 0;
    ASSERT_TRUE(RowPackedBox<32>::read_image(image, level0_end).ok());
    image.resize(level0_end);
    std::vector<std::uint8_t> written[kMipLevels];
    for (int level = 1; level < kMipLevels; ++level) {
      const int n = kChunkSize >> level;
      Box box({n, n, n});
      chunk.read_level(level, box);
      std::vector<std::uint8_t>& two = written[level];
      net_codec_encode(n, box.voxels(), two, kNetCodecVersion2);
      version2 += (two[0] & 0x0F) == kNetCodecVersion2;
      image.push_back(static_cast<std::uint8_t>(two.size() & 0xFF));
      image.push_back(static_cast<std::uint8_t>(two.size() >> 8));
      image.insert(image.end(), two.begin(), two.end());
    }
    auto back = read_all(image);
    ASSERT_TRUE(back.ok()) << back.error().detail;
    for (int level = 1; level < kMipLevels; ++level) {
      const auto unit = back->mip_unit(level);
      EXPECT_TRUE(std::equal(unit.begin(), unit.end(), written[level].begin(), written[level].end())) << "kept as stored";
      Box a, b;
      back->read_level(level, a);
      chunk.read_level(level, b);
      EXPECT_EQ(a, b) << "level " << level;
    }
    ++checked;
  });
  EXPECT_GT(checked, 50u);
  EXPECT_GT(version2, 0u) << "no mip of the generated terrain in version 2";
}

}  // namespace
}  // namespace terrane
