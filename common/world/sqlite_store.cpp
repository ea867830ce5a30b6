#include "common/world/sqlite_store.h"

#include <sqlite3.h>

#include <algorithm>
#include <charconv>
#include <climits>
#include <chrono>
#include <cstdio>
#include <limits>
#include <map>
#include <set>
#include <tuple>
#include <filesystem>
#include <sstream>

#include "common/cli/cli.h"
#include "common/codec/lz4_block.h"

namespace terrane {

namespace {


// Added to format 1 after its first release: worlds made before it gain the
// table the first time they are opened (readers that do not know it ignore it).
constexpr const char* kQuarantineSchema =
    "CREATE TABLE IF NOT EXISTS quarantine(id INTEGER PRIMARY KEY,"
    " cx INTEGER NOT NULL, cy INTEGER NOT NULL, cz INTEGER NOT NULL,"
    " revision INTEGER NOT NULL, data BLOB NOT NULL, reason TEXT NOT NULL, time INTEGER NOT NULL);"
    "CREATE INDEX IF NOT EXISTS quarantine_chunk ON quarantine(cx, cy, cz);";

// Format 2: the coarse images (common/world/coarse_image.h), one row per region.
constexpr const char* kCoarseSchema =
    "CREATE TABLE IF NOT EXISTS coarse(rx INTEGER NOT NULL, ry INTEGER NOT NULL, rz INTEGER NOT NULL,"
    " image BLOB NOT NULL, PRIMARY KEY(rx, ry, rz)) WITHOUT ROWID;";

// RAII for one prepared statement use: reset on scope exit.
struct StmtReset {
  sqlite3_stmt* s;
  ~StmtReset() {
    sqlite3_reset(s);
    sqlite3_clear_bindings(s);
  }
};

}  // namespace

SqliteStore::SqliteStore(std::string dir, sqlite3* db) : dir_(std::move(dir)), db_(db) {}

SqliteStore::~SqliteStore() {
  sqlite3_finalize(load_stmt_);
  sqlite3_finalize(save_stmt_);
  sqlite3_finalize(insert_stmt_);
  sqlite3_finalize(log_stmt_);
  sqlite3_finalize(quarantined_rev_stmt_);
  sqlite3_finalize(coarse_load_stmt_);
  sqlite3_finalize(coarse_save_stmt_);
  sqlite3_close(db_);
}

FileError SqliteStore::error(const std::string& what) const {
  return FileError{"world " + dir_ + ": " + what + (db_ ? std::string(": ") + sqlite3_errmsg(db_) : ""), {}};
}

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
  if (sqlite3_exec(store->db_, schema, nullptr, nullptr, &err) != SQLITE_OK ||
      sqlite3_exec(store->db_, kCoarseSchema, nullptr, nullptr, &err) != SQLITE_OK) {
    std::string msg = err ? err : "?";
    sqlite3_free(err);
    return FileError{"world " + dir + ": cannot create schema: " + msg, {}};
  }
  if (auto s = store->ensure_quarantine_table(); !s) return s.error();
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
  if (auto s = store->ensure_quarantine_table(); !s) return s.error();
  if (store->meta_.format_version < kWorldFormatVersion)
    if (auto s = store->upgrade_to_coarse(progress); !s) return s.error();
  return store;
}

FileStatus SqliteStore::upgrade_to_coarse(const Progress& progress) {
  auto total = stored_chunk_count();
  if (!total) return total.error();
  const auto start = std::chrono::steady_clock::now();
  auto last = start;
  const auto report = [&](std::int64_t done, bool final) {
    if (progress) return progress(done, *total);
    const auto now = std::chrono::steady_clock::now();
    if (!final && now - last < std::chrono::seconds(2)) return;
    last = now;
    std::fprintf(stderr, "world %s: building coarse images (format 2): %lld/%lld chunks\n", dir_.c_str(),
                 static_cast<long long>(done), static_cast<long long>(*total));
  };
  if (sqlite3_exec(db_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) != SQLITE_OK)
    return error("cannot begin the upgrade to format 2");
  const auto fail = [&](FileError e) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return e;
  };
  // Another process may have upgraded it while this one waited for the lock.
  {
    sqlite3_stmt* v = nullptr;
    bool done_already = false;
    if (sqlite3_prepare_v2(db_, "SELECT value FROM meta WHERE key = 'format_version'", -1, &v, nullptr) == SQLITE_OK &&
        sqlite3_step(v) == SQLITE_ROW)
      done_already = std::string(reinterpret_cast<const char*>(sqlite3_column_text(v, 0))) == "2";
    sqlite3_finalize(v);
    if (done_already) {
      sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr);
      meta_.format_version = kWorldFormatVersion;
      return Ok{};
    }
  }
  if (sqlite3_exec(db_, kCoarseSchema, nullptr, nullptr, nullptr) != SQLITE_OK ||
      sqlite3_exec(db_, "DELETE FROM coarse", nullptr, nullptr, nullptr) != SQLITE_OK)
    return fail(error("cannot create the coarse table"));
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "INSERT INTO coarse(rx, ry, rz, image) VALUES(?, ?, ?, ?)", -1, &st, nullptr) !=
      SQLITE_OK)
    return fail(error("cannot write coarse images"));
  // Chunks come in cx order: a region is complete (and written, so memory
  // stays bounded) once cx has passed it.
  std::map<std::tuple<int, int, int>, std::vector<CoarseEntry>> regions;
  bool write_failed = false;
  const auto write_before = [&](int rx_limit) {
    for (auto it = regions.begin(); it != regions.end() && std::get<0>(it->first) < rx_limit;) {
      const Vec3i r{std::get<0>(it->first), std::get<1>(it->first), std::get<2>(it->first)};
      const std::vector<std::uint8_t> image = encode_coarse_image(r, std::move(it->second));
      sqlite3_bind_int(st, 1, r.x);
      sqlite3_bind_int(st, 2, r.y);
      sqlite3_bind_int(st, 3, r.z);
      sqlite3_bind_blob(st, 4, image.data(), static_cast<int>(image.size()), SQLITE_STATIC);
      write_failed = write_failed || sqlite3_step(st) != SQLITE_DONE;
      sqlite3_reset(st);
      sqlite3_clear_bindings(st);
      it = regions.erase(it);
    }
  };
  std::int64_t done = 0;
  auto listed = for_each_chunk([&](Vec3i pos, std::uint64_t revision, std::span<const std::uint8_t> blob) {
    const Vec3i r = coarse_region_of(pos);
    write_before(r.x);
    // A damaged chunk gets no entry: it is served as its load decides
    // (quarantined and generated).
    if (auto chunk = decode_chunk_blob(blob))
      regions[{r.x, r.y, r.z}].push_back(CoarseEntry{pos, revision, coarse_voxels(&*chunk)});
    report(++done, false);
  });
  write_before(std::numeric_limits<int>::max());
  sqlite3_finalize(st);
  if (!listed) return fail(listed.error());
  if (write_failed) return fail(error("cannot write coarse images"));
  if (sqlite3_exec(db_, "INSERT OR REPLACE INTO meta(key, value) VALUES('format_version', '2')", nullptr, nullptr,
                   nullptr) != SQLITE_OK)
    return fail(error("cannot record format 2"));
  if (sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK)
    return fail(error("cannot commit the upgrade to format 2"));
  meta_.format_version = kWorldFormatVersion;
  report(done, true);
  return Ok{};
}

FileStatus SqliteStore::change_coarse(const std::vector<CoarseEntry>& set, const std::vector<Vec3i>& erase,
                                      const std::set<RegionKey>& repair, bool heal_all) {
  if (set.empty() && erase.empty() && repair.empty()) return Ok{};
  if (!coarse_save_stmt_ && sqlite3_prepare_v2(db_, "INSERT OR REPLACE INTO coarse(rx, ry, rz, image) VALUES(?, ?, ?, ?)",
                                               -1, &coarse_save_stmt_, nullptr) != SQLITE_OK)
    return error("cannot prepare coarse image write");
  // Per region: the image as stored, changed, written back.
  std::map<std::tuple<int, int, int>, std::pair<std::vector<const CoarseEntry*>, std::vector<Vec3i>>> by_region;
  for (const CoarseEntry& e : set) {
    const Vec3i r = coarse_region_of(e.chunk_pos);
    by_region[{r.x, r.y, r.z}].first.push_back(&e);
  }
  for (const Vec3i p : erase) {
    const Vec3i r = coarse_region_of(p);
    by_region[{r.x, r.y, r.z}].second.push_back(p);
  }
  for (const RegionKey& key : repair) by_region.try_emplace(key);
  for (const auto& [key, change] : by_region) {
    const Vec3i r{std::get<0>(key), std::get<1>(key), std::get<2>(key)};
    auto stored = read_image(r);
    if (!stored && !stored.error().decode) return stored.error();
    if (!stored) {
      // A damaged image is derived data: made again from the region's rows.
      auto rebuilt = read_past(r, {});
      if (!rebuilt) return rebuilt.error();
      stored = std::move(*rebuilt);
    }
    std::map<int, CoarseEntry> entries;
    for (CoarseEntry& e : *stored) entries[coarse_index(e.chunk_pos)] = std::move(e);
    for (const Vec3i p : change.second) entries.erase(coarse_index(p));
    for (const CoarseEntry* e : change.first) entries[coarse_index(e->chunk_pos)] = *e;
    std::vector<CoarseEntry> all;
    all.reserve(entries.size());
    for (auto& [i, e] : entries) all.push_back(std::move(e));
    // Whatever else of the region was behind its rows (a writer that
    // stopped before catching up) is made right with it: by the tools on
    // every write, by a server's writer where a load found it behind (its
    // own changes waiting are all it has to add otherwise, and this costs
    // a scan of the region's rows).
    if (heal_all || repair.count(key) != 0) {
      auto whole = read_past(r, std::move(all));
      if (!whole) return whole.error();
      all = std::move(*whole);
    }
    const std::vector<std::uint8_t> image = encode_coarse_image(r, std::move(all));
    StmtReset reset{coarse_save_stmt_};
    sqlite3_bind_int(coarse_save_stmt_, 1, r.x);
    sqlite3_bind_int(coarse_save_stmt_, 2, r.y);
    sqlite3_bind_int(coarse_save_stmt_, 3, r.z);
    sqlite3_bind_blob(coarse_save_stmt_, 4, image.data(), static_cast<int>(image.size()), SQLITE_STATIC);
    if (sqlite3_step(coarse_save_stmt_) != SQLITE_DONE) return error("cannot write coarse image");
  }
  return Ok{};
}

FileStatus SqliteStore::begin_read() {
  if (sqlite3_exec(db_, "BEGIN", nullptr, nullptr, nullptr) != SQLITE_OK) return error("cannot begin a read");
  return Ok{};
}

void SqliteStore::end_read() { sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr); }

FileResult<std::vector<CoarseEntry>> SqliteStore::load_coarse(Vec3i region) {
  auto image = read_image(region);
  if (!image) return image.error();
  return read_past(region, std::move(*image), &coarse_read_behind_);
}

FileResult<std::vector<CoarseEntry>> SqliteStore::read_past(Vec3i region, std::vector<CoarseEntry> entries,
                                                            bool* behind) {
  // The rows are the truth: an entry whose row has another revision (its
  // image not caught up: set_coarse_behind) is made from the row, and one
  // whose row went is dropped. A row with no entry is either newer than
  // the image or damaged: decoded, it gets one if it decodes.
  auto rows = revisions_in(region);
  if (!rows) return rows.error();
  std::map<int, std::uint64_t> revision;
  for (const auto& [p, rev] : *rows) revision[coarse_index(p)] = rev;
  std::vector<CoarseEntry> out;
  out.reserve(rows->size());
  for (CoarseEntry& e : entries) {
    auto it = revision.find(coarse_index(e.chunk_pos));
    if (it != revision.end() && it->second == e.revision) out.push_back(std::move(e));
  }
  const auto by_index = [](const CoarseEntry& a, const CoarseEntry& b) {
    return coarse_index(a.chunk_pos) < coarse_index(b.chunk_pos);
  };
  // Behind: an entry was dropped (another revision, or no row) or a row
  // had none.
  if (behind != nullptr) *behind = out.size() != entries.size() || out.size() != rows->size();
  if (out.size() < rows->size()) {
    std::set<int> have;
    for (const CoarseEntry& e : out) have.insert(coarse_index(e.chunk_pos));
    for (const auto& [p, rev] : *rows) {
      if (have.count(coarse_index(p)) != 0) continue;
      auto stored = load_chunk(p);
      if (!stored && !stored.error().decode) return stored.error();
      // A damaged row gets no entry (its load quarantines it).
      if (stored && stored->has_value())
        out.push_back(CoarseEntry{p, (*stored)->revision, coarse_voxels(&(*stored)->chunk)});
    }
  }
  if (!std::is_sorted(out.begin(), out.end(), by_index)) std::sort(out.begin(), out.end(), by_index);
  return out;
}

FileResult<std::vector<CoarseEntry>> SqliteStore::read_image(Vec3i region) {
  if (!coarse_load_stmt_ && sqlite3_prepare_v2(db_, "SELECT image FROM coarse WHERE rx = ? AND ry = ? AND rz = ?", -1,
                                               &coarse_load_stmt_, nullptr) != SQLITE_OK)
    return error("cannot prepare coarse image read");
  StmtReset reset{coarse_load_stmt_};
  sqlite3_bind_int(coarse_load_stmt_, 1, region.x);
  sqlite3_bind_int(coarse_load_stmt_, 2, region.y);
  sqlite3_bind_int(coarse_load_stmt_, 3, region.z);
  const int rc = sqlite3_step(coarse_load_stmt_);
  if (rc == SQLITE_DONE) return std::vector<CoarseEntry>{};
  if (rc != SQLITE_ROW) return error("cannot read coarse image");
  const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(coarse_load_stmt_, 0));
  const auto size = static_cast<std::size_t>(sqlite3_column_bytes(coarse_load_stmt_, 0));
  auto entries = decode_coarse_image(region, std::span<const std::uint8_t>(data, data ? size : 0));
  if (!entries) {
    std::ostringstream msg;
    msg << "world " << dir_ << ": the coarse image of region (" << region.x << ", " << region.y << ", " << region.z
        << ") is damaged: " << entries.error().describe();
    return FileError{msg.str(), entries.error()};
  }
  return std::move(*entries);
}

namespace {
// The chunk coordinates of table rows within a region (an index range scan),
// and with revisions set, each row's revision (the chunks table: one row
// per chunk).
FileResult<std::vector<Vec3i>> chunks_in_region(sqlite3* db, const char* table, Vec3i region,
                                                const std::function<FileError(const std::string&)>& error,
                                                std::vector<std::uint64_t>* revisions = nullptr) {
  sqlite3_stmt* st = nullptr;
  // cx and cy as lists, so the (cx, cy, cz) index is used for all three
  // (a range on cx alone would scan an 8-wide slab of the whole world).
  const Vec3i lo = region * kCoarseRegionChunks;
  std::string sql = revisions != nullptr ? "SELECT cx, cy, cz, revision FROM " : "SELECT DISTINCT cx, cy, cz FROM ";
  sql.append(table);
  for (const auto& [column, first] : {std::pair<const char*, int>{" WHERE cx IN (", lo.x}, {") AND cy IN (", lo.y}}) {
    sql.append(column);
    for (int i = 0; i < kCoarseRegionChunks; ++i) {
      if (i > 0) sql.push_back(',');
      sql.append(std::to_string(first + i));
    }
  }
  sql.append(") AND cz BETWEEN ?1 AND ?2");
  const auto read_error = [&] {
    std::string what = "cannot read the ";
    what.append(table).append(" table");
    return error(what);
  };
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &st, nullptr) != SQLITE_OK) return read_error();
  sqlite3_bind_int(st, 1, lo.z);
  sqlite3_bind_int(st, 2, lo.z + kCoarseRegionChunks - 1);
  std::vector<Vec3i> out;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    out.push_back(Vec3i{sqlite3_column_int(st, 0), sqlite3_column_int(st, 1), sqlite3_column_int(st, 2)});
    if (revisions != nullptr) revisions->push_back(static_cast<std::uint64_t>(sqlite3_column_int64(st, 3)));
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return read_error();
  return out;
}
}  // namespace

FileResult<std::vector<Vec3i>> SqliteStore::quarantined_in(Vec3i region) {
  return chunks_in_region(db_, "quarantine", region, [this](const std::string& w) { return error(w); });
}

FileResult<std::vector<Vec3i>> SqliteStore::stored_in(Vec3i region) {
  return chunks_in_region(db_, "chunks", region, [this](const std::string& w) { return error(w); });
}

FileResult<std::vector<std::pair<Vec3i, std::uint64_t>>> SqliteStore::revisions_in(Vec3i region) {
  std::vector<std::uint64_t> revisions;
  auto positions = chunks_in_region(db_, "chunks", region, [this](const std::string& w) { return error(w); }, &revisions);
  if (!positions) return positions.error();
  std::vector<std::pair<Vec3i, std::uint64_t>> out;
  out.reserve(positions->size());
  for (std::size_t i = 0; i < positions->size(); ++i) out.emplace_back((*positions)[i], revisions[i]);
  return out;
}

FileStatus SqliteStore::for_each_coarse(const std::function<void(Vec3i, const std::vector<CoarseEntry>&)>& fn) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT rx, ry, rz FROM coarse ORDER BY rx, ry, rz", -1, &st, nullptr) != SQLITE_OK)
    return error("cannot list coarse images");
  std::vector<Vec3i> regions;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW)
    regions.push_back(Vec3i{sqlite3_column_int(st, 0), sqlite3_column_int(st, 1), sqlite3_column_int(st, 2)});
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot list coarse images");
  for (const Vec3i r : regions) {
    auto entries = read_image(r);
    if (!entries) return entries.error();
    fn(r, *entries);
  }
  return Ok{};
}

FileStatus SqliteStore::ensure_quarantine_table() {
  // Look first: when the table exists (the usual case) opening stays a pure
  // read, so tools can open a world a server is writing without a write lock.
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'quarantine'", -1, &st,
                         nullptr) != SQLITE_OK)
    return error("cannot read schema");
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc == SQLITE_ROW) return Ok{};
  if (rc != SQLITE_DONE) return error("cannot read schema");
  char* err = nullptr;
  if (sqlite3_exec(db_, kQuarantineSchema, nullptr, nullptr, &err) != SQLITE_OK) {
    std::string msg = err ? err : "?";
    sqlite3_free(err);
    return FileError{"world " + dir_ + ": cannot create the quarantine table: " + msg, {}};
  }
  return Ok{};
}

FileStatus SqliteStore::write_meta(const WorldMeta& m) {
  const auto kv = meta_to_keys(m);
  if (sqlite3_exec(db_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) != SQLITE_OK)
    return error("cannot begin metadata transaction");
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "INSERT OR REPLACE INTO meta(key, value) VALUES(?, ?)", -1, &st, nullptr) != SQLITE_OK) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return error("cannot write metadata");
  }
  for (const auto& [k, v] : kv) {
    sqlite3_bind_text(st, 1, k.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(st, 2, v.c_str(), -1, SQLITE_TRANSIENT);
    if (sqlite3_step(st) != SQLITE_DONE) {
      sqlite3_finalize(st);
      sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
      return error("cannot write metadata key " + k);
    }
    sqlite3_reset(st);
  }
  sqlite3_finalize(st);
  if (sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK) {
    FileError e = error("cannot commit metadata");
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return e;
  }
  return Ok{};
}

FileStatus SqliteStore::load_meta() {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT key, value FROM meta", -1, &st, nullptr) != SQLITE_OK)
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

namespace {
constexpr const char* kEditLogSchema =
    "CREATE TABLE IF NOT EXISTS edit_log(id INTEGER PRIMARY KEY, tick INTEGER NOT NULL, time INTEGER NOT NULL,"
    " player TEXT NOT NULL, x0 INTEGER NOT NULL, y0 INTEGER NOT NULL, z0 INTEGER NOT NULL,"
    " x1 INTEGER NOT NULL, y1 INTEGER NOT NULL, z1 INTEGER NOT NULL, before BLOB NOT NULL, after BLOB NOT NULL);"
    "CREATE INDEX IF NOT EXISTS edit_log_player ON edit_log(player, id);"
    "CREATE INDEX IF NOT EXISTS edit_log_time ON edit_log(time);";

bool table_exists(sqlite3* db, const char* name) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", -1, &st, nullptr) !=
      SQLITE_OK)
    return false;
  sqlite3_bind_text(st, 1, name, -1, SQLITE_STATIC);
  const bool yes = sqlite3_step(st) == SQLITE_ROW;
  sqlite3_finalize(st);
  return yes;
}
}  // namespace

FileResult<std::vector<std::pair<std::string, std::string>>> SqliteStore::access_entries() {
  std::vector<std::pair<std::string, std::string>> out;
  if (!table_exists(db_, "access")) return out;  // made by the first write: nothing listed
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT key, value FROM access ORDER BY key", -1, &st, nullptr) != SQLITE_OK) {
    sqlite3_finalize(st);
    return error("cannot read the access lists");
  }
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW)
    out.emplace_back(reinterpret_cast<const char*>(sqlite3_column_text(st, 0)),
                     reinterpret_cast<const char*>(sqlite3_column_text(st, 1)));
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot read the access lists");
  return out;
}

FileStatus SqliteStore::put_access(const std::string& key, const std::string& value) {
  char* err = nullptr;
  if (sqlite3_exec(db_, "CREATE TABLE IF NOT EXISTS access(key TEXT PRIMARY KEY, value TEXT NOT NULL) WITHOUT ROWID",
                   nullptr, nullptr, &err) != SQLITE_OK) {
    sqlite3_free(err);
    return error("cannot create the access table");
  }
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "INSERT OR REPLACE INTO access(key, value) VALUES(?, ?)", -1, &st, nullptr) != SQLITE_OK)
    return error("cannot prepare an access write");
  sqlite3_bind_text(st, 1, key.data(), static_cast<int>(key.size()), SQLITE_TRANSIENT);
  sqlite3_bind_text(st, 2, value.data(), static_cast<int>(value.size()), SQLITE_TRANSIENT);
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot write the access lists");
  return Ok{};
}

FileStatus SqliteStore::erase_access(const std::string& key) {
  if (!table_exists(db_, "access")) return Ok{};  // no table: nothing to erase
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "DELETE FROM access WHERE key = ?", -1, &st, nullptr) != SQLITE_OK) {
    sqlite3_finalize(st);
    return error("cannot write the access lists");
  }
  sqlite3_bind_text(st, 1, key.data(), static_cast<int>(key.size()), SQLITE_TRANSIENT);
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot write the access lists");
  return Ok{};
}

FileStatus SqliteStore::set_bounds(const WorldBounds& bounds) {
  if (auto why = bounds.validate(); !why.empty()) return FileError{"world " + dir_ + ": " + why, {}};
  WorldMeta m = meta_;
  m.bounds = bounds;
  if (auto s = write_meta(m); !s) return s;
  meta_.bounds = bounds;
  return Ok{};
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
      sqlite3_prepare_v2(db_, "SELECT revision, data FROM chunks WHERE cx = ? AND cy = ? AND cz = ?", -1,
                         &load_stmt_, nullptr) != SQLITE_OK)
    return error("cannot prepare chunk read");
  StmtReset reset{load_stmt_};
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
  if (!stmt && sqlite3_prepare_v2(db_,
                                  overwrite ? "INSERT OR REPLACE INTO chunks(cx, cy, cz, revision, data) VALUES(?, ?, ?, ?, ?)"
                                            : "INSERT OR IGNORE INTO chunks(cx, cy, cz, revision, data) VALUES(?, ?, ?, ?, ?)",
                                  -1, &stmt, nullptr) != SQLITE_OK)
    return error("cannot prepare chunk write");
  sqlite3_stmt* save_stmt = stmt;
  if (sqlite3_exec(db_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) != SQLITE_OK)
    return error("cannot begin transaction");
  std::uint64_t logged_bytes = 0;
  if (!log.empty()) {
    if (!log_stmt_) {
      if (sqlite3_exec(db_, kEditLogSchema, nullptr, nullptr, nullptr) != SQLITE_OK ||
          sqlite3_prepare_v2(db_,
                             "INSERT INTO edit_log(tick, time, player, x0, y0, z0, x1, y1, z1, before, after)"
                             " VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                             -1, &log_stmt_, nullptr) != SQLITE_OK) {
        FileError e = error("cannot prepare the edit log");
        sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
        return e;
      }
    }
    for (const EditLogEntry& l : log) {
      logged_bytes += l.before.size() + l.after.size();
      StmtReset reset{log_stmt_};
      sqlite3_bind_int64(log_stmt_, 1, static_cast<sqlite3_int64>(l.tick));
      sqlite3_bind_int64(log_stmt_, 2, l.time_ms);
      sqlite3_bind_text(log_stmt_, 3, l.player.data(), static_cast<int>(l.player.size()), SQLITE_STATIC);
      const int c[6] = {l.box.min.x, l.box.min.y, l.box.min.z, l.box.max.x, l.box.max.y, l.box.max.z};
      for (int i = 0; i < 6; ++i) sqlite3_bind_int(log_stmt_, 4 + i, c[i]);
      sqlite3_bind_blob(log_stmt_, 10, l.before.data(), static_cast<int>(l.before.size()), SQLITE_STATIC);
      sqlite3_bind_blob(log_stmt_, 11, l.after.data(), static_cast<int>(l.after.size()), SQLITE_STATIC);
      if (sqlite3_step(log_stmt_) != SQLITE_DONE) {
        FileError e = error("cannot write the edit log");
        sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
        return e;
      }
    }
  }
  std::vector<CoarseEntry> coarse;
  std::vector<Vec3i> no_coarse;  // blobs that do not decode: no entry (a load quarantines them)
  for (const ChunkWrite& w : writes) {
    StmtReset reset{save_stmt};
    sqlite3_bind_int(save_stmt, 1, w.pos.x);
    sqlite3_bind_int(save_stmt, 2, w.pos.y);
    sqlite3_bind_int(save_stmt, 3, w.pos.z);
    sqlite3_bind_int64(save_stmt, 4, static_cast<sqlite3_int64>(w.revision));
    sqlite3_bind_blob(save_stmt, 5, w.blob.data(), static_cast<int>(w.blob.size()), SQLITE_STATIC);
    if (sqlite3_step(save_stmt) != SQLITE_DONE) {
      FileError e = error("cannot write chunk");
      sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
      return e;
    }
    if (sqlite3_changes(db_) == 0) continue;  // kept as it was (overwrite = false)
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
  // Behind: the entries wait in memory (loads read past them); an entry
  // that goes is taken out of the image now (rare: a blob that does not
  // decode), and out of what waits.
  if (coarse_behind_)
    for (const Vec3i p : no_coarse) {
      const Vec3i r = coarse_region_of(p);
      auto it = pending_coarse_.find({r.x, r.y, r.z});
      if (it == pending_coarse_.end()) continue;
      it->second.entries.erase(coarse_index(p));
      if (it->second.entries.empty() && !it->second.repair) pending_coarse_.erase(it);
    }
  if (auto c = change_coarse(coarse_behind_ ? std::vector<CoarseEntry>{} : coarse, no_coarse, {}, !coarse_behind_); !c) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return c.error();
  }
  if (sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK) {
    FileError e = error("cannot commit chunks");
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return e;
  }
  if (log_size_) {
    log_size_->first += static_cast<std::int64_t>(log.size());
    log_size_->second += logged_bytes;
  }
  if (coarse_behind_) {
    const auto now = std::chrono::steady_clock::now();
    for (CoarseEntry& e : coarse) {
      const Vec3i r = coarse_region_of(e.chunk_pos);
      auto [it, fresh] = pending_coarse_.try_emplace({r.x, r.y, r.z});
      if (fresh) it->second.since = now;
      CoarseEntry& slot = it->second.entries[coarse_index(e.chunk_pos)];
      if (slot.revision <= e.revision) slot = std::move(e);
    }
  }
  return Ok{};
}

void SqliteStore::repair_coarse(Vec3i region) {
  auto [it, fresh] = pending_coarse_.try_emplace({region.x, region.y, region.z});
  if (fresh) it->second.since = std::chrono::steady_clock::now();
  it->second.repair = true;
}

FileResult<std::size_t> SqliteStore::catch_up_coarse(std::size_t max_regions,
                                                    std::chrono::steady_clock::duration min_age) {
  if (pending_coarse_.empty() || max_regions == 0) return pending_coarse_.size();
  const auto now = std::chrono::steady_clock::now();
  const auto due = now - min_age;
  std::vector<std::pair<std::chrono::steady_clock::time_point, RegionKey>> oldest;
  for (const auto& [key, p] : pending_coarse_)
    if (p.since <= due) oldest.emplace_back(p.since, key);
  if (oldest.empty()) return pending_coarse_.size();
  if (oldest.size() > max_regions) {
    std::nth_element(oldest.begin(), oldest.begin() + static_cast<std::ptrdiff_t>(max_regions), oldest.end());
    oldest.resize(max_regions);
  }
  std::vector<CoarseEntry> set;
  std::set<RegionKey> repair;
  for (const auto& [since, key] : oldest) {
    const PendingImage& p = pending_coarse_.at(key);
    for (const auto& [i, e] : p.entries) set.push_back(e);
    if (p.repair) repair.insert(key);
  }
  const auto failed = [&](FileError e) -> FileResult<std::size_t> {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    // Tried again later, not at once: each failure doubles a region's wait
    // (kept at most a minute); after kMaxCoarseFailures its changes are
    // given up (the rows are the truth, and loads read past the image).
    for (const auto& [since, key] : oldest) {
      PendingImage& p = pending_coarse_.at(key);
      if (++p.failures >= kMaxCoarseFailures) {
        pending_coarse_.erase(key);
        continue;
      }
      p.since = now + std::min<std::chrono::steady_clock::duration>(std::chrono::seconds(1L << p.failures),
                                                                    std::chrono::minutes(1));
    }
    return e;
  };
  if (sqlite3_exec(db_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) != SQLITE_OK)
    return failed(error("cannot begin writing coarse images"));
  if (auto c = change_coarse(set, {}, repair, false); !c) return failed(c.error());
  if (sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK)
    return failed(error("cannot commit coarse images"));
  for (const auto& [since, key] : oldest) pending_coarse_.erase(key);
  return pending_coarse_.size();
}

FileResult<std::vector<EditLogEntry>> SqliteStore::edit_log(const EditLogQuery& q) {
  std::vector<EditLogEntry> out;
  if (!table_exists(db_, "edit_log")) return out;
  std::string sql = std::string("SELECT id, tick, time, player, x0, y0, z0, x1, y1, z1") +
                    (q.with_voxels ? ", before, after" : "") + " FROM edit_log WHERE time >= ?";
  if (!q.player.empty()) sql += " AND player = ?";
  if (q.box) sql += " AND x0 < ? AND x1 > ? AND y0 < ? AND y1 > ? AND z0 < ? AND z1 > ?";
  sql += " ORDER BY id DESC LIMIT ?";
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &st, nullptr) != SQLITE_OK) {
    sqlite3_finalize(st);
    return error("cannot read the edit log");
  }
  int n = 1;
  sqlite3_bind_int64(st, n++, q.since_ms);
  if (!q.player.empty()) sqlite3_bind_text(st, n++, q.player.data(), static_cast<int>(q.player.size()), SQLITE_STATIC);
  if (q.box) {
    const Region& b = *q.box;
    for (const int v : {b.max.x, b.min.x, b.max.y, b.min.y, b.max.z, b.min.z}) sqlite3_bind_int(st, n++, v);
  }
  sqlite3_bind_int64(st, n, static_cast<sqlite3_int64>(std::min<std::size_t>(q.limit, 1u << 30)));
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    EditLogEntry e;
    e.id = sqlite3_column_int64(st, 0);
    e.tick = static_cast<std::uint64_t>(sqlite3_column_int64(st, 1));
    e.time_ms = sqlite3_column_int64(st, 2);
    e.player = reinterpret_cast<const char*>(sqlite3_column_text(st, 3));
    e.box = {{sqlite3_column_int(st, 4), sqlite3_column_int(st, 5), sqlite3_column_int(st, 6)},
             {sqlite3_column_int(st, 7), sqlite3_column_int(st, 8), sqlite3_column_int(st, 9)}};
    if (q.with_voxels) {
      for (int c = 10; c <= 11; ++c) {
        const auto* p = static_cast<const std::uint8_t*>(sqlite3_column_blob(st, c));
        const int len = sqlite3_column_bytes(st, c);
        (c == 10 ? e.before : e.after).assign(p, p + len);
      }
    }
    out.push_back(std::move(e));
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot read the edit log");
  return out;
}

FileResult<std::int64_t> SqliteStore::prune_edit_log(std::int64_t before_ms, std::uint64_t max_bytes,
                                                    std::int64_t max_rows) {
  if (!table_exists(db_, "edit_log")) return std::int64_t{0};
  std::int64_t deleted = 0;
  // The size known, less what the prune by age takes (counted through the
  // time index first: only the rows it deletes are read).
  auto known = log_size_;
  log_size_.reset();  // known again below once every delete went through
  constexpr const char* kOld = " FROM edit_log WHERE id IN (SELECT id FROM edit_log WHERE time < ? ORDER BY id LIMIT ?)";
  std::pair<std::int64_t, std::uint64_t> old{0, 0};
  for (const bool count : {true, false}) {
    if (count && !known) continue;
    sqlite3_stmt* st = nullptr;
    const std::string sql = count ? std::string("SELECT count(*), coalesce(sum(length(before) + length(after)), 0)") + kOld
                                  : std::string("DELETE") + kOld;
    if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &st, nullptr) != SQLITE_OK) return error("cannot prune the edit log");
    sqlite3_bind_int64(st, 1, before_ms);
    sqlite3_bind_int64(st, 2, max_rows);
    const int rc = sqlite3_step(st);
    if (count && rc == SQLITE_ROW)
      old = {sqlite3_column_int64(st, 0), static_cast<std::uint64_t>(sqlite3_column_int64(st, 1))};
    sqlite3_finalize(st);
    if (rc != (count ? SQLITE_ROW : SQLITE_DONE)) return error("cannot prune the edit log");
  }
  deleted += sqlite3_changes(db_);
  if (known && deleted == old.first)
    log_size_ = std::pair<std::int64_t, std::uint64_t>{known->first - old.first, known->second - std::min(known->second, old.second)};
  if (max_bytes == 0 || deleted >= max_rows) return deleted;
  auto size = edit_log_size();
  if (!size) return size.error();
  std::uint64_t bytes = size->second;
  std::int64_t rows_left = size->first;
  // The oldest go first, until under the bound: read up to a thousand
  // sizes at a time, delete through the last one needed.
  while (bytes > max_bytes && deleted < max_rows) {
    sqlite3_stmt* sel = nullptr;
    if (sqlite3_prepare_v2(db_, "SELECT id, length(before) + length(after) FROM edit_log ORDER BY id LIMIT 1000", -1,
                           &sel, nullptr) != SQLITE_OK)
      return error("cannot prune the edit log");
    std::int64_t last = -1, rows = 0;
    int r;
    while (bytes > max_bytes && (r = sqlite3_step(sel)) == SQLITE_ROW) {
      last = sqlite3_column_int64(sel, 0);
      bytes -= std::min<std::uint64_t>(bytes, static_cast<std::uint64_t>(sqlite3_column_int64(sel, 1)));
      ++rows;
    }
    sqlite3_finalize(sel);
    if (rows == 0) break;
    sqlite3_stmt* del = nullptr;
    if (sqlite3_prepare_v2(db_, "DELETE FROM edit_log WHERE id <= ?", -1, &del, nullptr) != SQLITE_OK)
      return error("cannot prune the edit log");
    sqlite3_bind_int64(del, 1, last);
    const int d = sqlite3_step(del);
    sqlite3_finalize(del);
    if (d != SQLITE_DONE) {
      log_size_.reset();
      return error("cannot prune the edit log");
    }
    deleted += rows;
    rows_left -= rows;
    log_size_ = std::pair<std::int64_t, std::uint64_t>{rows_left, bytes};
  }
  return deleted;
}

FileResult<std::pair<std::int64_t, std::uint64_t>> SqliteStore::edit_log_size() {
  if (!table_exists(db_, "edit_log")) return std::pair<std::int64_t, std::uint64_t>{0, 0};
  if (log_size_) return *log_size_;
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT count(*), coalesce(sum(length(before) + length(after)), 0) FROM edit_log", -1,
                         &st, nullptr) != SQLITE_OK)
    return error("cannot measure the edit log");
  std::pair<std::int64_t, std::uint64_t> out{0, 0};
  const int rc = sqlite3_step(st);
  if (rc == SQLITE_ROW)
    out = {sqlite3_column_int64(st, 0), static_cast<std::uint64_t>(sqlite3_column_int64(st, 1))};
  sqlite3_finalize(st);
  if (rc == SQLITE_ROW) log_size_ = out;
  return out;
}

FileStatus SqliteStore::erase_chunk(Vec3i pos) {
  if (sqlite3_exec(db_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) != SQLITE_OK)
    return error("cannot begin chunk delete");
  const auto fail = [&](FileError e) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return e;
  };
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "DELETE FROM chunks WHERE cx = ? AND cy = ? AND cz = ?", -1, &st, nullptr) != SQLITE_OK)
    return fail(error("cannot prepare chunk delete"));
  sqlite3_bind_int(st, 1, pos.x);
  sqlite3_bind_int(st, 2, pos.y);
  sqlite3_bind_int(st, 3, pos.z);
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return fail(error("cannot delete chunk"));
  if (auto c = change_coarse({}, {pos}, {}, true); !c) return fail(c.error());
  if (sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK) return fail(error("cannot commit chunk delete"));
  return Ok{};
}

FileResult<std::optional<std::uint64_t>> SqliteStore::quarantine_chunk(Vec3i pos, const std::string& reason) {
  std::ostringstream where;
  where << "chunk (" << pos.x << ", " << pos.y << ", " << pos.z << ")";
  if (sqlite3_exec(db_, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) != SQLITE_OK)
    return error("cannot begin quarantine of " + where.str());
  auto fail = [&](const std::string& what) {
    FileError e = error(what + " " + where.str());
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return e;
  };
  // The row is copied inside SQLite: the blob moves byte for byte, however
  // damaged it is.
  const char* kSteps[2] = {
      "INSERT INTO quarantine(cx, cy, cz, revision, data, reason, time)"
      " SELECT cx, cy, cz, revision, data, ?4, CAST(strftime('%s', 'now') AS INTEGER)"
      " FROM chunks WHERE cx = ?1 AND cy = ?2 AND cz = ?3",
      "DELETE FROM chunks WHERE cx = ?1 AND cy = ?2 AND cz = ?3"};
  std::optional<std::uint64_t> revision;
  {
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db_, "SELECT revision FROM chunks WHERE cx = ? AND cy = ? AND cz = ?", -1, &st, nullptr) !=
        SQLITE_OK)
      return fail("cannot prepare quarantine of");
    sqlite3_bind_int(st, 1, pos.x);
    sqlite3_bind_int(st, 2, pos.y);
    sqlite3_bind_int(st, 3, pos.z);
    const int rc = sqlite3_step(st);
    if (rc == SQLITE_ROW) revision = static_cast<std::uint64_t>(sqlite3_column_int64(st, 0));
    sqlite3_finalize(st);
    if (rc != SQLITE_ROW && rc != SQLITE_DONE) return fail("cannot read revision of");
  }
  if (!revision) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return std::optional<std::uint64_t>{};
  }
  for (const char* sql : kSteps) {
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db_, sql, -1, &st, nullptr) != SQLITE_OK) return fail("cannot prepare quarantine of");
    sqlite3_bind_int(st, 1, pos.x);
    sqlite3_bind_int(st, 2, pos.y);
    sqlite3_bind_int(st, 3, pos.z);
    if (sqlite3_bind_parameter_count(st) >= 4) sqlite3_bind_text(st, 4, reason.c_str(), -1, SQLITE_TRANSIENT);
    const int rc = sqlite3_step(st);
    const int changed = sqlite3_changes(db_);
    sqlite3_finalize(st);
    if (rc != SQLITE_DONE) return fail("cannot quarantine");
    if (changed != 1) return fail("quarantine moved " + std::to_string(changed) + " rows for");
  }
  // The chunk is no longer stored: its coarse entry goes with it.
  if (auto c = change_coarse({}, {pos}, {}, true); !c) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return c.error();
  }
  if (sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK) return fail("cannot commit quarantine of");
  return revision;
}

FileResult<std::optional<std::uint64_t>> SqliteStore::quarantined_revision(Vec3i pos) {
  if (!quarantined_rev_stmt_ &&
      sqlite3_prepare_v2(db_, "SELECT max(revision) FROM quarantine WHERE cx = ? AND cy = ? AND cz = ?", -1,
                         &quarantined_rev_stmt_, nullptr) != SQLITE_OK)
    return error("cannot prepare quarantine read");
  StmtReset reset{quarantined_rev_stmt_};
  sqlite3_bind_int(quarantined_rev_stmt_, 1, pos.x);
  sqlite3_bind_int(quarantined_rev_stmt_, 2, pos.y);
  sqlite3_bind_int(quarantined_rev_stmt_, 3, pos.z);
  if (sqlite3_step(quarantined_rev_stmt_) != SQLITE_ROW) return error("cannot read quarantine");
  if (sqlite3_column_type(quarantined_rev_stmt_, 0) == SQLITE_NULL) return std::optional<std::uint64_t>{};
  return std::optional<std::uint64_t>{static_cast<std::uint64_t>(sqlite3_column_int64(quarantined_rev_stmt_, 0))};
}

FileStatus SqliteStore::for_each_quarantined(const std::function<void(const QuarantinedChunk&)>& fn) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT cx, cy, cz, revision, data, reason, time FROM quarantine ORDER BY id", -1, &st,
                         nullptr) != SQLITE_OK)
    return error("cannot list quarantined chunks");
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    QuarantinedChunk q;
    q.pos = Vec3i{sqlite3_column_int(st, 0), sqlite3_column_int(st, 1), sqlite3_column_int(st, 2)};
    q.revision = static_cast<std::uint64_t>(sqlite3_column_int64(st, 3));
    const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(st, 4));
    const auto size = static_cast<std::size_t>(sqlite3_column_bytes(st, 4));
    if (data) q.blob.assign(data, data + size);
    const auto* reason = reinterpret_cast<const char*>(sqlite3_column_text(st, 5));
    if (reason) q.reason = reason;
    q.time_unix_s = sqlite3_column_int64(st, 6);
    fn(q);
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot list quarantined chunks");
  return Ok{};
}

FileResult<std::int64_t> SqliteStore::quarantined_count() {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT count(*) FROM quarantine", -1, &st, nullptr) != SQLITE_OK)
    return error("cannot count quarantined chunks");
  std::int64_t n = -1;
  if (sqlite3_step(st) == SQLITE_ROW) n = sqlite3_column_int64(st, 0);
  sqlite3_finalize(st);
  if (n < 0) return error("cannot count quarantined chunks");
  return n;
}

FileStatus SqliteStore::for_each_chunk(
    const std::function<void(Vec3i, std::uint64_t, std::span<const std::uint8_t>)>& fn) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT cx, cy, cz, revision, data FROM chunks ORDER BY cx, cy, cz", -1, &st,
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
  if (sqlite3_prepare_v2(db_, "SELECT count(*) FROM chunks", -1, &st, nullptr) != SQLITE_OK)
    return error("cannot count chunks");
  std::int64_t n = -1;
  if (sqlite3_step(st) == SQLITE_ROW) n = sqlite3_column_int64(st, 0);
  sqlite3_finalize(st);
  if (n < 0) return error("cannot count chunks");
  return n;
}

FileStatus SqliteStore::backup_to(const std::string& dest_dir, const std::function<void(int, int)>& progress) {
  std::error_code ec;
  std::filesystem::create_directories(dest_dir, ec);
  if (ec) return FileError{"backup " + dest_dir + ": cannot create directory: " + ec.message(), {}};
  if (exists(dest_dir)) return FileError{"backup " + dest_dir + ": already holds a world", {}};
  const std::string path = (std::filesystem::path(dest_dir) / kWorldDatabaseName).string();
  sqlite3* dest = nullptr;
  if (sqlite3_open_v2(path.c_str(), &dest, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr) != SQLITE_OK) {
    std::string msg = "backup " + path + ": cannot create: " + (dest ? sqlite3_errmsg(dest) : "out of memory");
    sqlite3_close(dest);
    return FileError{msg, {}};
  }
  sqlite3_backup* b = sqlite3_backup_init(dest, "main", db_, "main");
  if (b == nullptr) {
    std::string msg = "backup " + path + ": " + sqlite3_errmsg(dest);
    sqlite3_close(dest);
    std::filesystem::remove(path, ec);
    return FileError{msg, {}};
  }
  // 256 pages per step (1 MiB at 4 KiB pages): short steps let the writer in.
  int rc;
  do {
    rc = sqlite3_backup_step(b, 256);
    if (progress) progress(sqlite3_backup_pagecount(b) - sqlite3_backup_remaining(b), sqlite3_backup_pagecount(b));
    if (rc == SQLITE_BUSY || rc == SQLITE_LOCKED) sqlite3_sleep(20);
  } while (rc == SQLITE_OK || rc == SQLITE_BUSY || rc == SQLITE_LOCKED);
  sqlite3_backup_finish(b);
  std::string msg = rc == SQLITE_DONE ? "" : std::string(sqlite3_errmsg(dest));
  if (rc == SQLITE_DONE) sqlite3_exec(dest, "PRAGMA journal_mode=WAL;", nullptr, nullptr, nullptr);
  sqlite3_close(dest);
  if (rc != SQLITE_DONE) {
    std::filesystem::remove(path, ec);
    return FileError{"backup " + path + ": " + msg, {}};
  }
  return Ok{};
}

FileResult<std::string> SqliteStore::pragma(const std::string& name) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, ("PRAGMA " + name).c_str(), -1, &st, nullptr) != SQLITE_OK)
    return error("cannot run pragma " + name);
  std::string out;
  if (sqlite3_step(st) == SQLITE_ROW) {
    const auto* t = reinterpret_cast<const char*>(sqlite3_column_text(st, 0));
    if (t) out = t;
  }
  sqlite3_finalize(st);
  return out;
}

}  // namespace terrane
