// terrane-bots presets (client/bots/presets.h): each resolves to the
// options it documents, flags and scenario lines override it, a saved
// scenario reads back to the same options, an unknown name is a usage
// error naming the known ones. Real runs of the presets' behaviours
// (teleport, hotspot, write-box builders) are in tests/client/bots_test.cpp.
#include "client/bots/presets.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "client/bots/options.h"
#include "tests/client/bots/parse_flags.h"
#include "tests/support/run_command.h"

namespace terrane::bots {
namespace {

namespace fs = std::filesystem;

BotsOptions with_preset(const std::vector<std::string>& extra) {
  std::vector<std::string> args = {"--connect", "127.0.0.1:7000"};
  args.insert(args.end(), extra.begin(), extra.end());
  BotsOptions o;
  EXPECT_EQ(parse_flags(args, &o), "");
  return o;
}

TEST(BotsPresets, JoinStormConnectsEveryBotAtOnceAndMeasuresFromTheStart) {
  const BotsOptions o = with_preset({"--preset", "join-storm"});
  EXPECT_EQ(o.preset, "join-storm");
  EXPECT_EQ(o.bots, 200);
  EXPECT_EQ(o.ramp_up_s, 0);
  EXPECT_TRUE(o.measure_from_start);
  EXPECT_EQ(o.join_timeout_s, 0);
  EXPECT_EQ(o.duration_s, 30);
  EXPECT_EQ(o.behavior, Behavior::kMixed);
  EXPECT_EQ(o.spread, 512);
}

TEST(BotsPresets, HotspotBotsConvergeOnTheSpawn) {
  const BotsOptions o = with_preset({"--preset", "hotspot"});
  EXPECT_EQ(o.behavior, Behavior::kHotspot);
  EXPECT_EQ(o.bots, 100);
  EXPECT_EQ(o.spread, 256);
  EXPECT_EQ(o.ramp_up_s, 10);
  EXPECT_EQ(o.duration_s, 60);
  EXPECT_EQ(o.edit_interval_s, 2);
}

TEST(BotsPresets, TeleportAndItsAliasFlyersJumpWithinTheServersBudget) {
  for (const char* name : {"teleport", "flyers"}) {
    const BotsOptions o = with_preset({"--preset", name});
    EXPECT_EQ(o.preset, "teleport") << name;
    EXPECT_EQ(o.behavior, Behavior::kTeleport);
    EXPECT_EQ(o.bots, 50);
    EXPECT_EQ(o.teleport_interval_s, 5);
    EXPECT_EQ(o.teleport_distance, 1024);
    // Within the default --max-speed 256's budget for the interval, and
    // beyond twice the view distance: every jump leaves the whole view.
    EXPECT_LE(o.teleport_distance, 256 * o.teleport_interval_s + 48);
    EXPECT_GT(o.teleport_distance, 2 * o.view_distance);
  }
}

TEST(BotsPresets, BuildersWriteTheLargestRawBoxes) {
  const BotsOptions o = with_preset({"--preset", "builders"});
  EXPECT_EQ(o.behavior, Behavior::kBuild);
  EXPECT_EQ(o.edit_shape, EditShape::kWriteBox);
  EXPECT_EQ(o.edit_radius, 16);  // boxes of 16 to 32 a side: up to 32^3, write_box's limit
  EXPECT_EQ(o.bots, 50);
}

// scripts/bots-scale.sh runs these two: the values it ran with before it
// used the presets.
TEST(BotsPresets, CrowdIsTheScaleScriptsCrowd) {
  const BotsOptions o = with_preset({"--preset", "crowd", "--bots", "500"});
  EXPECT_EQ(o.bots, 500);
  EXPECT_EQ(o.behavior, Behavior::kMixed);
  EXPECT_EQ(o.spread, 512);
  EXPECT_EQ(o.ramp_up_s, 20);
  EXPECT_EQ(o.join_timeout_s, 0);
  EXPECT_FALSE(o.measure_from_start);
  EXPECT_EQ(o.duration_s, 60);
  EXPECT_EQ(o.view_distance, 512);
  EXPECT_EQ(o.full_res_radius, 64);
  EXPECT_EQ(o.edit_interval_s, 2);
  EXPECT_EQ(o.edit_radius, 3);
  EXPECT_EQ(o.edit_shape, EditShape::kMixed);
  EXPECT_EQ(o.seed, 1u);
}

TEST(BotsPresets, WorldKeepsItsDensityWhateverTheNumberOfBots) {
  struct Case {
    int bots, spread;
    double ramp_up_s;
  };
  // spread = 3072 sqrt(N / 1000) truncated (awk's printf %d), ramp-up (N + 4) / 5.
  for (const Case c : {Case{1000, 3072, 200}, Case{250, 1536, 50}, Case{2000, 4344, 400}, Case{7, 257, 2}}) {
    const BotsOptions o = with_preset({"--bots", std::to_string(c.bots), "--preset", "world"});
    EXPECT_EQ(o.spread, c.spread) << c.bots;
    EXPECT_EQ(o.ramp_up_s, c.ramp_up_s) << c.bots;
    EXPECT_EQ(o.join_timeout_s, 600);
    EXPECT_EQ(o.duration_s, 60);
    EXPECT_EQ(o.view_distance, 512);
    EXPECT_EQ(o.full_res_radius, 64);
    EXPECT_EQ(o.edit_interval_s, 2);
    EXPECT_EQ(o.edit_radius, 3);
    EXPECT_EQ(o.behavior, Behavior::kMixed);
  }
  EXPECT_EQ(with_preset({"--preset", "world"}).bots, 1000);
}

// Every preset's listed values parse, and --list-presets shows each.
TEST(BotsPresets, EveryPresetIsValidAndListedWithItsDefaults) {
  const std::string text = presets_text();
  for (const Preset& p : presets()) {
    BotsOptions o;
    EXPECT_EQ(parse_flags({"--connect", "h:1", "--preset", p.name}, &o), "") << p.name;
    EXPECT_EQ(o.bots, p.default_bots);
    const auto at = text.find(std::string("\n  ") + p.name + ": ");
    ASSERT_NE(at, std::string::npos) << p.name;
    const std::string entry = text.substr(at, text.find("\n\n", at + 1) - at);
    for (const auto& [k, v] : p.values(p.default_bots))
      EXPECT_NE(entry.find(k + " = " + v), std::string::npos) << p.name << ": " << k;
  }
}

// Flags and scenario lines win over the preset, wherever they stand on
// the command line; the command line's preset wins over the file's.
TEST(BotsPresets, FlagsAndScenarioLinesOverrideThePreset) {
  for (const auto& args : std::vector<std::vector<std::string>>{
           {"--preset", "crowd", "--spread", "100", "--bots", "7", "--edit-shape", "sphere"},
           {"--spread", "100", "--bots", "7", "--edit-shape", "sphere", "--preset", "crowd"}}) {
    const BotsOptions o = with_preset(args);
    EXPECT_EQ(o.spread, 100);
    EXPECT_EQ(o.bots, 7);
    EXPECT_EQ(o.edit_shape, EditShape::kSphere);
    EXPECT_EQ(o.ramp_up_s, 20);  // the preset's, not given
  }
  const fs::path file = fs::temp_directory_path() / ("terrane-bots-preset-" + std::to_string(::getpid()));
  std::ofstream(file) << "preset = world\nspread = 10\nbots = 100\n";
  BotsOptions o = with_preset({"--scenario", file.string(), "--bots", "250"});
  EXPECT_EQ(o.preset, "world");
  EXPECT_EQ(o.spread, 10);       // the file's line
  EXPECT_EQ(o.bots, 250);        // the flag
  EXPECT_EQ(o.ramp_up_s, 50);    // the preset's, for the flag's bots
  o = with_preset({"--scenario", file.string(), "--preset", "hotspot"});
  EXPECT_EQ(o.preset, "hotspot");
  EXPECT_EQ(o.behavior, Behavior::kHotspot);
  EXPECT_EQ(o.spread, 10);  // the file's line still wins over the preset
  EXPECT_EQ(o.bots, 100);
  fs::remove(file);
}

// --save-scenario after a preset writes the resolved values: read back,
// alone, they are the same options.
TEST(BotsPresets, ASavedScenarioHoldsThePresetsResolvedValues) {
  const BotsOptions o = with_preset({"--preset", "world", "--bots", "250", "--edit-shape", "write-box",
                                     "--teleport-interval", "3", "--teleport-distance", "700"});
  const std::string text = scenario_text(o);
  for (const char* line : {"preset = world\n", "bots = 250\n", "spread = 1536\n", "ramp-up = 50\n", "wait-joined = 600\n",
                           "edit-shape = write-box\n", "teleport-interval = 3\n", "teleport-distance = 700\n"})
    EXPECT_NE(text.find(line), std::string::npos) << line << text;
  OptionValues kv;
  ASSERT_EQ(parse_scenario_text(text, "saved", &kv), "");
  BotsOptions again;
  ASSERT_EQ(apply_option_values(kv, &again), "");
  EXPECT_EQ(scenario_text(again), text);
  EXPECT_EQ(again.spread, 1536);
  EXPECT_EQ(again.edit_shape, EditShape::kWriteBox);
  // Through the file, as terrane-bots reads it.
  const fs::path file = fs::temp_directory_path() / ("terrane-bots-saved-" + std::to_string(::getpid()));
  std::ofstream(file) << text;
  BotsOptions read;
  ASSERT_EQ(parse_flags({"--scenario", file.string()}, &read), "");
  EXPECT_EQ(scenario_text(read), text);
  fs::remove(file);
}

TEST(BotsPresets, AnUnknownPresetIsNamedWithTheKnownOnes) {
  BotsOptions o;
  const std::string known = "join-storm, hotspot, teleport, builders, crowd, world (flyers is teleport)";
  EXPECT_EQ(parse_flags({"--connect", "h:1", "--preset", "stampede"}, &o),
            "--preset: 'stampede' is not a preset; known: " + known);
  OptionValues kv;
  ASSERT_EQ(parse_scenario_text("bots = 3\npreset = stampede\n", "s.txt", &kv), "");
  EXPECT_EQ(apply_option_values(kv, &o), "s.txt:2: preset: 'stampede' is not a preset; known: " + known);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--edit-shape", "cone"}, &o).find("--edit-shape: 'cone'"),
            std::string::npos);
  EXPECT_NE(parse_flags({"--connect", "h:1", "--teleport-interval", "0"}, &o).find("--teleport-interval: '0'"),
            std::string::npos);
  // A flag that contradicts a preset's value is refused as it would be without it.
  EXPECT_NE(parse_flags({"--connect", "h:1", "--preset", "world", "--measure-from", "start"}, &o).find("give one"),
            std::string::npos);
}

int run_binary(const std::string& args, std::string* output) {
  output->clear();
  return testing_support::run_command(std::string(TERRANE_BIN_DIR) + "/terrane-bots " + args, output);
}

TEST(BotsPresets, TheBinaryListsThePresetsAndRefusesAnUnknownOne) {
  std::string out;
  EXPECT_EQ(run_binary("--connect 127.0.0.1:1 --preset stampede", &out), 2);
  EXPECT_NE(out.find("--preset: 'stampede' is not a preset; known: join-storm, hotspot"), std::string::npos) << out;
  EXPECT_EQ(run_binary("--list-presets", &out), 0);
  for (const Preset& p : presets()) EXPECT_NE(out.find(std::string("  ") + p.name + ": "), std::string::npos) << out;
  EXPECT_EQ(run_binary("--help", &out), 0);
  EXPECT_NE(out.find("open loop"), std::string::npos) << out;
  EXPECT_NE(out.find("  join-storm: "), std::string::npos) << out;
}

}  // namespace
}  // namespace terrane::bots
