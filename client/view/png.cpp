#include "client/view/png.h"

#include <zlib.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>

namespace terrane::view {
namespace {

void put32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out.push_back(static_cast<std::uint8_t>(v >> s));
}
std::uint32_t get32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
}

void chunk(std::vector<std::uint8_t>& out, const char* type, const std::vector<std::uint8_t>& data) {
  put32(out, static_cast<std::uint32_t>(data.size()));
  const std::size_t start = out.size();
  out.insert(out.end(), type, type + 4);
  out.insert(out.end(), data.begin(), data.end());
  const uLong crc = crc32(0, out.data() + start, static_cast<uInt>(out.size() - start));
  put32(out, static_cast<std::uint32_t>(crc));
}

constexpr std::uint8_t kSignature[8] = {137, 80, 78, 71, 13, 10, 26, 10};

int paeth(int a, int b, int c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

}  // namespace

std::vector<std::uint8_t> encode_png(const Image& image) {
  const std::size_t stride = static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.channels);
  // Filter "Up" (2) on every row but the first: rendered images have long
  // vertical runs (sky), which it turns into zeros.
  std::vector<std::uint8_t> raw;
  raw.reserve((stride + 1) * static_cast<std::size_t>(image.height));
  for (int y = 0; y < image.height; ++y) {
    const std::uint8_t* row = image.pixels.data() + static_cast<std::size_t>(y) * stride;
    raw.push_back(y == 0 ? 0 : 2);
    if (y == 0) {
      raw.insert(raw.end(), row, row + stride);
      continue;
    }
    const std::uint8_t* above = row - stride;
    for (std::size_t i = 0; i < stride; ++i) raw.push_back(static_cast<std::uint8_t>(row[i] - above[i]));
  }
  uLongf zsize = compressBound(static_cast<uLong>(raw.size()));
  std::vector<std::uint8_t> z(zsize);
  compress2(z.data(), &zsize, raw.data(), static_cast<uLong>(raw.size()), 6);
  z.resize(zsize);

  std::vector<std::uint8_t> out(std::begin(kSignature), std::end(kSignature));
  std::vector<std::uint8_t> ihdr;
  put32(ihdr, static_cast<std::uint32_t>(image.width));
  put32(ihdr, static_cast<std::uint32_t>(image.height));
  ihdr.push_back(8);                                          // bit depth
  ihdr.push_back(image.channels == 4 ? 6 : 2);                // colour type RGBA / RGB
  ihdr.push_back(0);                                          // deflate
  ihdr.push_back(0);                                          // adaptive filtering
  ihdr.push_back(0);                                          // no interlace
  chunk(out, "IHDR", ihdr);
  chunk(out, "IDAT", z);
  chunk(out, "IEND", {});
  return out;
}

bool write_png(const std::string& path, const Image& image, std::string* error) {
  const std::vector<std::uint8_t> bytes = encode_png(image);
  std::ofstream f(path, std::ios::binary);
  if (!f) {
    *error = "cannot open " + path + " for writing: " + std::strerror(errno);
    return false;
  }
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!f) {
    *error = "cannot write " + path + ": " + std::strerror(errno);
    return false;
  }
  return true;
}

bool read_png(const std::string& path, Image& image, std::string* error) {
  std::ifstream f(path, std::ios::binary);
  if (!f) {
    *error = "cannot open " + path;
    return false;
  }
  const std::vector<std::uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (b.size() < 8 || std::memcmp(b.data(), kSignature, 8) != 0) {
    *error = path + ": not a PNG";
    return false;
  }
  std::vector<std::uint8_t> z;
  std::size_t at = 8;
  int depth = 0, type = 0, interlace = 0;
  while (at + 12 <= b.size()) {
    const std::uint32_t len = get32(&b[at]);
    if (len > b.size() - at - 12) break;
    const std::string t(reinterpret_cast<const char*>(&b[at + 4]), 4);
    const std::uint8_t* d = &b[at + 8];
    if (t == "IHDR" && len >= 13) {
      image.width = static_cast<int>(get32(d));
      image.height = static_cast<int>(get32(d + 4));
      depth = d[8];
      type = d[9];
      interlace = d[12];
    } else if (t == "IDAT") {
      z.insert(z.end(), d, d + len);
    }
    at += 12 + len;
  }
  if (depth != 8 || (type != 2 && type != 6) || interlace != 0 || image.width <= 0 || image.height <= 0 ||
      image.width > 16384 || image.height > 16384) {
    *error = path + ": unsupported PNG layout";
    return false;
  }
  image.channels = type == 6 ? 4 : 3;
  const std::size_t stride = static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.channels);
  std::vector<std::uint8_t> raw((stride + 1) * static_cast<std::size_t>(image.height));
  uLongf rsize = static_cast<uLongf>(raw.size());
  if (uncompress(raw.data(), &rsize, z.data(), static_cast<uLong>(z.size())) != Z_OK || rsize != raw.size()) {
    *error = path + ": bad image data";
    return false;
  }
  image.pixels.assign(stride * static_cast<std::size_t>(image.height), 0);
  const std::size_t bpp = static_cast<std::size_t>(image.channels);
  for (int y = 0; y < image.height; ++y) {
    const std::uint8_t filter = raw[static_cast<std::size_t>(y) * (stride + 1)];
    const std::uint8_t* in = &raw[static_cast<std::size_t>(y) * (stride + 1) + 1];
    std::uint8_t* row = &image.pixels[static_cast<std::size_t>(y) * stride];
    const std::uint8_t* up = y > 0 ? row - stride : nullptr;
    for (std::size_t i = 0; i < stride; ++i) {
      const int a = i >= bpp ? row[i - bpp] : 0, u = up ? up[i] : 0, c = (up && i >= bpp) ? up[i - bpp] : 0;
      int pred = 0;
      switch (filter) {
        case 0: pred = 0; break;
        case 1: pred = a; break;
        case 2: pred = u; break;
        case 3: pred = (a + u) / 2; break;
        case 4: pred = paeth(a, u, c); break;
        default: *error = path + ": bad filter"; return false;
      }
      row[i] = static_cast<std::uint8_t>(in[i] + pred);
    }
  }
  return true;
}

}  // namespace terrane::view
