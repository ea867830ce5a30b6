// GeneratorParams: the terrain generator's knobs, their accepted ranges and
// their text in a world's metadata ("key=value" lines).
//
// Plain values and pure functions: nothing here holds generator state, so any
// thread may call them. The metadata text is part of the saved world format
// (common/world/GENERATOR.md): its keys, order and number spelling do not
// change without bumping kGeneratorVersion.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "common/codec/decode_error.h"

namespace terrane {

inline constexpr std::uint32_t kGeneratorVersion = 1;

// The vertical range a default world is built for (Y is up). The generator
// is defined everywhere: below kWorldMinY + 4 it is solid Basalt, above the
// highest peak it is Air.
inline constexpr std::int32_t kWorldMinY = -128;
inline constexpr std::int32_t kWorldMaxY = 256;

// All knobs are part of the world's metadata (to_metadata); validate() gives
// the accepted ranges.
struct GeneratorParams {
  std::uint64_t seed = 1;
  // Water fills open air below this y (oceans, rivers, swamps).
  std::int32_t sea_level = 32;
  // Horizontal feature size multiplier: 2 makes continents, mountains and
  // rivers twice as wide. Range [0.25, 8].
  float terrain_scale = 1.0f;
  // Peak height of mountain ranges above the land, in voxels. Range [0, 400].
  float mountain_height = 160.0f;
  // Amplitude of rolling hills, in voxels. Range [0, 64].
  float hill_height = 18.0f;
  // Amplitude of the 3D surface perturbation (overhangs, arches) in
  // steep and mountainous terrain, in voxels. Range [0, 16].
  float overhang_strength = 7.0f;
  // Tunnels and caverns underground (and lava deep down).
  bool caves = true;

  friend bool operator==(const GeneratorParams&, const GeneratorParams&) = default;
};

// Returns an empty string when params are valid, else a message naming the
// first bad field.
std::string validate(const GeneratorParams& params);

// params moved into the ranges validate() accepts: out-of-range values are
// clamped, NaN and infinities become the default. Valid params come back
// unchanged.
GeneratorParams clamped(GeneratorParams params);

// Generator name, version and params as "key=value" lines, one per key, in a
// fixed order.
std::string to_metadata(const GeneratorParams& params);

// Parses to_metadata() output (lines in any order, "\r\n" accepted). Unknown
// keys, duplicates, missing keys, malformed or out-of-range values and a
// different generator name or version are rejected: the DecodeError carries
// the byte offset of the bad line and, if `message` is not null, *message
// names the line and key ("line 3 (seed): malformed value '-1'").
Result<GeneratorParams> params_from_metadata(std::string_view text, std::string* message = nullptr);

}  // namespace terrane
