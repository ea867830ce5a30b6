#include "common/codec/net_codec.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "common/vxraw/vxraw.h"

#include "tests/common/codec/test_units.h"

namespace terrane {
namespace {

constexpr int kSizes[] = {4, 8, 16};
constexpr std::uint8_t kVersions[] = {kNetCodecVersion1, kNetCodecVersion2};

using namespace test_units;

std::vector<std::uint8_t> encode(int n, const std::vector<Voxel>& v, std::uint8_t version = kNetCodecVersion) {
  std::vector<std::uint8_t> out;
  net_codec_encode(n, v, out, version);
  return out;
}

// In both format versions (a version-2 encoder writes version 2 only where
// it is shorter).
void expect_round_trip(int n, const std::vector<Voxel>& v) {
  std::size_t version1_size = 0;
  for (std::uint8_t version : kVersions) {
    const auto bytes = encode(n, v, version);
    if (version == kNetCodecVersion1) {
      EXPECT_EQ(bytes.at(0) & 0x0F, kNetCodecVersion1);
      version1_size = bytes.size();
    } else {
      EXPECT_LE(bytes.size(), version1_size);
    }
    EXPECT_LE(bytes.size(), net_codec_max_encoded_size(n));
    std::vector<Voxel> back = make_unit(n, solid(5));
    const Status s = net_codec_decode(n, bytes, back);
    ASSERT_TRUE(s.ok()) << "version " << int{version} << ": " << s.error().describe();
    EXPECT_EQ(back, v) << "version " << int{version};
    // Prefix decode with data after it reports the unit's own size.
    auto longer = bytes;
    longer.push_back(0xAB);
    auto used = net_codec_decode_prefix(n, longer, back);
    ASSERT_TRUE(used.ok());
    EXPECT_EQ(*used, bytes.size());
  }
}

// The worked examples of common/codec/NET_CODEC.md, one per unit kind: the encoder
// writes exactly these bytes and the decoder returns exactly these voxels
// (tests/spec/net_codec_reference.py decodes the same examples from the
// document with a decoder written from it alone).
TEST(NetCodec, SpecExamplesAreTheEncodersBytesAndDecodeToTheirVoxels) {
  auto hex = [](const std::string& h) {
    std::vector<std::uint8_t> out;
    for (std::size_t i = 0; i + 1 < h.size(); i += 3) out.push_back(static_cast<std::uint8_t>(std::stoi(h.substr(i, 2), nullptr, 16)));
    return out;
  };
  auto idx = [](int x, int y, int z) { return static_cast<std::size_t>((y * 4 + z) * 4 + x); };
  struct Example {
    const char* name;
    std::vector<Voxel> voxels;
    std::string bytes;
    std::uint8_t version = kNetCodecVersion1;
  };
  std::vector<Example> examples;
  examples.push_back({"kind 0", std::vector<Voxel>(64), "01"});
  examples.push_back({"kind 1", std::vector<Voxel>(64, make_voxel(3, 255)), "11 03"});
  examples.push_back({"kind 2", std::vector<Voxel>(64, make_voxel(3, 128)), "21 03 80"});
  std::vector<Voxel> layers(64);
  for (int z = 0; z < 4; ++z)
    for (int x = 0; x < 4; ++x) {
      layers[idx(x, 0, z)] = make_voxel(1, 255);
      layers[idx(x, 1, z)] = make_voxel(x == 2 && z == 1 ? 5 : 2, 255);
    }
  examples.push_back({"kind 3", layers, "31 03 10 08 05 c2 17 d6 49 34 e0 03"});
  const int scattered[64] = {3, 1, 1, 1, 1, 2, 1, 2, 2, 3, 2, 1, 3, 1, 1, 2, 1, 2, 1, 3, 1, 2, 3, 3, 2, 1, 1, 2, 3, 2, 3, 1,
                             1, 3, 1, 1, 3, 1, 2, 2, 3, 3, 3, 2, 3, 2, 1, 2, 1, 3, 2, 1, 1, 1, 2, 2, 2, 1, 3, 1, 1, 1, 1, 2};
  std::vector<Voxel> packed(64);
  for (int i = 0; i < 64; ++i) packed[static_cast<std::size_t>(i)] = make_voxel(static_cast<Material>(scattered[i]), 255);
  examples.push_back({"kind 4", packed, "41 42 20 0c 04 88 32 84 08 49 83 4c 10 a4 d4 8c 30 a0 42 80 00"});
  std::vector<Voxel> raw(64);
  std::string raw_hex = "51";
  for (int i = 0; i < 64; ++i) {
    raw[static_cast<std::size_t>(i)] = make_voxel(static_cast<Material>(1 + i % 63), static_cast<std::uint8_t>(4 * i + 3));
    char b[8];
    std::snprintf(b, sizeof b, " %02x %02x", 1 + i % 63, (4 * i + 3) & 255);
    raw_hex += b;
  }
  examples.push_back({"kind 5", raw, raw_hex});
  std::vector<Voxel> plane(64);
  for (int z = 0; z < 4; ++z)
    for (int x = 0; x < 4; ++x) plane[idx(x, 0, z)] = make_voxel(1, static_cast<std::uint8_t>(40 + 50 * x + 10 * z));
  examples.push_back({"version 2, kind 3", plane, "32 41 00 24 00 00 61 00 4b 12 58 24 49 92 24 0d 7c", kNetCodecVersion2});
  for (const Example& e : examples) {
    std::vector<std::uint8_t> out;
    net_codec_encode(4, e.voxels, out, e.version);
    EXPECT_EQ(out, hex(e.bytes)) << e.name;
    std::vector<Voxel> back(64);
    const auto used = net_codec_decode_prefix(4, hex(e.bytes), back);
    ASSERT_TRUE(used.ok()) << e.name;
    EXPECT_EQ(*used, hex(e.bytes).size()) << e.name;
    EXPECT_EQ(back, e.voxels) << e.name;
  }
}

TEST(NetCodec, MaxEncodedSizeIsBelowRaw) {
  EXPECT_EQ(net_codec_max_encoded_size(4), 129u);
  EXPECT_EQ(net_codec_max_encoded_size(8), 946u);
  EXPECT_EQ(net_codec_max_encoded_size(16), 7218u);
  for (int n : kSizes) EXPECT_LE(net_codec_max_encoded_size(n), static_cast<std::size_t>(2 * n * n * n + 1));
}

TEST(NetCodec, UniformUnitsCostOneToThreeBytes) {
  for (int n : kSizes) {
    EXPECT_EQ(encode(n, make_unit(n)).size(), 1u);
    EXPECT_EQ(encode(n, make_unit(n, solid(materials::kRock))).size(), 2u);
    EXPECT_EQ(encode(n, make_unit(n, make_voxel(materials::kWater, 100))).size(), 3u);
    expect_round_trip(n, make_unit(n));
    expect_round_trip(n, make_unit(n, solid(63)));
    expect_round_trip(n, make_unit(n, make_voxel(1, 0)));
  }
}

TEST(NetCodec, RoundTripsRandomUnits) {
  std::mt19937 rng(7);
  for (int n : kSizes) {
    for (int materials : {2, 3, 5, 17, 64}) {
      for (int rep = 0; rep < 5; ++rep) {
        expect_round_trip(n, random_unit(n, rng, materials, false));
        expect_round_trip(n, random_unit(n, rng, materials, true));
      }
    }
  }
}

TEST(NetCodec, WorstCaseStaysWithinBound) {
  std::mt19937 rng(11);
  for (int n : kSizes) {
    for (int rep = 0; rep < 20; ++rep) {
      auto v = random_unit(n, rng, 64, true);
      const auto bytes = encode(n, v);
      EXPECT_LE(bytes.size(), net_codec_max_encoded_size(n));
      expect_round_trip(n, v);
    }
  }
}

TEST(NetCodec, RoundTripsSingleVoxelDifferences) {
  for (int n : kSizes) {
    const int volume = n * n * n;
    for (int i : {0, 1, n - 1, n, n * n - 1, n * n, volume / 2, volume - 1}) {
      auto v = make_unit(n, solid(materials::kRock));
      v[static_cast<std::size_t>(i)] = Voxel{};
      expect_round_trip(n, v);
      v[static_cast<std::size_t>(i)] = make_voxel(materials::kRock, 7);
      expect_round_trip(n, v);
      auto a = make_unit(n);
      a[static_cast<std::size_t>(i)] = solid(63);
      expect_round_trip(n, a);
    }
  }
}

TEST(NetCodec, RoundTripsStructuredUnits) {
  for (int n : kSizes) {
    for (float base : {-1.0f, 0.5f, 2.3f, 5.0f}) {
      for (float slope : {0.0f, 0.25f, 0.7f, 1.9f}) expect_round_trip(n, terrain_unit(n, base, slope));
    }
    // Horizontal strata: rows and layers repeat.
    auto s = make_unit(n);
    for (int i = 0; i < n * n * n; ++i) s[static_cast<std::size_t>(i)] = solid(static_cast<Material>(1 + (i / (n * n)) % 4));
    expect_round_trip(n, s);
    // A strata unit is a handful of bytes.
    EXPECT_LT(encode(n, s).size(), static_cast<std::size_t>(3 * n));
  }
}

TEST(NetCodec, RoundTripsRealMinecraftUnits) {
  auto file = vxraw_read_file(std::string(TERRANE_TEST_DATA_DIR) + "/mc-1.16.vxraw.gz", VxrawLimits{});
  ASSERT_TRUE(file.ok());
  const Box& box = file->box;
  int checked = 0;
  for (int n : kSizes) {
    for (int uy = 32; uy + n <= 112; uy += 2 * n) {
      for (int uz = 0; uz + n <= box.size().z; uz += 5 * n) {
        for (int ux = 0; ux + n <= box.size().x; ux += 3 * n) {
          auto v = make_unit(n);
          for (int y = 0; y < n; ++y) {
            for (int z = 0; z < n; ++z) {
              for (int x = 0; x < n; ++x) v[idx(n, x, y, z)] = box.get(ux + x, uy + y, uz + z);
            }
          }
          expect_round_trip(n, v);
          ++checked;
        }
      }
    }
  }
  EXPECT_GT(checked, 100);
}

// Format version 1, byte for byte.
TEST(NetCodec, GoldenBytesVersion1) {
  EXPECT_EQ(encode(4, make_unit(4)), (std::vector<std::uint8_t>{0x01}));
  EXPECT_EQ(encode(4, make_unit(4, solid(8))), (std::vector<std::uint8_t>{0x11, 0x08}));
  EXPECT_EQ(encode(4, make_unit(4, make_voxel(2, 0x80))), (std::vector<std::uint8_t>{0x21, 0x02, 0x80}));
  // Rock below y = 2, Air above: palette {Air, Rock}, literal Rock, run 31,
  // literal (Air, 0 bits: it must differ from Rock), run 31.
  auto half = make_unit(4, solid(8));
  for (std::size_t i = 32; i < 64; ++i) half[i] = Voxel{};
  EXPECT_EQ(encode(4, half), (std::vector<std::uint8_t>{0x31, 0x01, 0x80, 0x10, 0xFC, 0xC0, 0x07}));
  // One voxel of Grass with occupancy 0x40 at the origin, Air elsewhere.
  auto dot = make_unit(4);
  dot[0] = make_voxel(2, 0x40);
  EXPECT_EQ(encode(4, dot), (std::vector<std::uint8_t>{0x31, 0x01, 0x20, 0x34, 0xD0, 0x00, 0x3D}));
  for (const auto& v : {half, dot}) expect_round_trip(4, v);
}

std::vector<std::vector<Voxel>> sample_units(int n) {
  std::mt19937 rng(3);
  std::vector<std::vector<Voxel>> units = {terrain_unit(n, 1.5f, 0.4f), terrain_unit(n, 0.2f, 1.3f),
                                           random_unit(n, rng, 5, false),
                                           random_unit(n, rng, 64, true), make_unit(n, solid(3)),
                                           make_unit(n, make_voxel(3, 9))};
  auto dot = make_unit(n);
  dot[static_cast<std::size_t>(n)] = solid(1);
  units.push_back(dot);
  return units;
}

TEST(NetCodec, RejectsEveryTruncatedPrefix) {
  for (int n : kSizes) {
    for (const auto& v : sample_units(n)) {
     for (std::uint8_t version : kVersions) {
      const auto bytes = encode(n, v, version);
      std::vector<Voxel> out = make_unit(n);
      for (std::size_t len = 0; len < bytes.size(); ++len) {
        // A copy of exactly len bytes, so ASan sees any read past it.
        std::vector<std::uint8_t> prefix(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(len));
        const Status s = net_codec_decode(n, prefix, out);
        ASSERT_FALSE(s.ok()) << "n=" << n << " len=" << len << " version " << int{version};
        EXPECT_EQ(s.error().code, DecodeErrorCode::kTruncated) << s.error().describe();
      }
     }
    }
  }
}

TEST(NetCodec, RejectsTrailingBytes) {
  for (int n : kSizes) {
    for (const auto& v : sample_units(n)) {
      for (std::uint8_t version : kVersions) {
        auto bytes = encode(n, v, version);
        bytes.push_back(0);
        std::vector<Voxel> out = make_unit(n);
        const Status s = net_codec_decode(n, bytes, out);
        ASSERT_FALSE(s.ok());
        EXPECT_EQ(s.error().code, DecodeErrorCode::kTrailingBytes);
      }
    }
  }
}

DecodeErrorCode decode_error(int n, const std::vector<std::uint8_t>& bytes) {
  std::vector<Voxel> out = make_unit(n);
  const Status s = net_codec_decode(n, bytes, out);
  EXPECT_FALSE(s.ok());
  return s.ok() ? DecodeErrorCode::kTruncated : s.error().code;
}

TEST(NetCodec, RejectsBadValues) {
  // Version and kind.
  EXPECT_EQ(decode_error(4, {0x00}), DecodeErrorCode::kBadVersion);
  EXPECT_EQ(decode_error(4, {0x03}), DecodeErrorCode::kBadVersion);
  EXPECT_EQ(decode_error(4, {0x61}), DecodeErrorCode::kInvalidValue);
  // Raw kind: Air with occupancy, material 64.
  {
    std::vector<std::uint8_t> raw(129, 0);
    raw[0] = 0x51;
    std::vector<Voxel> out = make_unit(4);
    EXPECT_TRUE(net_codec_decode(4, raw, out).ok());
    raw[2] = 1;
    EXPECT_EQ(decode_error(4, raw), DecodeErrorCode::kInvalidValue);
    raw[2] = 0;
    raw[1] = 64;
    EXPECT_EQ(decode_error(4, raw), DecodeErrorCode::kInvalidValue);
  }
  EXPECT_EQ(decode_error(4, {0xF1}), DecodeErrorCode::kInvalidValue);
  // Uniform material 0 (Air has its own kind) and >= 64.
  EXPECT_EQ(decode_error(4, {0x11, 0x00}), DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(decode_error(4, {0x11, 0x40}), DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(decode_error(4, {0x21, 0xFF, 0x10}), DecodeErrorCode::kInvalidValue);
  // Duplicate palette entry: count 2, materials 8, 8.
  EXPECT_EQ(decode_error(4, {0x31, 0x01, 0x82, 0x00, 0x00, 0x00}), DecodeErrorCode::kInvalidValue);
  // Packed kind, palette {8, 0} (count 2, 1 bit per index), not partial,
  // then 64 index bits: valid; with count 3 (2 bits) index 3 is out of range.
  {
    std::vector<std::uint8_t> ok = {0x41, 0x01, 0x02, 0x00};  // count-1=1, 8, 0, partial 0
    ok.resize(4 + 8, 0);  // 64 one-bit indices (all 0 -> Rock), 3 bits padding fit in byte 3
    std::vector<Voxel> out = make_unit(4);
    const Status s = net_codec_decode(4, ok, out);
    ASSERT_TRUE(s.ok()) << s.error().describe();
    EXPECT_EQ(out, make_unit(4, solid(8)));
  }
  // A run past the end: the "half" golden unit with its last run's
  // Exp-Golomb code replaced by one for a length of 512 or more.
  {
    std::vector<std::uint8_t> bytes = {0x31, 0x01, 0x80, 0x10, 0xFC, 0x00, 0x08, 0x00};
    EXPECT_EQ(decode_error(4, bytes), DecodeErrorCode::kInvalidValue);
  }
  {
    std::vector<std::uint8_t> bytes = {0x31, 0x01, 0x80, 0x10, 0xFC, 0xC0, 0x07};
    std::vector<Voxel> out = make_unit(4);
    ASSERT_TRUE(net_codec_decode(4, bytes, out).ok());
  }
  // Non-zero padding bits after a valid unit.
  {
    std::vector<std::uint8_t> bytes = {0x31, 0x01, 0x80, 0x10, 0xFC, 0xC0, 0x07};
    bytes.back() |= 0x80;
    EXPECT_EQ(decode_error(4, bytes), DecodeErrorCode::kInvalidValue);
  }
  // Wrong buffer size or unit size.
  std::vector<Voxel> small(10);
  EXPECT_FALSE(net_codec_decode(4, std::vector<std::uint8_t>{0x01}, small).ok());
  std::vector<Voxel> out = make_unit(4);
  EXPECT_FALSE(net_codec_decode(5, std::vector<std::uint8_t>{0x01}, out).ok());
}

// A version-2 encoder writes version 2 only for a token unit whose
// occupancies it predicts, and only when that is shorter: every other unit
// is version 1's bytes, so no unit is ever larger than in version 1.
TEST(NetCodec, VersionTwoIsUsedOnlyWhereItIsShorter) {
  std::mt19937 rng(5);
  for (int n : kSizes) {
    std::vector<std::vector<Voxel>> units = {make_unit(n), make_unit(n, solid(3)), make_unit(n, make_voxel(3, 9)),
                                             random_unit(n, rng, 5, false), random_unit(n, rng, 64, true)};
    for (float slope : {0.25f, 0.7f, 1.9f}) units.push_back(terrain_unit(n, 2.3f, slope));
    for (const auto& v : units) {
      const auto one = encode(n, v, kNetCodecVersion1), two = encode(n, v, kNetCodecVersion2);
      if ((two.at(0) & 0x0F) == kNetCodecVersion2) {
        EXPECT_EQ(two.at(0) >> 4, 3) << "n=" << n;
        EXPECT_TRUE(partial_occupancies(v));
        EXPECT_LT(two.size(), one.size()) << "n=" << n;
      } else {
        EXPECT_EQ(two, one) << "n=" << n;
      }
    }
  }
}

// A unit of a smooth surface two voxels thick, as a density function makes
// it: occupancy falls from 255 to 0 over two voxels above a tilted plane.
std::vector<Voxel> ramp_unit(int n, float slope_x, float slope_z) {
  auto v = make_unit(n);
  for (int y = 0; y < n; ++y)
    for (int z = 0; z < n; ++z)
      for (int x = 0; x < n; ++x) {
        const float h = static_cast<float>(n) / 2 + slope_x * static_cast<float>(x - n / 2) + slope_z * static_cast<float>(z - n / 2);
        const float f = std::clamp((h - static_cast<float>(y)) / 2.0f + 0.5f, 0.0f, 1.0f);
        if (f > 0) v[idx(n, x, y, z)] = make_voxel(materials::kRock, occupancy_byte(f));
      }
  return v;
}

// Smooth surfaces take at most 0.85x the bytes in version 2 (every unit of
// them here is version 2), and the same voxels come back.
TEST(NetCodec, VersionTwoCodesSmoothSurfacesInFewerBytes) {
  for (int n : {8, 16}) {
    for (float slope : {0.2f, 0.6f, 1.4f}) {
      const auto v = ramp_unit(n, slope, 0.3f);
      ASSERT_TRUE(partial_occupancies(v));
      const auto one = encode(n, v, kNetCodecVersion1), two = encode(n, v, kNetCodecVersion2);
      EXPECT_EQ(two.at(0), 0x32) << "n=" << n << " slope " << slope;
      EXPECT_LT(20 * two.size(), 17 * one.size()) << "n=" << n << " slope " << slope << ": " << two.size() << " vs " << one.size();
      expect_round_trip(n, v);
    }
  }
}

// A residual over 255, and a residual code of more than 8 zeros, are
// invalid; the same zeros with nothing after them are truncation.
TEST(NetCodec, VersionTwoRejectsResidualsOutOfRange) {
  // The spec's version-2 example up to voxel 0's residual (bit 33), which is
  // then replaced: palette {1, Air}, partial, order 0, custom rankings 0.
  const auto with_residual = [](std::uint32_t bits, unsigned count) {
    std::vector<std::uint8_t> b = {0x32, 0x41, 0x00, 0x24, 0x00};  // 33 bits after byte 0: ... index 0
    std::uint64_t acc = 0;
    unsigned pos = 33;
    for (unsigned i = 0; i < count; ++i) {
      if ((bits >> i) & 1) acc |= std::uint64_t{1} << (pos + i - 32);
    }
    pos += count;
    for (unsigned at = 32; at < pos + 8; at += 8) b.push_back(static_cast<std::uint8_t>(acc >> (at - 32)));
    return b;
  };
  // 8 zeros, a one, then 8 bits of ones: w = 511, u = 510 > 255.
  EXPECT_EQ(decode_error(4, with_residual(0x100u | (0xFFu << 9), 17)), DecodeErrorCode::kInvalidValue);
  // 9 zeros then a one: more than 8 zeros.
  EXPECT_EQ(decode_error(4, with_residual(1u << 9, 10)), DecodeErrorCode::kInvalidValue);
  // Zeros to the end: truncated.
  EXPECT_EQ(decode_error(4, std::vector<std::uint8_t>{0x32, 0x41, 0x00, 0x24, 0x00, 0x00, 0x00}), DecodeErrorCode::kTruncated);
}

// Random byte strings never crash the decoder, and whatever decodes holds
// valid voxels and re-encodes to the same voxels.
TEST(NetCodec, GarbageDecodesSafely) {
  std::mt19937 rng(99);
  for (int n : kSizes) {
    std::vector<Voxel> out = make_unit(n);
    for (int rep = 0; rep < 3000; ++rep) {
      std::vector<std::uint8_t> bytes(rng() % 64);
      for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
      if (!bytes.empty()) bytes[0] = static_cast<std::uint8_t>((bytes[0] & 0xF0) | (1 + rep % 2));
      if (net_codec_decode(n, bytes, out).ok()) {
        for (Voxel v : out) {
          ASSERT_LT(v.material, kMaterialCount);
          if (v.material == kAir) {
            ASSERT_EQ(v.occupancy, 0);
          }
        }
        expect_round_trip(n, out);
      }
    }
  }
}

}  // namespace
}  // namespace terrane
