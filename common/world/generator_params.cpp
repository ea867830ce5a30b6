#include "common/world/generator_params.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>

#include "common/world/noise.h"

namespace terrane {

namespace {

constexpr std::string_view kGeneratorName = "terrane.density";

// A number as the metadata spells it (shortest round-trip text).
template <class T>
std::string number_text(T value) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), value);
  return std::string(buf, static_cast<std::size_t>(r.ptr - buf));
}

template <class T>
void append_kv(std::string& s, std::string_view key, T value) {
  s += key;
  s += '=';
  s += number_text(value);
  s += '\n';
}

// The accepted ranges, written once for validate() and clamped(); the float
// knobs in the order validate() checks them.
constexpr std::int32_t kSeaLevelMin = -100;
constexpr std::int32_t kSeaLevelMax = 400;
struct FloatRange {
  float GeneratorParams::*field;
  const char* name;
  float lo, hi;
};
constexpr std::array<FloatRange, 4> kFloatRanges = {{
    {&GeneratorParams::terrain_scale, "terrain_scale", 0.25f, 8.0f},
    {&GeneratorParams::mountain_height, "mountain_height", 0.0f, 400.0f},
    {&GeneratorParams::hill_height, "hill_height", 0.0f, 64.0f},
    {&GeneratorParams::overhang_strength, "overhang_strength", 0.0f, 16.0f},
}};

template <class T>
bool parse_number(std::string_view v, T& out) {
  if (v.empty()) return false;
  const auto r = std::from_chars(v.data(), v.data() + v.size(), out);
  return r.ec == std::errc{} && r.ptr == v.data() + v.size();
}

}  // namespace

std::string validate(const GeneratorParams& p) {
  if (p.sea_level < kSeaLevelMin || p.sea_level > kSeaLevelMax) {
    return "sea_level out of range [" + number_text(kSeaLevelMin) + ", " + number_text(kSeaLevelMax) + "]";
  }
  for (const FloatRange& r : kFloatRanges) {
    const float v = p.*r.field;
    if (!std::isfinite(v) || v < r.lo || v > r.hi) {
      return std::string(r.name) + " out of range [" + number_text(r.lo) + ", " + number_text(r.hi) + "]";
    }
  }
  return {};
}

GeneratorParams clamped(GeneratorParams p) {
  const GeneratorParams d;
  p.sea_level = std::clamp(p.sea_level, kSeaLevelMin, kSeaLevelMax);
  for (const FloatRange& r : kFloatRanges) {
    float& v = p.*r.field;
    v = std::isfinite(v) ? clampf(v, r.lo, r.hi) : d.*r.field;
  }
  return p;
}

std::string to_metadata(const GeneratorParams& params) {
  std::string s;
  s.append("generator=").append(kGeneratorName).push_back('\n');
  append_kv(s, "version", kGeneratorVersion);
  append_kv(s, "seed", params.seed);
  append_kv(s, "sea_level", params.sea_level);
  append_kv(s, "terrain_scale", params.terrain_scale);
  append_kv(s, "mountain_height", params.mountain_height);
  append_kv(s, "hill_height", params.hill_height);
  append_kv(s, "overhang_strength", params.overhang_strength);
  s.append("caves=").append(params.caves ? "true" : "false").push_back('\n');
  return s;
}

Result<GeneratorParams> params_from_metadata(std::string_view text, std::string* message) {
  enum Key { kKeyName, kKeyVersion, kKeySeed, kKeySea, kKeyScale, kKeyMountain, kKeyHill, kKeyOverhang, kKeyCaves, kKeyCount };
  static constexpr std::array<std::string_view, kKeyCount> kKeys = {
      "generator", "version", "seed", "sea_level", "terrain_scale", "mountain_height", "hill_height",
      "overhang_strength", "caves"};
  std::array<bool, kKeyCount> seen{};
  GeneratorParams p;
  std::size_t line_no = 0;

  auto fail = [&](DecodeErrorCode code, std::size_t offset, const char* detail, const std::string& msg) {
    if (message != nullptr) *message = msg;
    return Result<GeneratorParams>(DecodeError{code, offset, detail});
  };

  std::size_t pos = 0;
  while (pos < text.size()) {
    const std::size_t line_start = pos;
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line.empty()) continue;
    const std::string where = "line " + std::to_string(line_no);
    const std::size_t eq = line.find('=');
    if (eq == std::string_view::npos) {
      return fail(DecodeErrorCode::kInvalidValue, line_start, "expected key=value",
                  where + ": expected key=value, got '" + std::string(line) + "'");
    }
    const std::string_view key = line.substr(0, eq), value = line.substr(eq + 1);
    const std::string what = where + " (" + std::string(key) + ")";
    int k = 0;
    while (k < kKeyCount && kKeys[k] != key) ++k;
    if (k == kKeyCount) {
      return fail(DecodeErrorCode::kInvalidValue, line_start, "unknown key", what + ": unknown key");
    }
    if (seen[k]) return fail(DecodeErrorCode::kInvalidValue, line_start, "duplicate key", what + ": duplicate key");
    seen[k] = true;
    bool ok = true;
    switch (static_cast<Key>(k)) {
      case kKeyName:
        if (value != kGeneratorName) {
          return fail(DecodeErrorCode::kBadMagic, line_start, "not a terrane.density generator",
                      what + ": unknown generator '" + std::string(value) + "'");
        }
        break;
      case kKeyVersion: {
        std::uint32_t v = 0;
        if (!parse_number(value, v)) {
          ok = false;
        } else if (v != kGeneratorVersion) {
          return fail(DecodeErrorCode::kBadVersion, line_start, "unsupported generator version",
                      what + ": version " + std::string(value) + " is not " + std::to_string(kGeneratorVersion));
        }
        break;
      }
      case kKeySeed: ok = parse_number(value, p.seed); break;
      case kKeySea: ok = parse_number(value, p.sea_level); break;
      case kKeyScale: ok = parse_number(value, p.terrain_scale); break;
      case kKeyMountain: ok = parse_number(value, p.mountain_height); break;
      case kKeyHill: ok = parse_number(value, p.hill_height); break;
      case kKeyOverhang: ok = parse_number(value, p.overhang_strength); break;
      case kKeyCaves:
        if (value == "true") {
          p.caves = true;
        } else if (value == "false") {
          p.caves = false;
        } else {
          ok = false;
        }
        break;
      case kKeyCount: break;
    }
    if (!ok) {
      return fail(DecodeErrorCode::kInvalidValue, line_start, "malformed value",
                  what + ": malformed value '" + std::string(value) + "'");
    }
  }
  for (int k = 0; k < kKeyCount; ++k) {
    if (!seen[k]) {
      return fail(DecodeErrorCode::kTruncated, text.size(), "missing key",
                  "missing key '" + std::string(kKeys[k]) + "'");
    }
  }
  if (std::string err = validate(p); !err.empty()) {
    return fail(DecodeErrorCode::kInvalidValue, 0, "parameter out of range", err);
  }
  return p;
}

}  // namespace terrane
