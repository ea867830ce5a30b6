#include "common/world/generator_params.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace terrane {
namespace {

GeneratorParams unusual() {
  GeneratorParams p;
  p.seed = 0xFEDCBA9876543210ull;
  p.sea_level = -17;
  p.terrain_scale = 1.37f;
  p.mountain_height = 211.3f;
  p.hill_height = 0.1f;
  p.overhang_strength = 3.0f;
  p.caves = false;
  return p;
}

// The metadata text is part of the saved world format: the default params'
// text, byte for byte.
TEST(GeneratorParams, DefaultMetadataTextIsPinned) {
  EXPECT_EQ(to_metadata(GeneratorParams{}),
            "generator=terrane.density\nversion=1\nseed=1\nsea_level=32\nterrain_scale=1\n"
            "mountain_height=160\nhill_height=18\noverhang_strength=7\ncaves=true\n");
}

TEST(GeneratorParams, MetadataRoundTrips) {
  for (const GeneratorParams& p : {GeneratorParams{}, unusual()}) {
    const std::string text = to_metadata(p);
    std::string message;
    const Result<GeneratorParams> parsed = params_from_metadata(text, &message);
    ASSERT_TRUE(parsed.ok()) << message << "\n" << text;
    EXPECT_EQ(*parsed, p);
    EXPECT_EQ(to_metadata(*parsed), text);
  }
  // The shortest text that reads back as the same float, not a rounded one.
  EXPECT_NE(to_metadata(unusual()).find("\nmountain_height=211.3\n"), std::string::npos);
}

TEST(GeneratorParams, BadKeyIsNamedWithItsLineAndOffset) {
  const std::string good = to_metadata(GeneratorParams{});
  const std::string text = good + "colour=blue\n";
  std::string message;
  const Result<GeneratorParams> parsed = params_from_metadata(text, &message);
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(parsed.error().offset, good.size());  // the bad line's first byte
  EXPECT_EQ(message, "line 10 (colour): unknown key");
}

TEST(GeneratorParams, BadValueIsNamedWithItsKey) {
  std::string text = to_metadata(GeneratorParams{});
  const std::size_t at = text.find("hill_height=18");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 14, "hill_height=tall");
  std::string message;
  const Result<GeneratorParams> parsed = params_from_metadata(text, &message);
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(parsed.error().offset, at);
  EXPECT_EQ(message, "line 7 (hill_height): malformed value 'tall'");
}

TEST(GeneratorParams, OutOfRangeAndMissingKeysAreNamed) {
  GeneratorParams far;
  far.terrain_scale = 9.0f;
  std::string message;
  Result<GeneratorParams> parsed = params_from_metadata(to_metadata(far), &message);
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(message, "terrain_scale out of range [0.25, 8]");

  std::string text = to_metadata(GeneratorParams{});
  text.erase(text.find("seed=1\n"), 7);
  parsed = params_from_metadata(text, &message);
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.error().code, DecodeErrorCode::kTruncated);
  EXPECT_EQ(message, "missing key 'seed'");
}

TEST(GeneratorParams, OtherVersionIsRejected) {
  std::string text = to_metadata(GeneratorParams{});
  text.replace(text.find("version=1"), 9, "version=7");
  std::string message;
  const Result<GeneratorParams> parsed = params_from_metadata(text, &message);
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.error().code, DecodeErrorCode::kBadVersion);
  EXPECT_EQ(message, "line 2 (version): version 7 is not 1");
}

TEST(GeneratorParams, ValidateNamesTheFirstBadField) {
  GeneratorParams p;
  EXPECT_EQ(validate(p), "");
  p.overhang_strength = -1.0f;
  EXPECT_EQ(validate(p), "overhang_strength out of range [0, 16]");
  p.sea_level = 401;
  EXPECT_EQ(validate(p), "sea_level out of range [-100, 400]");
  p = GeneratorParams{};
  p.hill_height = std::nanf("");
  EXPECT_EQ(validate(p), "hill_height out of range [0, 64]");
}

TEST(GeneratorParams, ClampedIsValidAndKeepsValidParams) {
  EXPECT_EQ(clamped(unusual()), unusual());
  GeneratorParams bad;
  bad.seed = 99;
  bad.sea_level = -5000;
  bad.terrain_scale = std::nanf("");
  bad.mountain_height = 1e30f;
  bad.hill_height = -3.0f;
  bad.overhang_strength = INFINITY;
  const GeneratorParams c = clamped(bad);
  EXPECT_EQ(validate(c), "");
  EXPECT_EQ(c.seed, 99u);
  EXPECT_EQ(c.sea_level, -100);
  EXPECT_EQ(c.terrain_scale, GeneratorParams{}.terrain_scale);  // NaN: the default
  EXPECT_EQ(c.mountain_height, 400.0f);
  EXPECT_EQ(c.hill_height, 0.0f);
  EXPECT_EQ(c.overhang_strength, GeneratorParams{}.overhang_strength);  // infinite: the default
}

}  // namespace
}  // namespace terrane
