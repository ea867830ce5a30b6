#include "common/world/world_store.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <map>

#include "common/cli/cli.h"
#include "common/codec/byte_order.h"
#include "common/codec/lz4_block.h"

#include <zlib.h>

namespace terrane {

namespace {

constexpr std::uint8_t kBlobVersion = 1;
constexpr std::uint8_t kBlobCodecByteRleLz4 = 1;
constexpr std::uint8_t kBlobCodecImageLz4 = 2;
// The largest chunk image: level 0 (form, layer map, every layer wide: 64
// slot units of 18 words, data length, data up to a 64-byte record at the
// last 15-bit offset), then three mip unit lengths and at most 0xFFFF bytes
// of units.
constexpr std::size_t kMaxChunkImageBytes = 1 + kChunkSize + 2 * kChunkSize * (kChunkSize / 2 + 2) * 2 + 2 +
                                            RowPackedBox<kChunkSize>::kOffsetMask + 2 * kChunkSize + 3 * 2 + 0xFFFF;
static_assert(kMaxChunkImageBytes == 100'711);

std::uint32_t image_crc(std::span<const std::uint8_t> image) {
  return static_cast<std::uint32_t>(crc32(0L, image.data(), static_cast<uInt>(image.size())));
}
constexpr int kChunkVoxels = kChunkSize * kChunkSize * kChunkSize;

std::string join_lines(const std::vector<std::string>& v) {
  std::string out;
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (i) out += '\n';
    out += v[i];
  }
  return out;
}

std::vector<std::string> split_lines(const std::string& s) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (start <= s.size()) {
    const std::size_t nl = s.find('\n', start);
    out.push_back(s.substr(start, nl == std::string::npos ? std::string::npos : nl - start));
    if (nl == std::string::npos) break;
    start = nl + 1;
  }
  return out;
}

}  // namespace

std::vector<std::string> default_material_names() {
  std::vector<std::string> names(kDefaultMaterialNames.begin(), kDefaultMaterialNames.end());
  return names;
}

std::vector<std::uint8_t> encode_chunk_blob(const Chunk& chunk) {
  thread_local std::vector<std::uint8_t> image;
  image.clear();
  if (!chunk.write_image(image)) {
    // A chunk without an image (rows beyond 15-bit offsets): codec 1.
    Box box;
    chunk.read_level(0, box);
    return encode_chunk_blob_byte_rle(box);
  }
  std::vector<std::uint8_t> out{kBlobVersion, kBlobCodecImageLz4};
  append_le32(out, image_crc(image));
  lz4_compress(image, out);
  return out;
}

std::vector<std::uint8_t> encode_chunk_blob(const Box& box) { return encode_chunk_blob(Chunk::from_box(box)); }

std::vector<std::uint8_t> encode_chunk_blob_byte_rle(const Box& box) {
  std::vector<std::uint8_t> out{kBlobVersion, kBlobCodecByteRleLz4};
  byte_rle_lz4_encode(box.voxels(), out);
  return out;
}

Result<Chunk> decode_chunk_blob(std::span<const std::uint8_t> blob) {
  if (blob.size() < 2) return DecodeError{DecodeErrorCode::kTruncated, blob.size(), "chunk blob header"};
  if (blob[0] != kBlobVersion) return DecodeError{DecodeErrorCode::kBadVersion, 0, "chunk blob version"};
  if (blob[1] == kBlobCodecImageLz4) {
    if (blob.size() < 6) return DecodeError{DecodeErrorCode::kTruncated, blob.size(), "chunk blob checksum"};
    thread_local std::vector<std::uint8_t> image(kMaxChunkImageBytes);
    auto n = lz4_decompress_into(blob.subspan(6), image);
    if (!n) {
      DecodeError e = n.error();
      e.offset += 6;
      return e;
    }
    const std::span<const std::uint8_t> bytes(image.data(), *n);
    if (image_crc(bytes) != load_le32(blob.data() + 2))
      return DecodeError{DecodeErrorCode::kInvalidValue, 2, "chunk blob checksum does not match its image"};
    std::size_t pos = 0;
    auto chunk = Chunk::read_image(bytes, pos);
    // (Offsets inside the image are offsets into the decompressed bytes,
    // as the errors' texts say.)
    if (!chunk) return chunk.error();
    if (pos != *n) return DecodeError{DecodeErrorCode::kInvalidValue, pos, "chunk image: bytes after it"};
    return chunk;
  }
  if (blob[1] != kBlobCodecByteRleLz4) return DecodeError{DecodeErrorCode::kInvalidValue, 1, "chunk blob codec"};
  thread_local Box box({kChunkSize, kChunkSize, kChunkSize});
  const Status s = byte_rle_lz4_decode(blob.subspan(2), box.voxels());
  if (!s) {
    DecodeError e = s.error();
    e.offset += 2;
    return e;
  }
  static_assert(kChunkVoxels == 32768);
  return Chunk::from_box(box);
}


std::vector<std::pair<std::string, std::string>> meta_to_keys(const WorldMeta& m) {
  return {
      {"format_version", std::to_string(m.format_version)},
      {"generator", m.generator == GeneratorKind::kTerrain ? "terrain" : "none"},
      {"generator_params", m.generator_params},
      {"bounds_y", std::to_string(m.bounds.min_y) + "," + std::to_string(m.bounds.max_y)},
      {"bounds_xz", m.bounds.bounded_xz ? std::to_string(m.bounds.min_x) + "," + std::to_string(m.bounds.min_z) +
                                              "," + std::to_string(m.bounds.max_x) + "," +
                                              std::to_string(m.bounds.max_z)
                                        : ""},
      {"materials", join_lines(m.materials)},
      {"epoch", std::to_string(m.epoch)},
      {"world_id", std::to_string(m.world_id)},
  };
}

std::optional<std::uint64_t> parse_world_id(const std::string& text) {
  if (text.empty() || !std::isdigit(static_cast<unsigned char>(text[0]))) return std::nullopt;
  char* end = nullptr;
  errno = 0;
  const unsigned long long id = std::strtoull(text.c_str(), &end, 10);
  if (*end != '\0' || errno != 0) return std::nullopt;
  return id;
}

FileResult<WorldMeta> meta_from_keys(const std::vector<std::pair<std::string, std::string>>& keys,
                                     const std::string& where) {
  std::map<std::string, std::string> kv(keys.begin(), keys.end());
  auto need = [&](const char* key) -> const std::string* {
    auto it = kv.find(key);
    return it == kv.end() ? nullptr : &it->second;
  };
  WorldMeta m;
  std::int64_t n[4];
  const std::string* v = need("format_version");
  if (!v || !parse_int_list<std::int64_t>(*v, n, 1)) return FileError{where + ": metadata key format_version missing or malformed", {}};
  if (n[0] < 1 || n[0] > kWorldFormatVersion)
    return FileError{where + ": format version " + *v + " is not supported (this build reads " +
                         std::to_string(kWorldFormatVersion) + ")", {}};
  m.format_version = static_cast<std::uint32_t>(n[0]);
  v = need("generator");
  if (!v || (*v != "terrain" && *v != "none"))
    return FileError{where + ": metadata key generator must be 'terrain' or 'none'", {}};
  m.generator = *v == "terrain" ? GeneratorKind::kTerrain : GeneratorKind::kNone;
  if ((v = need("generator_params"))) m.generator_params = *v;
  v = need("bounds_y");
  if (!v || !parse_int_list<std::int64_t>(*v, n, 2) || n[0] < -kMaxWorldCoordinate || n[1] > kMaxWorldCoordinate)
    return FileError{where + ": metadata key bounds_y missing or malformed (want min,max)", {}};
  m.bounds.min_y = static_cast<std::int32_t>(n[0]);
  m.bounds.max_y = static_cast<std::int32_t>(n[1]);
  v = need("bounds_xz");
  if (v && !v->empty()) {
    if (!parse_int_list<std::int64_t>(*v, n, 4) ||
        std::any_of(n, n + 4, [](std::int64_t c) { return c < -kMaxWorldCoordinate || c > kMaxWorldCoordinate; }))
      return FileError{where + ": metadata key bounds_xz malformed (want x0,z0,x1,z1)", {}};
    m.bounds.bounded_xz = true;
    m.bounds.min_x = static_cast<std::int32_t>(n[0]);
    m.bounds.min_z = static_cast<std::int32_t>(n[1]);
    m.bounds.max_x = static_cast<std::int32_t>(n[2]);
    m.bounds.max_z = static_cast<std::int32_t>(n[3]);
  }
  if (auto why = m.bounds.validate(); !why.empty()) return FileError{where + ": " + why, {}};
  if ((v = need("materials")) && !v->empty()) m.materials = split_lines(*v);
  if (m.materials.size() > static_cast<std::size_t>(kMaterialCount))
    return FileError{where + ": material table has more than 64 entries", {}};
  v = need("epoch");
  if (!v || !parse_int_list<std::int64_t>(*v, n, 1) || n[0] < 0) return FileError{where + ": metadata key epoch missing or malformed", {}};
  m.epoch = static_cast<std::uint64_t>(n[0]);
  // Absent in worlds made before it: none yet.
  if ((v = need("world_id"))) {
    const auto id = parse_world_id(*v);
    if (!id) return FileError{where + ": metadata key world_id malformed (want a decimal number)", {}};
    m.world_id = *id;
  }
  return m;
}

}  // namespace terrane
