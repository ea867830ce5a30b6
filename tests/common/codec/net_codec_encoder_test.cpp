// The network voxel codec's unit encoder (common/codec/net_codec_encoder.h):
// which kind it picks for edge-case units, the fields it writes, and that
// the decoder gives the same voxels back.
#include "common/codec/net_codec_encoder.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "common/codec/net_codec.h"
#include "common/codec/net_codec_decoder.h"
#include "common/codec/net_codec_tables.h"

#include "tests/common/codec/test_units.h"

namespace terrane::net_codec_detail {
namespace {

using namespace test_units;

constexpr int kSizes[] = {4, 8, 16};

std::vector<std::uint8_t> encode(int n, const std::vector<Voxel>& v) {
  std::vector<std::uint8_t> out;
  switch (n) {
    case 4: encode_unit<4>(v.data(), out, kNetCodecVersion1); break;
    case 8: encode_unit<8>(v.data(), out, kNetCodecVersion1); break;
    default: encode_unit<16>(v.data(), out, kNetCodecVersion1); break;
  }
  return out;
}

Result<std::size_t> decode(int n, const std::vector<std::uint8_t>& bytes, std::vector<Voxel>& out) {
  switch (n) {
    case 4: return decode_unit<4>(bytes, out);
    case 8: return decode_unit<8>(bytes, out);
    default: return decode_unit<16>(bytes, out);
  }
}

int kind_of(const std::vector<std::uint8_t>& bytes) { return bytes.at(0) >> 4; }

// The palette header of a kind 3 or 4 unit: (count, partial).
std::pair<int, bool> palette_header(const std::vector<std::uint8_t>& bytes) {
  BitReader r(bytes.data() + 1, bytes.data() + bytes.size());
  r.refill();
  const int count = static_cast<int>(r.get(6)) + 1;
  for (int i = 0; i < count; ++i) {
    r.refill();
    r.get(6);
  }
  r.refill();
  return {count, r.get(1) != 0};
}

// Encodes, checks the bound and the version, decodes the voxels back.
std::vector<std::uint8_t> expect_round_trip(int n, const std::vector<Voxel>& v) {
  const auto bytes = encode(n, v);
  EXPECT_LE(bytes.size(), net_codec_max_encoded_size(n));
  EXPECT_EQ(bytes.at(0) & 0x0F, kNetCodecVersion);
  std::vector<Voxel> back = make_unit(n, solid(7));
  const auto used = decode(n, bytes, back);
  EXPECT_TRUE(used.ok()) << used.error().describe();
  if (used.ok()) {
    EXPECT_EQ(*used, bytes.size());
  }
  EXPECT_EQ(back, v);
  return bytes;
}

TEST(NetCodecEncoder, AllAirIsOneByte) {
  for (int n : kSizes) {
    EXPECT_EQ(expect_round_trip(n, make_unit(n)), (std::vector<std::uint8_t>{kNetCodecVersion | (kKindAir << 4)}));
  }
}

TEST(NetCodecEncoder, AllSolidIsTwoBytesAndUniformOccupancyThree) {
  for (int n : kSizes) {
    EXPECT_EQ(expect_round_trip(n, make_unit(n, solid(63))), (std::vector<std::uint8_t>{0x11, 63}));
    EXPECT_EQ(expect_round_trip(n, make_unit(n, make_voxel(1, 1))), (std::vector<std::uint8_t>{0x21, 1, 1}));
  }
}

TEST(NetCodecEncoder, AppendsAfterWhatTheBufferHolds) {
  std::vector<std::uint8_t> out = {0xAA, 0xBB};
  encode_unit<4>(make_unit(4, solid(3)).data(), out, kNetCodecVersion1);
  EXPECT_EQ(out, (std::vector<std::uint8_t>{0xAA, 0xBB, 0x11, 3}));
}

// One solid voxel in Air is a short token stream of two palette entries.
TEST(NetCodecEncoder, OneVoxelDifferenceIsATokenStream) {
  for (int n : kSizes) {
    const auto volume = static_cast<std::size_t>(n * n * n);
    for (std::size_t at : {std::size_t{0}, volume / 2, volume - 1}) {
      auto v = make_unit(n);
      v[at] = solid(9);
      const auto bytes = expect_round_trip(n, v);
      EXPECT_EQ(kind_of(bytes), kKindTokens);
      EXPECT_EQ(palette_header(bytes), std::make_pair(2, false));
      EXPECT_LE(bytes.size(), 12u) << "n=" << n << " at=" << at;
    }
  }
}

// A single voxel with a partial occupancy turns on the unit's partial flag,
// and its occupancy comes back exactly; the full ones stay full.
TEST(NetCodecEncoder, PartialOccupancyIsKeptExactly) {
  for (int n : kSizes) {
    auto v = make_unit(n, solid(4));
    v[idx(n, 1, 1, 1)] = make_voxel(4, 77);
    v[idx(n, 2, 0, 3)] = make_voxel(5, 1);
    const auto bytes = expect_round_trip(n, v);
    EXPECT_EQ(kind_of(bytes), kKindTokens);
    EXPECT_EQ(palette_header(bytes), std::make_pair(2, true));
  }
}

// All 64 materials in one unit: the palette at its limit (count - 1 = 63).
TEST(NetCodecEncoder, PaletteOfAllSixtyFourMaterialsRoundTrips) {
  for (int n : kSizes) {
    auto v = make_unit(n);
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = solid(static_cast<Material>(i % kMaterialCount));
    const auto bytes = expect_round_trip(n, v);
    ASSERT_TRUE(kind_of(bytes) == kKindTokens || kind_of(bytes) == kKindPacked);
    EXPECT_EQ(palette_header(bytes), std::make_pair(64, false));
    // Partial occupancies on top.
    for (std::size_t i = 0; i < v.size(); ++i) {
      if (v[i].material != kAir) v[i].occupancy = static_cast<std::uint8_t>(1 + i % 200);
    }
    const auto partial = expect_round_trip(n, v);
    if (kind_of(partial) != kKindRaw) {
      EXPECT_EQ(palette_header(partial), std::make_pair(64, true));
    }
  }
}

// Random materials without partial occupancies do not compress as tokens:
// the packed form bounds them, 6 bits a voxel with a full palette.
TEST(NetCodecEncoder, RandomUnitsFallBackToPacked) {
  std::mt19937 rng(11);
  for (int n : kSizes) {
    const auto bytes = expect_round_trip(n, random_unit(n, rng, 64, false));
    EXPECT_EQ(kind_of(bytes), kKindPacked) << "n=" << n;
  }
}

// Every voxel a different material at a partial occupancy: for 4^3 raw
// voxels (128 bytes) beat the packed form (160 bytes), which wins above.
TEST(NetCodecEncoder, WorstCaseFourCubedIsRawAndLargerUnitsPacked) {
  for (int n : kSizes) {
    auto v = make_unit(n);
    for (std::size_t i = 0; i < v.size(); ++i) {
      const auto m = static_cast<Material>((i * 37) % kMaterialCount);
      v[i] = make_voxel(m, m == kAir ? 0 : static_cast<std::uint8_t>(1 + (i * 101) % 250));
    }
    const auto bytes = expect_round_trip(n, v);
    if (n == 4) {
      EXPECT_EQ(kind_of(bytes), kKindRaw);
      EXPECT_EQ(bytes.size(), 1u + 2u * 64u);
    } else {
      EXPECT_EQ(kind_of(bytes), kKindPacked);
    }
  }
}

// Layers and rows that repeat are copies: far below packed size.
TEST(NetCodecEncoder, RepeatedRowsAndLayersAreCopies) {
  for (int n : kSizes) {
    auto v = make_unit(n);
    for (int y = 0; y < n; ++y) {
      for (int z = 0; z < n; ++z) {
        for (int x = 0; x < n; ++x) v[idx(n, x, y, z)] = solid(static_cast<Material>(1 + x % 3));
      }
    }
    const auto bytes = expect_round_trip(n, v);
    EXPECT_EQ(kind_of(bytes), kKindTokens);
    EXPECT_LE(bytes.size(), 24u) << "n=" << n;
  }
}

TEST(NetCodecEncoder, TerrainAndRandomUnitsRoundTrip) {
  std::mt19937 rng(5);
  for (int n : kSizes) {
    for (float slope : {0.0f, 0.4f, 1.7f}) expect_round_trip(n, terrain_unit(n, 1.5f, slope));
    for (int materials : {2, 3, 9, 64}) {
      for (bool partial : {false, true}) expect_round_trip(n, random_unit(n, rng, materials, partial));
    }
  }
}

}  // namespace
}  // namespace terrane::net_codec_detail
