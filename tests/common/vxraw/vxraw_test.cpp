#include "common/vxraw/vxraw.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <climits>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>

namespace terrane {
namespace {

using Bytes = std::vector<std::uint8_t>;
namespace fs = std::filesystem;

Bytes gzip(const Bytes& in) {
  z_stream zs{};
  EXPECT_EQ(deflateInit2(&zs, 6, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
  Bytes out(deflateBound(&zs, static_cast<uLong>(in.size())) + 32);
  zs.next_in = const_cast<Bytef*>(in.data());
  zs.avail_in = static_cast<uInt>(in.size());
  zs.next_out = out.data();
  zs.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&zs, Z_FINISH), Z_STREAM_END);
  out.resize(zs.total_out);
  deflateEnd(&zs);
  return out;
}

Box random_box(Vec3i size, unsigned seed) {
  std::mt19937 rng(seed);
  Box box(size);
  for (auto& v : box.voxels()) {
    v = make_voxel(static_cast<Material>(rng() % 4 == 0 ? 0 : rng() % kMaterialCount),
                   static_cast<std::uint8_t>(rng() % 2 == 0 ? 255 : rng()));
  }
  return box;
}

Bytes header(Vec3i size, Vec3i origin) {
  Bytes h{'V', 'X', 'R', 'A', 'W', '1', 0, 0};
  for (std::int32_t v : {size.x, size.y, size.z, origin.x, origin.y, origin.z}) {
    for (int i = 0; i < 4; ++i) h.push_back(static_cast<std::uint8_t>(static_cast<std::uint32_t>(v) >> (8 * i)));
  }
  return h;
}

DecodeError decode_err(const Bytes& bytes, VxrawLimits limits = {}) {
  auto r = vxraw_decode(bytes, limits);
  EXPECT_FALSE(r.ok());
  return r.ok() ? DecodeError{} : r.error();
}

Bytes read_bytes(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(f), {});
}

void write_bytes(const fs::path& p, const Bytes& b) {
  std::ofstream f(p, std::ios::binary);
  f.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = fs::temp_directory_path() / ("terrane-vxraw-test-" + std::to_string(rd()));
    fs::create_directories(path_);
  }
  ~TempDir() { fs::remove_all(path_); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

TEST(Vxraw, EncodeGoldenBytes) {
  Box box(Vec3i{2, 1, 1});
  box.set(1, 0, 0, make_voxel(materials::kGrass, 200));
  Bytes expected = header({2, 1, 1}, {-1, 2, 300});
  expected.insert(expected.end(), {0, 0, 2, 200});
  EXPECT_EQ(vxraw_encode(box, {-1, 2, 300}), expected);
  EXPECT_EQ(expected[20], 0xFF);  // origin.x = -1, little-endian
}

TEST(Vxraw, MemoryRoundTrip) {
  const Box box = random_box({7, 5, 3}, 1);
  const Vec3i origin{-100, 20, 7};
  auto r = vxraw_decode(vxraw_encode(box, origin), {});
  ASSERT_TRUE(r.ok()) << r.error().describe();
  EXPECT_EQ(r->box, box);
  EXPECT_EQ(r->origin, origin);
  EXPECT_EQ(r->repaired_air, 0u);
}

TEST(Vxraw, GzipMemoryRoundTrip) {
  const Box box = random_box({16, 9, 11}, 2);
  auto r = vxraw_decode(gzip(vxraw_encode(box, {1, 2, 3})), {});
  ASSERT_TRUE(r.ok()) << r.error().describe();
  EXPECT_EQ(r->box, box);
  EXPECT_EQ(r->origin, (Vec3i{1, 2, 3}));
}

TEST(Vxraw, FileRoundTripPlainAndGzip) {
  TempDir dir;
  const Box box = random_box({33, 17, 20}, 3);
  for (bool gz : {false, true}) {
    const std::string path = (dir.path() / (gz ? "box.vxraw.gz" : "box.vxraw")).string();
    const FileStatus w = vxraw_write_file(path, box, {5, -6, 7}, gz);
    ASSERT_TRUE(w.ok()) << w.error().message;
    const Bytes bytes = read_bytes(path);
    ASSERT_GE(bytes.size(), 2u);
    EXPECT_EQ(bytes[0] == 0x1f && bytes[1] == 0x8b, gz);
    auto r = vxraw_read_file(path, {});
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->box, box);
    EXPECT_EQ(r->origin, (Vec3i{5, -6, 7}));
  }
  // Only the two finished files: no temporaries left behind.
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 2);
}

TEST(Vxraw, WriteReplacesExistingFile) {
  TempDir dir;
  const std::string path = (dir.path() / "w.vxraw").string();
  ASSERT_TRUE(vxraw_write_file(path, random_box({4, 4, 4}, 4), {}, false).ok());
  const Box second = random_box({2, 3, 4}, 5);
  ASSERT_TRUE(vxraw_write_file(path, second, {}, false).ok());
  auto r = vxraw_read_file(path, {});
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->box, second);
}

TEST(Vxraw, WriteToMissingDirectoryFails) {
  TempDir dir;
  const std::string path = (dir.path() / "no" / "such" / "w.vxraw").string();
  const FileStatus w = vxraw_write_file(path, Box({1, 1, 1}), {}, true);
  ASSERT_FALSE(w.ok());
  EXPECT_NE(w.error().message.find(path), std::string::npos);
}

TEST(Vxraw, LoadsMinecraft19Sample) {
  auto r = vxraw_read_file(TERRANE_TEST_DATA_DIR "/mc-1.9.vxraw.gz", {});
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->box.size(), (Vec3i{384, 256, 208}));
  EXPECT_EQ(r->origin, (Vec3i{-384, 0, -512}));
  std::size_t non_air = 0;
  for (Voxel v : r->box.voxels()) non_air += v.material != kAir;
  EXPECT_EQ(non_air, 4941334u);
  EXPECT_EQ(r->repaired_air, 0u);
}

TEST(Vxraw, RepairsAirOccupancy) {
  Bytes bytes = header({3, 1, 1}, {});
  bytes.insert(bytes.end(), {0, 7, 0, 0, 0, 255});
  auto r = vxraw_decode(bytes, {});
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->repaired_air, 2u);
  for (Voxel v : r->box.voxels()) EXPECT_EQ(v, Voxel{});
}

TEST(VxrawDecode, RejectsMaterialAtFirstOffendingOffset) {
  Box box(Vec3i{10, 2, 3}, solid(materials::kRock));
  Bytes bytes = vxraw_encode(box, {});
  bytes[32 + 2 * 17] = 64;
  bytes[32 + 2 * 40] = 200;
  DecodeError e = decode_err(bytes);
  EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(e.offset, 32u + 2 * 17);
  e = decode_err(gzip(bytes));
  EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(e.offset, 32u + 2 * 17);
}

TEST(VxrawDecode, RejectsBadMagicAndVersion) {
  Bytes bytes = vxraw_encode(Box({1, 1, 1}), {});
  Bytes bad = bytes;
  bad[0] = 'X';
  EXPECT_EQ(decode_err(bad).code, DecodeErrorCode::kBadMagic);
  bad = bytes;
  bad[5] = '2';
  EXPECT_EQ(decode_err(bad).code, DecodeErrorCode::kBadVersion);
  EXPECT_EQ(decode_err(Bytes(40, 0)).code, DecodeErrorCode::kBadMagic);
}

TEST(VxrawDecode, RejectsNonPositiveSizes) {
  for (Vec3i size : {Vec3i{0, 1, 1}, Vec3i{1, 0, 1}, Vec3i{1, 1, -5}, Vec3i{INT32_MIN, 1, 1}}) {
    const DecodeError e = decode_err(header(size, {}));
    EXPECT_EQ(e.code, DecodeErrorCode::kInvalidValue);
  }
  EXPECT_EQ(decode_err(header({1, 1, -5}, {})).offset, 16u);
}

TEST(VxrawDecode, RejectsOverflowAndLimit) {
  EXPECT_EQ(decode_err(header({INT32_MAX, INT32_MAX, INT32_MAX}, {})).code, DecodeErrorCode::kOverLimit);
  EXPECT_EQ(decode_err(header({65536, 65536, 1}, {})).code, DecodeErrorCode::kOverLimit);  // 2^32 > 2^31
  Bytes bytes = vxraw_encode(Box({4, 4, 4}), {});
  EXPECT_EQ(decode_err(bytes, VxrawLimits{63}).code, DecodeErrorCode::kOverLimit);
  EXPECT_TRUE(vxraw_decode(bytes, VxrawLimits{64}).ok());
}

TEST(VxrawDecode, RejectsBoxPastCoordinateRange) {
  EXPECT_EQ(decode_err(header({2, 1, 1}, {INT32_MAX, 0, 0})).offset, 20u);
  Bytes ok = header({1, 1, 1}, {INT32_MAX - 1, INT32_MIN, 0});
  ok.insert(ok.end(), {0, 0});
  EXPECT_TRUE(vxraw_decode(ok, {}).ok());
}

TEST(VxrawDecode, RejectsShortAndLongFiles) {
  const Bytes bytes = vxraw_encode(random_box({3, 4, 5}, 6), {});
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    auto r = vxraw_decode(std::span(bytes).first(n), {});
    ASSERT_FALSE(r.ok()) << "prefix " << n;
    EXPECT_EQ(r.error().code, DecodeErrorCode::kTruncated) << "prefix " << n;
  }
  Bytes longer = bytes;
  longer.push_back(0);
  const DecodeError e = decode_err(longer);
  EXPECT_EQ(e.code, DecodeErrorCode::kTrailingBytes);
  EXPECT_EQ(e.offset, bytes.size());
}

TEST(VxrawDecode, RejectsEveryTruncatedGzipPrefix) {
  const Bytes packed = gzip(vxraw_encode(random_box({6, 5, 4}, 7), {}));
  for (std::size_t n = 0; n < packed.size(); ++n) {
    EXPECT_FALSE(vxraw_decode(std::span(packed).first(n), {}).ok()) << "prefix " << n;
  }
}

TEST(VxrawDecode, RejectsDamagedGzip) {
  const Bytes packed = gzip(vxraw_encode(random_box({20, 20, 20}, 8), {}));
  std::mt19937 rng(9);
  int rejected = 0;
  for (int i = 0; i < 200; ++i) {
    Bytes bad = packed;
    bad[10 + rng() % (bad.size() - 10)] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    rejected += !vxraw_decode(bad, {}).ok();
  }
  // The CRC-32 and length trailer catch every single-byte change.
  EXPECT_EQ(rejected, 200);
}

TEST(VxrawDecode, RejectsDataAfterTheGzipStream) {
  Bytes packed = gzip(vxraw_encode(Box({2, 2, 2}), {}));
  packed.push_back(0);
  EXPECT_EQ(decode_err(packed).code, DecodeErrorCode::kTrailingBytes);
}

TEST(VxrawDecode, GzipInflationIsBoundedByTheHeader) {
  // A tiny header followed by a megabyte that compresses to almost nothing:
  // rejected as trailing bytes after inflating one byte past the voxels.
  Bytes bomb = header({1, 1, 1}, {});
  bomb.resize(bomb.size() + (1 << 20), 0);
  const Bytes packed = gzip(bomb);
  ASSERT_LT(packed.size(), 2048u);
  const DecodeError e = decode_err(packed);
  EXPECT_EQ(e.code, DecodeErrorCode::kTrailingBytes);
  EXPECT_EQ(e.offset, 34u);
}

TEST(VxrawReadFile, ErrorsNameTheFile) {
  TempDir dir;
  const std::string missing = (dir.path() / "missing.vxraw").string();
  auto r = vxraw_read_file(missing, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find(missing), std::string::npos);
  EXPECT_NE(r.error().message.find("cannot open"), std::string::npos);
  EXPECT_FALSE(r.error().decode.has_value());

  const std::string text = (dir.path() / "notes.txt").string();
  write_bytes(text, Bytes(100, 'a'));
  r = vxraw_read_file(text, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("not a VXRAW file"), std::string::npos) << r.error().message;

  Bytes bytes = vxraw_encode(Box({4, 4, 4}, solid(materials::kSand)), {});
  bytes[32 + 2 * 9] = 77;
  const std::string bad = (dir.path() / "bad.vxraw.gz").string();
  write_bytes(bad, gzip(bytes));
  r = vxraw_read_file(bad, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find(bad), std::string::npos);
  EXPECT_NE(r.error().message.find("at byte 50 of the decompressed data"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("material"), std::string::npos);
  ASSERT_TRUE(r.error().decode.has_value());
  EXPECT_EQ(r.error().decode->offset, 50u);

  Bytes damaged = gzip(vxraw_encode(random_box({10, 10, 10}, 10), {}));
  damaged[damaged.size() / 2] ^= 0x55;
  const std::string dpath = (dir.path() / "damaged.vxraw.gz").string();
  write_bytes(dpath, damaged);
  r = vxraw_read_file(dpath, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("gzip"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("compressed file"), std::string::npos) << r.error().message;

  Bytes cut = gzip(vxraw_encode(random_box({10, 10, 10}, 11), {}));
  cut.resize(cut.size() - 20);
  const std::string cpath = (dir.path() / "cut.vxraw.gz").string();
  write_bytes(cpath, cut);
  r = vxraw_read_file(cpath, {});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("cut short"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace terrane
