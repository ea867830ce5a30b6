// The network voxel codec's unit decoder (common/codec/net_codec_decoder.h)
// on hand-written units: what it accepts, and the explicit error it returns
// for truncated and corrupt bytes, on both token paths (with and without
// partial occupancies) and at every unit size. After an error the output
// still holds valid voxels.
#include "common/codec/net_codec_decoder.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "common/codec/bit_io.h"
#include "common/codec/net_codec.h"
#include "common/codec/net_codec_encoder.h"
#include "common/codec/net_codec_tables.h"

#include "tests/common/codec/test_units.h"

namespace terrane::net_codec_detail {
namespace {

using namespace test_units;

constexpr int kSizes[] = {4, 8, 16};

Result<std::size_t> decode(int n, const std::vector<std::uint8_t>& bytes, std::vector<Voxel>& out) {
  switch (n) {
    case 4: return decode_unit<4>(bytes, out);
    case 8: return decode_unit<8>(bytes, out);
    default: return decode_unit<16>(bytes, out);
  }
}

void expect_valid_voxels(const std::vector<Voxel>& out) {
  for (Voxel v : out) {
    ASSERT_LT(v.material, kMaterialCount);
    if (v.material == kAir) {
      ASSERT_EQ(v.occupancy, 0);
    }
  }
}

// Decodes bytes that must fail; returns the error, after checking that the
// output holds valid voxels.
DecodeError decode_error(int n, const std::vector<std::uint8_t>& bytes) {
  std::vector<Voxel> out = make_unit(n, solid(2));
  const auto r = decode(n, bytes, out);
  EXPECT_FALSE(r.ok()) << "n=" << n;
  expect_valid_voxels(out);
  return r.ok() ? DecodeError{} : r.error();
}

// A unit written bit by bit as NET_CODEC.md lays it out.
class UnitWriter {
 public:
  explicit UnitWriter(std::uint8_t kind) : w_(buf_.data() + 1) {
    buf_[0] = static_cast<std::uint8_t>(kNetCodecVersion | (kind << 4));
  }
  UnitWriter(const UnitWriter&) = delete;
  UnitWriter& operator=(const UnitWriter&) = delete;

  UnitWriter& put(std::uint32_t value, unsigned bits) {
    w_.put(value, bits);
    return *this;
  }
  // count - 1, the materials, the partial flag.
  UnitWriter& palette(const std::vector<Material>& materials, bool partial) {
    put(static_cast<std::uint32_t>(materials.size() - 1), 6);
    for (Material m : materials) put(m, 6);
    return put(partial ? 1 : 0, 1);
  }
  // An Exp-Golomb length of order m: z zeros, a one, z bits of r, m bits of t.
  UnitWriter& length(std::uint32_t l, unsigned m) {
    const std::uint32_t v = l - 1;
    const std::uint32_t w = (v >> m) + 1;
    unsigned z = 0;
    while ((w >> (z + 1)) != 0) ++z;
    put(0, z);
    put(1, 1);
    put(w - (1u << z), z);
    return put(v & ((1u << m) - 1), m);
  }
  std::vector<std::uint8_t> bytes() {
    const std::size_t size = 1 + w_.finish();
    return {buf_.begin(), buf_.begin() + static_cast<std::ptrdiff_t>(size)};
  }

 private:
  std::vector<std::uint8_t> buf_ = std::vector<std::uint8_t>(1024, 0);
  BitWriter w_;
};

// Default type codes after Lit (NET_CODEC.md), as LSB-first values.
constexpr std::uint32_t kAfterLitRun = 0b0;      // rank 0: "0"
constexpr std::uint32_t kAfterLitCopyZ = 0b01;   // rank 1: "1 0"
constexpr std::uint32_t kAfterLitLit = 0b011;    // rank 2: "1 1 0"
constexpr std::uint32_t kAfterLitCopyY = 0b111;  // rank 3: "1 1 1"

// A one-material token unit (material 8): default codes, the first voxel,
// and then what the caller writes.
UnitWriter& one_material_tokens(UnitWriter& u, bool partial) {
  u.palette({8}, partial).put(0, 1);  // custom = 0
  if (partial) u.put(0, 1);           // first voxel at full occupancy
  return u;
}

TEST(NetCodecDecoder, ReturnsTheUnitsSizeAndLeavesLaterBytesUnread) {
  for (int n : kSizes) {
    std::mt19937 rng(1);
    for (const auto& v :
         {make_unit(n), make_unit(n, solid(4)), terrain_unit(n, 1.5f, 0.4f), random_unit(n, rng, 6, false)}) {
      std::vector<std::uint8_t> bytes;
      net_codec_encode(n, v, bytes);
      const std::size_t size = bytes.size();
      bytes.insert(bytes.end(), {0xFF, 0x00, 0x13});
      std::vector<Voxel> out = make_unit(n);
      const auto used = decode(n, bytes, out);
      ASSERT_TRUE(used.ok()) << used.error().describe();
      EXPECT_EQ(*used, size);
      EXPECT_EQ(out, v);
    }
  }
}

TEST(NetCodecDecoder, ReadsAHandWrittenTokenUnitOnBothPaths) {
  for (int n : kSizes) {
    const std::uint32_t volume = static_cast<std::uint32_t>(n * n * n);
    for (bool partial : {false, true}) {
      UnitWriter u(kKindTokens);
      one_material_tokens(u, partial).put(kAfterLitRun, 1).length(volume - 1, 0);
      std::vector<Voxel> out = make_unit(n);
      const auto bytes = u.bytes();
      const auto used = decode(n, bytes, out);
      ASSERT_TRUE(used.ok()) << used.error().describe();
      EXPECT_EQ(*used, bytes.size());
      EXPECT_EQ(out, make_unit(n, solid(8)));
    }
  }
}

TEST(NetCodecDecoder, EveryStrictPrefixIsTruncated) {
  std::mt19937 rng(2);
  for (int n : kSizes) {
    const std::vector<std::vector<Voxel>> units = {make_unit(n, solid(3)), make_unit(n, make_voxel(3, 9)),
                                                   terrain_unit(n, 1.5f, 0.4f), random_unit(n, rng, 5, false),
                                                   random_unit(n, rng, 64, false), random_unit(n, rng, 64, true)};
    for (const auto& v : units) {
      std::vector<std::uint8_t> bytes;
      net_codec_encode(n, v, bytes);
      for (std::size_t len = 1; len < bytes.size(); ++len) {
        // Exactly len bytes, so ASan sees any read past them.
        const std::vector<std::uint8_t> prefix(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(len));
        const DecodeError e = decode_error(n, prefix);
        ASSERT_EQ(e.code, DecodeErrorCode::kTruncated) << "n=" << n << " len=" << len << " " << e.describe();
      }
    }
  }
}

TEST(NetCodecDecoder, RejectsUnknownVersionsAndKinds) {
  EXPECT_EQ(decode_error(4, {0x03}).code, DecodeErrorCode::kBadVersion);
  EXPECT_EQ(decode_error(4, {0x10}).code, DecodeErrorCode::kBadVersion);
  for (std::uint8_t kind = 6; kind < 16; ++kind) {
    const DecodeError e = decode_error(8, {static_cast<std::uint8_t>(kNetCodecVersion | (kind << 4)), 0, 0, 0});
    EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue);
    EXPECT_EQ(e.offset, 0u);
  }
}

TEST(NetCodecDecoder, RejectsUniformUnitsWithoutASolidMaterial) {
  for (const std::vector<std::uint8_t>& bytes :
       {std::vector<std::uint8_t>{0x11, 0}, {0x11, 64}, {0x21, 0, 0}, {0x21, 200, 5}}) {
    const DecodeError e = decode_error(4, bytes);
    EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue);
    EXPECT_EQ(e.offset, 1u);
  }
  EXPECT_EQ(decode_error(4, {0x21, 5}).code, DecodeErrorCode::kTruncated);
}

TEST(NetCodecDecoder, RawUnitsRejectAirWithOccupancyAndMaterialsOver63) {
  std::vector<std::uint8_t> raw(1 + 2 * 64, 0);
  raw[0] = static_cast<std::uint8_t>(kNetCodecVersion | (kKindRaw << 4));
  raw[1 + 2 * 10] = 64;  // voxel 10's material
  DecodeError e = decode_error(4, raw);
  EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(e.offset, 21u);
  raw[1 + 2 * 10] = 0;
  raw[1 + 2 * 20 + 1] = 1;  // voxel 20: Air with occupancy
  e = decode_error(4, raw);
  EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(e.offset, 42u);
}

TEST(NetCodecDecoder, RejectsADuplicatePaletteMaterial) {
  for (std::uint8_t kind : {kKindTokens, kKindPacked}) {
    UnitWriter u(kind);
    u.palette({8, 3, 8}, false).put(0, 64);
    EXPECT_EQ(decode_error(4, u.bytes()).code, DecodeErrorCode::kInvalidValue);
  }
}

TEST(NetCodecDecoder, PackedUnitsRejectAnIndexOutsideThePalette) {
  UnitWriter u(kKindPacked);
  u.palette({1, 2, 3}, false);  // 2-bit indices, 3 is out of range
  for (int i = 0; i < 63; ++i) u.put(2, 2);
  u.put(3, 2);
  EXPECT_EQ(decode_error(4, u.bytes()).code, DecodeErrorCode::kInvalidValue);
}

TEST(NetCodecDecoder, RejectsRankingIdThree) {
  {
    UnitWriter u(kKindTokens);
    u.palette({8}, false).put(1, 1).put(0, 2).put(3, 2);  // after Lit: second index 3
    u.put(0, 64);
    EXPECT_EQ(decode_error(4, u.bytes()).code, DecodeErrorCode::kInvalidValue);
  }
  {
    UnitWriter u(kKindTokens);
    u.palette({8}, false).put(1, 1).put(0, 2).put(0, 2).put(3, 2);  // after Run: 3
    u.put(0, 64);
    EXPECT_EQ(decode_error(4, u.bytes()).code, DecodeErrorCode::kInvalidValue);
  }
}

// Without partial occupancies a literal differs from the voxel before it,
// so a one-material palette has none after the first voxel.
TEST(NetCodecDecoder, RejectsALiteralInAOneMaterialUnit) {
  for (int n : kSizes) {
    UnitWriter u(kKindTokens);
    one_material_tokens(u, false).put(kAfterLitLit, 3).put(0, 64);
    EXPECT_EQ(decode_error(n, u.bytes()).code, DecodeErrorCode::kInvalidValue);
  }
}

// The second voxel cannot copy from a row or layer before the unit, on
// either path; at 16^3 the wide writes are checked too.
TEST(NetCodecDecoder, RejectsACopyFromBeforeTheUnitStart) {
  for (int n : kSizes) {
    for (bool partial : {false, true}) {
      for (std::uint32_t length : {1u, 40u}) {
        UnitWriter z(kKindTokens);
        one_material_tokens(z, partial).put(kAfterLitCopyZ, 2).length(length, length_order(kCopyZ, n)).put(0, 64);
        EXPECT_EQ(decode_error(n, z.bytes()).code, DecodeErrorCode::kInvalidValue) << "n=" << n;
        UnitWriter y(kKindTokens);
        one_material_tokens(y, partial).put(kAfterLitCopyY, 3).length(length, length_order(kCopyY, n)).put(0, 64);
        EXPECT_EQ(decode_error(n, y.bytes()).code, DecodeErrorCode::kInvalidValue) << "n=" << n;
      }
    }
  }
}

TEST(NetCodecDecoder, RejectsARunPastTheEndOfTheUnit) {
  for (int n : kSizes) {
    const std::uint32_t volume = static_cast<std::uint32_t>(n * n * n);
    for (bool partial : {false, true}) {
      // One voxel too many, from voxel 1; then a short run too many after a
      // run that leaves one voxel.
      UnitWriter u(kKindTokens);
      one_material_tokens(u, partial).put(kAfterLitRun, 1).length(volume, 0).put(0, 64);
      EXPECT_EQ(decode_error(n, u.bytes()).code, DecodeErrorCode::kInvalidValue) << "n=" << n;
      UnitWriter v(kKindTokens);
      // After Run the default codes give CopyZ "0", Lit "1 0", CopyY "1 1".
      one_material_tokens(v, partial).put(kAfterLitRun, 1).length(volume - 2, 0);
      v.put(0b11, 2).length(2, length_order(kCopyY, n)).put(0, 64);
      EXPECT_EQ(decode_error(n, v.bytes()).code, DecodeErrorCode::kInvalidValue) << "n=" << n;
    }
  }
}

// More than 12 zeros open a length code: invalid when a one bit follows,
// truncated when the unit ends in zeros.
TEST(NetCodecDecoder, RejectsAnOverlongLengthCode) {
  for (int n : kSizes) {
    for (bool partial : {false, true}) {
      UnitWriter u(kKindTokens);
      one_material_tokens(u, partial).put(kAfterLitRun, 1).put(0, 13).put(1, 1).put(0, 30);
      EXPECT_EQ(decode_error(n, u.bytes()).code, DecodeErrorCode::kInvalidValue);
      UnitWriter t(kKindTokens);
      one_material_tokens(t, partial).put(kAfterLitRun, 1).put(0, 20);
      EXPECT_EQ(decode_error(n, t.bytes()).code, DecodeErrorCode::kTruncated);
    }
  }
}

TEST(NetCodecDecoder, RejectsNonZeroPaddingBits) {
  for (int n : kSizes) {
    const std::uint32_t volume = static_cast<std::uint32_t>(n * n * n);
    UnitWriter u(kKindTokens);
    one_material_tokens(u, true).put(kAfterLitRun, 1).length(volume - 1, 0);
    auto bytes = u.bytes();
    std::vector<Voxel> out = make_unit(n);
    ASSERT_TRUE(decode(n, bytes, out).ok());
    // 6 + 6 + 1 + 1 bits of header, 1 occupancy flag, 1 type code and a
    // length of 13, 19 or 25 bits: 29, 35 or 41 bits, so the last byte's top
    // bit is padding.
    bytes.back() |= 0x80;
    const DecodeError e = decode_error(n, bytes);
    EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue) << e.describe();
  }
}

// Whatever random bytes decode to, the decoder stops inside them and leaves
// valid voxels.
TEST(NetCodecDecoder, RandomBytesFailCleanlyOrDecodeValidVoxels) {
  std::mt19937 rng(9);
  for (int n : kSizes) {
    std::vector<Voxel> out = make_unit(n);
    for (int rep = 0; rep < 2000; ++rep) {
      std::vector<std::uint8_t> bytes(1 + rng() % 48);
      for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
      bytes[0] = static_cast<std::uint8_t>((bytes[0] & 0xF0) | kNetCodecVersion);
      const auto used = decode(n, bytes, out);
      if (used.ok()) {
        EXPECT_LE(*used, bytes.size());
      }
      expect_valid_voxels(out);
    }
  }
}

}  // namespace
}  // namespace terrane::net_codec_detail
