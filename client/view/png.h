// PNG writer: 8-bit RGB or RGBA images, zlib-compressed (no filter
// prediction beyond "Up"), for screenshots and README pictures.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace terrane::view {

struct Image {
  int width = 0, height = 0;
  int channels = 3;                 // 3 (RGB) or 4 (RGBA)
  std::vector<std::uint8_t> pixels; // rows top to bottom, width * channels bytes each
};

// Encodes the image as PNG bytes. Precondition: pixels.size() ==
// width * height * channels, width and height > 0.
std::vector<std::uint8_t> encode_png(const Image& image);
// Writes a PNG file; false with *error set on failure.
bool write_png(const std::string& path, const Image& image, std::string* error);
// Reads back a PNG this writer produced (8-bit RGB/RGBA, non-interlaced,
// any standard filter), for tests. False with *error set otherwise.
bool read_png(const std::string& path, Image& image, std::string* error);

}  // namespace terrane::view
