#include "common/world/sqlite_store.h"

#include <sqlite3.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "common/world/sqlite_util.h"

namespace terrane {

SqliteStore::SqliteStore(std::string dir, sqlite3* db)
    : dir_(std::move(dir)),
      db_(db),
      edit_log_(db, dir_),
      quarantine_(db, dir_),
      coarse_(db, dir_, [this](Vec3i pos) { return load_chunk(pos); }),
      access_(db, dir_) {}

SqliteStore::~SqliteStore() {
  sqlite3_finalize(load_stmt_);
  sqlite3_finalize(save_stmt_);
  sqlite3_finalize(insert_stmt_);
}

void SqliteStore::CloseDatabase::operator()(sqlite3* db) const { sqlite3_close(db); }

FileError SqliteStore::error(const std::string& what) const { return sqlite_error(db(), dir_, what); }

FileResult<std::unique_ptr<WorldStore>> SqliteStore::reopen() const {
  auto s = open(dir_);
  if (!s) return s.error();
  return std::unique_ptr<WorldStore>(std::move(*s));
}

bool SqliteStore::exists(const std::string& dir) {
  std::error_code ec;
  return std::filesystem::exists(std::filesystem::path(dir) / kWorldDatabaseName, ec);
}

namespace {

FileResult<sqlite3*> open_db(const std::string& dir, bool create) {
  const std::string path = (std::filesystem::path(dir) / kWorldDatabaseName).string();
  sqlite3* db = nullptr;
  const int flags = SQLITE_OPEN_READWRITE | (create ? SQLITE_OPEN_CREATE : 0) | SQLITE_OPEN_NOMUTEX;
  if (sqlite3_open_v2(path.c_str(), &db, flags, nullptr) != SQLITE_OK) {
    std::string msg = "world " + dir + ": cannot open " + path + ": " + (db ? sqlite3_errmsg(db) : "out of memory");
    sqlite3_close(db);
    return FileError{msg, {}};
  }
  sqlite3_busy_timeout(db, 5000);
  // WAL + synchronous=FULL: a committed transaction survives a crash and a
  // power loss; readers (backups, tools) never block the writer.
  // A page cache of up to 32 MiB per connection (SQLite's default is 2):
  // a large world's b-tree pages above its chunks' rows then stay cached,
  // where with 2 MiB the writer read them again (a system call each) for
  // nearly every chunk it saved. Pages are allocated as they are used.
  const char* setup =
      "PRAGMA journal_mode=WAL;"
      "PRAGMA synchronous=FULL;"
      "PRAGMA foreign_keys=ON;"
      "PRAGMA cache_size=-32768;";
  char* err = nullptr;
  if (sqlite3_exec(db, setup, nullptr, nullptr, &err) != SQLITE_OK) {
    std::string msg = "world " + dir + ": cannot configure " + path + ": " + (err ? err : "?");
    sqlite3_free(err);
    sqlite3_close(db);
    return FileError{msg, {}};
  }
  return db;
}

}  // namespace

FileResult<std::unique_ptr<SqliteStore>> SqliteStore::create(const std::string& dir, const WorldMeta& meta) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return FileError{"world " + dir + ": cannot create directory: " + ec.message(), {}};
  if (exists(dir)) return FileError{"world " + dir + ": already exists (" + kWorldDatabaseName + " present)", {}};
  if (auto why = meta.bounds.validate(); !why.empty()) return FileError{"world " + dir + ": " + why, {}};
  if (meta.materials.size() > static_cast<std::size_t>(kMaterialCount))
    return FileError{"world " + dir + ": material table has more than 64 entries", {}};
  auto result = create_in(dir, meta);
  if (!result) {
    // Leave no half-made world behind: it could be neither opened nor created again.
    const std::filesystem::path db_path = std::filesystem::path(dir) / kWorldDatabaseName;
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(db_path.string() + suffix, ec);
  }
  return result;
}

FileResult<std::unique_ptr<SqliteStore>> SqliteStore::create_in(const std::string& dir, const WorldMeta& meta) {
  auto db = open_db(dir, true);
  if (!db) return db.error();
  std::unique_ptr<SqliteStore> store(new SqliteStore(dir, *db));
  const char* schema =
      "CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT NOT NULL) WITHOUT ROWID;"
      "CREATE TABLE chunks(cx INTEGER NOT NULL, cy INTEGER NOT NULL, cz INTEGER NOT NULL,"
      " revision INTEGER NOT NULL, data BLOB NOT NULL, PRIMARY KEY(cx, cy, cz)) WITHOUT ROWID;";
  char* err = nullptr;
  if (sqlite3_exec(store->db(), schema, nullptr, nullptr, &err) != SQLITE_OK ||
      sqlite3_exec(store->db(), SqliteCoarseImages::kSchema, nullptr, nullptr, &err) != SQLITE_OK) {
    std::string msg = err ? err : "?";
    sqlite3_free(err);
    return FileError{"world " + dir + ": cannot create schema: " + msg, {}};
  }
  if (auto s = store->quarantine_.ensure_table(); !s) return s.error();
  if (auto s = store->write_meta(meta); !s) return s.error();
  if (auto s = store->load_meta(); !s) return s.error();
  return store;
}

FileResult<std::unique_ptr<SqliteStore>> SqliteStore::open(const std::string& dir, const Progress& progress) {
  if (!exists(dir)) return FileError{"world " + dir + ": no world here (" + kWorldDatabaseName + " missing)", {}};
  auto db = open_db(dir, false);
  if (!db) return db.error();
  std::unique_ptr<SqliteStore> store(new SqliteStore(dir, *db));
  if (auto s = store->load_meta(); !s) return s.error();
  if (auto s = store->quarantine_.ensure_table(); !s) return s.error();
  if (store->meta_.format_version < kWorldFormatVersion)
    if (auto s = store->upgrade(progress); !s) return s.error();
  return store;
}

FileStatus SqliteStore::upgrade(const Progress& progress) {
  const std::string current = std::to_string(kWorldFormatVersion);
  SqliteTransaction tx(db());
  if (!tx.began()) return error("cannot begin the upgrade to format " + current);
  // Another process may have upgraded it while this one waited for the lock.
  std::string stored;
  {
    sqlite3_stmt* v = nullptr;
    if (sqlite3_prepare_v2(db(), "SELECT value FROM meta WHERE key = 'format_version'", -1, &v, nullptr) == SQLITE_OK &&
        sqlite3_step(v) == SQLITE_ROW)
      stored = sqlite_column_string(v, 0);
    sqlite3_finalize(v);
  }
  if (stored == current) {
    tx.commit();
    meta_.format_version = kWorldFormatVersion;
    return Ok{};
  }
  // Format 1 -> 2: the coarse images, built from every chunk.
  if (stored == "1") {
    auto total = stored_chunk_count();
    if (!total) return total.error();
    auto last = std::chrono::steady_clock::now();
    const auto report = [&](std::int64_t done, bool final) {
      if (progress) return progress(done, *total);
      const auto now = std::chrono::steady_clock::now();
      if (!final && now - last < std::chrono::seconds(2)) return;
      last = now;
      std::fprintf(stderr, "world %s: building coarse images (format 2): %lld/%lld chunks\n", dir_.c_str(),
                   static_cast<long long>(done), static_cast<long long>(*total));
    };
    std::int64_t done = 0;
    auto built = coarse_.rebuild([this](const SqliteCoarseImages::ChunkRowFn& fn) { return for_each_chunk(fn); },
                                 [&] { report(++done, false); });
    if (!built) return built.error();
    report(done, true);
  }
  // Format 2 -> 3: chunk blobs of codec 2 (chunk images) are written from
  // now on; the stored codec-1 blobs stay and are read as they are, so this
  // is the version alone. A reader of format 2 refuses the world from here
  // on, so it never meets a blob it cannot read.
  const std::string set = "INSERT OR REPLACE INTO meta(key, value) VALUES('format_version', '" + current + "')";
  if (sqlite3_exec(db(), set.c_str(), nullptr, nullptr, nullptr) != SQLITE_OK)
    return error("cannot record format " + current);
  if (!tx.commit()) return error("cannot commit the upgrade to format " + current);
  meta_.format_version = kWorldFormatVersion;
  return Ok{};
}

FileStatus SqliteStore::begin_read() {
  if (sqlite3_exec(db(), "BEGIN", nullptr, nullptr, nullptr) != SQLITE_OK) return error("cannot begin a read");
  return Ok{};
}

void SqliteStore::end_read() { sqlite3_exec(db(), "COMMIT", nullptr, nullptr, nullptr); }

FileResult<std::vector<CoarseEntry>> SqliteStore::load_coarse(Vec3i region) { return coarse_.load(region); }

FileResult<std::vector<Vec3i>> SqliteStore::quarantined_in(Vec3i region) { return quarantine_.in_region(region); }

FileResult<std::vector<Vec3i>> SqliteStore::stored_in(Vec3i region) {
  return sqlite_chunks_in_region(db(), dir_, "chunks", region);
}

FileStatus SqliteStore::for_each_coarse(const std::function<void(Vec3i, const std::vector<CoarseEntry>&)>& fn) {
  return coarse_.for_each(fn);
}

FileStatus SqliteStore::write_meta(const WorldMeta& m) {
  const auto kv = meta_to_keys(m);
  SqliteTransaction tx(db());
  if (!tx.began()) return error("cannot begin metadata transaction");
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db(), "INSERT OR REPLACE INTO meta(key, value) VALUES(?, ?)", -1, &st, nullptr) != SQLITE_OK)
    return error("cannot write metadata");
  for (const auto& [k, v] : kv) {
    sqlite3_bind_text(st, 1, k.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(st, 2, v.c_str(), -1, SQLITE_TRANSIENT);
    if (sqlite3_step(st) != SQLITE_DONE) {
      FileError e = error("cannot write metadata key " + k);
      sqlite3_finalize(st);
      return e;
    }
    sqlite3_reset(st);
  }
  sqlite3_finalize(st);
  if (!tx.commit()) return error("cannot commit metadata");
  return Ok{};
}

FileStatus SqliteStore::load_meta() {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db(), "SELECT key, value FROM meta", -1, &st, nullptr) != SQLITE_OK)
    return error("not a Terrane world database (no meta table)");
  std::vector<std::pair<std::string, std::string>> kv;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    const auto* k = reinterpret_cast<const char*>(sqlite3_column_text(st, 0));
    const auto* v = reinterpret_cast<const char*>(sqlite3_column_text(st, 1));
    if (k && v) kv.emplace_back(k, v);
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot read metadata");
  auto m = meta_from_keys(kv, "world " + dir_);
  if (!m) return m.error();
  meta_ = std::move(*m);
  return Ok{};
}

FileResult<std::vector<std::pair<std::string, std::string>>> SqliteStore::access_entries() {
  return access_.entries();
}

FileStatus SqliteStore::put_access(const std::string& key, const std::string& value) {
  return access_.put(key, value);
}

FileStatus SqliteStore::erase_access(const std::string& key) { return access_.erase(key); }

FileStatus SqliteStore::set_bounds(const WorldBounds& bounds) {
  if (auto why = bounds.validate(); !why.empty()) return FileError{"world " + dir_ + ": " + why, {}};
  WorldMeta m = meta_;
  m.bounds = bounds;
  if (auto s = write_meta(m); !s) return s;
  meta_.bounds = bounds;
  return Ok{};
}

FileResult<std::uint64_t> SqliteStore::name_world(std::uint64_t candidate) {
  // One server at a time writes a SQLite world (its lock), so no race.
  if (meta_.world_id != 0) return meta_.world_id;
  WorldMeta m = meta_;
  m.world_id = candidate;
  if (auto s = write_meta(m); !s) return s.error();
  meta_.world_id = candidate;
  return candidate;
}

FileStatus SqliteStore::set_epoch(std::uint64_t epoch) {
  WorldMeta m = meta_;
  m.epoch = epoch;
  if (auto s = write_meta(m); !s) return s;
  meta_.epoch = epoch;
  return Ok{};
}

FileResult<std::optional<StoredChunk>> SqliteStore::load_chunk(Vec3i pos) {
  if (!load_stmt_ &&
      sqlite3_prepare_v2(db(), "SELECT revision, data FROM chunks WHERE cx = ? AND cy = ? AND cz = ?", -1,
                         &load_stmt_, nullptr) != SQLITE_OK)
    return error("cannot prepare chunk read");
  SqliteStmtReset reset{load_stmt_};
  sqlite3_bind_int(load_stmt_, 1, pos.x);
  sqlite3_bind_int(load_stmt_, 2, pos.y);
  sqlite3_bind_int(load_stmt_, 3, pos.z);
  const int rc = sqlite3_step(load_stmt_);
  if (rc == SQLITE_DONE) return std::optional<StoredChunk>{};
  if (rc != SQLITE_ROW) return error("cannot read chunk");
  const auto revision = static_cast<std::uint64_t>(sqlite3_column_int64(load_stmt_, 0));
  const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(load_stmt_, 1));
  const auto size = static_cast<std::size_t>(sqlite3_column_bytes(load_stmt_, 1));
  auto chunk = decode_chunk_blob(std::span<const std::uint8_t>(data, data ? size : 0));
  if (!chunk) {
    std::ostringstream msg;
    msg << "world " << dir_ << ": chunk (" << pos.x << ", " << pos.y << ", " << pos.z
        << ") is damaged: " << chunk.error().describe();
    return FileError{msg.str(), chunk.error()};
  }
  return std::optional<StoredChunk>{StoredChunk{revision, std::move(*chunk)}};
}

FileStatus SqliteStore::save_chunks(std::span<const ChunkWrite> writes, bool overwrite,
                                   std::span<const EditLogEntry> log) {
  sqlite3_stmt*& stmt = overwrite ? save_stmt_ : insert_stmt_;
  if (!stmt && sqlite3_prepare_v2(db(),
                                  overwrite ? "INSERT OR REPLACE INTO chunks(cx, cy, cz, revision, data) VALUES(?, ?, ?, ?, ?)"
                                            : "INSERT OR IGNORE INTO chunks(cx, cy, cz, revision, data) VALUES(?, ?, ?, ?, ?)",
                                  -1, &stmt, nullptr) != SQLITE_OK)
    return error("cannot prepare chunk write");
  sqlite3_stmt* save_stmt = stmt;
  SqliteTransaction tx(db());
  if (!tx.began()) return error("cannot begin transaction");
  auto logged_bytes = edit_log_.append(log);
  if (!logged_bytes) return logged_bytes.error();
  std::vector<CoarseEntry> coarse;
  std::vector<Vec3i> no_coarse;  // blobs that do not decode: no entry (a load quarantines them)
  for (const ChunkWrite& w : writes) {
    SqliteStmtReset reset{save_stmt};
    sqlite3_bind_int(save_stmt, 1, w.pos.x);
    sqlite3_bind_int(save_stmt, 2, w.pos.y);
    sqlite3_bind_int(save_stmt, 3, w.pos.z);
    sqlite3_bind_int64(save_stmt, 4, static_cast<sqlite3_int64>(w.revision));
    sqlite3_bind_blob(save_stmt, 5, w.blob.data(), static_cast<int>(w.blob.size()), SQLITE_STATIC);
    if (sqlite3_step(save_stmt) != SQLITE_DONE) return error("cannot write chunk");
    if (sqlite3_changes(db()) == 0) continue;  // kept as it was (overwrite = false)
    CoarseEntry e{w.pos, w.revision, {}};
    if (w.coarse) {
      e.voxels = *w.coarse;
    } else if (auto chunk = decode_chunk_blob(w.blob)) {
      e.voxels = coarse_voxels(&*chunk);
    } else {
      no_coarse.push_back(w.pos);
      continue;
    }
    coarse.push_back(e);
  }
  if (auto c = coarse_.written(coarse, no_coarse); !c) return c.error();
  if (!tx.commit()) return error("cannot commit chunks");
  edit_log_.committed(log.size(), *logged_bytes);
  coarse_.committed(std::move(coarse));
  return Ok{};
}

void SqliteStore::repair_coarse(Vec3i region) { coarse_.repair(region); }

FileResult<std::size_t> SqliteStore::catch_up_coarse(std::size_t max_regions,
                                                    std::chrono::steady_clock::duration min_age) {
  return coarse_.catch_up(max_regions, min_age);
}

FileResult<std::vector<EditLogEntry>> SqliteStore::edit_log(const EditLogQuery& q) { return edit_log_.query(q); }

FileResult<std::int64_t> SqliteStore::prune_edit_log(std::int64_t before_ms, std::uint64_t max_bytes,
                                                    std::int64_t max_rows) {
  return edit_log_.prune(before_ms, max_bytes, max_rows);
}

FileResult<EditLogSize> SqliteStore::edit_log_size() { return edit_log_.size(); }

FileStatus SqliteStore::erase_chunk(Vec3i pos) {
  SqliteTransaction tx(db());
  if (!tx.began()) return error("cannot begin chunk delete");
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db(), "DELETE FROM chunks WHERE cx = ? AND cy = ? AND cz = ?", -1, &st, nullptr) != SQLITE_OK)
    return error("cannot prepare chunk delete");
  sqlite3_bind_int(st, 1, pos.x);
  sqlite3_bind_int(st, 2, pos.y);
  sqlite3_bind_int(st, 3, pos.z);
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot delete chunk");
  if (auto c = coarse_.erased(pos); !c) return c.error();
  if (!tx.commit()) return error("cannot commit chunk delete");
  return Ok{};
}

FileResult<std::optional<std::uint64_t>> SqliteStore::quarantine_chunk(Vec3i pos, const std::string& reason) {
  // The chunk is no longer stored: its coarse entry goes with it.
  return quarantine_.move_aside(pos, reason, [&] { return coarse_.erased(pos); });
}

FileResult<std::optional<std::uint64_t>> SqliteStore::quarantined_revision(Vec3i pos) {
  return quarantine_.revision(pos);
}

FileStatus SqliteStore::for_each_quarantined(const std::function<void(const QuarantinedChunk&)>& fn) {
  return quarantine_.for_each(fn);
}

FileResult<std::int64_t> SqliteStore::quarantined_count() { return quarantine_.count(); }

FileStatus SqliteStore::for_each_chunk(
    const std::function<void(Vec3i, std::uint64_t, std::span<const std::uint8_t>)>& fn) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db(), "SELECT cx, cy, cz, revision, data FROM chunks ORDER BY cx, cy, cz", -1, &st,
                         nullptr) != SQLITE_OK)
    return error("cannot list chunks");
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    const Vec3i pos{sqlite3_column_int(st, 0), sqlite3_column_int(st, 1), sqlite3_column_int(st, 2)};
    const auto rev = static_cast<std::uint64_t>(sqlite3_column_int64(st, 3));
    const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(st, 4));
    const auto size = static_cast<std::size_t>(sqlite3_column_bytes(st, 4));
    fn(pos, rev, std::span<const std::uint8_t>(data, data ? size : 0));
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot list chunks");
  return Ok{};
}

FileResult<std::int64_t> SqliteStore::stored_chunk_count() {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db(), "SELECT count(*) FROM chunks", -1, &st, nullptr) != SQLITE_OK)
    return error("cannot count chunks");
  std::int64_t n = -1;
  if (sqlite3_step(st) == SQLITE_ROW) n = sqlite3_column_int64(st, 0);
  sqlite3_finalize(st);
  if (n < 0) return error("cannot count chunks");
  return n;
}

FileStatus SqliteStore::backup_to(const std::string& dest_dir, const std::function<void(int, int)>& progress) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (exists(dest_dir)) return FileError{"backup " + dest_dir + ": already holds a world", {}};
  // The copy is made in DEST.partial and renamed to DEST once whole: a
  // failed backup (a full disk, an I/O error) leaves neither DEST nor
  // DEST.partial, and DEST is never a half-written world. A DEST.partial
  // left by a backup that was killed is replaced.
  fs::path dest = fs::path(dest_dir).lexically_normal();
  if (!dest.has_filename()) dest = dest.parent_path();
  const fs::path partial = fs::path(dest.string() + ".partial");
  if (dest.has_parent_path()) {
    fs::create_directories(dest.parent_path(), ec);
    if (ec) return FileError{"backup " + dest_dir + ": cannot create directory: " + ec.message(), {}};
  }
  fs::remove_all(partial, ec);
  fs::create_directory(partial, ec);
  if (ec) return FileError{"backup " + dest_dir + ": cannot create " + partial.string() + ": " + ec.message(), {}};
  const auto failed = [&](std::string msg) -> FileStatus {
    std::error_code ignored;
    fs::remove_all(partial, ignored);
    return FileError{std::move(msg), {}};
  };
  const std::string path = (partial / kWorldDatabaseName).string();
  sqlite3* dest_db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &dest_db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr) != SQLITE_OK) {
    std::string msg = "backup " + path + ": cannot create: " + (dest_db ? sqlite3_errmsg(dest_db) : "out of memory");
    sqlite3_close(dest_db);
    return failed(std::move(msg));
  }
  sqlite3_backup* b = sqlite3_backup_init(dest_db, "main", db(), "main");
  if (b == nullptr) {
    std::string msg = "backup " + path + ": " + sqlite3_errmsg(dest_db);
    sqlite3_close(dest_db);
    return failed(std::move(msg));
  }
  // 256 pages per step (1 MiB at 4 KiB pages): short steps let the writer in.
  int rc;
  do {
    rc = sqlite3_backup_step(b, 256);
    if (progress) progress(sqlite3_backup_pagecount(b) - sqlite3_backup_remaining(b), sqlite3_backup_pagecount(b));
    if (rc == SQLITE_BUSY || rc == SQLITE_LOCKED) sqlite3_sleep(20);
  } while (rc == SQLITE_OK || rc == SQLITE_BUSY || rc == SQLITE_LOCKED);
  sqlite3_backup_finish(b);
  std::string msg = rc == SQLITE_DONE ? "" : std::string(sqlite3_errmsg(dest_db));
  // The copy is a world of its own once served: its first server start names
  // it (WorldMeta::world_id), so clients never take its chunks for the
  // original's at an equal revision.
  if (rc == SQLITE_DONE &&
      sqlite3_exec(dest_db, "UPDATE meta SET value = '0' WHERE key = 'world_id'", nullptr, nullptr, nullptr) != SQLITE_OK) {
    rc = SQLITE_ERROR;
    msg = sqlite3_errmsg(dest_db);
  }
  if (rc == SQLITE_DONE && sqlite3_exec(dest_db, "PRAGMA journal_mode=WAL;", nullptr, nullptr, nullptr) != SQLITE_OK) {
    rc = SQLITE_ERROR;
    msg = sqlite3_errmsg(dest_db);
  }
  if (sqlite3_close(dest_db) != SQLITE_OK && rc == SQLITE_DONE) {
    rc = SQLITE_ERROR;
    msg = "cannot close the copy";
  }
  if (rc != SQLITE_DONE) return failed("backup " + dest.string() + ": " + msg);
  fs::rename(partial, dest, ec);
  if (ec) return failed("backup " + dest.string() + ": cannot rename " + partial.string() + " to it: " + ec.message());
  return Ok{};
}

FileResult<std::string> SqliteStore::pragma(const std::string& name) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db(), ("PRAGMA " + name).c_str(), -1, &st, nullptr) != SQLITE_OK)
    return error("cannot run pragma " + name);
  std::string out;
  if (sqlite3_step(st) == SQLITE_ROW) out = sqlite_column_string(st, 0);
  sqlite3_finalize(st);
  return out;
}

}  // namespace terrane
