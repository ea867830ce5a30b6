#include "common/codec/byte_rle.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace terrane {
namespace {

using Bytes = std::vector<std::uint8_t>;

// Straightforward one-voxel-at-a-time encoder: the reference the word-scanning
// encoder must match byte for byte.
Bytes reference_encode(const std::vector<Voxel>& voxels) {
  Bytes out;
  std::size_t i = 0;
  while (i < voxels.size()) {
    const Voxel v = voxels[i];
    std::size_t n = 1;
    while (i + n < voxels.size() && n < 256 && voxels[i + n] == v) ++n;
    const bool occ = v.material != kAir && v.occupancy != 255;
    out.push_back(static_cast<std::uint8_t>(v.material | (occ ? 0x40 : 0) | (n > 1 ? 0x80 : 0)));
    if (occ) out.push_back(v.occupancy);
    if (n > 1) out.push_back(static_cast<std::uint8_t>(n - 1));
    i += n;
  }
  return out;
}

Bytes encode(const std::vector<Voxel>& voxels) {
  Bytes out;
  byte_rle_encode(voxels, out);
  return out;
}

std::vector<Voxel> decode_ok(const Bytes& bytes, std::size_t count) {
  std::vector<Voxel> out(count);
  const Status s = byte_rle_decode(bytes, out);
  EXPECT_TRUE(s.ok()) << s.error().describe();
  return out;
}

DecodeError decode_err(const Bytes& bytes, std::size_t count) {
  std::vector<Voxel> out(count);
  const Status s = byte_rle_decode(bytes, out);
  EXPECT_FALSE(s.ok());
  return s.ok() ? DecodeError{} : s.error();
}

Voxel random_voxel(std::mt19937& rng) {
  const auto m = static_cast<Material>(rng() % kMaterialCount);
  // Half the solids full, half with a random occupancy.
  const auto occ = static_cast<std::uint8_t>(rng() % 2 == 0 ? 255 : rng() % 256);
  return make_voxel(m, occ);
}

// Runs of random lengths (1..max_run) of random voxels.
std::vector<Voxel> random_runs(std::mt19937& rng, std::size_t count, std::size_t max_run) {
  std::vector<Voxel> v;
  v.reserve(count);
  while (v.size() < count) {
    const Voxel x = random_voxel(rng);
    const std::size_t n = std::min<std::size_t>(1 + rng() % max_run, count - v.size());
    v.insert(v.end(), n, x);
  }
  return v;
}

void expect_round_trip(const std::vector<Voxel>& voxels) {
  const Bytes bytes = encode(voxels);
  EXPECT_EQ(bytes, reference_encode(voxels));
  EXPECT_LE(bytes.size(), byte_rle_max_encoded_size(voxels.size()));
  Bytes direct(byte_rle_max_encoded_size(voxels.size()));
  direct.resize(byte_rle_encode_to(voxels, direct));
  EXPECT_EQ(direct, bytes);
  EXPECT_EQ(decode_ok(bytes, voxels.size()), voxels);
}

TEST(ByteRle, UniformSolidChunkIs128TwoByteRuns) {
  const std::vector<Voxel> chunk(32 * 32 * 32, solid(materials::kRock));
  const Bytes bytes = encode(chunk);
  ASSERT_EQ(bytes.size(), 256u);
  for (std::size_t i = 0; i < bytes.size(); i += 2) {
    EXPECT_EQ(bytes[i], 0x88);      // count bit | Rock (8)
    EXPECT_EQ(bytes[i + 1], 0xFF);  // 256 voxels
  }
  EXPECT_EQ(decode_ok(bytes, chunk.size()), chunk);
}

TEST(ByteRle, AllAirChunkIs128TwoByteRuns) {
  const std::vector<Voxel> chunk(32 * 32 * 32, Voxel{});
  const Bytes bytes = encode(chunk);
  ASSERT_EQ(bytes.size(), 256u);
  for (std::size_t i = 0; i < bytes.size(); i += 2) {
    EXPECT_EQ(bytes[i], 0x80);
    EXPECT_EQ(bytes[i + 1], 0xFF);
  }
  EXPECT_EQ(decode_ok(bytes, chunk.size()), chunk);
}

TEST(ByteRle, GoldenBytes) {
  using namespace materials;
  EXPECT_EQ(encode({}), Bytes{});
  EXPECT_EQ(encode({Voxel{}}), (Bytes{0x00}));
  EXPECT_EQ(encode({Voxel{}, Voxel{}}), (Bytes{0x80, 0x01}));
  EXPECT_EQ(encode({solid(kSand)}), (Bytes{0x06}));
  EXPECT_EQ(encode({make_voxel(kGrass, 100)}), (Bytes{0x42, 100}));
  EXPECT_EQ(encode(std::vector<Voxel>(3, make_voxel(kGrass, 100))), (Bytes{0xC2, 100, 0x02}));
  EXPECT_EQ(encode(std::vector<Voxel>(257, solid(kRock))), (Bytes{0x88, 0xFF, 0x08}));

  // Air x5, Water at half occupancy, one full Sand, 256 of material 63 at occupancy 0.
  std::vector<Voxel> mixed(5, Voxel{});
  mixed.push_back(make_voxel(kWater, 127));
  mixed.push_back(solid(kSand));
  mixed.insert(mixed.end(), 256, make_voxel(63, 0));
  const Bytes golden{0x80, 0x04, 0x41, 0x7F, 0x06, 0xFF, 0x00, 0xFF};
  EXPECT_EQ(encode(mixed), golden);
  EXPECT_EQ(decode_ok(golden, mixed.size()), mixed);
}

TEST(ByteRle, RunLengthsAroundTheLimit) {
  // {voxels, expected bytes} for a full solid: one lead (+ count) per 256.
  const std::pair<std::size_t, std::size_t> cases[] = {{1, 1},   {2, 2},   {255, 2}, {256, 2},
                                                       {257, 3}, {258, 4}, {512, 4}, {513, 5}};
  for (auto [count, size] : cases) {
    const std::vector<Voxel> v(count, solid(materials::kSnow));
    EXPECT_EQ(encode(v).size(), size) << count << " voxels";
    expect_round_trip(v);
  }
}

TEST(ByteRle, RunsOfOne) {
  std::vector<Voxel> v;
  for (int i = 0; i < 1000; ++i) v.push_back(solid(static_cast<Material>(1 + i % 63)));
  EXPECT_EQ(encode(v).size(), v.size());
  expect_round_trip(v);
}

TEST(ByteRle, WorstCaseIsTwoBytesPerVoxel) {
  std::vector<Voxel> v;
  for (int i = 0; i < 32768; ++i) v.push_back(make_voxel(i % 2 == 0 ? materials::kMud : materials::kIce, 7));
  const Bytes bytes = encode(v);
  EXPECT_EQ(bytes.size(), byte_rle_max_encoded_size(v.size()));
  expect_round_trip(v);
}

TEST(ByteRle, RunsCrossing256) {
  std::vector<Voxel> v(100, solid(materials::kRock));
  v.insert(v.end(), 300, make_voxel(materials::kRock, 3));
  v.insert(v.end(), 1, solid(materials::kRock));
  v.insert(v.end(), 700, Voxel{});
  v.insert(v.end(), 256, solid(materials::kRock));
  expect_round_trip(v);
}

TEST(ByteRle, RandomVoxelsRoundTrip) {
  std::mt19937 rng(1234);
  for (std::size_t count : {0, 1, 2, 3, 4, 5, 7, 8, 9, 31, 1000, 32768}) {
    std::vector<Voxel> v(count);
    for (auto& x : v) x = random_voxel(rng);
    expect_round_trip(v);
  }
}

TEST(ByteRle, RandomRunsRoundTrip) {
  std::mt19937 rng(99);
  for (std::size_t max_run : {2, 5, 40, 300, 2000}) {
    for (int rep = 0; rep < 10; ++rep) expect_round_trip(random_runs(rng, 32768, max_run));
  }
  // Enough short runs to pass several of the encoder's internal blocks.
  expect_round_trip(random_runs(rng, 200000, 3));
}

TEST(ByteRle, EncodeAppends) {
  Bytes out{1, 2, 3};
  byte_rle_encode(std::vector<Voxel>(2, Voxel{}), out);
  EXPECT_EQ(out, (Bytes{1, 2, 3, 0x80, 0x01}));
}

TEST(ByteRle, AirOccupancyIsNotEncoded) {
  // A raw Air voxel with an occupancy byte (never produced by make_voxel)
  // still encodes as plain Air, so the output always decodes.
  const std::vector<Voxel> v{Voxel{kAir, 9}, Voxel{kAir, 0}};
  const Bytes bytes = encode(v);
  EXPECT_EQ(bytes, (Bytes{0x00, 0x00}));
  EXPECT_EQ(decode_ok(bytes, 2), (std::vector<Voxel>{Voxel{}, Voxel{}}));
}

TEST(ByteRleDecode, EmptyInputEmptyOutput) { decode_ok({}, 0); }

TEST(ByteRleDecode, AcceptsRedundantDefaultOccupancy) {
  EXPECT_EQ(decode_ok({0x48, 0xFF}, 1), (std::vector<Voxel>{solid(materials::kRock)}));
}

TEST(ByteRleDecode, RejectsCountByteZero) {
  const DecodeError e = decode_err({0x88, 0x00}, 1);
  EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(e.offset, 1u);
}

TEST(ByteRleDecode, RejectsAirWithOccupancyBit) {
  for (std::uint8_t lead : {std::uint8_t{0x40}, std::uint8_t{0xC0}}) {
    const DecodeError e = decode_err({0x06, lead, 0x05, 0x01}, 3);
    EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue);
    EXPECT_EQ(e.offset, 1u);
  }
}

TEST(ByteRleDecode, RejectsRunPastEndOfOutput) {
  const DecodeError e = decode_err({0x01, 0x88, 0x02}, 3);  // 1 + 3 voxels into 3
  EXPECT_EQ(e.code, DecodeErrorCode::kOverLimit);
  EXPECT_EQ(e.offset, 1u);
  EXPECT_EQ(decode_err({0x01}, 0).code, DecodeErrorCode::kTrailingBytes);
}

TEST(ByteRleDecode, RejectsTruncation) {
  EXPECT_EQ(decode_err({}, 1).code, DecodeErrorCode::kTruncated);
  EXPECT_EQ(decode_err({0x48}, 1).code, DecodeErrorCode::kTruncated);        // missing occupancy
  EXPECT_EQ(decode_err({0xC8, 0x10}, 2).code, DecodeErrorCode::kTruncated);  // missing count
  EXPECT_EQ(decode_err({0x88}, 2).code, DecodeErrorCode::kTruncated);
  const DecodeError e = decode_err({0x88, 0x01}, 3);  // 2 of 3 voxels
  EXPECT_EQ(e.code, DecodeErrorCode::kTruncated);
  EXPECT_EQ(e.offset, 2u);
}

TEST(ByteRleDecode, RejectsTrailingBytes) {
  const DecodeError e = decode_err({0x08, 0x08}, 1);
  EXPECT_EQ(e.code, DecodeErrorCode::kTrailingBytes);
  EXPECT_EQ(e.offset, 1u);
}

TEST(ByteRleDecode, ReportsErrorsInsideALargeChunk) {
  // Errors early in a big output, where the decoder's unchecked fast path runs.
  const Bytes prefix{0x88, 0xFF, 0x42, 0x10, 0x00};  // 256 Rock, 1 Grass, 1 Air
  struct Case {
    Bytes tail;
    DecodeErrorCode code;
    std::size_t offset;
  } cases[] = {
      {{0x88, 0x00, 0x88, 0xFF}, DecodeErrorCode::kInvalidValue, 6},
      {{0xC8, 0x10, 0x00, 0x88, 0xFF}, DecodeErrorCode::kInvalidValue, 7},
      {{0x40, 0x10, 0x88, 0xFF}, DecodeErrorCode::kInvalidValue, 5},
      {{0xC0, 0x10, 0x05}, DecodeErrorCode::kInvalidValue, 5},
  };
  for (const Case& c : cases) {
    Bytes bytes = prefix;
    bytes.insert(bytes.end(), c.tail.begin(), c.tail.end());
    const DecodeError e = decode_err(bytes, 32768);
    EXPECT_EQ(e.code, c.code);
    EXPECT_EQ(e.offset, c.offset);
  }
}

TEST(ByteRleDecode, EveryTruncatedPrefixFails) {
  std::mt19937 rng(7);
  const std::vector<Voxel> v = random_runs(rng, 4096, 20);
  const Bytes bytes = encode(v);
  std::vector<Voxel> out(v.size());
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    const Status s = byte_rle_decode(std::span(bytes).first(n), out);
    ASSERT_FALSE(s.ok()) << "prefix " << n;
    EXPECT_EQ(s.error().code, DecodeErrorCode::kTruncated) << "prefix " << n;
  }
  Bytes longer = bytes;
  longer.push_back(0x00);
  EXPECT_EQ(decode_err(longer, v.size()).code, DecodeErrorCode::kTrailingBytes);
}

}  // namespace
}  // namespace terrane
