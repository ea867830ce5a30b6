#include "client/view/png.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

namespace terrane::view {
namespace {

TEST(Png, RoundTripsRgbAndRgba) {
  for (const int channels : {3, 4}) {
    Image img;
    img.width = 37;
    img.height = 23;
    img.channels = channels;
    for (int i = 0; i < img.width * img.height * channels; ++i)
      img.pixels.push_back(static_cast<std::uint8_t>((i * 7919) ^ (i >> 3)));
    const auto path =
        (std::filesystem::temp_directory_path() / ("terrane-png-" + std::to_string(::getpid()) + ".png")).string();
    std::string error;
    ASSERT_TRUE(write_png(path, img, &error)) << error;
    Image back;
    ASSERT_TRUE(read_png(path, back, &error)) << error;
    std::filesystem::remove(path);
    EXPECT_EQ(back.width, img.width);
    EXPECT_EQ(back.height, img.height);
    EXPECT_EQ(back.channels, channels);
    EXPECT_EQ(back.pixels, img.pixels);
  }
}

TEST(Png, RejectsWhatIsNotAPng) {
  const auto path =
      (std::filesystem::temp_directory_path() / ("terrane-notpng-" + std::to_string(::getpid()))).string();
  FILE* f = std::fopen(path.c_str(), "wb");
  std::fputs("hello", f);
  std::fclose(f);
  Image img;
  std::string error;
  EXPECT_FALSE(read_png(path, img, &error));
  EXPECT_NE(error.find("not a PNG"), std::string::npos);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace terrane::view
