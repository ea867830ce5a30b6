#include "client/bots/options.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>

#include "client/bots/presets.h"
#include "common/cli/cli.h"
#include "protocol/messages.h"
#include "protocol/tokens_file.h"

namespace terrane::bots {

const char* const kBotsHelp =
    "usage: terrane-bots --connect HOST:PORT [--preset NAME] [options]\n"
    "       terrane-bots --list-presets\n"
    "       terrane-bots compare A.json B.json [--html A_VS_B.html]\n"
    "       terrane-bots merge PART.json... --report ALL.json [--html ALL.html]\n"
    "\n"
    "Runs N headless bots in one process against a terrane-server, each with its own replica,\n"
    "and reports what replication cost and whether every replica stayed right.\n"
    "\n"
    "Exit status:\n"
    "  0  the run passed, and every threshold held\n"
    "  1  the run failed: replica mismatches, unexpected disconnects, failed connections or\n"
    "     joins, no edit acknowledged, the server unreachable, or a file that could not be\n"
    "     read or written (whatever the thresholds)\n"
    "  2  bad usage: an unknown or malformed flag, scenario line or threshold expression\n"
    "  3  the run was sound but a threshold was broken (each is named with its value)\n"
    "\n"
    "  --connect HOST:PORT       server address (required); several, comma-separated, for the\n"
    "                            servers of one shared world (terrane-server --store\n"
    "                            postgresql://...): bot i connects to the (i mod n)-th, and the\n"
    "                            report splits edit fan-out by whether the receiver is on the\n"
    "                            editor's server\n"
    "  --bots N                  bots (default 10)\n"
    "  --duration S              seconds from the first connection to the end of edits (default 30)\n"
    "  --preset NAME             start from a named scenario's defaults: join-storm, hotspot,\n"
    "                            teleport (or flyers), builders, crowd, world (the list below,\n"
    "                            and terrane-bots --list-presets); flags and scenario lines\n"
    "                            given besides override them\n"
    "  --list-presets            describe each preset with its defaults\n"
    "  --behavior B              idle | walk | fly | dig | build | mixed | teleport | hotspot\n"
    "                            (default mixed):\n"
    "                              walk   moves along the surface (5 voxels/s) inside its full-resolution\n"
    "                                     region, never through solid ground\n"
    "                              fly    travels at 40 voxels/s above the terrain (stresses streaming)\n"
    "                              dig    digs spheres and boxes at ray-cast targets\n"
    "                              build  builds spheres and boxes at ray-cast targets\n"
    "                              mixed  60% walk, 30% idle, 10% fly; every bot edits: dig or build\n"
    "                                     (even odds), sphere 80% / box 20%\n"
    "                              teleport  every --teleport-interval jumps --teleport-distance\n"
    "                                     voxels to a random point within that distance of the spawn,\n"
    "                                     8 voxels above it, so the server streams a whole new view;\n"
    "                                     edits (dig or build) between jumps\n"
    "                              hotspot  flies from its start to the spawn (--spawn), lands on\n"
    "                                     the ground there and stays, editing (dig or build) around it\n"
    "                            Edits are sent open loop: each editing bot sends at its own rate\n"
    "                            (--edit-interval, Poisson) whatever the replies, never waiting\n"
    "                            for an ack; only an edit due while 8 of the bot's edits are\n"
    "                            unanswered is not sent (the server queues 64 per client;\n"
    "                            the report counts them: edits_held_back)\n"
    "  --spawn X,Y,Z             centre of the start area (default: the server's spawn)\n"
    "  --spread R                bots start spread over an R x R square around the spawn (default 0)\n"
    "  --view-distance N         voxels (default 256; the server caps it)\n"
    "  --full-res-radius N       voxels (default 64; the server caps it)\n"
    "  --ramp-up S               connections spread over S seconds; latency samples of edits sent\n"
    "                            before S are not counted (default 0)\n"
    "  --seed N                  random seed: positions, roles, edits (default 1)\n"
    "  --token T                 auth token for the server, the same for every bot\n"
    "  --token-file FILE         read that token from FILE (its first line), so it is on no\n"
    "                            command line\n"
    "  --name-prefix P           bot i joins as P followed by i (default bot-: bot-0, bot-1, ...);\n"
    "                            a server with a tokens file needs a line 'bot-I TOKEN' for each\n"
    "  --tokens-file FILE        bot i joins as the i-th player line of FILE, a tokens file as\n"
    "                            terrane-server reads it ('NAME TOKEN [player|admin]', admin\n"
    "                            lines skipped): each bot its own name and token; FILE needs a\n"
    "                            player line for every bot (not with --token, --token-file or\n"
    "                            --name-prefix)\n"
    "  --server-metrics HOST:PORT\n"
    "                            the server's metrics endpoint (terrane-server --metrics): the\n"
    "                            report adds the server's CPU, peak RSS, tick and commit times,\n"
    "                            edits and bytes by message type over the run, and per second\n"
    "                            in the JSON timeline\n"
    "  --edit-interval S         mean seconds between edits per editing bot (default 2)\n"
    "  --edit-radius R           largest sphere radius, boxes up to 2R on a side (default 3, max 32)\n"
    "  --edit-shape S            mixed (default: sphere 80%, box 20%) | sphere | box (fill_box,\n"
    "                            one material) | write-box (write_box: raw voxels of patterned\n"
    "                            materials, R to 2R a side, at most 32^3 voxels)\n"
    "  --teleport-interval S     seconds between a teleporting bot's jumps (default 5)\n"
    "  --teleport-distance N     voxels a jump goes (default 1024); the server drops a bot whose\n"
    "                            jump is over its budget: --max-speed (256) x the interval + 48\n"
    "  --latency-ms N            emulated downstream latency per bot (default 0)\n"
    "  --bandwidth-kbps N        emulated downstream cap per bot, kilobits/s (default 0: none)\n"
    "  --hash-checks N           region-hash checks per bot during the run, at least (default 5);\n"
    "                            every bot also checks its whole full-resolution region at the end\n"
    "  --quiet S                 pause after the last edit ack before the final check (default 1)\n"
    "  --wait-joined S           start the duration once every bot has joined (coarse view and\n"
    "                            full-resolution region), waiting at most S seconds after the\n"
    "                            ramp-up; latencies count from then (default 0: the duration\n"
    "                            counts from the first connection)\n"
    "  --measure-from WHEN       ramp-up (default): latencies count from the end of the ramp-up;\n"
    "                            start: from the first connection, so edits and their fan-out\n"
    "                            are measured while the bots join (a join wave)\n"
    "  --threads N               io threads shared by all bots (default: one per core)\n"
    "  --shared-chunks N         chunks packed from Full records kept for all bots to share, so\n"
    "                            equal bytes are packed once in this process (default 16 for\n"
    "                            each of its bots, at least 4096; 0: each bot packs its own)\n"
    "  --chunk-cache DIR         keep the bots' chunks in DIR across runs: each bot joins from what\n"
    "                            DIR holds of its view (claimed, so the server sends only what\n"
    "                            changed) and saves its replica there at the end (default: none)\n"
    "  --chunk-cache-mb N        the cache's size at most, MiB; the least recently used regions\n"
    "                            go first (default 1024)\n"
    "  --report FILE.json        write the JSON report\n"
    "  --html FILE.html          write a self-contained HTML report with charts\n"
    "  --scenario FILE           read options from FILE (key=value per line, the flag names);\n"
    "                            flags given on the command line override it\n"
    "  --save-scenario FILE      write the effective options as a scenario file\n"
    "  --progress auto|on|off    live progress line (default auto: only on a terminal)\n"
    "  --threshold EXPR          a goal for the whole run, METRIC OP NUMBER with OP one of\n"
    "                            < <= > >= == != (e.g. fanout_p99<100, mismatches==0,\n"
    "                            rejected_pct<=1); repeatable; the report lists each with its\n"
    "                            value, and a broken one exits 3. Metrics: latencies in ms\n"
    "                            fanout_p50 fanout_p95 fanout_p99 fanout_max\n"
    "                            fanout_other_server_p99 ack_p50 ack_p95 ack_p99 ack_max\n"
    "                            join_coarse_p50 join_coarse_p95 join_coarse_p99 join_full_p50\n"
    "                            join_full_p95 join_full_p99 round_trip_p99 io_lag_p99; counts\n"
    "                            mismatches disconnects connect_failures joins_incomplete\n"
    "                            edits_acked hash_unanswered; rejected_pct (edits rejected, %\n"
    "                            of sent); bytes_per_bot_s (bytes received per bot per second);\n"
    "                            steady_bytes_per_bot_s (the same after each bot's join: the\n"
    "                            byte budget, split by cause in the report).\n"
    "                            With @1s after it (fanout_p99<100@1s) the goal holds in every\n"
    "                            measured second that has a value: fanout_*, ack_*,\n"
    "                            round_trip_p99, bytes_per_bot_s; the worst second is reported.\n"
    "  --shard I/N               run part I (from 0) of N of the scenario: the bots i with\n"
    "                            i mod N == I, each with the start, role and seed it has when\n"
    "                            one process runs all --bots (N processes, on as many machines,\n"
    "                            run the whole scenario; merge their reports with\n"
    "                            terrane-bots merge)\n"
    "  --help                    this text\n"
    "\n"
    "terrane-bots merge PART.json... --report ALL.json [--html ALL.html] combines the reports of\n"
    "the parts of one sharded run: counts add up, latency histograms merge (percentiles of the\n"
    "whole run, not averages), per second too; thresholds are evaluated again on the whole.\n";

namespace {

using Values = OptionValues;

const std::set<std::string>& value_keys() {
  static const std::set<std::string> k = {
      "connect",        "bots",         "duration",    "behavior",     "spawn",         "spread",
      "view-distance",  "full-res-radius", "ramp-up",  "seed",         "token",   "token-file", "tokens-file", "name-prefix",       "server-metrics", "edit-interval",
      "edit-radius",    "latency-ms",   "bandwidth-kbps", "hash-checks", "quiet",        "wait-joined",  "measure-from", "threads",     "shared-chunks", "chunk-cache", "chunk-cache-mb",
      "report",         "html",         "save-scenario", "progress",   "scenario",     "threshold",
      "shard",          "preset",       "edit-shape",  "teleport-interval", "teleport-distance"};
  return k;
}

std::string bad(const std::string& where, const std::string& value, const std::string& what) {
  return where + ": '" + value + "' " + what;
}

bool parse_i64(const std::string& s, std::int64_t* v) {
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *v);
  return ec == std::errc() && p == s.data() + s.size();
}

bool parse_f64(const std::string& s, double* v) {
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *v);
  return ec == std::errc() && p == s.data() + s.size() && std::isfinite(*v);
}

}  // namespace

const char* behavior_name(Behavior b) {
  switch (b) {
    case Behavior::kIdle: return "idle";
    case Behavior::kWalk: return "walk";
    case Behavior::kFly: return "fly";
    case Behavior::kDig: return "dig";
    case Behavior::kBuild: return "build";
    case Behavior::kMixed: return "mixed";
    case Behavior::kTeleport: return "teleport";
    case Behavior::kHotspot: return "hotspot";
  }
  return "?";
}

bool behavior_edits(Behavior b) {
  return b != Behavior::kIdle && b != Behavior::kWalk && b != Behavior::kFly;
}

const char* edit_shape_name(EditShape s) {
  switch (s) {
    case EditShape::kMixed: return "mixed";
    case EditShape::kSphere: return "sphere";
    case EditShape::kBox: return "box";
    case EditShape::kWriteBox: return "write-box";
  }
  return "?";
}

std::string parse_scenario_text(const std::string& text, const std::string& source, Values* out) {
  std::istringstream in(text);
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    const std::string where = source + ":" + std::to_string(n);
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    line = trim_blanks(line);
    if (line.empty()) continue;
    const auto eq = line.find('=');
    if (eq == std::string::npos) return where + ": expected key=value, got '" + line + "'";
    std::string key = trim_blanks(line.substr(0, eq));
    const std::string value = trim_blanks(line.substr(eq + 1));
    if (key.rfind("--", 0) == 0) key = key.substr(2);
    if (value_keys().count(key) == 0 || key == "scenario") return where + ": unknown key '" + key + "'";
    out->emplace(key, std::make_pair(value, where + ": " + key));
  }
  return "";
}

std::string apply_option_values(const Values& given, BotsOptions* o) {
  Values values;
  if (auto err = expand_preset(given, &values); !err.empty()) return err;
  bool thresholds_given = false, token_given = false, prefix_given = false;
  for (const auto& [key, vw] : values) {
    const std::string& v = vw.first;
    const std::string& where = vw.second;
    std::int64_t i = 0;
    double d = 0;
    auto int_in = [&](std::int64_t lo, std::int64_t hi, auto* field) -> std::string {
      if (!parse_i64(v, &i) || i < lo || i > hi)
        return bad(where, v, "is not an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
      *field = static_cast<std::remove_pointer_t<decltype(field)>>(i);
      return "";
    };
    auto num_in = [&](double lo, double hi, auto* field) -> std::string {
      if (!parse_f64(v, &d) || d < lo || d > hi) {
        std::ostringstream r;
        r << "is not a number in [" << lo << ", " << hi << "]";
        return bad(where, v, r.str());
      }
      *field = static_cast<std::remove_pointer_t<decltype(field)>>(d);
      return "";
    };
    std::string err;
    if (key == "connect") {
      o->servers.clear();
      std::size_t start = 0;
      while (start <= v.size()) {
        const std::size_t comma = std::min(v.find(',', start), v.size());
        const std::string one = v.substr(start, comma - start);
        const auto hp = parse_host_port(one);
        if (!hp || hp->second == 0) return bad(where, v, "is not HOST:PORT[,HOST:PORT...] (port 1..65535)");
        o->servers.emplace_back(hp->first, hp->second);
        start = comma + 1;
      }
      o->host = o->servers.front().first;
      o->port = o->servers.front().second;
    } else if (key == "server-metrics") {
      const auto hp = parse_host_port(v);
      if (!hp || hp->second == 0) return bad(where, v, "is not HOST:PORT (port 1..65535)");
      o->metrics_host = hp->first;
      o->metrics_port = hp->second;
    } else if (key == "bots") {
      err = int_in(1, 100000, &o->bots);
    } else if (key == "duration") {
      err = num_in(0.5, 86400, &o->duration_s);
    } else if (key == "behavior") {
      bool found = false;
      for (Behavior b : {Behavior::kIdle, Behavior::kWalk, Behavior::kFly, Behavior::kDig, Behavior::kBuild,
                         Behavior::kMixed, Behavior::kTeleport, Behavior::kHotspot})
        if (v == behavior_name(b)) o->behavior = b, found = true;
      if (!found) return bad(where, v, "is not one of idle, walk, fly, dig, build, mixed, teleport, hotspot");
    } else if (key == "preset") {
      const Preset* p = find_preset(v);
      if (p == nullptr) return bad(where, v, "is not a preset; known: " + preset_names());
      o->preset = p->name;
    } else if (key == "edit-shape") {
      bool found = false;
      for (EditShape e : {EditShape::kMixed, EditShape::kSphere, EditShape::kBox, EditShape::kWriteBox})
        if (v == edit_shape_name(e)) o->edit_shape = e, found = true;
      if (!found) return bad(where, v, "is not one of mixed, sphere, box, write-box");
    } else if (key == "teleport-interval") {
      err = num_in(0.5, 3600, &o->teleport_interval_s);
    } else if (key == "teleport-distance") {
      err = int_in(1, 1 << 20, &o->teleport_distance);
    } else if (key == "spawn") {
      std::int32_t xyz[3];
      if (!parse_int_list<std::int32_t>(v, xyz, 3) || std::abs(xyz[0]) > (1 << 24) || std::abs(xyz[1]) > (1 << 24) ||
          std::abs(xyz[2]) > (1 << 24))
        return bad(where, v, "is not X,Y,Z (integers within +-2^24)");
      o->spawn = {xyz[0], xyz[1], xyz[2]};
      o->spawn_set = true;
    } else if (key == "spread") {
      err = int_in(0, 1 << 20, &o->spread);
    } else if (key == "view-distance") {
      err = int_in(1, 65536, &o->view_distance);
    } else if (key == "full-res-radius") {
      err = int_in(1, 65536, &o->full_res_radius);
    } else if (key == "ramp-up") {
      err = num_in(0, 86400, &o->ramp_up_s);
    } else if (key == "seed") {
      if (!parse_i64(v, &i) || i < 0) return bad(where, v, "is not a non-negative integer");
      o->seed = static_cast<std::uint64_t>(i);
    } else if (key == "token") {
      if (v.size() > kMaxAuthTokenBytes) return bad(where, v.substr(0, 16) + "...", "is longer than 256 bytes");
      o->token = v;
      token_given = true;
    } else if (key == "token-file") {
      std::ifstream f(v);
      std::string first;
      if (!f || !std::getline(f, first)) return bad(where, v, "cannot be read");
      first = trim_blanks(first);
      if (first.empty()) return bad(where, v, "has no token on its first line");
      if (first.size() > kMaxAuthTokenBytes) return bad(where, v, "holds a token longer than 256 bytes");
      o->token = first;
      o->token_file = v;
    } else if (key == "name-prefix") {
      // Room for the largest index's digits within a Hello's name.
      if (v.empty() || v.size() > kMaxClientNameBytes - 6 || v.find_first_of(" \t") != std::string::npos)
        return bad(where, v, "is not a name prefix (1 to 58 bytes, no blanks)");
      o->name_prefix = v;
      prefix_given = true;
    } else if (key == "tokens-file") {
      auto entries = read_tokens_file(v);
      if (!entries) return where + ": " + entries.error().message;
      o->players.clear();
      for (const TokensFileEntry& e : *entries)
        if (!e.admin) o->players.emplace_back(e.name, e.token);
      o->tokens_file = v;
    } else if (key == "edit-interval") {
      err = num_in(0.01, 86400, &o->edit_interval_s);
    } else if (key == "edit-radius") {
      err = num_in(0.5, 32, &o->edit_radius);
    } else if (key == "latency-ms") {
      err = int_in(0, 60000, &o->latency_ms);
    } else if (key == "bandwidth-kbps") {
      err = int_in(0, 100000000, &o->bandwidth_kbps);
    } else if (key == "hash-checks") {
      err = int_in(0, 100000, &o->hash_checks);
    } else if (key == "quiet") {
      err = num_in(0, 600, &o->quiet_s);
    } else if (key == "wait-joined") {
      err = num_in(0, 86400, &o->join_timeout_s);
    } else if (key == "measure-from") {
      if (v != "ramp-up" && v != "start") return bad(where, v, "is not ramp-up or start");
      o->measure_from_start = v == "start";
    } else if (key == "threads") {
      err = int_in(0, 256, &o->threads);
    } else if (key == "shared-chunks") {
      err = int_in(0, 1000000, &o->shared_chunks);
    } else if (key == "chunk-cache") {
      if (v.empty()) return bad(where, v, "is empty (a directory)");
      o->chunk_cache_dir = v;
    } else if (key == "chunk-cache-mb") {
      err = int_in(1, 1 << 20, &o->chunk_cache_mb);
    } else if (key == "report") {
      o->report_path = v;
    } else if (key == "html") {
      o->html_path = v;
    } else if (key == "save-scenario") {
      o->save_scenario_path = v;
    } else if (key == "threshold") {
      if (!thresholds_given) o->thresholds.clear();
      thresholds_given = true;
      Threshold t;
      if (auto e = parse_threshold(v, &t); !e.empty()) return where + ": " + e;
      o->thresholds.push_back(t);
    } else if (key == "shard") {
      const auto slash = v.find('/');
      std::int64_t index = -1, count = 0;
      if (slash == std::string::npos || !parse_i64(v.substr(0, slash), &index) ||
          !parse_i64(v.substr(slash + 1), &count) || count < 1 || count > 100000 || index < 0 || index >= count)
        return bad(where, v, "is not I/N with 0 <= I < N (the I-th of N parts, counted from 0)");
      o->shard_index = static_cast<int>(index);
      o->shard_count = static_cast<int>(count);
    } else if (key == "progress") {
      if (v != "auto" && v != "on" && v != "off") return bad(where, v, "is not auto, on or off");
      o->progress = v;
    }
    if (!err.empty()) return err;
  }
  if (token_given && !o->token_file.empty()) return "--token and --token-file: give one of them";
  if (!o->tokens_file.empty()) {
    if (token_given || !o->token_file.empty() || prefix_given)
      return "--tokens-file: gives each bot its name and token; not with --token, --token-file or --name-prefix";
    if (static_cast<int>(o->players.size()) < o->bots)
      return "--tokens-file: " + o->tokens_file + " has " + std::to_string(o->players.size()) +
             " player lines for " + std::to_string(o->bots) + " bots (bot i joins as the i-th)";
  }
  if (o->shard_count > o->bots)
    return "--shard: " + std::to_string(o->shard_count) + " parts of " + std::to_string(o->bots) +
           " bots leave a part without bots";
  if (o->measure_from_start && o->join_timeout_s > 0)
    return "--measure-from start: measures while the bots join, --wait-joined after; give one of them";
  if (o->ramp_up_s >= o->duration_s && o->join_timeout_s <= 0)
    return "--ramp-up: must be shorter than --duration (or give --wait-joined, which starts the duration after the joins)";
  return "";
}

BotLogin bot_login(const BotsOptions& o, int i) {
  if (!o.players.empty()) {
    const auto& p = o.players[static_cast<std::size_t>(i) % o.players.size()];
    return {p.first, p.second};
  }
  return {o.name_prefix + std::to_string(i), o.token};
}

int io_threads(const BotsOptions& o) {
  return o.threads > 0 ? o.threads : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

std::size_t shared_chunks_for(const BotsOptions& o) {
  if (o.shared_chunks >= 0) return static_cast<std::size_t>(o.shared_chunks);
  return std::max<std::size_t>(4096, 16 * static_cast<std::size_t>(shard_bots(o)));
}

double hash_check_span_s(const BotsOptions& o) {
  const double window =
      o.join_timeout_s > 0 || o.measure_from_start ? o.duration_s : o.duration_s - o.ramp_up_s;
  return std::clamp(window / (o.hash_checks + 1), 0.2, 10.0);
}

std::string parse_bots_options(int argc, char** argv, int first, BotsOptions* out, bool* help, bool* list_presets) {
  Values flags;
  std::string scenario;
  *help = false;
  if (list_presets != nullptr) *list_presets = false;
  for (int a = first; a < argc; ++a) {
    std::string arg = argv[a];
    if (arg == "--help" || arg == "-h") {
      *help = true;
      return "";
    }
    if (arg == "--list-presets" && list_presets != nullptr) {
      *list_presets = true;
      return "";
    }
    if (arg.rfind("--", 0) != 0) return "unexpected argument '" + arg + "'";
    std::string key = arg.substr(2), value;
    if (auto eq = key.find('='); eq != std::string::npos) {
      value = key.substr(eq + 1);
      key.resize(eq);
    } else {
      if (value_keys().count(key) == 0) return "unknown option --" + key;
      if (a + 1 >= argc) return "--" + key + ": missing value";
      value = argv[++a];
    }
    if (value_keys().count(key) == 0) return "unknown option --" + key;
    if (key == "scenario")
      scenario = value;
    else
      flags.emplace(key, std::make_pair(value, "--" + key));
  }
  Values values;
  if (!scenario.empty()) {
    std::ifstream f(scenario);
    if (!f) return "--scenario: cannot read '" + scenario + "'";
    std::stringstream text;
    text << f.rdbuf();
    if (auto err = parse_scenario_text(text.str(), scenario, &values); !err.empty()) return err;
  }
  for (const auto& [k, v] : flags) values.erase(k);  // the command line wins
  values.insert(flags.begin(), flags.end());
  if (values.count("connect") == 0) return "--connect HOST:PORT is required";
  return apply_option_values(values, out);
}

std::string scenario_text(const BotsOptions& o) {
  std::ostringstream s;
  s << "# terrane-bots scenario (terrane-bots --scenario FILE)\n";
  // The preset's name is kept for the record; every value below wins over it.
  if (!o.preset.empty()) s << "preset = " << o.preset << "\n";
  s << "connect = ";
  for (std::size_t i = 0; i < o.servers.size(); ++i) s << (i ? "," : "") << o.servers[i].first << ":" << o.servers[i].second;
  if (o.servers.empty()) s << o.host << ":" << o.port;
  s << "\n";
  s << "bots = " << o.bots << "\n";
  s << "duration = " << o.duration_s << "\n";
  s << "behavior = " << behavior_name(o.behavior) << "\n";
  if (o.spawn_set) s << "spawn = " << o.spawn.x << "," << o.spawn.y << "," << o.spawn.z << "\n";
  s << "spread = " << o.spread << "\n";
  s << "view-distance = " << o.view_distance << "\n";
  s << "full-res-radius = " << o.full_res_radius << "\n";
  s << "ramp-up = " << o.ramp_up_s << "\n";
  s << "seed = " << o.seed << "\n";
  if (!o.tokens_file.empty())
    s << "tokens-file = " << o.tokens_file << "\n";
  else if (!o.token_file.empty())
    s << "token-file = " << o.token_file << "\n";
  else if (!o.token.empty())
    s << "token = " << o.token << "\n";
  if (o.tokens_file.empty()) s << "name-prefix = " << o.name_prefix << "\n";
  if (o.metrics_port != 0) s << "server-metrics = " << o.metrics_host << ":" << o.metrics_port << "\n";
  s << "edit-interval = " << o.edit_interval_s << "\n";
  s << "edit-radius = " << o.edit_radius << "\n";
  s << "edit-shape = " << edit_shape_name(o.edit_shape) << "\n";
  s << "teleport-interval = " << o.teleport_interval_s << "\n";
  s << "teleport-distance = " << o.teleport_distance << "\n";
  s << "latency-ms = " << o.latency_ms << "\n";
  s << "bandwidth-kbps = " << o.bandwidth_kbps << "\n";
  s << "hash-checks = " << o.hash_checks << "\n";
  s << "quiet = " << o.quiet_s << "\n";
  s << "wait-joined = " << o.join_timeout_s << "\n";
  s << "measure-from = " << (o.measure_from_start ? "start" : "ramp-up") << "\n";
  s << "threads = " << o.threads << "\n";
  if (o.shared_chunks >= 0) s << "shared-chunks = " << o.shared_chunks << "\n";
  if (!o.chunk_cache_dir.empty()) s << "chunk-cache = " << o.chunk_cache_dir << "\n";
  s << "chunk-cache-mb = " << o.chunk_cache_mb << "\n";
  for (const Threshold& t : o.thresholds) s << "threshold = " << t.expression << "\n";
  if (o.shard_count > 1) s << "shard = " << o.shard_index << "/" << o.shard_count << "\n";
  return s.str();
}

}  // namespace terrane::bots
