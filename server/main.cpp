// terrane-server: the authoritative Terrane world server.
//
//   terrane-server --world DIR [--bind ADDR] [--port N] [options]
//   terrane-server --store postgresql://HOST:PORT/DB --server-id N [options]
//
// Logs `listening on ADDR:PORT` once it accepts connections (and
// "creating a new world at DIR" first when DIR holds none); SIGINT or
// SIGTERM stops it cleanly (sessions told why, world saved). Exit status:
// 0 after a clean stop, 75 after `terrane-admin shutdown --restart` (so a
// supervisor restarting on failure, e.g. Docker's `restart: on-failure`,
// brings it back), 1 when the world cannot be opened (or is missing with
// --no-create, or its disk is short of --min-free-mb), the port bound, or a
// tick's changes could not be saved (the server then stops itself), 2 on
// bad usage (flags, --config file, tokens file).
#include <sys/resource.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <functional>
#include <optional>
#include <string>

#include <asio.hpp>

#include "common/cli/cli.h"
#include "server/net/limits.h"
#include "server/base/log.h"
#include "server/server.h"
#include "server/storage/postgres_store.h"

namespace terrane {
namespace {

// The exit status after `terrane-admin shutdown --restart`: not 0, so a
// supervisor that restarts on failure (Docker's `restart: on-failure`,
// systemd's `Restart=on-failure`) restarts it; 75 is EX_TEMPFAIL ("try
// again").
constexpr int kExitRestart = 75;

constexpr const char* kHelp =
    "usage: terrane-server --world DIR [options]\n"
    "       terrane-server --store postgresql://HOST:PORT/DB --server-id N [options]\n"
    "\n"
    "Serves a Terrane world over TCP (protocol/PROTOCOL.md). DIR is created with the default\n"
    "generated world when it holds none (the log says 'creating a new world at DIR'), unless\n"
    "--no-create. Exit status: 0 after a clean stop (SIGINT, SIGTERM, terrane-admin shutdown),\n"
    "1 when the world cannot be opened or stored or the port bound, 2 on bad usage.\n"
    "\n"
    "  --world DIR                 world directory (SQLite; this or --store is required)\n"
    "  --no-create                 refuse to start (exit 1) when DIR holds no world, rather than\n"
    "                              create one (a restored backup's path mistyped)\n"
    "  --store URL                 the world in PostgreSQL (libpq URL; the database must exist,\n"
    "                              Terrane's tables are made in it), shared with other servers:\n"
    "                              each writes only regions it holds by lease\n"
    "                              (server/storage/STORE_POSTGRESQL.md); --world DIR is the same\n"
    "                              as --store DIR\n"
    "  --server-id N               this server's id in a PostgreSQL world, 0 to 2147483647, one\n"
    "                              per running server (required with a postgresql:// store)\n"
    "  --lease-ms N                how long a region lease lasts without renewal; renewed every\n"
    "                              tenth of it (default 5000)\n"
    "  --advertise HOST:PORT       where clients reach this server, told to the others so they can\n"
    "                              redirect clients here (default: --bind and the port listened on;\n"
    "                              with --bind 0.0.0.0 or :: and no --advertise, none is)\n"
    "  --redirect-margin N         a client whose every region within N voxels another server\n"
    "                              writes is redirected there, keeping what it holds; 0 never\n"
    "                              redirects (default 32, at most 128)\n"
    "  --bind ADDR                 address to listen on (default 127.0.0.1)\n"
    "  --port N                    TCP port; 0 picks a free one (default 0); see the log line\n"
    "                              'listening on ADDR:PORT'\n"
    "  --metrics ADDR:PORT         serve GET /metrics (Prometheus text format) and GET /health\n"
    "                              over HTTP here: 200 'ready' while ticking and storing, 503\n"
    "                              'starting', 'draining' (a shutdown pending) or 'failing' and\n"
    "                              why; port 0 picks a free one (default: off)\n"
    "  --border X0,Z0,X1,Z1        set the world border (kept in the world): nothing is generated,\n"
    "                              streamed or editable outside x0 <= x < x1, z0 <= z < z1;\n"
    "                              'none' removes it (default: the world's, if any); a world in\n"
    "                              PostgreSQL takes a new border only while no other server runs\n"
    "  --tick-hz N                 simulation ticks per second; an edit waits for the next one\n"
    "                              (default 60)\n"
    "  --view-distance N           view distance before a client says (voxels, default 2048)\n"
    "  --full-res-radius N         full-resolution radius before a client says (default 128)\n"
    "  --max-view-distance N       cap on client view distances (default 2048, at most 4096)\n"
    "  --max-full-res-radius N     cap on client full-resolution radii (default 256)\n"
    "  --max-clients N             connections at once (default 1024; the open-file limit is\n"
    "                              raised to fit)\n"
    "  --max-queue-bytes N         per-client send queue; a client further behind is dropped\n"
    "                              (default 16777216)\n"
    "  --stream-window-bytes N     per-client streaming window (default 524288)\n"
    "  --stream-yield-ms N         streaming pauses while work waits longer than N ms on the io\n"
    "                              threads or the world strand, so edits and updates keep\n"
    "                              their pace (default 20; 0: streaming never yields)\n"
    "  --io-threads N              network and replication threads (default 2)\n"
    "  --worker-threads N          chunk loading and generation threads (default 2)\n"
    "  --no-thread-priorities      run every thread at the process's niceness (default: the\n"
    "                              loader threads at +5, below the world, writer and io threads)\n"
    "  --write-timeout-ms N        drop a client whose socket takes no data for this long\n"
    "                              (default 10000)\n"
    "  --socket-send-buffer N      SO_SNDBUF of client sockets in bytes (default: OS default)\n"
    "  --presence-hz N             presence updates per second, 0 = off (default 2)\n"
    "  --presence-max N            nearest clients listed in presence (default 32, at most 64)\n"
    "  --mip-refresh-ms N          refresh the mips a client holds at most this often, with\n"
    "                              their newest bytes (default 500; 0 = every tick)\n"
    "  --hash-push-ms N            push one chunk hash per client this often, 0 = off\n"
    "                              (default 1000)\n"
    "  --exact-horizon             send no estimates: a distant chunk never generated is generated\n"
    "                              whole before its coarse mip is sent (by default its mip is\n"
    "                              first estimated at the mip's resolution, then replaced)\n"
    "  --no-horizon-images         start a new view with each chunk's own 4^3 mip instead of\n"
    "                              whole regions at 2^3 or 1 voxel per chunk (horizon images)\n"
    "  --no-outer-horizon          send every client the horizon images of clients that do not take\n"
    "                              level 6 (1 voxel per 2^3 chunks beyond 1,024 voxels; those that\n"
    "                              do say so in Hello): 2^3 voxels per chunk within a quarter of the\n"
    "                              view, 1 voxel per chunk beyond\n"
    "  --no-mip-patches            refresh a changed mip whole, never as a patch of its changed\n"
    "                              4^3 sub-units (clients that take patches say so in Hello)\n"
    "  --no-presence-records       send whole Presence lists, never PresenceRecords (what changed)\n"
    "  --resident-chunks N         chunks kept loaded beyond those held at full resolution or\n"
    "                              being edited; the least recently used go first (default 32768)\n"
    "  --auth-token T              require this shared token in Hello\n"
    "  --tokens-file FILE          per-player tokens, lines 'NAME TOKEN [player|admin]' ('#'\n"
    "                              comments); admins may run terrane-admin commands; read\n"
    "                              again on SIGHUP (with the bans and whitelist; a bad file\n"
    "                              keeps the previous tokens and the log says why)\n"
    "  --admin-token T             whoever gives this token joins as an admin (terrane-admin);\n"
    "                              at least 8 characters\n"
    "  --open                      serve without authentication on a non-loopback address\n"
    "                              (without tokens the server is open; it refuses to do so\n"
    "                              beyond loopback unless this is given)\n"
    "  --edits-per-second N        per-client edit rate; a flood beyond 2 s of it drops the\n"
    "                              client (default 20)\n"
    "  --max-edit-voxels N         larger edits are rejected (default 262144 = 64^3)\n"
    "  --max-speed N               voxels per second a client may move; faster drops it\n"
    "                              (default 256, 0 = unchecked)\n"
    "  --inbound-bytes-per-second N   per-client inbound rate, burst 4x (default 1048576)\n"
    "  --outbound-bytes-per-second N  per-client streaming rate (default 33554432)\n"
    "  --handshake-timeout-ms N    Hello must arrive within this (default 5000)\n"
    "  --idle-timeout-ms N         drop a client silent this long (default 30000)\n"
    "  --frame-timeout-ms N        drop a client that leaves a frame incomplete this long\n"
    "                              (default 10000)\n"
    "  --history-bytes N           undo/redo history per client in bytes (default 4194304)\n"
    "  --edit-log-days N           keep the edit log (terrane-admin log, rollback) this many days,\n"
    "                              0 = for ever (default 30)\n"
    "  --edit-log-mb N             and at most this many MiB of logged voxels, the oldest going\n"
    "                              first; 0 = no bound (default 1024)\n"
    "  --min-free-mb N             refuse to start when the world directory's file system has\n"
    "                              less than N MiB free (default 64; 0: no check); see the gauge\n"
    "                              terrane_disk_free_bytes\n"
    "  --max-frame-bytes N         largest frame accepted (default 1048576)\n"
    "  --backup-every DURATION     back the world up this often (e.g. 30m, 6h, 1d; a number\n"
    "                              alone is seconds; at least 100ms) with the online backup\n"
    "                              (consistent while the server runs) into --backup-dir, as\n"
    "                              world-YYYYMMDDTHHMMSS.mmmZ (UTC); a world directory only\n"
    "  --backup-dir DIR            where scheduled backups go (required with --backup-every)\n"
    "  --backup-keep N             keep the newest N scheduled backups in DIR, removing older\n"
    "                              ones (default 7); see terrane_backup_last_success_timestamp_seconds\n"
    "  --log-format text|json      log lines as text (default) or one JSON object a line:\n"
    "                              time (local, with its offset), level, logger, message\n"
    "  --log-file PATH             append the log to PATH instead of stdout; SIGHUP reopens it\n"
    "                              at PATH (after logrotate moved it away: no copytruncate)\n"
    "  --log-level LEVEL           the lowest level logged: trace, debug, info, warn, error or off\n"
    "                              (default info; a release build has no debug or trace lines)\n"
    "  --test-drop-updates N       TEST ONLY: silently drop the first N update batches\n"
    "  --test-corrupt-updates N    TEST ONLY: send the first N update batches with one voxel wrong\n"
    "  --config FILE               read options from FILE: 'name = value' per line (names as\n"
    "                              above without --, flags as 'name = true'); the command line\n"
    "                              wins\n"
    "  --help                      this text\n"
    "\n"
    "Exit status: 0 after a clean stop (SIGINT, SIGTERM, terrane-admin shutdown), 75 after\n"
    "terrane-admin shutdown --restart (so a supervisor restarting on failure restarts it:\n"
    "Docker's restart: on-failure, systemd's Restart=on-failure), 1 when the world cannot be\n"
    "opened or stored or the port bound, 2 on bad usage.\n";

// "90", "90s", "500ms", "15m", "6h", "1d" as milliseconds; nullopt if not one.
std::optional<std::int64_t> parse_duration_ms(const std::string& text) {
  std::size_t digits = 0;
  while (digits < text.size() && text[digits] >= '0' && text[digits] <= '9') ++digits;
  if (digits == 0 || digits > 9) return std::nullopt;
  const std::int64_t n = std::stoll(text.substr(0, digits));
  const std::string unit = text.substr(digits);
  if (unit.empty() || unit == "s") return n * 1000;
  if (unit == "ms") return n;
  if (unit == "m") return n * 60'000;
  if (unit == "h") return n * 3'600'000;
  if (unit == "d") return n * 86'400'000;
  return std::nullopt;
}

int usage_error(const std::string& message) {
  std::fprintf(stderr, "terrane-server: %s\n\n%s", message.c_str(), kHelp);
  return 2;
}

int run(int argc, char** argv) {
  CommandLine cl({"world", "store", "server-id", "lease-ms", "advertise", "redirect-margin", "bind", "port", "metrics", "border", "tick-hz", "view-distance", "full-res-radius", "max-view-distance",
                  "max-full-res-radius", "max-clients", "max-queue-bytes", "stream-window-bytes", "stream-yield-ms", "io-threads",
                  "worker-threads", "write-timeout-ms", "socket-send-buffer", "auth-token", "presence-hz", "presence-max", "hash-push-ms", "mip-refresh-ms",
                  "resident-chunks", "tokens-file", "admin-token", "edits-per-second", "max-edit-voxels", "max-speed",
                  "inbound-bytes-per-second", "outbound-bytes-per-second", "handshake-timeout-ms", "idle-timeout-ms",
                  "frame-timeout-ms", "max-frame-bytes", "history-bytes", "edit-log-days", "edit-log-mb", "min-free-mb", "log-format", "log-file", "log-level", "backup-every", "backup-keep", "backup-dir", "config", "test-drop-updates", "test-corrupt-updates"},
                 {"help", "open", "no-create", "exact-horizon", "no-horizon-images", "no-outer-horizon", "no-mip-patches",
                  "no-presence-records",
                  "no-thread-priorities"});
  if (auto err = cl.parse(argc, argv, 1); !err.empty()) return usage_error(err);
  if (cl.flag("help")) return std::printf("%s", kHelp), 0;
  if (cl.has("config"))
    if (auto e = cl.load_file(cl.get("config")); !e.empty()) return usage_error("config: " + e);
  if (!cl.positional().empty()) return usage_error("unexpected argument " + cl.positional().front());
  if (cl.has("world") == cl.has("store"))
    return usage_error(cl.has("world") ? "give --world DIR or --store URL, not both"
                                       : "--world DIR (or --store URL) is required");
  ServerOptions o;
  std::string err;
  const std::string where = cl.has("world") ? cl.get("world") : cl.get("store");
  if (PostgresStore::is_url(where)) {
    o.cluster.store_url = where;
    if (!cl.has("server-id")) return usage_error("--server-id N is required with a PostgreSQL store");
    o.cluster.server_id = static_cast<std::uint32_t>(cl.get_int("server-id", 0, 0, kMaxServerId, &err));
    o.cluster.lease = std::chrono::milliseconds(cl.get_int("lease-ms", 5000, 500, kMaxLease.count(), &err));
    if (cl.has("advertise")) {
      std::string why;
      auto a = parse_server_address(cl.get("advertise"), &why);
      if (!a) return usage_error("--advertise: " + why);
      o.cluster.advertise = a->text();
    }
    o.cluster.redirect_margin = static_cast<std::int32_t>(cl.get_int("redirect-margin", 32, 0, 128, &err));
  } else {
    if (where.find("://") != std::string::npos)
      return usage_error("--store: '" + where + "' is neither a postgresql:// URL nor a world directory");
    for (const char* cluster_only : {"server-id", "lease-ms", "advertise", "redirect-margin"})
      if (cl.has(cluster_only))
        return usage_error(std::string("--") + cluster_only + " is for a PostgreSQL store (--store postgresql://...)");
    o.world_dir = where;
  }
  o.net.bind_address = cl.get("bind", o.net.bind_address);
  o.net.port = static_cast<std::uint16_t>(cl.get_int("port", 0, 0, 65535, &err));
  o.ops.metrics_address = cl.get("metrics");
  if (cl.has("border")) {
    o.border_set = true;
    if (cl.get("border") != "none") {
      std::int32_t c[4];
      if (!parse_int_list<std::int32_t>(cl.get("border"), c, 4))
        return usage_error("--border: '" + cl.get("border") + "' is not X0,Z0,X1,Z1 (or none)");
      o.border = WorldBounds{0, 1, true, c[0], c[2], c[1], c[3]};
      if (auto why = o.border.validate(); !why.empty()) return usage_error("--border: " + why);
    }
  }
  if (cl.has("metrics"))
    if (auto hp = parse_host_port(o.ops.metrics_address); !hp) return usage_error("--metrics: " + hp.error().message);
  o.world.tick_hz = static_cast<std::uint32_t>(cl.get_int("tick-hz", o.world.tick_hz, 1, 1000, &err));
  constexpr std::int64_t kViewLimit = ReplicationOptions::kViewDistanceLimit;
  o.replication.max_view_distance =
      static_cast<std::int32_t>(cl.get_int("max-view-distance", o.replication.max_view_distance, 0, kViewLimit, &err));
  o.replication.max_full_res_radius = static_cast<std::int32_t>(cl.get_int("max-full-res-radius", o.replication.max_full_res_radius, 0, 4096, &err));
  o.replication.default_view_distance = static_cast<std::int32_t>(cl.get_int("view-distance", o.replication.default_view_distance, 0, kViewLimit, &err));
  o.replication.default_full_res_radius = static_cast<std::int32_t>(cl.get_int("full-res-radius", o.replication.default_full_res_radius, 0, 4096, &err));
  o.net.max_clients = static_cast<std::size_t>(cl.get_int("max-clients", 1024, 1, 100000, &err));
  o.net.session.max_queue_bytes =
      static_cast<std::size_t>(cl.get_int("max-queue-bytes", 16 << 20, 1 << 16, std::int64_t{1} << 34, &err));
  o.replication.stream_window_bytes =
      static_cast<std::size_t>(cl.get_int("stream-window-bytes", 512 << 10, 1 << 12, std::int64_t{1} << 32, &err));
  o.replication.stream_yield = std::chrono::milliseconds(cl.get_int("stream-yield-ms", 20, 0, 60000, &err));
  o.net.io_threads = static_cast<int>(cl.get_int("io-threads", 2, 1, 64, &err));
  o.storage.worker_threads = static_cast<int>(cl.get_int("worker-threads", 2, 1, 256, &err));
  o.net.session.write_timeout = std::chrono::milliseconds(cl.get_int("write-timeout-ms", 10000, 100, 3600000, &err));
  o.net.session.socket_send_buffer_bytes = static_cast<int>(cl.get_int("socket-send-buffer", 0, 0, 1 << 30, &err));
  o.ops.auth_token = cl.get("auth-token");
  o.ops.admin_token = cl.get("admin-token");
  if (cl.has("admin-token") && o.ops.admin_token.size() < 8)
    return usage_error("--admin-token: at least 8 characters (it lets its holder kick, ban and stop the server)");
  o.ops.allow_open = cl.flag("open");
  o.replication.horizon_estimates = !cl.flag("exact-horizon");
  o.replication.horizon_images = !cl.flag("no-horizon-images");
  o.replication.outer_horizon = !cl.flag("no-outer-horizon");
  o.replication.mip_patches = !cl.flag("no-mip-patches");
  o.replication.presence_records = !cl.flag("no-presence-records");
  o.thread_priorities = !cl.flag("no-thread-priorities");
  o.world.edits_per_second = static_cast<double>(cl.get_int("edits-per-second", 20, 0, 100000, &err));
  o.replication.max_edit_voxels = cl.get_int("max-edit-voxels", kMaxEditVolume, 1, kMaxEditVolume, &err);
  o.replication.max_speed = static_cast<double>(cl.get_int("max-speed", 256, 0, 1 << 20, &err));
  o.net.session.inbound_bytes_per_second =
      static_cast<double>(cl.get_int("inbound-bytes-per-second", 1 << 20, 0, std::int64_t{1} << 40, &err));
  o.net.session.inbound_burst_bytes = std::max(o.net.session.inbound_bytes_per_second * 4, 1.0 * (1 << 20));
  o.replication.outbound_bytes_per_second =
      static_cast<double>(cl.get_int("outbound-bytes-per-second", 32 << 20, 0, std::int64_t{1} << 40, &err));
  o.net.session.handshake_timeout =
      std::chrono::milliseconds(cl.get_int("handshake-timeout-ms", 5000, 100, 3600000, &err));
  o.net.session.idle_timeout = std::chrono::milliseconds(cl.get_int("idle-timeout-ms", 30000, 100, 86400000, &err));
  o.net.session.frame_timeout = std::chrono::milliseconds(cl.get_int("frame-timeout-ms", 10000, 100, 3600000, &err));
  o.net.session.max_frame_bytes =
      static_cast<std::size_t>(cl.get_int("max-frame-bytes", kDefaultMaxFrameBytes, 64 << 10, kDefaultMaxFrameBytes, &err));
  o.world.history_bytes_per_client =
      static_cast<std::size_t>(cl.get_int("history-bytes", 4 << 20, 0, std::int64_t{1} << 34, &err));
  o.world.presence_hz = static_cast<std::uint32_t>(cl.get_int("presence-hz", 2, 0, 100, &err));
  o.storage.edit_log_days = static_cast<std::uint32_t>(cl.get_int("edit-log-days", 30, 0, 36500, &err));
  o.storage.edit_log_mb = static_cast<std::uint32_t>(cl.get_int("edit-log-mb", 1024, 0, 1 << 22, &err));
  o.storage.min_free_mb = static_cast<std::uint64_t>(cl.get_int("min-free-mb", 64, 0, std::int64_t{1} << 40, &err));
  o.world.presence_max_entries = static_cast<std::size_t>(cl.get_int("presence-max", 32, 1, 64, &err));
  o.replication.hash_push_ms = static_cast<std::uint32_t>(cl.get_int("hash-push-ms", 1000, 0, 3600000, &err));
  o.world.mip_refresh_ms = static_cast<std::uint32_t>(cl.get_int("mip-refresh-ms", 500, 0, 60000, &err));
  o.world.resident_chunks = static_cast<std::size_t>(cl.get_int("resident-chunks", 32768, 0, 1 << 24, &err));
  o.faults.drop_updates = static_cast<int>(cl.get_int("test-drop-updates", 0, 0, 1000000, &err));
  o.faults.corrupt_updates = static_cast<int>(cl.get_int("test-corrupt-updates", 0, 0, 1000000, &err));
  if (!err.empty()) return usage_error(err);
  o.create_world = !cl.flag("no-create");
  if (o.ops.auth_token.empty() && !cl.has("tokens-file") && !o.ops.allow_open &&
      !is_loopback_address(o.net.bind_address))
    return usage_error("refusing to serve " + o.net.bind_address +
                       " without authentication: give --auth-token or --tokens-file, or --open to allow anyone");
  if (cl.has("tokens-file") && cl.has("auth-token"))
    return usage_error("give --auth-token or --tokens-file, not both: with a tokens file each player has a token "
                       "of their own (add a line 'NAME TOKEN' per player)");
  if (cl.has("tokens-file")) {
    auto tokens = load_tokens_file(cl.get("tokens-file"));
    if (!tokens) return usage_error(tokens.error().message);
    if (tokens->empty()) return usage_error("tokens file " + cl.get("tokens-file") + " lists no players");
    o.ops.player_tokens = std::move(*tokens);
    o.ops.tokens_file = cl.get("tokens-file");
  }

  if (cl.has("backup-every")) {
    const auto ms = parse_duration_ms(cl.get("backup-every"));
    if (!ms || *ms < 100 || *ms > 366LL * 86'400'000)
      return usage_error("--backup-every: '" + cl.get("backup-every") +
                         "' is not a duration from 100ms to 366d (e.g. 30m, 6h, 1d)");
    if (!cl.has("backup-dir")) return usage_error("--backup-every: give --backup-dir DIR, where the backups go");
    if (o.world_dir.empty())
      return usage_error("--backup-every: the world is in PostgreSQL; back it up with PostgreSQL's own tools");
    o.ops.backups.every = std::chrono::milliseconds(*ms);
    o.ops.backups.dir = cl.get("backup-dir");
    o.ops.backups.keep = static_cast<int>(cl.get_int("backup-keep", 7, 1, 100000, &err));
    if (!err.empty()) return usage_error(err);
  } else if (cl.has("backup-dir") || cl.has("backup-keep")) {
    return usage_error(std::string("--") + (cl.has("backup-dir") ? "backup-dir" : "backup-keep") +
                       ": scheduled backups need --backup-every DURATION");
  }
  const std::string log_format = cl.get("log-format", "text");
  if (log_format != "text" && log_format != "json")
    return usage_error("--log-format: '" + log_format + "' is neither text nor json");
  const std::string log_level = cl.get("log-level", "info");
  if (!set_server_log_level(log_level))
    return usage_error("--log-level: '" + log_level + "' is none of trace, debug, info, warn, error, off");
  if (cl.has("log-format") || cl.has("log-file"))
    if (auto e = configure_server_log(log_format == "json" ? LogFormat::kJson : LogFormat::kText, cl.get("log-file"));
        !e.empty())
      return usage_error("--log-file: " + e);

  // One descriptor per client plus the store, the listener and a margin.
  rlimit nofile{};
  if (getrlimit(RLIMIT_NOFILE, &nofile) == 0) {
    const rlim_t want = static_cast<rlim_t>(o.net.max_clients) + 64;
    if (nofile.rlim_cur < want) {
      nofile.rlim_cur = std::min(want, nofile.rlim_max);
      setrlimit(RLIMIT_NOFILE, &nofile);
    }
    if (nofile.rlim_cur < want)
      server_log().warn("open-file limit {} is below --max-clients {} + 64; connections beyond it will fail",
                        nofile.rlim_cur, o.net.max_clients);
  }

  // Signals are caught on a private io_context so the server's own threads
  // never block on them; the loop below ends on SIGINT or SIGTERM, or when
  // the server asks (a storage failure, terrane-admin shutdown), saying
  // why. SIGHUP reopens the log file (--log-file) and reloads the tokens
  // file, bans and whitelist, and the server goes on.
  asio::io_context signals_io;
  std::string why;  // written on signals_io's thread only
  auto stop_because = [&signals_io, &why](std::string reason) {
    asio::post(signals_io, [&signals_io, &why, reason = std::move(reason)] {
      if (why.empty()) why = reason;
      signals_io.stop();
    });
  };
  o.world.on_fatal = [stop_because] { stop_because("a storage failure"); };
  // terrane-admin shutdown, once its warning time is up; --restart makes the
  // exit status kExitRestart.
  bool restart_asked = false;  // written on signals_io's thread only
  o.ops.on_shutdown = [&signals_io, &why, &restart_asked](bool restart) {
    asio::post(signals_io, [&signals_io, &why, &restart_asked, restart] {
      if (why.empty()) {
        why = restart ? "an operator's shutdown with --restart (terrane-admin), its warning time up"
                      : "an operator's shutdown (terrane-admin), its warning time up";
        restart_asked = restart;
      }
      signals_io.stop();
    });
  };
  auto server = Server::create(o);
  if (!server) {
    server_log().error("{}", server.error().message);
    return 1;
  }
  asio::signal_set signals(signals_io, SIGINT, SIGTERM);
  signals.add(SIGHUP);
  std::function<void(const asio::error_code&, int)> on_signal = [&](const asio::error_code& ec, int sig) {
    if (ec) return;
    if (sig == SIGHUP) {
      if (auto e = reopen_server_log(); !e.empty()) server_log().error("SIGHUP: {}; logging on to the old file", e);
      server_log().info("signal {} (SIGHUP): reloading the tokens file, bans and whitelist", sig);
      (*server)->reload();
      return signals.async_wait(on_signal);
    }
    if (why.empty()) why = "signal " + std::to_string(sig) + (sig == SIGINT ? " (SIGINT)" : " (SIGTERM)");
    signals_io.stop();
  };
  signals.async_wait(on_signal);
  (*server)->start();
  signals_io.run();
  server_log().info("shutting down: {}", why);
  (*server)->stop();
  if ((*server)->storage_failed()) {
    server_log().critical("stopped after a storage failure: the edits of the failed tick were not acknowledged (and "
                          "not saved, unless their rejections said the outcome is unknown)");
    return 1;
  }
  return restart_asked ? kExitRestart : 0;
}

}  // namespace
}  // namespace terrane

int main(int argc, char** argv) { return terrane::run(argc, argv); }
