// SqliteCoarseImages: a world's coarse images (format 2), the table
// "coarse" of world.sqlite (common/world/WORLD_FORMAT.md): per 256³
// region, the 4³ mip and revision of every stored chunk in it
// (common/world/coarse_image.h), so a distant view does not decode them.
// Written in the same transaction as the chunks, or behind them
// (set_behind): the images' changes then wait here in memory, coalesced per
// region, until catch_up writes them; load reads the rows' revisions and
// decodes the few chunks whose entry lags, so what it returns always
// matches the rows.
// It owns its statements, the changes waiting and whether the last load
// read past its image; the connection is SqliteStore's, which outlives it,
// and so are the chunk rows (read through load_chunk and the chunks table).
// Thread-safety: the connection's owner thread (SqliteStore's).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include "common/world/world_store.h"

struct sqlite3;
struct sqlite3_stmt;

namespace terrane {

class SqliteCoarseImages {
 public:
  static constexpr const char* kSchema =
      "CREATE TABLE IF NOT EXISTS coarse(rx INTEGER NOT NULL, ry INTEGER NOT NULL, rz INTEGER NOT NULL,"
      " image BLOB NOT NULL, PRIMARY KEY(rx, ry, rz)) WITHOUT ROWID;";
  // A chunk row decoded (none if it has no row; an error with decode set if
  // its blob is damaged): SqliteStore::load_chunk.
  using LoadChunk = std::function<FileResult<std::optional<StoredChunk>>(Vec3i)>;
  using ChunkRowFn = std::function<void(Vec3i, std::uint64_t, std::span<const std::uint8_t>)>;
  // Calls its argument for every chunk row in (cx, cy, cz) order:
  // SqliteStore::for_each_chunk.
  using ForEachChunkRow = std::function<FileStatus(const ChunkRowFn&)>;

  // db: an open world (not owned; outlives this); dir names it in errors.
  SqliteCoarseImages(sqlite3* db, std::string dir, LoadChunk load_chunk);
  ~SqliteCoarseImages();
  SqliteCoarseImages(const SqliteCoarseImages&) = delete;
  SqliteCoarseImages& operator=(const SqliteCoarseImages&) = delete;

  // Inside the caller's transaction: the table made if needed and every
  // image built again from the chunk rows (the upgrade from format 1);
  // on_row called after each row. A damaged row gets no entry.
  FileStatus rebuild(const ForEachChunkRow& rows, const std::function<void()>& on_row);

  // Inside the caller's transaction, which wrote these chunk rows: set,
  // their entries; undecodable, rows whose blob does not decode (their
  // entries go). Behind: only the entries going are written now.
  FileStatus written(const std::vector<CoarseEntry>& set, const std::vector<Vec3i>& undecodable);
  // After that transaction committed: behind, set waits for catch_up.
  void committed(std::vector<CoarseEntry> set);
  // Inside the caller's transaction, which deleted the chunk's row: its
  // entry goes (and the rest of its region is made to match the rows).
  FileStatus erased(Vec3i chunk_pos);

  // The region's entries, as its rows are (read past any lag).
  FileResult<std::vector<CoarseEntry>> load(Vec3i region);
  // The image as stored (no entries if there is none).
  FileResult<std::vector<CoarseEntry>> load_as_kept(Vec3i region);
  // Whether the last load read past its image.
  bool read_behind() const { return read_behind_; }
  // Calls fn(region, entries) for every image as stored.
  FileStatus for_each(const std::function<void(Vec3i, const std::vector<CoarseEntry>&)>& fn);

  // Images behind the chunks (WorldStore::set_coarse_behind).
  void set_behind(bool on) { behind_ = on; }
  // In one transaction of its own, the images of up to max_regions regions
  // whose oldest waiting change is at least min_age old (oldest first); how
  // many regions still have changes waiting.
  FileResult<std::size_t> catch_up(std::size_t max_regions, std::chrono::steady_clock::duration min_age);
  std::size_t pending() const { return pending_.size(); }
  // The region's image is rewritten from its rows at the next catch_up.
  void repair(Vec3i region);

 private:
  using RegionKey = std::tuple<int, int, int>;
  // Inside a transaction: the images of the regions of entries, changed.
  // set: entries to put; erase: chunks whose entries go.
  // repair: regions rewritten even if nothing of them changes; heal_all,
  // or a region in repair: made to match its rows (read_past) as well.
  FileStatus change(const std::vector<CoarseEntry>& set, const std::vector<Vec3i>& erase,
                    const std::set<RegionKey>& repair, bool heal_all);
  // entries (an image's) made to match the region's rows: entries whose row
  // has another revision or none are made from the row or dropped, rows
  // without one decoded; in index order (with no entries: the region made
  // from its rows alone, a damaged image's repair). behind, if given: set
  // to whether entries did not match the rows.
  FileResult<std::vector<CoarseEntry>> read_past(Vec3i region, std::vector<CoarseEntry> entries,
                                                 bool* behind = nullptr);
  // The region's chunk rows and their revisions (an index range scan).
  FileResult<std::vector<std::pair<Vec3i, std::uint64_t>>> revisions_in(Vec3i region);
  FileError error(const std::string& what) const;

  sqlite3* db_;
  std::string dir_;
  LoadChunk load_chunk_;
  sqlite3_stmt* load_stmt_ = nullptr;
  sqlite3_stmt* save_stmt_ = nullptr;
  bool behind_ = false;
  bool read_behind_ = false;  // the last load read past its image
  // Images' changes not written yet (behind), per region: due from when,
  // the entries by coarse_index, whether the whole region is to be made
  // from its rows, and failed attempts.
  struct PendingImage {
    std::chrono::steady_clock::time_point since;
    std::map<int, CoarseEntry> entries;
    bool repair = false;
    int failures = 0;
  };
  static constexpr int kMaxFailures = 5;
  std::map<RegionKey, PendingImage> pending_;
};

}  // namespace terrane
