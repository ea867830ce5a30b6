// terrane-world: create, fill, inspect, convert and move Terrane worlds.
//
//   terrane-world generate --world DIR|--store URL [--server-id N] [--box x0,y0,z0,x1,y1,z1] [--seed N]
//   terrane-world import   --world DIR|--store URL [--server-id N] FILE.vxraw[.gz]
//   terrane-world export   --world DIR|--store URL --box x0,y0,z0,x1,y1,z1 FILE.vxraw[.gz]
//   terrane-world stats    --world DIR|--store URL [--box ...] [--json]
//   terrane-world check    --world DIR [--quarantine]
//   terrane-world backup   --world DIR --to DEST
//   terrane-world migrate  --world DIR --to postgresql://... [--server-id N]
//
// A world is a directory (SQLite) or a PostgreSQL database (a postgresql://
// URL; --world and --store each take either, as terrane-server's do). A
// command that writes a PostgreSQL world takes the leases of the regions it
// writes for a server id of its own (a LeaseKeeper, as a server does) and
// gives them up at the end. Messages name a database without its password.
//
// Exit status: 0 on success, 1 on a failure of the work (I/O, damaged data),
// 2 on bad usage. Every error names what and where.
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "common/cli/cli.h"
#include "common/codec/lz4_block.h"
#include "common/vxraw/vxraw.h"
#include "common/world/sqlite_store.h"
#include "common/world/world.h"
#include "common/world/world_lock.h"
#include "server/cluster/lease_keeper.h"
#include "server/storage/postgres_store.h"
#include "server/tools/enhance_command.h"
#include "server/tools/world_stats.h"

namespace terrane {
namespace {

constexpr const char* kUsage =
    "usage: terrane-world COMMAND (--world DIR | --store URL) [options]\n"
    "\n"
    "A world is a directory (SQLite: one server) or a PostgreSQL database shared by several\n"
    "servers (--store postgresql://[USER@]HOST:PORT/DB; server/storage/STORE_POSTGRESQL.md).\n"
    "--world and --store each take either. Commands that write a PostgreSQL world take the\n"
    "leases of the regions they write for a server id of their own (--server-id N).\n"
    "A world directory has one writer at a time: generate, import, migrate and check\n"
    "--quarantine take its lock (world.lock) and are refused, naming the holder, while a\n"
    "server serves it; check, stats, export and backup only read and may run beside one.\n"
    "\n"
    "Commands:\n"
    "  generate   create a generated world (if there is none) and pre-generate a box of it\n"
    "  import     write a VXRAW box (plain or .gz) into a world, creating an empty world if needed\n"
    "  export     write a box of a world to a VXRAW file (.gz: gzip-compressed)\n"
    "  stats      the storage results table for a box: voxels, codecs, memory\n"
    "  check      decode every stored chunk, list quarantined ones (exit 1 on any of either)\n"
    "  backup     copy a world directory, consistently, even while a server is writing to it\n"
    "             (a PostgreSQL world: pg_dump)\n"
    "  migrate    copy a world directory into a PostgreSQL database that holds no world yet\n"
    "  enhance    voxel detail enhancement of a VXRAW box (subdivision or resampling, lighting)\n"
    "\n"
    "Run 'terrane-world COMMAND --help' for a command's options.\n";

constexpr const char* kGenerateHelp =
    "usage: terrane-world generate (--world DIR | --store URL [--server-id N]) [--box x0,y0,z0,x1,y1,z1]\n"
    "                              [--seed N] [--threads N]\n"
    "\n"
    "Creates a world with Terrane's terrain generator (unless the directory or database already\n"
    "holds one) and stores every generated chunk of the box, all-Air ones too (a few dozen\n"
    "bytes each), so a server neither generates nor estimates any of them. Chunks already\n"
    "stored are left alone, so running it twice is safe (and fills in what an older version\n"
    "left out: it stored no all-Air chunk).\n"
    "\n"
    "  --world DIR    world directory (created if missing), or a postgresql:// URL\n"
    "  --store URL    the world in PostgreSQL (libpq URL; the database must exist, Terrane's\n"
    "                 tables are made in it), or a directory\n"
    "  --server-id N  required with a PostgreSQL world: the server id, 0 to 2147483647, whose\n"
    "                 region leases the writes take, as a server's do. Use an id no running\n"
    "                 server uses (taking a running server's id takes its regions from it, and\n"
    "                 it stops). A region a running server holds is refused, naming it; while\n"
    "                 the tool runs, servers cannot edit the regions it holds. The leases are\n"
    "                 given up at the end.\n"
    "  --box B        half-open box x0,y0,z0,x1,y1,z1 (default -256,-64,-256,256,192,256)\n"
    "  --seed N       generator seed for a new world (default 1)\n"
    "  --threads N    generator threads (default: all cores)\n";

constexpr const char* kImportHelp =
    "usage: terrane-world import (--world DIR | --store URL [--server-id N]) FILE\n"
    "\n"
    "Writes the voxels of a VXRAW file (plain or gzip) at the box's origin. A new world made\n"
    "this way has no generator: everything outside imported boxes is Air, and material ids\n"
    "beyond the default table get generic names (Material23, ...). Chunks are written in\n"
    "batches; if a batch fails, the batches before it stay imported (the error says how far).\n"
    "\n"
    "  --world DIR    world directory (created if missing), or a postgresql:// URL\n"
    "  --store URL    the world in PostgreSQL (libpq URL; the database must exist), or a\n"
    "                 directory; a database that holds no world is given one\n"
    "  --server-id N  required with a PostgreSQL world: the server id, 0 to 2147483647, whose\n"
    "                 region leases the writes take, as a server's do. Use an id no running\n"
    "                 server uses (taking a running server's id takes its regions from it, and\n"
    "                 it stops). A region a running server holds is refused, naming it. The\n"
    "                 leases are given up at the end.\n";

constexpr const char* kExportHelp =
    "usage: terrane-world export (--world DIR | --store URL) --box x0,y0,z0,x1,y1,z1 [--raw] FILE\n"
    "\n"
    "Writes the box to FILE as VXRAW, gzip-compressed unless --raw is given or FILE does not\n"
    "end in .gz. The file is written to a temporary name and renamed when complete.\n"
    "A PostgreSQL world is only read: no --server-id, no leases.\n";

constexpr const char* kStatsHelp =
    "usage: terrane-world stats (--world DIR | --store URL) [--box x0,y0,z0,x1,y1,z1] [--json]\n"
    "\n"
    "Measures a box of the world (default: the default box for generated worlds, the box of\n"
    "the stored chunks otherwise): voxels, non-empty voxels, partial occupancy, materials,\n"
    "then bytes for disk byte RLE (32^3 units), byte RLE + LZ4, network bit-packed RLE in\n"
    "16^3 and 4^3 units, memory unpacked and row-packed, with encode/decode MB/s.\n"
    "--json prints one JSON object instead of the table.\n"
    "A PostgreSQL world is only read: no --server-id, no leases.\n";

constexpr const char* kCheckHelp =
    "usage: terrane-world check (--world DIR [--quarantine] | --store URL)\n"
    "\n"
    "Reads the metadata and decodes every stored chunk. Each damaged chunk is reported with\n"
    "its chunk coordinates and what is wrong. Chunks already in the quarantine table (damaged\n"
    "rows a server or an earlier check moved aside) are listed with their coordinates, revision,\n"
    "time and reason. Every coarse image entry (each chunk's 4^3 mip, what distant views are\n"
    "served from) is compared with its chunk: one newer than its chunk, or with other voxels at\n"
    "the same revision, is wrong; one older, or missing, is behind (a server writes the images\n"
    "after the chunks, and readers read past that), counted but not an error. Exit status 1 if\n"
    "any chunk is damaged or quarantined or any coarse entry is wrong.\n"
    "\n"
    "A PostgreSQL world (--store URL) is read in one read-only snapshot, beside running servers:\n"
    "each chunk row is decoded and its coarse mip column compared with its blob's (wrong if it\n"
    "differs: rows and mips are written together); quarantined rows are listed. Its damaged\n"
    "rows are quarantined by the server writing their region, as it loads them.\n"
    "\n"
    "  --quarantine   move each damaged row to the quarantine table (one transaction per chunk;\n"
    "                 its blob is kept byte for byte) so a server serves the chunk as generated\n"
    "                 instead of failing to read it (world directories only). This writes the\n"
    "                 world, so it takes the directory's lock: refused while a server serves it\n"
    "                 (which quarantines damaged rows itself as it loads them)\n";

constexpr const char* kBackupHelp =
    "usage: terrane-world backup --world DIR --to DEST\n"
    "\n"
    "Copies the world to DEST (a new directory) with SQLite's online backup: safe while a\n"
    "server runs; the copy is the state of one moment.\n"
    "\n"
    "World directories only: back a PostgreSQL world up with PostgreSQL's own tools (pg_dump,\n"
    "or continuous archiving), which copy one consistent state while servers write. To copy a\n"
    "world directory into PostgreSQL, use 'terrane-world migrate'.\n";

constexpr const char* kMigrateHelp =
    "usage: terrane-world migrate --world DIR --to postgresql://[USER@]HOST:PORT/DB [--server-id N]\n"
    "\n"
    "Copies a world directory into a PostgreSQL database that holds no world yet (the database\n"
    "must exist; Terrane's tables are made in it), so that several servers can share it\n"
    "(terrane-server --store URL). Copied: the metadata (generator and its parameters, bounds,\n"
    "material table, epoch), every stored chunk row with its revision and blob (in batches of\n"
    "256, with their coarse mips), and the access lists. NOT copied: the edit log (undo history\n"
    "and 'who changed this') and the quarantine (damaged rows set aside: their chunks are served\n"
    "as generated). The directory is not changed.\n"
    "\n"
    "A chunk that does not decode stops the copy, named: run 'terrane-world check --world DIR\n"
    "--quarantine' first. The world's metadata is written last, so a copy that stopped leaves\n"
    "the database without a world and can be run again. A database that holds a world is\n"
    "refused. The directory's lock is held for the copy: a server serving DIR refuses it\n"
    "(stop the server first), and no server can start on DIR until the copy ends.\n"
    "\n"
    "  --world DIR    the world directory to copy\n"
    "  --to URL       the PostgreSQL database (libpq URL)\n"
    "  --server-id N  the server id, 0 to 2147483647, whose region leases the writes take\n"
    "                 (default 2147483647); use an id no running server uses. The leases are\n"
    "                 given up at the end.\n";

// Chunks per transaction when migrating.
constexpr std::size_t kMigrateBatch = 256;

int usage_error(const std::string& message, const char* help) {
  std::fprintf(stderr, "terrane-world: %s\n\n%s", message.c_str(), help);
  return 2;
}

int failure(const std::string& message) {
  std::fprintf(stderr, "terrane-world: %s\n", message.c_str());
  return 1;
}

// A progress line on stderr: redrawn in place on a terminal, a line every
// 10% otherwise.
class Progress {
 public:
  Progress(std::string what, std::uint64_t total)
      : what_(std::move(what)), total_(total), tty_(isatty(2) != 0), start_(std::chrono::steady_clock::now()) {}
  void update(std::uint64_t done) {
    const int pct = total_ ? static_cast<int>(done * 100 / total_) : 100;
    if (tty_) {
      const auto now = std::chrono::steady_clock::now();
      if (done != total_ && now - last_draw_ < std::chrono::milliseconds(100)) return;
      last_draw_ = now;
      const int width = 30;
      const int filled = pct * width / 100;
      std::fprintf(stderr, "\r%s [%.*s%*s] %3d%% %llu/%llu %.1fs", what_.c_str(), filled,
                   "##############################", width - filled, "", pct, static_cast<unsigned long long>(done),
                   static_cast<unsigned long long>(total_), elapsed());
      if (done == total_) std::fputc('\n', stderr);
    } else if (elapsed() >= 2.0 && (pct / 10 != last_decile_ || done == total_)) {
      // Off a terminal, stay quiet for short jobs, then a line every 10%.
      last_decile_ = pct / 10;
      std::fprintf(stderr, "%s: %d%% (%llu/%llu) %.1fs\n", what_.c_str(), pct, static_cast<unsigned long long>(done),
                   static_cast<unsigned long long>(total_), elapsed());
    }
  }

 private:
  double elapsed() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  std::string what_;
  std::uint64_t total_;
  bool tty_;
  int last_decile_ = -1;
  std::chrono::steady_clock::time_point start_, last_draw_{};
};

std::vector<Vec3i> chunks_in(const Region& r) {
  std::vector<Vec3i> out;
  for_each_chunk_in(r, [&](Vec3i c) { out.push_back(c); });
  return out;
}

// Where a command's world is: --world or --store (exactly one), a
// directory or a postgresql:// URL.
struct WorldPlace {
  std::string where;  // as given (a URL may hold a password: never print it)
  bool postgres = false;
};

// "" and *out set, or the usage error.
std::string world_place(const CommandLine& cl, WorldPlace* out) {
  if (cl.has("world") && cl.has("store")) return "give --world DIR or --store URL, not both";
  if (!cl.has("world") && !cl.has("store")) return "--world DIR (or --store URL) is required";
  out->where = cl.has("world") ? cl.get("world") : cl.get("store");
  out->postgres = PostgresStore::is_url(out->where);
  if (const auto scheme = out->where.find("://"); !out->postgres && scheme != std::string::npos)
    return fmt::format("'{}...' is neither a postgresql:// URL nor a world directory",
                       out->where.substr(0, scheme + 3));
  return {};
}

// The server id whose leases a write to a PostgreSQL world takes:
// --server-id, else fallback, else a usage error in *error. nullopt for a
// directory (where --server-id is a usage error).
std::optional<std::uint32_t> writer_id(const CommandLine& cl, const WorldPlace& place,
                                       std::optional<std::uint32_t> fallback, std::string* error) {
  if (!place.postgres) {
    if (cl.has("server-id")) *error = "--server-id is for a PostgreSQL world (--store postgresql://...)";
    return std::nullopt;
  }
  if (!cl.has("server-id") && !fallback) {
    *error = "--server-id N is required to write a PostgreSQL world: an id (0 to 2147483647) no running "
             "server uses";
    return std::nullopt;
  }
  return static_cast<std::uint32_t>(cl.get_int("server-id", fallback.value_or(0), 0, kMaxServerId, error));
}

// The region leases of a tool that writes a PostgreSQL world, kept alive by
// a LeaseKeeper; release() gives them up (the destructor does, if not done).
class ToolLeases {
 public:
  ToolLeases() = default;
  ToolLeases(const ToolLeases&) = delete;
  ToolLeases& operator=(const ToolLeases&) = delete;
  ~ToolLeases() { release(); }

  // Opens the keeper for server id on url's database and makes store's
  // writes take their leases from it.
  FileStatus attach(const std::string& url, std::uint32_t id, PostgresStore& store) {
    const LeaseTimes times{};
    auto keeper = LeaseKeeper::open(url, id, times, [shown = store.where()](const RegionLease& lost,
                                                                               const std::string& why) {
      std::fprintf(stderr, "terrane-world: world %s: lost the lease of region (%d, %d, %d): %s; writes there are "
                   "refused\n", shown.c_str(), lost.region.x, lost.region.y, lost.region.z, why.c_str());
    });
    if (!keeper) return FileError{keeper.error().message, std::nullopt};
    keeper_ = std::move(*keeper);
    where_ = store.where();
    store.set_lease_source(keeper_->claiming_source(), times.lease);  // a database restart is waited for a lease time
    return Ok{};
  }
  // Gives every lease up (they would otherwise run out within a lease time).
  void release() {
    if (!keeper_ || released_) return;
    released_ = true;
    if (auto r = keeper_->release_all(); !r)
      std::fprintf(stderr, "terrane-world: warning: world %s: giving the region leases up: %s (they run out by "
                   "themselves within %lld ms)\n", where_.c_str(), r.error().message.c_str(),
                   static_cast<long long>(LeaseTimes{}.lease.count()));
  }

 private:
  std::unique_ptr<LeaseKeeper> keeper_;
  std::string where_;
  bool released_ = false;
};

// A world a command works on. The leases and the lock are declared first,
// so the world's store (whose writes ask them) goes before them.
struct ToolWorld {
  ToolLeases leases;
  WorldLock lock;  // a world directory the command writes
  std::unique_ptr<World> world;
  bool created = false;  // made by this command
};

// Opens the world at place. make: the metadata of a new world where place
// holds none (World::create for a directory, create_world for a database);
// without it, no world there is an error. writer: for a PostgreSQL world
// that the command writes, the server id whose leases the writes take
// (nullopt: read only). writing: for a world directory the command writes,
// the command's name: its one-writer lock is taken (WorldLock), so a
// server serving it, or another tool writing it, refuses the command.
FileStatus open_tool_world(const WorldPlace& place, std::optional<std::uint32_t> writer,
                           const std::function<WorldMeta()>& make, ToolWorld& out, const char* writing = nullptr) {
  if (!place.postgres) {
    if (writing) {
      if (make) {
        std::error_code ec;
        std::filesystem::create_directories(place.where, ec);
        if (ec) return FileError{"world " + place.where + ": cannot create directory: " + ec.message(), {}};
      } else if (!SqliteStore::exists(place.where)) {
        return FileError{"world " + place.where + ": no world here (" + kWorldDatabaseName + " missing)", {}};
      }
      auto lock = WorldLock::take(place.where, writing);
      if (!lock) return lock.error();
      out.lock = std::move(*lock);
    }
    const bool create = make && !SqliteStore::exists(place.where);
    auto w = create ? World::create(place.where, make()) : World::open(place.where);
    if (!w) return w.error();
    out.world = std::move(*w);
    out.created = create;
    return Ok{};
  }
  auto store = PostgresStore::open(place.where);
  if (!store) return FileError{store.error().message, std::nullopt};
  PostgresStore& pg = **store;
  if (writer)
    if (auto s = out.leases.attach(place.where, *writer, pg); !s) return s;
  if (!pg.has_world()) {
    if (!make)
      return FileError{fmt::format("world {}: the database holds no world (make one with terrane-world migrate, "
                                   "generate or import, or start a server on it)",
                                   pg.where()),
                       std::nullopt};
    if (auto made = pg.create_world(make()); !made) return FileError{made.error().message, std::nullopt};
    out.created = true;
  }
  auto w = World::open(std::unique_ptr<WorldStore>(std::move(*store)));
  if (!w) return w.error();
  out.world = std::move(*w);
  return Ok{};
}

int cmd_generate(int argc, char** argv) {
  CommandLine cl({"world", "store", "server-id", "box", "seed", "threads"}, {"help"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kGenerateHelp);
  if (cl.flag("help")) return std::printf("%s", kGenerateHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kGenerateHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kGenerateHelp);
  std::string err;
  const Region box = cl.get_region("box", &err).value_or(kDefaultWorldBox);
  const auto seed = cl.get_int("seed", 1, 0, INT64_MAX, &err);
  const auto threads = cl.get_int("threads", std::max(1u, std::thread::hardware_concurrency()), 1, 256, &err);
  const auto writer = writer_id(cl, place, std::nullopt, &err);
  if (!err.empty()) return usage_error(err, kGenerateHelp);

  ToolWorld opened;
  if (auto s = open_tool_world(place, writer, [&] { return default_world_meta(static_cast<std::uint64_t>(seed)); },
                               opened, "terrane-world generate");
      !s)
    return failure(s.error().message);
  std::unique_ptr<World>& world = opened.world;
  const std::string where = world->store().where();
  if (opened.created) {
    std::fprintf(stderr, "created world %s (seed %lld)\n", where.c_str(), static_cast<long long>(seed));
  } else {
    if (!world->generator()) return failure("world " + where + " has no generator (it was made by import)");
    if (cl.has("seed") && world->generator()->params().seed != static_cast<std::uint64_t>(seed))
      return failure("world " + where + " exists with seed " + std::to_string(world->generator()->params().seed) +
                     ", not " + std::to_string(seed) + " (use another --world or --store to make a new one)");
    std::fprintf(stderr, "world %s exists; filling in missing chunks\n", where.c_str());
  }

  const Region clipped = world->meta().bounds.clamp(box);
  if (clipped.empty()) return failure("--box lies entirely outside the world's bounds");
  std::vector<Vec3i> todo;
  // Revision to store each with: 0, or above a quarantined row's so that
  // revisions only grow (common/world/WORLD_FORMAT.md, quarantine).
  std::vector<std::uint64_t> todo_revision;
  for (Vec3i c : chunks_in(clipped)) {
    auto stored = world->store().load_chunk(c);
    if (!stored) return failure(stored.error().message);
    if (stored->has_value()) continue;
    auto floor = world->store().quarantined_revision(c);
    if (!floor) return failure(floor.error().message);
    todo.push_back(c);
    todo_revision.push_back(floor->has_value() ? **floor + 1 : 0);
  }

  // Workers generate and encode; this thread stores in batches. The mutex
  // guards only the hand-over queue between them.
  std::atomic<std::size_t> next{0};
  std::atomic<std::uint64_t> air_chunks{0};
  std::mutex mu;
  std::condition_variable cv;
  std::deque<ChunkWrite> ready;
  std::size_t finished = 0;
  auto worker = [&] {
    Box box32;
    std::vector<ChunkWrite> local;
    for (;;) {
      const std::size_t i = next.fetch_add(1);
      if (i >= todo.size()) break;
      world->generate_chunk_box(todo[i], box32);
      // Stored even when all Air: a chunk without a row is the generator's,
      // and a server would estimate it and generate it again whenever a
      // client looks at it (the sky above the terrain, most of a view).
      ChunkWrite w{todo[i], todo_revision[i], encode_chunk_blob(box32), coarse_voxels(box32)};
      if (all_air(box32.voxels())) air_chunks.fetch_add(1, std::memory_order_relaxed);
      std::lock_guard lock(mu);
      ready.push_back(std::move(w));
      cv.notify_one();
    }
    std::lock_guard lock(mu);
    ++finished;
    cv.notify_one();
  };
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t) pool.emplace_back(worker);

  Progress progress("generate", todo.size());
  std::uint64_t done = 0;
  std::string save_error;
  std::vector<ChunkWrite> batch;
  for (;;) {
    {
      std::unique_lock lock(mu);
      cv.wait(lock, [&] { return !ready.empty() || finished == pool.size(); });
      while (!ready.empty()) {
        batch.push_back(std::move(ready.front()));
        ready.pop_front();
      }
    }
    const bool last = [&] { std::lock_guard lock(mu); return finished == pool.size() && ready.empty(); }();
    if (batch.size() >= 64 || (last && !batch.empty())) {
      done += batch.size();
      if (save_error.empty()) {
        // Never overwrite: a server may have stored an edit of the chunk meanwhile.
        if (auto s = world->store().save_chunks(batch, /*overwrite=*/false); !s) save_error = s.error().message;
      }
      batch.clear();
      progress.update(done);
    }
    if (last && batch.empty()) break;
  }
  for (auto& t : pool) t.join();
  if (!save_error.empty()) return failure(save_error);
  if (todo.empty()) progress.update(0);
  opened.leases.release();
  std::printf("generated and stored %llu chunks (%llu of them all Air) in box %d,%d,%d..%d,%d,%d of world %s\n",
              static_cast<unsigned long long>(done), static_cast<unsigned long long>(air_chunks.load()), clipped.min.x,
              clipped.min.y, clipped.min.z, clipped.max.x, clipped.max.y, clipped.max.z, where.c_str());
  return 0;
}

int cmd_import(int argc, char** argv) {
  CommandLine cl({"world", "store", "server-id"}, {"help"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kImportHelp);
  if (cl.flag("help")) return std::printf("%s", kImportHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kImportHelp);
  if (cl.positional().size() != 1) return usage_error("expected exactly one FILE", kImportHelp);
  std::string err;
  const auto writer = writer_id(cl, place, std::nullopt, &err);
  if (!err.empty()) return usage_error(err, kImportHelp);
  const std::string path = cl.positional()[0];
  auto file = vxraw_read_file(path, VxrawLimits{});
  if (!file) return failure(file.error().message);
  if (file->repaired_air)
    std::fprintf(stderr, "%s: %llu Air voxels had non-zero occupancy; stored as 0\n", path.c_str(),
                 static_cast<unsigned long long>(file->repaired_air));

  // A new world: no generator, the default materials and generic names for
  // the ids the file uses beyond them.
  const auto new_meta = [&] {
    WorldMeta meta;
    meta.generator = GeneratorKind::kNone;
    meta.materials = default_material_names();
    // An imported box sets the vertical bounds when it reaches beyond the defaults.
    meta.bounds.min_y = std::min(meta.bounds.min_y, file->origin.y);
    meta.bounds.max_y = std::max(meta.bounds.max_y, file->origin.y + file->box.size().y);
    bool used[kMaterialCount] = {};
    for (const Voxel v : file->box.voxels()) used[v.material] = true;
    for (int m = static_cast<int>(meta.materials.size()); m < kMaterialCount; ++m)
      if (used[m]) {
        meta.materials.resize(static_cast<std::size_t>(m) + 1);
      }
    for (std::size_t m = kDefaultMaterialNames.size(); m < meta.materials.size(); ++m)
      meta.materials[m] = "Material" + std::to_string(m);
    return meta;
  };
  ToolWorld opened;
  if (auto s = open_tool_world(place, writer, new_meta, opened, "terrane-world import"); !s)
    return failure(s.error().message);
  std::unique_ptr<World>& world = opened.world;
  const std::string where = world->store().where();
  if (opened.created) std::fprintf(stderr, "created world %s (no generator)\n", where.c_str());
  const Region target = Region::from_min_size(file->origin, file->box.size());
  const Region clipped = world->meta().bounds.clamp(target);
  if (!(clipped == target))
    std::fprintf(stderr, "warning: part of the box lies outside the world's bounds and was not imported\n");
  // Import a slab of chunk layers at a time so progress shows and memory stays bounded.
  const std::vector<Vec3i> chunks = chunks_in(clipped);
  Progress progress("import", chunks.size());
  std::uint64_t done = 0;
  for (std::size_t i = 0; i < chunks.size(); i += 64) {
    std::vector<ChunkWrite> writes;
    for (std::size_t k = i; k < std::min(chunks.size(), i + 64); ++k) {
      const Vec3i cp = chunks[k];
      auto chunk = world->load_chunk(cp);
      if (!chunk) return failure(chunk.error().message);
      const Vec3i origin = chunk_origin(cp);
      chunk->chunk.modify(Region{clipped.min - origin, clipped.max - origin},
                          [&](Vec3i l, Voxel) { return file->box.get(l + origin - file->origin); });
      writes.push_back(
        ChunkWrite{cp, chunk->revision + 1, encode_chunk_blob(chunk->chunk), coarse_voxels(&chunk->chunk)});
    }
    if (auto s = world->store().save_chunks(writes); !s)
      return failure(s.error().message + " (" + std::to_string(done) + " of " + std::to_string(chunks.size()) +
                     " chunks were imported before the failure)");
    done += writes.size();
    progress.update(done);
  }
  opened.leases.release();
  std::printf("imported %s: box %d,%d,%d..%d,%d,%d (%llu chunks) into world %s\n", path.c_str(), clipped.min.x,
              clipped.min.y, clipped.min.z, clipped.max.x, clipped.max.y, clipped.max.z,
              static_cast<unsigned long long>(done), where.c_str());
  return 0;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Reads a box of the world; refuses boxes too large to hold in memory.
FileResult<Box> read_world_box(World& world, const Region& box) {
  constexpr std::int64_t kMaxVoxels = std::int64_t{1} << 31;
  if (box.volume() > kMaxVoxels)
    return FileError{"box of " + std::to_string(box.volume()) + " voxels is over the limit of " +
                         std::to_string(kMaxVoxels), {}};
  Box out(box.size());
  if (auto s = world.read_box(box.min, out); !s) return s.error();
  return out;
}

int cmd_export(int argc, char** argv) {
  CommandLine cl({"world", "store", "box"}, {"help", "raw"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kExportHelp);
  if (cl.flag("help")) return std::printf("%s", kExportHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kExportHelp);
  if (!cl.has("box")) return usage_error("--box x0,y0,z0,x1,y1,z1 is required", kExportHelp);
  if (cl.positional().size() != 1) return usage_error("expected exactly one FILE", kExportHelp);
  std::string err;
  const auto box = cl.get_region("box", &err);
  if (!err.empty()) return usage_error(err, kExportHelp);
  ToolWorld opened;  // read only: no leases
  if (auto s = open_tool_world(place, std::nullopt, nullptr, opened); !s) return failure(s.error().message);
  auto content = read_world_box(*opened.world, *box);
  if (!content) return failure(content.error().message);
  const std::string path = cl.positional()[0];
  const bool gzip = !cl.flag("raw") && ends_with(path, ".gz");
  if (auto s = vxraw_write_file(path, *content, box->min, gzip); !s) return failure(s.error().message);
  std::printf("exported box %d,%d,%d..%d,%d,%d to %s\n", box->min.x, box->min.y, box->min.z, box->max.x, box->max.y,
              box->max.z, path.c_str());
  return 0;
}

int cmd_stats(int argc, char** argv) {
  CommandLine cl({"world", "store", "box"}, {"help", "json"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kStatsHelp);
  if (cl.flag("help")) return std::printf("%s", kStatsHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kStatsHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kStatsHelp);
  std::string err;
  auto box = cl.get_region("box", &err);
  if (!err.empty()) return usage_error(err, kStatsHelp);
  ToolWorld opened;  // read only: no leases
  if (auto s = open_tool_world(place, std::nullopt, nullptr, opened); !s) return failure(s.error().message);
  World& world = *opened.world;
  if (!box) {
    if (world.generator()) {
      box = world.meta().bounds.clamp(kDefaultWorldBox);
    } else {
      // The bounding box of the stored chunks.
      bool any = false;
      Region r{};
      auto s = world.store().for_each_chunk([&](Vec3i pos, std::uint64_t, std::span<const std::uint8_t>) {
        const Region c = chunk_region(pos);
        r = any ? Region{min3(r.min, c.min), max3(r.max, c.max)} : c;
        any = true;
      });
      if (!s) return failure(s.error().message);
      if (!any) return failure("world " + world.store().where() + " is empty; give --box");
      box = r;
    }
  }
  auto content = read_world_box(world, *box);
  if (!content) return failure(content.error().message);
  const BoxStats stats = measure_box(*box, *content);
  std::fputs(cl.flag("json") ? stats_json(stats).c_str() : stats_table(stats).c_str(), stdout);
  return 0;
}

// Prints a quarantined row as check lists it.
void print_quarantined(const QuarantinedChunk& q);

// Lists a store's quarantined rows (SqliteStore or PostgresStore); how many.
template <class Store>
FileResult<std::uint64_t> list_quarantined(Store& store) {
  std::uint64_t n = 0;
  auto s = store.for_each_quarantined([&](const QuarantinedChunk& q) {
    ++n;
    print_quarantined(q);
  });
  if (!s) return s.error();
  return n;
}

void print_quarantined(const QuarantinedChunk& q) {
  char when[32] = "?";
  const std::time_t t = static_cast<std::time_t>(q.time_unix_s);
  if (std::tm tm{}; gmtime_r(&t, &tm) != nullptr) std::strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S UTC", &tm);
  std::fprintf(stderr, "chunk (%d, %d, %d): quarantined at %s, revision %llu, %zu bytes: %s\n", q.pos.x, q.pos.y,
               q.pos.z, when, static_cast<unsigned long long>(q.revision), q.blob.size(), q.reason.c_str());
}

// check of a PostgreSQL world: every chunk row decoded and its coarse mip
// column compared with its blob's, in one read-only snapshot; quarantined
// rows listed.
int check_postgres(const WorldPlace& place) {
  auto opened = PostgresStore::open(place.where);
  if (!opened) return failure(opened.error().message);
  PostgresStore& store = **opened;
  const std::string& shown = store.where();  // no password
  auto total = store.stored_chunk_count();
  if (!total) return failure(total.error().message);
  Progress progress("check", static_cast<std::uint64_t>(*total));
  std::uint64_t done = 0, coarse_bad = 0;
  std::vector<std::pair<Vec3i, std::string>> damaged;
  auto s = store.for_each_chunk_row([&](Vec3i pos, std::uint64_t, FileResult<std::span<const std::uint8_t>> blob,
                                        const std::optional<CoarseVoxels>& coarse) {
    progress.update(++done);
    if (!blob) {  // its units after its blob do not make it
      damaged.emplace_back(pos, blob.error().message);
      std::fprintf(stderr, "chunk (%d, %d, %d): damaged: %s\n", pos.x, pos.y, pos.z, blob.error().message.c_str());
      return;
    }
    auto chunk = decode_chunk_blob(*blob);
    if (!chunk) {
      damaged.emplace_back(pos, chunk.error().describe());
      std::fprintf(stderr, "chunk (%d, %d, %d): damaged: %s\n", pos.x, pos.y, pos.z, chunk.error().describe().c_str());
      return;
    }
    if (!coarse || *coarse != coarse_voxels(&*chunk))
      if (++coarse_bad <= 20)
        std::fprintf(stderr, "chunk (%d, %d, %d): coarse mip %s\n", pos.x, pos.y, pos.z,
                     coarse ? "differs from the chunk's" : "does not decode");
  });
  if (!s) return failure(s.error().message);
  auto quarantined = list_quarantined(store);
  if (!quarantined) return failure(quarantined.error().message);
  std::printf("checked %llu chunks of world %s: %zu damaged, %llu quarantined, %llu coarse mips wrong\n",
              static_cast<unsigned long long>(done), shown.c_str(), damaged.size(),
              static_cast<unsigned long long>(*quarantined), static_cast<unsigned long long>(coarse_bad));
  if (!damaged.empty())
    std::fprintf(stderr,
                 "terrane-world: world %s has %zu damaged chunk rows; the server writing each region quarantines "
                 "them as it loads them\n",
                 shown.c_str(), damaged.size());
  return damaged.empty() && *quarantined == 0 && coarse_bad == 0 ? 0 : 1;
}

int cmd_check(int argc, char** argv) {
  CommandLine cl({"world", "store"}, {"help", "quarantine"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kCheckHelp);
  if (cl.flag("help")) return std::printf("%s", kCheckHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kCheckHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kCheckHelp);
  if (place.postgres) {
    if (cl.flag("quarantine"))
      return usage_error("--quarantine is for world directories; in a PostgreSQL world the server writing a "
                         "region quarantines its damaged rows as it loads them", kCheckHelp);
    return check_postgres(place);
  }
  const std::string& dir = place.where;
  // Moving rows aside writes the world: not beside its server (which
  // quarantines damaged rows itself as it loads them). Checking only reads.
  WorldLock lock;
  if (cl.flag("quarantine")) {
    if (!SqliteStore::exists(dir)) return failure("world " + dir + ": no world here (" + kWorldDatabaseName + " missing)");
    auto taken = WorldLock::take(dir, "terrane-world check --quarantine");
    if (!taken) return failure(taken.error().message);
    lock = std::move(*taken);
  }
  auto opened = SqliteStore::open(dir);
  if (!opened) return failure(opened.error().message);
  SqliteStore& store = **opened;
  auto total = store.stored_chunk_count();
  if (!total) return failure(total.error().message);
  Progress progress("check", static_cast<std::uint64_t>(*total));
  std::uint64_t done = 0;
  std::vector<std::pair<Vec3i, std::string>> damaged;
  // Each chunk's coarse entry as its blob implies, to compare with the images.
  std::map<std::tuple<int, int, int>, CoarseEntry> expected;
  // The chunks and the images as of one moment (a server may be writing).
  if (auto r = store.begin_read(); !r) return failure(r.error().message);
  struct EndRead {
    SqliteStore& s;
    bool open = true;
    void end() {
      if (open) s.end_read();
      open = false;
    }
    ~EndRead() { end(); }
  } read{store};
  auto s = store.for_each_chunk([&](Vec3i pos, std::uint64_t revision, std::span<const std::uint8_t> blob) {
    if (auto chunk = decode_chunk_blob(blob); !chunk) {
      damaged.emplace_back(pos, chunk.error().describe());
      std::fprintf(stderr, "chunk (%d, %d, %d): damaged: %s\n", pos.x, pos.y, pos.z, chunk.error().describe().c_str());
    } else {
      expected[{pos.x, pos.y, pos.z}] = CoarseEntry{pos, revision, coarse_voxels(&*chunk)};
    }
    progress.update(++done);
  });
  if (!s) return failure(s.error().message);
  // The coarse images: one entry per good chunk, equal to it.
  // An entry older than its chunk, or missing for a chunk, is behind: a
  // server writes the images after the chunks (loads read past that), and
  // one that stopped before catching up leaves them so until the next
  // write into their region. Not wrong; counted.
  std::uint64_t coarse_bad = 0, images = 0, coarse_behind = 0;
  const auto bad_entry = [&](Vec3i p, const char* what) {
    if (++coarse_bad <= 20) std::fprintf(stderr, "chunk (%d, %d, %d): coarse image %s\n", p.x, p.y, p.z, what);
  };
  s = store.for_each_coarse([&](Vec3i, const std::vector<CoarseEntry>& entries) {
    ++images;
    for (const CoarseEntry& e : entries) {
      auto it = expected.find({e.chunk_pos.x, e.chunk_pos.y, e.chunk_pos.z});
      if (it == expected.end()) {
        bad_entry(e.chunk_pos, "entry without a stored chunk");
        continue;
      }
      if (e.revision < it->second.revision) ++coarse_behind;
      else if (it->second.revision != e.revision) bad_entry(e.chunk_pos, "revision newer than the chunk's");
      else if (it->second.voxels != e.voxels) bad_entry(e.chunk_pos, "voxels differ from the chunk's mip");
      expected.erase(it);
    }
  });
  if (!s) return failure(s.error().message);
  coarse_behind += expected.size();  // good chunks without an entry
  read.end();
  std::uint64_t moved = 0;
  if (cl.flag("quarantine")) {
    for (const auto& [pos, reason] : damaged) {
      auto m = store.quarantine_chunk(pos, reason);
      if (!m) return failure(m.error().message);
      if (m->has_value()) ++moved;
    }
  }
  auto listed = list_quarantined(store);
  if (!listed) return failure(listed.error().message);
  const std::uint64_t quarantined = *listed;
  std::printf("checked %llu chunks and %llu coarse images of world %s: %zu damaged",
              static_cast<unsigned long long>(done), static_cast<unsigned long long>(images), dir.c_str(),
              damaged.size());
  if (cl.flag("quarantine")) std::printf(" (%llu moved to quarantine)", static_cast<unsigned long long>(moved));
  std::printf(", %llu quarantined, %llu coarse entries wrong, %llu behind their chunks\n",
              static_cast<unsigned long long>(quarantined), static_cast<unsigned long long>(coarse_bad),
              static_cast<unsigned long long>(coarse_behind));
  if (quarantined > 0)
    std::fprintf(stderr,
                 "terrane-world: world %s has %llu quarantined chunk rows: damaged data set aside in its quarantine "
                 "table (common/world/WORLD_FORMAT.md); the chunks are served as generated until restored\n",
                 dir.c_str(), static_cast<unsigned long long>(quarantined));
  if (!damaged.empty() && !cl.flag("quarantine"))
    std::fprintf(stderr,
                 "terrane-world: world %s has %zu damaged chunks; 'check --quarantine' moves them aside (a server "
                 "does so when it loads them)\n",
                 dir.c_str(), damaged.size());
  if (coarse_bad > 0)
    std::fprintf(stderr, "terrane-world: world %s has %llu wrong coarse image entries (a server would serve distant "
                 "views from them)\n", dir.c_str(), static_cast<unsigned long long>(coarse_bad));
  return damaged.empty() && quarantined == 0 && coarse_bad == 0 ? 0 : 1;
}

int cmd_backup(int argc, char** argv) {
  CommandLine cl({"world", "store", "to"}, {"help"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kBackupHelp);
  if (cl.flag("help")) return std::printf("%s", kBackupHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kBackupHelp);
  if (!cl.has("to")) return usage_error("--to DEST is required", kBackupHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kBackupHelp);
  if (place.postgres)
    return usage_error("backup copies a world directory; back a PostgreSQL world up with PostgreSQL's own tools "
                       "(pg_dump, or continuous archiving)", kBackupHelp);
  if (PostgresStore::is_url(cl.get("to")))
    return usage_error("backup copies a world directory to a new directory; to copy one into PostgreSQL, use "
                       "'terrane-world migrate --world DIR --to URL'", kBackupHelp);
  const std::string& dir = place.where;
  auto store = SqliteStore::open(dir);
  if (!store) return failure(store.error().message);
  std::unique_ptr<Progress> progress;
  auto s = (*store)->backup_to(cl.get("to"), [&](int done, int total) {
    if (!progress) progress = std::make_unique<Progress>("backup", static_cast<std::uint64_t>(total));
    progress->update(static_cast<std::uint64_t>(done));
  });
  if (!s) return failure(s.error().message);
  std::printf("backed up world %s to %s\n", dir.c_str(), cl.get("to").c_str());
  return 0;
}

int cmd_migrate(int argc, char** argv) {
  CommandLine cl({"world", "to", "server-id"}, {"help"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kMigrateHelp);
  if (cl.flag("help")) return std::printf("%s", kMigrateHelp), 0;
  if (!cl.has("world")) return usage_error("--world DIR (the world directory to copy) is required", kMigrateHelp);
  if (!cl.has("to")) return usage_error("--to postgresql://... (the database to copy into) is required", kMigrateHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kMigrateHelp);
  const std::string dir = cl.get("world");
  const std::string url = cl.get("to");
  if (PostgresStore::is_url(dir))
    return usage_error("--world names the world directory to copy from, not a database", kMigrateHelp);
  if (!PostgresStore::is_url(url))
    return usage_error("--to takes a postgresql:// URL (to copy a world directory to another directory, use "
                       "'terrane-world backup')", kMigrateHelp);
  std::string err;
  const WorldPlace to{url, true};
  const auto id = writer_id(cl, to, kMaxServerId, &err);
  if (!err.empty()) return usage_error(err, kMigrateHelp);

  // The directory is locked for the copy: a server still writing it would
  // acknowledge edits the copy never sees.
  if (!SqliteStore::exists(dir)) return failure("world " + dir + ": no world here (" + kWorldDatabaseName + " missing)");
  auto lock = WorldLock::take(dir, "terrane-world migrate");
  if (!lock) return failure(lock.error().message);
  auto opened_src = SqliteStore::open(dir);
  if (!opened_src) return failure(opened_src.error().message);
  SqliteStore& src = **opened_src;
  ToolLeases leases;  // before the store, whose writes ask them
  auto opened_dst = PostgresStore::open(url);
  if (!opened_dst) return failure(opened_dst.error().message);
  PostgresStore& dst = **opened_dst;
  const std::string& shown = dst.where();  // no password
  if (dst.has_world())
    return failure("database " + shown + " already holds a world; migrate copies into a database that holds none "
                   "(give another database, or drop this one's terrane_ tables first)");
  if (auto rows = dst.stored_chunk_count(); !rows) {
    return failure(rows.error().message);
  } else if (*rows > 0) {
    std::fprintf(stderr, "database %s holds %lld chunk rows but no world (a migrate that stopped?): the rows of "
                 "chunks stored in %s are replaced\n", shown.c_str(), static_cast<long long>(*rows), dir.c_str());
  }
  if (auto s = leases.attach(url, *id, dst); !s) return failure(s.error().message);

  // The chunk rows, streamed a batch at a time.
  auto total_rows = src.stored_chunk_count();
  if (!total_rows) return failure(total_rows.error().message);
  const auto total = static_cast<std::uint64_t>(*total_rows);
  Progress progress("migrate", total);
  std::uint64_t copied = 0;
  std::string error;
  std::vector<ChunkWrite> batch;
  batch.reserve(kMigrateBatch);
  const auto flush = [&] {
    if (batch.empty() || !error.empty()) return;
    if (auto s = dst.save_chunks(batch); !s) {
      error = fmt::format("{} ({} of {} chunks were copied before the failure; the database holds no world yet, "
                          "so migrate can be run again)",
                          s.error().message, copied, total);
      return;
    }
    copied += batch.size();
    batch.clear();
    progress.update(std::min(copied, total));
  };
  auto s = src.for_each_chunk([&](Vec3i pos, std::uint64_t revision, std::span<const std::uint8_t> blob) {
    if (!error.empty()) return;
    // Decoded here, before anything of its batch is written: a damaged row
    // stops the copy, named (and its coarse mip is made from the decoding).
    auto chunk = decode_chunk_blob(blob);
    if (!chunk) {
      error = fmt::format("world {}: chunk ({}, {}, {}) does not decode: {}; run 'terrane-world check --world {} "
                          "--quarantine' to move damaged chunks aside, then migrate again ({} of {} chunks were "
                          "copied; the database holds no world yet)",
                          dir, pos.x, pos.y, pos.z, chunk.error().describe(), dir, copied, total);
      return;
    }
    batch.push_back(
        ChunkWrite{pos, revision, std::vector<std::uint8_t>(blob.begin(), blob.end()), coarse_voxels(&*chunk)});
    if (batch.size() >= kMigrateBatch) flush();
  });
  if (!s) return failure(s.error().message);
  flush();
  if (!error.empty()) return failure(error);
  if (copied == 0) progress.update(0);

  // The access lists.
  auto access = src.access_entries();
  if (!access) return failure(access.error().message);
  for (const auto& [key, value] : *access)
    if (auto put = dst.put_access(key, value); !put) return failure(put.error().message);

  // The metadata last: until it is there the database holds no world, so
  // no server serves half a copy, and a copy that stopped can run again.
  if (auto made = dst.create_world(src.meta()); !made) return failure(made.error().message);
  if (meta_to_keys(dst.meta()) != meta_to_keys(src.meta()))
    return failure("database " + shown + ": a world was made in it while copying (a server started on it?) and "
                   "its metadata was kept; the copied chunks and access lists are in it. Drop the database's "
                   "terrane_ tables and migrate again");
  leases.release();

  // What is not copied, said plainly.
  auto quarantined = src.quarantined_count();
  if (!quarantined) return failure(quarantined.error().message);
  auto log = src.edit_log_size();
  if (!log) return failure(log.error().message);
  if (*quarantined > 0 || log->first > 0)
    std::fprintf(stderr, "not copied: %lld edit log entries and %lld quarantined chunk rows of world %s (they stay "
                 "there)\n", static_cast<long long>(log->first), static_cast<long long>(*quarantined), dir.c_str());
  std::printf("migrated %llu chunks and %zu access entries of world %s to %s (edit log and quarantine not copied)\n",
              static_cast<unsigned long long>(copied), access->size(), dir.c_str(), shown.c_str());
  return 0;
}

}  // namespace
}  // namespace terrane

int main(int argc, char** argv) {
  using namespace terrane;
  if (argc < 2) return usage_error("no command given", kUsage);
  const std::string cmd = argv[1];
  if (cmd == "--help" || cmd == "-h" || cmd == "help") return std::printf("%s", kUsage), 0;
  if (cmd == "generate") return cmd_generate(argc, argv);
  if (cmd == "import") return cmd_import(argc, argv);
  if (cmd == "export") return cmd_export(argc, argv);
  if (cmd == "stats") return cmd_stats(argc, argv);
  if (cmd == "check") return cmd_check(argc, argv);
  if (cmd == "backup") return cmd_backup(argc, argv);
  if (cmd == "migrate") return cmd_migrate(argc, argv);
  if (cmd == "enhance") return run_enhance_command(argc, argv);
  return usage_error("unknown command '" + cmd + "'", kUsage);
}
