#include "common/world/sqlite_coarse_images.h"

#include <sqlite3.h>

#include <algorithm>
#include <limits>
#include <sstream>
#include <utility>

#include "common/world/sqlite_util.h"

namespace terrane {

namespace {

// Writes a region's image with st, an INSERT into coarse(rx, ry, rz, image);
// whether it went through.
bool write_image(sqlite3_stmt* st, Vec3i region, std::vector<CoarseEntry> entries) {
  const std::vector<std::uint8_t> image = encode_coarse_image(region, std::move(entries));
  SqliteStmtReset reset{st};
  sqlite3_bind_int(st, 1, region.x);
  sqlite3_bind_int(st, 2, region.y);
  sqlite3_bind_int(st, 3, region.z);
  sqlite3_bind_blob(st, 4, image.data(), static_cast<int>(image.size()), SQLITE_STATIC);
  return sqlite3_step(st) == SQLITE_DONE;
}

}  // namespace

SqliteCoarseImages::SqliteCoarseImages(sqlite3* db, std::string dir, LoadChunk load_chunk)
    : db_(db), dir_(std::move(dir)), load_chunk_(std::move(load_chunk)) {}

SqliteCoarseImages::~SqliteCoarseImages() {
  sqlite3_finalize(load_stmt_);
  sqlite3_finalize(save_stmt_);
}

FileError SqliteCoarseImages::error(const std::string& what) const { return sqlite_error(db_, dir_, what); }

FileStatus SqliteCoarseImages::rebuild(const ForEachChunkRow& rows, const std::function<void()>& on_row) {
  if (sqlite3_exec(db_, kSchema, nullptr, nullptr, nullptr) != SQLITE_OK ||
      sqlite3_exec(db_, "DELETE FROM coarse", nullptr, nullptr, nullptr) != SQLITE_OK)
    return error("cannot create the coarse table");
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "INSERT INTO coarse(rx, ry, rz, image) VALUES(?, ?, ?, ?)", -1, &st, nullptr) !=
      SQLITE_OK)
    return error("cannot write coarse images");
  // Chunks come in cx order: a region is complete (and written, so memory
  // stays bounded) once cx has passed it.
  std::map<std::tuple<int, int, int>, std::vector<CoarseEntry>> regions;
  bool write_failed = false;
  const auto write_before = [&](int rx_limit) {
    for (auto it = regions.begin(); it != regions.end() && std::get<0>(it->first) < rx_limit;) {
      const Vec3i r{std::get<0>(it->first), std::get<1>(it->first), std::get<2>(it->first)};
      write_failed = !write_image(st, r, std::move(it->second)) || write_failed;
      it = regions.erase(it);
    }
  };
  auto listed = rows([&](Vec3i pos, std::uint64_t revision, std::span<const std::uint8_t> blob) {
    const Vec3i r = coarse_region_of(pos);
    write_before(r.x);
    // A damaged chunk gets no entry: it is served as its load decides
    // (quarantined and generated).
    if (auto chunk = decode_chunk_blob(blob))
      regions[{r.x, r.y, r.z}].push_back(CoarseEntry{pos, revision, coarse_voxels(&*chunk)});
    on_row();
  });
  write_before(std::numeric_limits<int>::max());
  sqlite3_finalize(st);
  if (!listed) return listed.error();
  if (write_failed) return error("cannot write coarse images");
  return Ok{};
}

FileStatus SqliteCoarseImages::change(const std::vector<CoarseEntry>& set, const std::vector<Vec3i>& erase,
                                      const std::set<RegionKey>& repair, bool heal_all) {
  if (set.empty() && erase.empty() && repair.empty()) return Ok{};
  if (!save_stmt_ && sqlite3_prepare_v2(db_, "INSERT OR REPLACE INTO coarse(rx, ry, rz, image) VALUES(?, ?, ?, ?)", -1,
                                        &save_stmt_, nullptr) != SQLITE_OK)
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
    auto stored = load_as_kept(r);
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
    if (!write_image(save_stmt_, r, std::move(all))) return error("cannot write coarse image");
  }
  return Ok{};
}

FileStatus SqliteCoarseImages::written(const std::vector<CoarseEntry>& set, const std::vector<Vec3i>& undecodable) {
  // Behind: the entries wait in memory (loads read past them); an entry
  // that goes is taken out of the image now (rare: a blob that does not
  // decode), and out of what waits.
  if (behind_)
    for (const Vec3i p : undecodable) {
      const Vec3i r = coarse_region_of(p);
      auto it = pending_.find({r.x, r.y, r.z});
      if (it == pending_.end()) continue;
      it->second.entries.erase(coarse_index(p));
      if (it->second.entries.empty() && !it->second.repair) pending_.erase(it);
    }
  return change(behind_ ? std::vector<CoarseEntry>{} : set, undecodable, {}, !behind_);
}

void SqliteCoarseImages::committed(std::vector<CoarseEntry> set) {
  if (!behind_) return;
  const auto now = std::chrono::steady_clock::now();
  for (CoarseEntry& e : set) {
    const Vec3i r = coarse_region_of(e.chunk_pos);
    auto [it, fresh] = pending_.try_emplace({r.x, r.y, r.z});
    if (fresh) it->second.since = now;
    CoarseEntry& slot = it->second.entries[coarse_index(e.chunk_pos)];
    if (slot.revision <= e.revision) slot = std::move(e);
  }
}

FileStatus SqliteCoarseImages::erased(Vec3i chunk_pos) { return change({}, {chunk_pos}, {}, true); }

FileResult<std::vector<CoarseEntry>> SqliteCoarseImages::load(Vec3i region) {
  auto image = load_as_kept(region);
  if (!image) return image.error();
  return read_past(region, std::move(*image), &read_behind_);
}

FileResult<std::vector<CoarseEntry>> SqliteCoarseImages::read_past(Vec3i region, std::vector<CoarseEntry> entries,
                                                                   bool* behind) {
  // The rows are the truth: an entry whose row has another revision (its
  // image not caught up: set_behind) is made from the row, and one
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
      auto stored = load_chunk_(p);
      if (!stored && !stored.error().decode) return stored.error();
      // A damaged row gets no entry (its load quarantines it).
      if (stored && stored->has_value())
        out.push_back(CoarseEntry{p, (*stored)->revision, coarse_voxels(&(*stored)->chunk)});
    }
  }
  if (!std::is_sorted(out.begin(), out.end(), by_index)) std::sort(out.begin(), out.end(), by_index);
  return out;
}

FileResult<std::vector<CoarseEntry>> SqliteCoarseImages::load_as_kept(Vec3i region) {
  if (!load_stmt_ && sqlite3_prepare_v2(db_, "SELECT image FROM coarse WHERE rx = ? AND ry = ? AND rz = ?", -1,
                                        &load_stmt_, nullptr) != SQLITE_OK)
    return error("cannot prepare coarse image read");
  SqliteStmtReset reset{load_stmt_};
  sqlite3_bind_int(load_stmt_, 1, region.x);
  sqlite3_bind_int(load_stmt_, 2, region.y);
  sqlite3_bind_int(load_stmt_, 3, region.z);
  const int rc = sqlite3_step(load_stmt_);
  if (rc == SQLITE_DONE) return std::vector<CoarseEntry>{};
  if (rc != SQLITE_ROW) return error("cannot read coarse image");
  const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(load_stmt_, 0));
  const auto size = static_cast<std::size_t>(sqlite3_column_bytes(load_stmt_, 0));
  auto entries = decode_coarse_image(region, std::span<const std::uint8_t>(data, data ? size : 0));
  if (!entries) {
    std::ostringstream msg;
    msg << "world " << dir_ << ": the coarse image of region (" << region.x << ", " << region.y << ", " << region.z
        << ") is damaged: " << entries.error().describe();
    return FileError{msg.str(), entries.error()};
  }
  return std::move(*entries);
}

FileResult<std::vector<std::pair<Vec3i, std::uint64_t>>> SqliteCoarseImages::revisions_in(Vec3i region) {
  std::vector<std::uint64_t> revisions;
  auto positions = sqlite_chunks_in_region(db_, dir_, "chunks", region, &revisions);
  if (!positions) return positions.error();
  std::vector<std::pair<Vec3i, std::uint64_t>> out;
  out.reserve(positions->size());
  for (std::size_t i = 0; i < positions->size(); ++i) out.emplace_back((*positions)[i], revisions[i]);
  return out;
}

FileStatus SqliteCoarseImages::for_each(const std::function<void(Vec3i, const std::vector<CoarseEntry>&)>& fn) {
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
    auto entries = load_as_kept(r);
    if (!entries) return entries.error();
    fn(r, *entries);
  }
  return Ok{};
}

void SqliteCoarseImages::repair(Vec3i region) {
  auto [it, fresh] = pending_.try_emplace({region.x, region.y, region.z});
  if (fresh) it->second.since = std::chrono::steady_clock::now();
  it->second.repair = true;
}

FileResult<std::size_t> SqliteCoarseImages::catch_up(std::size_t max_regions,
                                                     std::chrono::steady_clock::duration min_age) {
  if (pending_.empty() || max_regions == 0) return pending_.size();
  const auto now = std::chrono::steady_clock::now();
  const auto due = now - min_age;
  std::vector<std::pair<std::chrono::steady_clock::time_point, RegionKey>> oldest;
  for (const auto& [key, p] : pending_)
    if (p.since <= due) oldest.emplace_back(p.since, key);
  if (oldest.empty()) return pending_.size();
  if (oldest.size() > max_regions) {
    std::nth_element(oldest.begin(), oldest.begin() + static_cast<std::ptrdiff_t>(max_regions), oldest.end());
    oldest.resize(max_regions);
  }
  std::vector<CoarseEntry> set;
  std::set<RegionKey> remake;
  for (const auto& [since, key] : oldest) {
    const PendingImage& p = pending_.at(key);
    for (const auto& [i, e] : p.entries) set.push_back(e);
    if (p.repair) remake.insert(key);
  }
  SqliteTransaction tx(db_);
  const auto failed = [&](FileError e) -> FileResult<std::size_t> {
    // Tried again later, not at once: each failure doubles a region's wait
    // (kept at most a minute); after kMaxFailures its changes are
    // given up (the rows are the truth, and loads read past the image).
    for (const auto& [since, key] : oldest) {
      PendingImage& p = pending_.at(key);
      if (++p.failures >= kMaxFailures) {
        pending_.erase(key);
        continue;
      }
      p.since = now + std::min<std::chrono::steady_clock::duration>(std::chrono::seconds(1L << p.failures),
                                                                    std::chrono::minutes(1));
    }
    return e;
  };
  if (!tx.began()) return failed(error("cannot begin writing coarse images"));
  if (auto c = change(set, {}, remake, false); !c) return failed(c.error());
  if (!tx.commit()) return failed(error("cannot commit coarse images"));
  for (const auto& [since, key] : oldest) pending_.erase(key);
  return pending_.size();
}

}  // namespace terrane
