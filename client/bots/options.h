// terrane-bots options: one struct filled from a scenario file (key=value
// lines, the flag names without "--") and then the command line, which
// overrides the file. Every error names the flag (or file and line) and the
// value. Thread-safety: plain data and pure functions.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "client/bots/thresholds.h"
#include "common/voxel/vec3.h"

namespace terrane::bots {

enum class Behavior : std::uint8_t { kIdle, kWalk, kFly, kDig, kBuild, kMixed, kTeleport, kHotspot };
const char* behavior_name(Behavior b);
// Whether bots of that behaviour edit (a run of them fails with no edit acked).
bool behavior_edits(Behavior b);

// The shape of the bots' edits (--edit-shape): spheres and uniform boxes
// (fill_box) at 80 / 20 %, or one of them, or boxes of raw voxels
// (write_box) of edit_radius to 2 x edit_radius a side, at most
// kMaxRawBoxVolume.
enum class EditShape : std::uint8_t { kMixed, kSphere, kBox, kWriteBox };
const char* edit_shape_name(EditShape s);

struct BotsOptions {
  std::string host = "127.0.0.1";
  std::uint16_t port = 0;  // required (--connect): the first server
  // Every server given (--connect A,B,C: servers of one shared world); bot
  // i connects to servers[i % size].
  std::vector<std::pair<std::string, std::uint16_t>> servers;
  int bots = 10;
  double duration_s = 30;
  Behavior behavior = Behavior::kMixed;
  bool spawn_set = false;  // else the server's spawn (Welcome)
  Vec3i spawn;
  int spread = 0;  // bots start spread over a square of this side around the spawn (voxels)
  int view_distance = 256;
  int full_res_radius = 64;
  double ramp_up_s = 0;   // connections spread over this; latency samples before it end are not counted
  // ... unless measure_from_start: every sample counts from the first
  // connection (a join wave: edits and their fan-out while bots join).
  bool measure_from_start = false;
  std::uint64_t seed = 1;
  // Who the bots join as (bot_login): bot i is name_prefix + i with the one
  // token (--token, or --token-file: read from a file, so that it is on no
  // command line), or the i-th player line of a tokens file (--tokens-file,
  // the server's format: each bot its own name and token).
  std::string token;
  std::string token_file;
  std::string name_prefix = "bot-";
  std::string tokens_file;
  std::vector<std::pair<std::string, std::string>> players;  // tokens_file's player lines: name, token
  // The server's metrics endpoint (terrane-server --metrics): "" = none.
  std::string metrics_host;
  std::uint16_t metrics_port = 0;
  double edit_interval_s = 2;  // mean seconds between edits per editing bot (Poisson)
  float edit_radius = 3;       // largest sphere radius (boxes up to 2x this on a side)
  EditShape edit_shape = EditShape::kMixed;
  // Behavior::kTeleport: every teleport_interval_s each bot jumps
  // teleport_distance voxels to a random point within teleport_distance
  // of the spawn (x and z), so the server streams it a whole new view.
  // The server accepts the jump as one move if it is within its budget
  // (terrane-server --max-speed x the interval, plus 48 voxels).
  double teleport_interval_s = 5;
  int teleport_distance = 1024;
  // The preset the options started from (presets.h), "" for none: saved
  // with the resolved values, which win over it when read back.
  std::string preset;
  int latency_ms = 0;          // per-bot downstream latency (client/client.h NetworkEmulation)
  int bandwidth_kbps = 0;      // per-bot downstream cap, kilobits per second
  int hash_checks = 5;         // region-hash checks per bot during the run, at least
  double quiet_s = 1;          // after the last ack, before the final full check
  // > 0: the duration starts once every bot has joined (coarse view and
  // full-resolution region), waiting at most this long after the ramp-up;
  // 0: the duration counts from the first connection.
  double join_timeout_s = 0;
  int threads = 0;             // io threads for all bots; 0: one per core (io_threads)
  // Chunks packed from Full records kept for every bot to share (entries;
  // 0: each bot packs its own; -1, the default: shared_chunks_for()). Bots
  // near one another receive the same records: packing each once halves
  // what they cost this process.
  int shared_chunks = -1;
  // Chunks kept across runs (--chunk-cache DIR, client/chunk_cache.h; empty:
  // none): every bot joins from what it holds of its view and saves its
  // replica there at the end. At most chunk_cache_mb MiB of files.
  std::string chunk_cache_dir;
  int chunk_cache_mb = 1024;
  std::string report_path;     // JSON
  std::string html_path;
  std::string save_scenario_path;
  std::string progress = "auto";  // auto (terminal only), on, off
  // Goals evaluated on the whole run (--threshold, repeatable); the command
  // line's replace a scenario file's.
  std::vector<Threshold> thresholds;
  // --shard I/N: this process runs part I (0 <= I < N) of the scenario,
  // the bots i with i mod N == I, each as it starts when one process runs
  // all `bots` (plan_bots, runner.h); N = 1: every bot.
  int shard_index = 0, shard_count = 1;
};

// The name and token bot i joins with. The probe that reads the server's
// Welcome before the run joins as the shard's first bot (o.shard_index),
// so a server admitting by name needs no line for it.
struct BotLogin {
  std::string name;
  std::string token;
};
BotLogin bot_login(const BotsOptions& o, int i);

// Whether bot i (of all o.bots) is in o's shard.
inline bool in_shard(const BotsOptions& o, int i) { return i % o.shard_count == o.shard_index; }
// How many of o.bots are in o's shard.
inline int shard_bots(const BotsOptions& o) {
  return (o.bots - o.shard_index + o.shard_count - 1) / o.shard_count;
}

// Seconds between a bot's region-hash checks, so that every bot makes at
// least hash_checks of them in the measured run: the duration after the
// last connection (the ramp-up is part of the duration), or the whole
// duration when it starts once every bot has joined (join_timeout_s > 0)
// or when every sample counts from the first connection (measure_from_start).
// Between 0.2 and 10 s.
double hash_check_span_s(const BotsOptions& o);

// The io threads the bots share: threads, or one per core. (Two per core
// were the default while a bot's handler could run for milliseconds: world
// 1,000's bots' io lag p95 was 62-100 ms with one per core, 22-25 ms with
// two, 2026-11-26. With bots that decode and pack a record once per
// process, the extra threads cost more in wake-ups and context switches
// than they saved: crowd 500, 2026-11-30, two runs each way, bots CPU
// 36.5-37.2 s and fan-out p99 41-44 ms with one per core against
// 42.6-44.1 s and 74-110 ms with two; world 1,000 one run each, bots CPU
// 128.5 against 137.6 s, fan-out p99 33.5 against 28.8 ms, io lag p95
// 4.5 against 3.9 ms.)
int io_threads(const BotsOptions& o);

// The shared packed chunks' entries: shared_chunks, or by default 16 per
// bot of this shard and at least 4,096. (A fixed 4,096 kept a third of
// the Full records world 300's bots received shared; 16,384 kept two
// thirds, for 4 % less of the bots' CPU and 3 % more of their peak memory:
// scripts/bots-scale.sh world 300, two runs each way, 2026-12-03.)
std::size_t shared_chunks_for(const BotsOptions& o);

// Parses "terrane-bots [flags]" (argv[first..argc)). Returns "" on success,
// else the error (for exit status 2). Sets *help when --help was given
// (and *list_presets when --list-presets was, if list_presets is given).
std::string parse_bots_options(int argc, char** argv, int first, BotsOptions* out, bool* help,
                               bool* list_presets = nullptr);

// Option values by key: (value, where it was given: "--flag" or
// "FILE:LINE: key"), in the order given. A key given twice keeps both:
// the last wins, except `threshold`, whose values all apply.
using OptionValues = std::multimap<std::string, std::pair<std::string, std::string>>;

// Parses scenario text into key -> (value, "FILE:LINE"). '#' starts a
// comment; blank lines are skipped; "key = value" with optional spaces.
std::string parse_scenario_text(const std::string& text, const std::string& source, OptionValues* out);

// Applies the values to *o; returns the first error. Thresholds given
// replace those *o had. A `preset` value (presets.h) first adds the
// preset's defaults for every key the values do not give: the values win.
std::string apply_option_values(const OptionValues& values, BotsOptions* o);

// The scenario file text that reproduces *o (every key, flags' names).
std::string scenario_text(const BotsOptions& o);

extern const char* const kBotsHelp;

}  // namespace terrane::bots
