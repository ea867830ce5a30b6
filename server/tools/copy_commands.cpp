// terrane-world backup and migrate: the commands that copy a world
// (server/tools/world_tool.h has what they share).
#include "server/tools/world_tool.h"

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
#include "server/storage/postgres_store.h"

namespace terrane::world_tool {

namespace {

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

}  // namespace

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
  // The copy is named by its first server start (WorldMeta::world_id).
  WorldMeta copied_meta = src.meta();
  copied_meta.world_id = 0;
  if (auto made = dst.create_world(copied_meta); !made) return failure(made.error().message);
  if (meta_to_keys(dst.meta()) != meta_to_keys(copied_meta))
    return failure("database " + shown + ": a world was made in it while copying (a server started on it?) and "
                   "its metadata was kept; the copied chunks and access lists are in it. Drop the database's "
                   "terrane_ tables and migrate again");
  leases.release();

  // What is not copied, said plainly.
  auto quarantined = src.quarantined_count();
  if (!quarantined) return failure(quarantined.error().message);
  auto log = src.edit_log_size();
  if (!log) return failure(log.error().message);
  if (*quarantined > 0 || log->entries > 0)
    std::fprintf(stderr, "not copied: %lld edit log entries and %lld quarantined chunk rows of world %s (they stay "
                 "there)\n", static_cast<long long>(log->entries), static_cast<long long>(*quarantined), dir.c_str());
  std::printf("migrated %llu chunks and %zu access entries of world %s to %s (edit log and quarantine not copied)\n",
              static_cast<unsigned long long>(copied), access->size(), dir.c_str(), shown.c_str());
  return 0;
}

}  // namespace terrane::world_tool
