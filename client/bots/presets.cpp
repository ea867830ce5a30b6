#include "client/bots/presets.h"

#include <charconv>
#include <cmath>
#include <sstream>

namespace terrane::bots {

namespace {

using Values = std::vector<std::pair<std::string, std::string>>;

// crowd and world are scripts/bots-scale.sh's scale scenarios (figures in
// docs/results.md): mixed bots, full-resolution radius 64, view distance
// 512, a sphere of radius <= 3 (or a box) every 2 s per bot, 60 s measured.
Values crowd(int) {
  return {{"behavior", "mixed"},        {"spread", "512"},       {"ramp-up", "20"},     {"wait-joined", "0"},
          {"measure-from", "ramp-up"},  {"duration", "60"},      {"view-distance", "512"},
          {"full-res-radius", "64"},    {"edit-interval", "2"},  {"edit-radius", "3"},  {"edit-shape", "mixed"},
          {"seed", "1"}};
}

// Constant density: 1,000 bots over 3,072 x 3,072 voxels, the square
// growing with sqrt(N) (as awk's printf %d, truncated), joining at 5 a
// second; the 60 s start once every bot has joined.
Values world(int bots) {
  const int spread = static_cast<int>(3072.0 * std::sqrt(static_cast<double>(bots) / 1000.0));
  return {{"behavior", "mixed"},
          {"spread", std::to_string(spread)},
          {"ramp-up", std::to_string((bots + 4) / 5)},
          {"wait-joined", "600"},
          {"measure-from", "ramp-up"},
          {"duration", "60"},
          {"view-distance", "512"},
          {"full-res-radius", "64"},
          {"edit-interval", "2"},
          {"edit-radius", "3"},
          {"edit-shape", "mixed"},
          {"seed", "1"}};
}

Values join_storm(int) {
  return {{"behavior", "mixed"},       {"spread", "512"},      {"ramp-up", "0"},     {"wait-joined", "0"},
          {"measure-from", "start"},   {"duration", "30"},     {"view-distance", "256"},
          {"full-res-radius", "64"},   {"edit-interval", "2"}, {"edit-radius", "3"}, {"edit-shape", "mixed"}};
}

Values hotspot(int) {
  return {{"behavior", "hotspot"},      {"spread", "256"},      {"ramp-up", "10"},    {"wait-joined", "0"},
          {"measure-from", "ramp-up"},  {"duration", "60"},     {"view-distance", "256"},
          {"full-res-radius", "64"},    {"edit-interval", "2"}, {"edit-radius", "3"}, {"edit-shape", "mixed"}};
}

// A jump of 1,024 voxels every 5 s is within the server's default budget
// (--max-speed 256: 256 x 5 + 48 = 1,328 voxels) and four times the view
// distance: every jump leaves the whole view behind.
Values teleport(int) {
  return {{"behavior", "teleport"},       {"teleport-interval", "5"}, {"teleport-distance", "1024"},
          {"spread", "256"},              {"ramp-up", "5"},           {"wait-joined", "0"},
          {"measure-from", "ramp-up"},    {"duration", "60"},         {"view-distance", "256"},
          {"full-res-radius", "64"},      {"edit-interval", "2"},     {"edit-radius", "3"},
          {"edit-shape", "mixed"}};
}

// Raw boxes of 16 to 32 voxels a side: up to kMaxRawBoxVolume (32^3)
// voxels each, the largest write_box the protocol carries.
Values builders(int) {
  return {{"behavior", "build"},        {"edit-shape", "write-box"}, {"edit-radius", "16"}, {"edit-interval", "2"},
          {"spread", "256"},            {"ramp-up", "10"},           {"wait-joined", "0"},
          {"measure-from", "ramp-up"},  {"duration", "60"},          {"view-distance", "256"},
          {"full-res-radius", "64"}};
}

}  // namespace

const std::vector<Preset>& presets() {
  static const std::vector<Preset> k = {
      {"join-storm",
       "every bot connects at once (no ramp-up) and latencies count from the first connection: edits and their "
       "fan-out while the whole crowd joins",
       200, join_storm, "", "terrane-bots --connect HOST:PORT --preset join-storm --bots 300"},
      {"hotspot",
       "every bot flies from its start to the spawn (or --spawn), lands there and stays, editing the ground "
       "around it: every edit fans out to every bot",
       100, hotspot, "", "terrane-bots --connect HOST:PORT --preset hotspot --spawn 0,80,0"},
      {"teleport",
       "views jump: every --teleport-interval each bot jumps --teleport-distance voxels to a random point within "
       "that distance of the spawn, so the server streams it a whole new view (alias: flyers)",
       50, teleport, "", "terrane-bots --connect HOST:PORT --preset flyers --bots 100"},
      {"builders",
       "large raw edits: every bot writes boxes of 16 to 32 voxels a side (write_box, up to 32^3 voxels of "
       "patterned materials) at ray-cast targets",
       50, builders, "", "terrane-bots --connect HOST:PORT --preset builders --bots 100"},
      {"crowd",
       "scripts/bots-scale.sh crowd: every bot within a 512 x 512 square, so every bot sees every edit", 500, crowd,
       "", "scripts/bots-scale.sh crowd 500  (terrane-bots --connect HOST:PORT --preset crowd --bots 500)"},
      {"world",
       "scripts/bots-scale.sh world: bots at a constant density, 1,000 over 3,072 x 3,072 voxels, joining at 5 a "
       "second; the duration starts once every bot has joined",
       1000, world, "spread = 3072 x sqrt(bots / 1000) (truncated), ramp-up = ceil(bots / 5) s",
       "scripts/bots-scale.sh world 1000  (terrane-bots --connect HOST:PORT --preset world --bots 1000)"},
  };
  return k;
}

const Preset* find_preset(const std::string& name) {
  const std::string n = name == "flyers" ? "teleport" : name;
  for (const Preset& p : presets())
    if (n == p.name) return &p;
  return nullptr;
}

std::string preset_names() {
  std::string s;
  for (const Preset& p : presets()) s += (s.empty() ? "" : ", ") + std::string(p.name);
  return s + " (flyers is teleport)";
}

namespace {

// words, wrapped before column 96: the first line starts with first, the
// others with indent.
std::string wrapped(const std::vector<std::string>& words, const std::string& first, const std::string& indent) {
  std::string out, line = first;
  bool bare = true;  // no word on this line yet
  for (const std::string& w : words) {
    if (!bare && line.size() + 1 + w.size() > 95) {
      out += line + "\n";
      line = indent;
      bare = true;
    }
    line += (bare ? "" : " ") + w;
    bare = false;
  }
  return out + line + "\n";
}

std::vector<std::string> words_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

}  // namespace

std::string presets_text() {
  std::ostringstream s;
  s << "Presets (--preset NAME, or 'preset = NAME' in a scenario file). Flags and scenario lines\n"
       "override a preset's defaults; --save-scenario writes the resolved values.\n";
  for (const Preset& p : presets()) {
    s << "\n" << wrapped(words_of(std::string(p.summary) + "."), "  " + std::string(p.name) + ": ", "    ");
    std::vector<std::string> items = {"bots = " + std::to_string(p.default_bots) + ","};
    const auto values = p.values(p.default_bots);
    for (std::size_t i = 0; i < values.size(); ++i)
      items.push_back(values[i].first + " = " + values[i].second + (i + 1 < values.size() ? "," : ""));
    // "key = value" stays on one line: no break within an item.
    std::string line = "    defaults:", out;
    for (const std::string& item : items) {
      if (line.size() + 1 + item.size() > 95) {
        out += line + "\n";
        line = "     ";
      }
      line += " " + item;
    }
    s << out << line << "\n";
    if (*p.notes != '\0') s << wrapped(words_of(p.notes), "    ", "    ");
    s << "    e.g. " << p.example << "\n";
  }
  return s.str();
}

std::string expand_preset(const OptionValues& given, OptionValues* out) {
  *out = given;
  const auto [first, last] = given.equal_range("preset");
  if (first == last) return "";
  const auto& [name, where] = std::prev(last)->second;
  const Preset* p = find_preset(name);
  if (p == nullptr) return where + ": '" + name + "' is not a preset; known: " + preset_names();
  int bots = p->default_bots;
  if (const auto b = given.equal_range("bots"); b.first != b.second) {
    const std::string& v = std::prev(b.second)->second.first;
    int n = 0;
    auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), n);
    if (ec == std::errc() && end == v.data() + v.size() && n >= 1) bots = n;
  } else {
    out->emplace("bots", std::make_pair(std::to_string(bots), "preset " + std::string(p->name) + ": bots"));
  }
  for (const auto& [k, v] : p->values(bots))
    if (given.count(k) == 0) out->emplace(k, std::make_pair(v, "preset " + std::string(p->name) + ": " + k));
  return "";
}

}  // namespace terrane::bots
