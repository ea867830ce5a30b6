// terrane-bots presets: named scenarios with their own defaults
// (--preset NAME, or `preset = NAME` in a scenario file). A preset is a
// set of option values taken for every key the scenario file and the
// command line leave out: what they give wins. Some values depend on the
// number of bots (world: the area grows with it), taken after the
// overrides. Thread-safety: constant data and pure functions.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "client/bots/options.h"

namespace terrane::bots {

struct Preset {
  const char* name;
  const char* summary;  // what it stresses, for --list-presets
  int default_bots;
  // Its option values (flag names without "--") for `bots` bots, in the
  // order --list-presets shows them; `bots` itself is not among them.
  std::vector<std::pair<std::string, std::string>> (*values)(int bots);
  const char* notes;  // how values depend on --bots, or ""
  const char* example;  // a command line (docs/load-testing.md)
};

// Every preset, in the order --list-presets shows them.
const std::vector<Preset>& presets();
// The preset of that name (or alias: flyers is teleport), else nullptr.
const Preset* find_preset(const std::string& name);
// "join-storm, hotspot, ...": for errors.
std::string preset_names();
// The --list-presets text: each preset, its summary and its defaults.
std::string presets_text();

// *out = given plus, when given holds a `preset` (the last one wins), that
// preset's values for each key given lacks, each from "preset NAME". The
// preset's `bots` count is given's when it is a valid integer. Returns ""
// or the error (an unknown preset, naming the known ones).
std::string expand_preset(const OptionValues& given, OptionValues* out);

}  // namespace terrane::bots
