#include "common/vxraw/vxraw.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstring>
#include <memory>

namespace terrane {
namespace {

constexpr std::array<std::uint8_t, 8> kMagic = {'V', 'X', 'R', 'A', 'W', '1', 0, 0};
constexpr std::size_t kMagicNameSize = 5;  // "VXRAW" before the version byte
constexpr std::size_t kIoBlock = 64 * 1024;  // file and zlib buffer size

// ---------------------------------------------------------------------------
// Byte sources: the reader pulls the plain VXRAW stream through one of these.

class ByteSource {
 public:
  virtual ~ByteSource() = default;
  // Reads up to n bytes to dst, fewer only at the end of the input.
  virtual Result<std::size_t> read(std::uint8_t* dst, std::size_t n) = 0;
  // Called after the last expected byte: checks nothing follows the data in
  // the underlying container (the plain stream's own end is checked by
  // reading one byte past it).
  virtual Status finish() { return Ok{}; }
};

class MemorySource final : public ByteSource {
 public:
  explicit MemorySource(std::span<const std::uint8_t> bytes) : bytes_(bytes) {}

  Result<std::size_t> read(std::uint8_t* dst, std::size_t n) override {
    const std::size_t k = std::min(n, bytes_.size() - pos_);
    if (k > 0) std::memcpy(dst, bytes_.data() + pos_, k);
    pos_ += k;
    return k;
  }

 private:
  std::span<const std::uint8_t> bytes_;
  std::size_t pos_ = 0;
};

class FileSource final : public ByteSource {
 public:
  explicit FileSource(std::FILE* file) : file_(file) {}

  Result<std::size_t> read(std::uint8_t* dst, std::size_t n) override {
    std::size_t got = 0;
    while (got < n) {
      const std::size_t k = std::fread(dst + got, 1, n - got, file_);
      got += k;
      if (k == 0) {
        if (std::ferror(file_) != 0) {
          io_errno_ = errno != 0 ? errno : EIO;
          return DecodeError{DecodeErrorCode::kTruncated, pos_ + got, "read error"};
        }
        break;
      }
    }
    pos_ += got;
    return got;
  }

  int io_errno() const { return io_errno_; }

 private:
  std::FILE* file_;
  std::size_t pos_ = 0;
  int io_errno_ = 0;
};

// Inflates a single gzip member read from `raw`. It only produces what the
// caller asks for, so output is bounded by the caller's reads.
class InflateSource final : public ByteSource {
 public:
  explicit InflateSource(ByteSource& raw) : raw_(raw), in_(kIoBlock) {
    init_status_ = inflateInit2(&zs_, 16 + MAX_WBITS);  // gzip wrapper only
  }
  ~InflateSource() override {
    if (init_status_ == Z_OK) inflateEnd(&zs_);
  }
  InflateSource(const InflateSource&) = delete;
  InflateSource& operator=(const InflateSource&) = delete;

  Result<std::size_t> read(std::uint8_t* dst, std::size_t n) override {
    if (init_status_ != Z_OK) return fail(DecodeErrorCode::kOverLimit, "zlib could not start (out of memory)");
    std::size_t produced = 0;
    while (produced < n && !ended_) {
      if (zs_.avail_in == 0 && !raw_eof_) {
        auto got = raw_.read(in_.data(), in_.size());
        if (!got) return got.error();
        if (*got == 0) raw_eof_ = true;
        zs_.next_in = in_.data();
        zs_.avail_in = static_cast<uInt>(*got);
      }
      const std::size_t want = std::min<std::size_t>(n - produced, UINT_MAX);
      zs_.next_out = dst + produced;
      zs_.avail_out = static_cast<uInt>(want);
      const int ret = inflate(&zs_, Z_NO_FLUSH);
      produced += want - zs_.avail_out;
      if (ret == Z_STREAM_END) {
        ended_ = true;
      } else if (ret == Z_BUF_ERROR) {
        if (zs_.avail_in == 0 && raw_eof_) return fail(DecodeErrorCode::kTruncated, "gzip stream cut short");
      } else if (ret != Z_OK) {
        zlib_message_ = zs_.msg != nullptr ? zs_.msg : "";
        return fail(DecodeErrorCode::kInvalidValue, "gzip data damaged");
      }
    }
    return produced;
  }

  Status finish() override {
    if (!ended_) return fail(DecodeErrorCode::kTruncated, "gzip stream cut short");
    std::uint8_t b;
    if (zs_.avail_in == 0) {
      auto got = raw_.read(&b, 1);
      if (!got) return got.error();
      if (*got == 0) return Ok{};
    }
    return fail(DecodeErrorCode::kTrailingBytes, "data after the gzip stream");
  }

  // True when the last error was about the compressed bytes; its offset then
  // counts compressed bytes.
  bool compressed_error() const { return compressed_error_; }
  const std::string& zlib_message() const { return zlib_message_; }

 private:
  DecodeError fail(DecodeErrorCode code, const char* detail) {
    compressed_error_ = true;
    return DecodeError{code, static_cast<std::size_t>(zs_.total_in), detail};
  }

  ByteSource& raw_;
  std::vector<std::uint8_t> in_;
  z_stream zs_{};
  int init_status_ = Z_OK;
  bool raw_eof_ = false;
  bool ended_ = false;
  bool compressed_error_ = false;
  std::string zlib_message_;
};

// ---------------------------------------------------------------------------
// Header and voxel checks.

std::int32_t get_i32(const std::uint8_t* p) {
  const std::uint32_t u = std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 |
                          std::uint32_t{p[3]} << 24;
  return static_cast<std::int32_t>(u);
}

void put_i32(std::uint8_t* p, std::int32_t v) {
  const auto u = static_cast<std::uint32_t>(v);
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(u >> (8 * i));
}

struct Header {
  Vec3i size;
  Vec3i origin;
};

Result<Header> parse_header(const std::uint8_t* h, const VxrawLimits& limits) {
  if (!std::equal(kMagic.begin(), kMagic.begin() + kMagicNameSize, h)) {
    return DecodeError{DecodeErrorCode::kBadMagic, 0, "not a VXRAW file"};
  }
  if (!std::equal(kMagic.begin() + kMagicNameSize, kMagic.end(), h + kMagicNameSize)) {
    return DecodeError{DecodeErrorCode::kBadVersion, kMagicNameSize, "VXRAW version other than 1"};
  }
  Header hd;
  const std::int32_t s[3] = {get_i32(h + 8), get_i32(h + 12), get_i32(h + 16)};
  const std::int32_t o[3] = {get_i32(h + 20), get_i32(h + 24), get_i32(h + 28)};
  for (std::size_t i = 0; i < 3; ++i) {
    if (s[i] <= 0) return DecodeError{DecodeErrorCode::kInvalidValue, 8 + 4 * i, "box size not positive"};
    // The far corner must be representable, so origin + size cannot wrap later.
    if (std::int64_t{o[i]} + s[i] > INT32_MAX) {
      return DecodeError{DecodeErrorCode::kInvalidValue, 20 + 4 * i, "box extends past the int32 coordinate range"};
    }
  }
  // Each factor is <= 2^31, so sx * sy fits; the last step divides instead
  // of multiplying so nothing can overflow.
  const std::int64_t xy = std::int64_t{s[0]} * s[1];
  if (xy > limits.max_voxels || xy > limits.max_voxels / s[2]) {
    return DecodeError{DecodeErrorCode::kOverLimit, 8, "voxel count above the limit"};
  }
  hd.size = {s[0], s[1], s[2]};
  hd.origin = {o[0], o[1], o[2]};
  return hd;
}

// Checks materials and repairs Air in place over `count` voxels at p.
// Returns the index of the first voxel with a material >= 64, or count.
std::size_t check_voxels(std::uint8_t* p, std::size_t count, std::uint64_t& repaired) {
  constexpr std::size_t kBlock = 4096;
  for (std::size_t start = 0; start < count; start += kBlock) {
    const std::size_t end = std::min(count, start + kBlock);
    unsigned bad = 0;
    for (std::size_t i = start; i < end; ++i) bad |= p[2 * i];
    if (bad >= kMaterialCount) {
      for (std::size_t i = start; i < end; ++i) {
        if (p[2 * i] >= kMaterialCount) return i;
      }
    }
    std::uint64_t fixed = 0;
    for (std::size_t i = start; i < end; ++i) {
      const bool air = p[2 * i] == kAir;
      fixed += static_cast<std::uint64_t>(air && p[2 * i + 1] != 0);
      p[2 * i + 1] = air ? std::uint8_t{0} : p[2 * i + 1];
    }
    repaired += fixed;
  }
  return count;
}

Result<VxrawFile> decode_stream(ByteSource& src, const VxrawLimits& limits) {
  std::uint8_t header[kVxrawHeaderSize];
  auto got = src.read(header, kVxrawHeaderSize);
  if (!got) return got.error();
  if (*got < kVxrawHeaderSize) return DecodeError{DecodeErrorCode::kTruncated, *got, "shorter than the VXRAW header"};
  auto hd = parse_header(header, limits);
  if (!hd) return hd.error();

  VxrawFile file;
  file.origin = hd->origin;
  file.box.resize(hd->size);
  const std::size_t count = file.box.voxel_count();
  auto* bytes = reinterpret_cast<std::uint8_t*>(file.box.voxels().data());
  got = src.read(bytes, 2 * count);
  if (!got) return got.error();
  if (*got < 2 * count) {
    return DecodeError{DecodeErrorCode::kTruncated, kVxrawHeaderSize + *got, "shorter than the header's box size"};
  }
  std::uint8_t extra;
  got = src.read(&extra, 1);
  if (!got) return got.error();
  if (*got != 0) return DecodeError{DecodeErrorCode::kTrailingBytes, kVxrawHeaderSize + 2 * count, "bytes after the last voxel"};
  if (Status s = src.finish(); !s) return s.error();

  const std::size_t bad = check_voxels(bytes, count, file.repaired_air);
  if (bad != count) {
    return DecodeError{DecodeErrorCode::kInvalidValue, kVxrawHeaderSize + 2 * bad, "material id >= 64"};
  }
  return file;
}

bool is_gzip(const std::uint8_t* p, std::size_t n) { return n >= 2 && p[0] == 0x1f && p[1] == 0x8b; }

void write_header(std::uint8_t* h, Vec3i size, Vec3i origin) {
  std::copy(kMagic.begin(), kMagic.end(), h);
  put_i32(h + 8, size.x);
  put_i32(h + 12, size.y);
  put_i32(h + 16, size.z);
  put_i32(h + 20, origin.x);
  put_i32(h + 24, origin.y);
  put_i32(h + 28, origin.z);
}

// Copies n voxels as VXRAW bytes, writing Air with occupancy 0.
void copy_voxels(const Voxel* src, std::size_t n, std::uint8_t* dst) {
  for (std::size_t i = 0; i < n; ++i) {
    dst[2 * i] = src[i].material;
    dst[2 * i + 1] = src[i].material == kAir ? std::uint8_t{0} : src[i].occupancy;
  }
}

std::string errno_text(int err) { return std::strerror(err); }

// ---------------------------------------------------------------------------
// File output: plain or deflated into a FILE*, remembering the first error.

class FileSink {
 public:
  FileSink(std::FILE* file, bool gzip) : file_(file), gzip_(gzip) {
    if (gzip_) {
      out_.resize(kIoBlock);
      if (deflateInit2(&zs_, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
        error_ = "zlib could not start";
      } else {
        deflating_ = true;
      }
    }
  }
  ~FileSink() {
    if (deflating_) deflateEnd(&zs_);
  }
  FileSink(const FileSink&) = delete;
  FileSink& operator=(const FileSink&) = delete;

  void write(const std::uint8_t* p, std::size_t n) {
    if (!error_.empty()) return;
    if (!gzip_) {
      put(p, n);
      return;
    }
    zs_.next_in = const_cast<Bytef*>(p);  // zlib's API is not const-correct; it only reads
    zs_.avail_in = static_cast<uInt>(n);  // callers pass blocks of at most kIoBlock
    drain(Z_NO_FLUSH);
  }

  void finish() {
    if (gzip_ && error_.empty()) drain(Z_FINISH);
  }

  const std::string& error() const { return error_; }

 private:
  void put(const std::uint8_t* p, std::size_t n) {
    if (std::fwrite(p, 1, n, file_) != n) error_ = "write error: " + errno_text(errno);
  }

  void drain(int flush) {
    for (;;) {
      zs_.next_out = out_.data();
      zs_.avail_out = static_cast<uInt>(out_.size());
      const int ret = deflate(&zs_, flush);
      if (ret == Z_STREAM_ERROR) {
        error_ = "zlib deflate failed";
        return;
      }
      put(out_.data(), out_.size() - zs_.avail_out);
      if (!error_.empty()) return;
      if (flush == Z_FINISH ? ret == Z_STREAM_END : zs_.avail_out != 0) return;
    }
  }

  std::FILE* file_;
  bool gzip_;
  bool deflating_ = false;
  z_stream zs_{};
  std::vector<std::uint8_t> out_;
  std::string error_;
};

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

}  // namespace

Result<VxrawFile> vxraw_decode(std::span<const std::uint8_t> bytes, const VxrawLimits& limits) {
  MemorySource mem(bytes);
  if (is_gzip(bytes.data(), bytes.size())) {
    InflateSource gz(mem);
    return decode_stream(gz, limits);
  }
  return decode_stream(mem, limits);
}

std::vector<std::uint8_t> vxraw_encode(const Box& box, Vec3i origin) {
  std::vector<std::uint8_t> out(kVxrawHeaderSize + 2 * box.voxel_count());
  write_header(out.data(), box.size(), origin);
  copy_voxels(box.voxels().data(), box.voxel_count(), out.data() + kVxrawHeaderSize);
  return out;
}

FileResult<VxrawFile> vxraw_read_file(const std::string& path, const VxrawLimits& limits) {
  FilePtr file(std::fopen(path.c_str(), "rb"));
  if (!file) return FileError{path + ": cannot open: " + errno_text(errno), std::nullopt};

  std::uint8_t magic[2];
  const std::size_t n = std::fread(magic, 1, 2, file.get());
  const bool gzip = is_gzip(magic, n);
  if (std::fseek(file.get(), 0, SEEK_SET) != 0) return FileError{path + ": cannot seek: " + errno_text(errno), std::nullopt};

  FileSource raw(file.get());
  std::optional<InflateSource> gz;
  if (gzip) gz.emplace(raw);
  auto result = gzip ? decode_stream(*gz, limits) : decode_stream(raw, limits);
  if (result) return std::move(result).value();

  const DecodeError& e = result.error();
  if (raw.io_errno() != 0) return FileError{path + ": read error: " + errno_text(raw.io_errno()), e};
  std::string msg = path + ": ";
  if (gzip && gz->compressed_error()) {
    msg += std::string(e.detail) + " at byte " + std::to_string(e.offset) + " of the compressed file";
    if (!gz->zlib_message().empty()) msg += " (zlib: " + gz->zlib_message() + ")";
  } else if (e.code == DecodeErrorCode::kBadMagic) {
    msg += gzip ? "not a VXRAW file (gzip data, but no VXRAW magic inside)" : "not a VXRAW file (bad magic)";
  } else {
    msg += std::string(to_string(e.code)) + " at byte " + std::to_string(e.offset) +
           (gzip ? " of the decompressed data" : "") + ": " + e.detail;
  }
  return FileError{std::move(msg), e};
}

FileStatus vxraw_write_file(const std::string& path, const Box& box, Vec3i origin, bool gzip) {
  std::string tmp = path + ".tmp.XXXXXX";
  const int fd = mkstemp(tmp.data());
  if (fd < 0) return FileError{path + ": cannot create temporary file " + tmp + ": " + errno_text(errno), std::nullopt};
  // mkstemp creates 0600; give the finished file ordinary permissions.
  (void)fchmod(fd, 0644);
  FilePtr file(fdopen(fd, "wb"));
  if (!file) {
    const int err = errno;
    close(fd);
    unlink(tmp.c_str());
    return FileError{path + ": cannot open temporary file: " + errno_text(err), std::nullopt};
  }

  std::string error;
  {
    FileSink sink(file.get(), gzip);
    std::uint8_t header[kVxrawHeaderSize];
    write_header(header, box.size(), origin);
    sink.write(header, sizeof header);
    std::vector<std::uint8_t> block(kIoBlock);
    const std::span<const Voxel> voxels = box.voxels();
    for (std::size_t i = 0; i < voxels.size() && sink.error().empty(); i += kIoBlock / 2) {
      const std::size_t n = std::min(kIoBlock / 2, voxels.size() - i);
      copy_voxels(voxels.data() + i, n, block.data());
      sink.write(block.data(), 2 * n);
    }
    sink.finish();
    error = sink.error();
  }
  if (error.empty() && std::fflush(file.get()) != 0) error = "write error: " + errno_text(errno);
  if (error.empty() && fsync(fileno(file.get())) != 0) error = "fsync failed: " + errno_text(errno);
  if (std::fclose(file.release()) != 0 && error.empty()) error = "close failed: " + errno_text(errno);
  if (error.empty() && std::rename(tmp.c_str(), path.c_str()) != 0) error = "cannot rename into place: " + errno_text(errno);
  if (!error.empty()) {
    unlink(tmp.c_str());
    return FileError{path + ": " + error, std::nullopt};
  }
  return Ok{};
}

}  // namespace terrane
