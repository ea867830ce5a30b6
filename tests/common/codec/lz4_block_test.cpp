#include "common/codec/lz4_block.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "common/codec/byte_rle.h"

namespace terrane {
namespace {

using Bytes = std::vector<std::uint8_t>;

Bytes compress(const Bytes& in) {
  Bytes out;
  lz4_compress(in, out);
  return out;
}

Bytes sample(std::size_t n, unsigned seed) {
  // Compressible: short random words repeated with variation.
  std::mt19937 rng(seed);
  Bytes b(n);
  for (std::size_t i = 0; i < n; ++i) b[i] = static_cast<std::uint8_t>(i % 64 < 40 ? i % 7 : rng() % 256);
  return b;
}

TEST(Lz4Block, RoundTrip) {
  for (std::size_t n : {0, 1, 5, 100, 4096, 100000}) {
    const Bytes in = sample(n, static_cast<unsigned>(n));
    const Bytes packed = compress(in);
    EXPECT_LE(packed.size(), lz4_max_compressed_size(n));
    auto out = lz4_decompress(packed, n);
    ASSERT_TRUE(out.ok()) << out.error().describe();
    EXPECT_EQ(*out, in);
  }
}

TEST(Lz4Block, HeaderIsMinimalVarint) {
  EXPECT_EQ(compress({}), (Bytes{0x00}));
  const Bytes packed = compress(Bytes(300, 7));
  EXPECT_EQ(packed[0], 0xAC);
  EXPECT_EQ(packed[1], 0x02);
  auto size = lz4_decoded_size(packed);
  ASSERT_TRUE(size.ok());
  EXPECT_EQ(*size, 300u);
}

TEST(Lz4Block, AppendsToOutput) {
  Bytes out{9, 9};
  lz4_compress(Bytes{1, 2, 3}, out);
  EXPECT_EQ(out[0], 9);
  auto back = lz4_decompress(std::span(out).subspan(2), 3);
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(*back, (Bytes{1, 2, 3}));
}

TEST(Lz4Block, RejectsDeclaredSizeOverCap) {
  const Bytes packed = compress(sample(1000, 1));
  auto out = lz4_decompress(packed, 999);
  ASSERT_FALSE(out.ok());
  EXPECT_EQ(out.error().code, DecodeErrorCode::kOverLimit);
  // A forged 2 GB declaration (LZ4's maximum) with almost no data is refused
  // before allocating.
  const Bytes forged{0x80, 0x80, 0x80, 0xF0, 0x07, 0x00};
  ASSERT_EQ(*lz4_decoded_size(forged), kLz4MaxInputSize);
  EXPECT_EQ(lz4_decompress(forged, 1 << 20).error().code, DecodeErrorCode::kOverLimit);
  // Above what LZ4 can express at all.
  EXPECT_EQ(lz4_decoded_size(Bytes{0xFF, 0xFF, 0xFF, 0xFF, 0x0F}).error().code, DecodeErrorCode::kOverLimit);
  EXPECT_EQ(lz4_decoded_size(Bytes{0x80, 0x80, 0x80, 0x80, 0x80, 0x01}).error().code, DecodeErrorCode::kOverLimit);
}

TEST(Lz4Block, RejectsBadHeader) {
  EXPECT_EQ(lz4_decoded_size(Bytes{}).error().code, DecodeErrorCode::kTruncated);
  EXPECT_EQ(lz4_decoded_size(Bytes{0x80}).error().code, DecodeErrorCode::kTruncated);
  EXPECT_EQ(lz4_decoded_size(Bytes{0x85, 0x00}).error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(lz4_decompress(Bytes{0x05}, 100).error().code, DecodeErrorCode::kTruncated);
  EXPECT_EQ(lz4_decompress(Bytes{0x00, 0x00}, 100).error().code, DecodeErrorCode::kTrailingBytes);
}

TEST(Lz4Block, RejectsCorruptData) {
  const Bytes in = sample(5000, 3);
  const Bytes packed = compress(in);
  ASSERT_GE(packed.size(), 10u);

  // Declared size off by one either way.
  Bytes bigger = packed, smaller = packed;
  ASSERT_EQ(packed[0], 0x88);  // 5000 = 0x88 0x27
  bigger[0] = 0x89;
  smaller[0] = 0x87;
  EXPECT_FALSE(lz4_decompress(bigger, 10000).ok());
  EXPECT_FALSE(lz4_decompress(smaller, 10000).ok());

  // Every truncation, and one extra byte.
  for (std::size_t n = 0; n < packed.size(); ++n) {
    EXPECT_FALSE(lz4_decompress(std::span(packed).first(n), 10000).ok()) << "prefix " << n;
  }
  Bytes longer = packed;
  longer.push_back(0);
  EXPECT_FALSE(lz4_decompress(longer, 10000).ok());

  // A body of garbage.
  Bytes garbage{0x88, 0x27};
  garbage.insert(garbage.end(), 64, 0xFF);
  EXPECT_FALSE(lz4_decompress(garbage, 10000).ok());

  // Random byte flips must never crash; any success must have the declared size.
  std::mt19937 rng(5);
  for (int i = 0; i < 2000; ++i) {
    Bytes bad = packed;
    bad[2 + rng() % (bad.size() - 2)] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    auto out = lz4_decompress(bad, 10000);
    if (out.ok()) {
      EXPECT_EQ(out->size(), in.size());
    }
  }
}

TEST(Lz4Block, DecompressIntoCallerBuffer) {
  const Bytes in = sample(777, 4);
  const Bytes packed = compress(in);
  Bytes buf(1000);
  auto n = lz4_decompress_into(packed, buf);
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, in.size());
  EXPECT_TRUE(std::equal(in.begin(), in.end(), buf.begin()));
  Bytes small(776);
  EXPECT_EQ(lz4_decompress_into(packed, small).error().code, DecodeErrorCode::kOverLimit);
}

TEST(ByteRleLz4, RoundTrip) {
  std::mt19937 rng(11);
  std::vector<Voxel> v(32768);
  for (std::size_t i = 0; i < v.size();) {
    const Voxel x = make_voxel(static_cast<Material>(rng() % 10), static_cast<std::uint8_t>(rng() % 3 == 0 ? rng() : 255));
    const std::size_t n = std::min<std::size_t>(1 + rng() % 50, v.size() - i);
    std::fill_n(v.begin() + static_cast<std::ptrdiff_t>(i), n, x);
    i += n;
  }
  Bytes packed, scratch;
  byte_rle_lz4_encode(v, packed, scratch);
  std::vector<Voxel> out(v.size());
  const Status s = byte_rle_lz4_decode(packed, out, scratch);
  ASSERT_TRUE(s.ok()) << s.error().describe();
  EXPECT_EQ(out, v);
}

TEST(ByteRleLz4, UniformChunkIsTiny) {
  const std::vector<Voxel> chunk(32768, solid(materials::kGrass));
  Bytes packed;
  byte_rle_lz4_encode(chunk, packed);
  EXPECT_LT(packed.size(), 32u);
  std::vector<Voxel> out(chunk.size());
  ASSERT_TRUE(byte_rle_lz4_decode(packed, out).ok());
  EXPECT_EQ(out, chunk);
}

TEST(ByteRleLz4, RejectsDeclaredSizeAboveRleBound) {
  Bytes packed;
  lz4_compress(Bytes(5, 0x00), packed);  // 5 RLE bytes cannot describe 2 voxels
  std::vector<Voxel> out(2);
  EXPECT_EQ(byte_rle_lz4_decode(packed, out).error().code, DecodeErrorCode::kOverLimit);
}

TEST(ByteRleLz4, RejectsBadRleInside) {
  Bytes packed;
  lz4_compress(Bytes{0x88, 0x00}, packed);  // count byte 0
  std::vector<Voxel> out(1);
  const Status s = byte_rle_lz4_decode(packed, out);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(s.error().offset, 1u);
}

}  // namespace
}  // namespace terrane
