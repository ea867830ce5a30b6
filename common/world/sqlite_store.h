// SqliteStore: a world on disk (the WorldStore of one server). A world is a directory holding world.sqlite,
// an embedded SQLite database in WAL mode (format: common/world/WORLD_FORMAT.md):
//   - meta: format version, generator kind and parameters, bounds, material
//     table, epoch;
//   - chunks: one row per stored 32³ chunk: its coordinates, a revision that
//     only ever grows, and the voxels as byte RLE + LZ4;
//   - quarantine: damaged chunk rows moved aside (coordinates, revision, the
//     blob as it was, the reason, the time), kept until someone looks;
//   - coarse (format 2): per 256³ region, the 4³ mip and revision of every
//     stored chunk in it (common/world/coarse_image.h), so a distant view
//     does not decode them. Written in the same transaction as the chunks,
//     or, by a server (set_coarse_behind), after them: load_coarse then
//     reads the rows' revisions and decodes the few chunks whose entry
//     lags, so what it returns always matches the rows.
// Chunks never stored are generated on demand from the metadata (see World).
// The finer mips are not stored: they are rebuilt from level 0 on load.
//
// SqliteStore owns the connection, the metadata and the chunk rows; the
// other tables have owners of their own over its connection, which it
// holds and delegates to: SqliteEditLog, SqliteQuarantine,
// SqliteCoarseImages, SqliteAccess.
//
// Errors are returned as FileError naming the world and, for chunk data,
// the chunk's coordinates; a damaged blob never crashes the reader.
// Thread-safety: one owner thread per object (one SQLite connection).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/world/sqlite_access.h"
#include "common/world/sqlite_coarse_images.h"
#include "common/world/sqlite_edit_log.h"
#include "common/world/sqlite_quarantine.h"
#include "common/world/world_store.h"

struct sqlite3;
struct sqlite3_stmt;

namespace terrane {

inline constexpr const char* kWorldDatabaseName = "world.sqlite";

class SqliteStore final : public WorldStore {
 public:
  // Creates the directory (if needed) and a new world in it; fails if the
  // directory already holds a world.
  static FileResult<std::unique_ptr<SqliteStore>> create(const std::string& dir, const WorldMeta& meta);
  // Opens an existing world; fails with a clear message if there is none or
  // its format version is not one we read. A format-1 world is upgraded
  // first (its coarse images built from every chunk, in one transaction);
  // progress(done, total) is called as that goes, or a line is printed to
  // stderr every few seconds when progress is null.
  using Progress = std::function<void(std::int64_t done, std::int64_t total)>;
  static FileResult<std::unique_ptr<SqliteStore>> open(const std::string& dir, const Progress& progress = nullptr);
  static bool exists(const std::string& dir);

  ~SqliteStore() override;

  const std::string& dir() const { return dir_; }
  const std::string& where() const override { return dir_; }
  FileResult<std::unique_ptr<WorldStore>> reopen() const override;
  const WorldMeta& meta() const override { return meta_; }
  FileStatus set_epoch(std::uint64_t epoch) override;
  FileResult<std::uint64_t> name_world(std::uint64_t candidate) override;
  FileStatus set_bounds(const WorldBounds& bounds) override;

  FileResult<std::optional<StoredChunk>> load_chunk(Vec3i pos) override;
  FileResult<std::vector<CoarseEntry>> load_coarse(Vec3i region) override;
  FileResult<std::vector<CoarseEntry>> load_coarse_as_kept(Vec3i region) override {
    return coarse_.load_as_kept(region);
  }
  FileResult<std::vector<Vec3i>> quarantined_in(Vec3i region) override;
  FileResult<std::vector<Vec3i>> stored_in(Vec3i region) override;
  // Coarse images behind the chunks: save_chunks leaves the images' changes
  // pending in memory (the rows are the truth: load_coarse reads past any
  // lag) and catch_up_coarse writes them. Costs a commit the image rewrites
  // (about four fifths of a server tick's commit), and coalesces a region's
  // changes while they wait. Writes pending when the process dies are
  // caught up by the next write into their region (until then, loads
  // decode them).
  void set_coarse_behind(bool on) override { coarse_.set_behind(on); }
  // In one transaction, the images of up to max_regions regions whose
  // oldest pending change is at least min_age old (oldest first); how many
  // regions still have pending changes.
  FileResult<std::size_t> catch_up_coarse(std::size_t max_regions, std::chrono::steady_clock::duration min_age) override;
  std::size_t coarse_pending() const override { return coarse_.pending(); }
  // The region's image is rewritten from its rows at the next catch-up (a
  // load found it behind: maybe left by a writer that stopped before
  // catching up, which nothing else would repair until the next write
  // there).
  void repair_coarse(Vec3i region) override;
  bool coarse_read_behind() const override { return coarse_.read_behind(); }
  FileStatus begin_read() override;
  void end_read() override;
  // Calls fn(region, entries) for every coarse image as stored, which may
  // be behind the chunks (set_coarse_behind; terrane-world check).
  FileStatus for_each_coarse(const std::function<void(Vec3i, const std::vector<CoarseEntry>&)>& fn);
  FileStatus save_chunks(std::span<const ChunkWrite> writes, bool overwrite = true,
                         std::span<const EditLogEntry> log = {}) override;
  FileResult<std::vector<EditLogEntry>> edit_log(const EditLogQuery& q) override;
  FileResult<std::int64_t> prune_edit_log(std::int64_t before_ms, std::uint64_t max_bytes,
                                          std::int64_t max_rows = 10000) override;
  // Counted once (a scan of the whole log), then kept by this store's own
  // writes and prunes.
  FileResult<EditLogSize> edit_log_size() override;
  FileStatus erase_chunk(Vec3i pos);

  // The quarantine is the table "quarantine".
  FileResult<std::optional<std::uint64_t>> quarantine_chunk(Vec3i pos, const std::string& reason) override;
  FileResult<std::optional<std::uint64_t>> quarantined_revision(Vec3i pos) override;
  // Calls fn for every quarantined row, oldest first.
  FileStatus for_each_quarantined(const std::function<void(const QuarantinedChunk&)>& fn);
  FileResult<std::int64_t> quarantined_count();
  FileStatus for_each_chunk(
      const std::function<void(Vec3i, std::uint64_t, std::span<const std::uint8_t>)>& fn) override;
  FileResult<std::int64_t> stored_chunk_count() override;
  // Copies the whole database to dest_dir/world.sqlite with SQLite's online
  // backup, a few hundred pages at a time, so a running server keeps
  // writing; the copy is a consistent snapshot. dest_dir must not hold a
  // world already (an empty directory is replaced). The copy is made in
  // dest_dir.partial and renamed to dest_dir when whole: on failure neither
  // is left. progress(done_pages, total_pages) is called as it goes.
  FileStatus backup_to(const std::string& dest_dir, const std::function<void(int, int)>& progress);
  // The access lists are the table "access", made on the first write.
  FileResult<std::vector<std::pair<std::string, std::string>>> access_entries() override;
  FileStatus put_access(const std::string& key, const std::string& value) override;
  FileStatus erase_access(const std::string& key) override;
  // Runs `PRAGMA name` and returns the first column as text (tests, checks).
  FileResult<std::string> pragma(const std::string& name);

 private:
  SqliteStore(std::string dir, sqlite3* db);
  static FileResult<std::unique_ptr<SqliteStore>> create_in(const std::string& dir, const WorldMeta& meta);
  FileStatus load_meta();
  // Brings an older world to kWorldFormatVersion in one transaction (format 1
  // gains the coarse images; format 2 only its version: WORLD_FORMAT.md).
  FileStatus upgrade(const Progress& progress);
  FileStatus write_meta(const WorldMeta& meta);
  FileError error(const std::string& what) const;
  sqlite3* db() const { return db_.get(); }

  struct CloseDatabase {
    void operator()(sqlite3* db) const;
  };
  std::string dir_;
  // Declared before the owners below: closed after they finalized their
  // statements (a connection with statements left does not close).
  std::unique_ptr<sqlite3, CloseDatabase> db_;
  // The chunk rows (table "chunks"): read, written over, written if absent.
  sqlite3_stmt* load_stmt_ = nullptr;
  sqlite3_stmt* save_stmt_ = nullptr;
  sqlite3_stmt* insert_stmt_ = nullptr;
  WorldMeta meta_;
  // The other tables, each with its owner over this connection.
  SqliteEditLog edit_log_;
  SqliteQuarantine quarantine_;
  SqliteCoarseImages coarse_;
  SqliteAccess access_;
};

}  // namespace terrane
