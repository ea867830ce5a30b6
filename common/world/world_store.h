// WorldStore: a world on disk. A world is a directory holding world.sqlite,
// an embedded SQLite database in WAL mode (format: common/world/WORLD_FORMAT.md):
//   - meta: format version, generator kind and parameters, bounds, material
//     table, epoch;
//   - chunks: one row per stored 32³ chunk: its coordinates, a revision that
//     only ever grows, and the voxels as byte RLE + LZ4;
//   - quarantine: damaged chunk rows moved aside (coordinates, revision, the
//     blob as it was, the reason, the time), kept until someone looks;
//   - coarse (format 2): per 256³ region, the 4³ mip and revision of every
//     stored chunk in it (common/world/coarse_image.h), written in the same
//     transaction as the chunks, so a distant view never decodes them.
// Chunks never stored are generated on demand from the metadata (see World).
// The finer mips are not stored: they are rebuilt from level 0 on load.
//
// Errors are returned as FileError naming the world and, for chunk data,
// the chunk's coordinates; a damaged blob never crashes the reader.
// Thread-safety: one owner thread per WorldStore (one SQLite connection).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/chunk.h"
#include "common/vxraw/vxraw.h"
#include "common/world/coarse_image.h"
#include "common/world/world_bounds.h"

struct sqlite3;
struct sqlite3_stmt;

namespace terrane {

// Format 2 added the coarse images; a format-1 world gains them (and
// becomes format 2) the first time it is opened.
inline constexpr std::uint32_t kWorldFormatVersion = 2;
inline constexpr const char* kWorldDatabaseName = "world.sqlite";

enum class GeneratorKind : std::uint8_t {
  kNone,     // nothing outside stored chunks (e.g. imported worlds)
  kTerrain,  // TerrainGenerator with the stored parameters
};

struct WorldMeta {
  std::uint32_t format_version = kWorldFormatVersion;
  GeneratorKind generator = GeneratorKind::kTerrain;
  std::string generator_params;  // TerrainGenerator::to_metadata() text
  WorldBounds bounds;
  std::vector<std::string> materials;  // index = material id
  std::uint64_t epoch = 1;             // bumped by every server start
};

// The default material table, with generic names for ids the table lacks.
std::vector<std::string> default_material_names();

// Chunk blob (version 1): [version u8 = 1][codec u8 = 1: byte RLE + LZ4]
// [LZ4 block of the byte RLE of the 32³ voxels in Box order].
std::vector<std::uint8_t> encode_chunk_blob(const Chunk& chunk);
// The same from a 32³ box of voxels (precondition: box is 32³).
std::vector<std::uint8_t> encode_chunk_blob(const Box& box);
Result<Chunk> decode_chunk_blob(std::span<const std::uint8_t> blob);

struct StoredChunk {
  std::uint64_t revision = 0;
  Chunk chunk;
};

// A chunk row moved aside because its blob did not decode.
struct QuarantinedChunk {
  Vec3i pos;
  std::uint64_t revision = 0;       // the row's revision when it was moved
  std::string reason;               // why it was moved (the decode error)
  std::int64_t time_unix_s = 0;     // when it was moved
  std::vector<std::uint8_t> blob;   // byte for byte as it was stored
};

struct ChunkWrite {
  Vec3i pos;
  std::uint64_t revision;
  std::vector<std::uint8_t> blob;  // encode_chunk_blob output
  // The chunk's coarse_voxels; decoded from the blob when not given.
  std::optional<CoarseVoxels> coarse = std::nullopt;
};

// One applied edit in the edit log (table edit_log): who, when, the box
// and its voxels before and after (byte RLE, Box order), as undo keeps them.
struct EditLogEntry {
  std::int64_t id = 0;  // assigned by the store, increasing
  std::uint64_t tick = 0;
  std::int64_t time_ms = 0;  // Unix milliseconds
  std::string player;
  Region box;
  std::vector<std::uint8_t> before, after;
};

// Which edits to list, newest first.
struct EditLogQuery {
  std::string player;              // "" = anyone
  std::optional<Region> box;       // edits whose box meets this one
  std::int64_t since_ms = 0;       // at or after this time
  std::size_t limit = 100;
  bool with_voxels = false;        // fill before/after
};

class WorldStore {
 public:
  // Creates the directory (if needed) and a new world in it; fails if the
  // directory already holds a world.
  static FileResult<std::unique_ptr<WorldStore>> create(const std::string& dir, const WorldMeta& meta);
  // Opens an existing world; fails with a clear message if there is none or
  // its format version is not one we read. A format-1 world is upgraded
  // first (its coarse images built from every chunk, in one transaction);
  // progress(done, total) is called as that goes, or a line is printed to
  // stderr every few seconds when progress is null.
  using Progress = std::function<void(std::int64_t done, std::int64_t total)>;
  static FileResult<std::unique_ptr<WorldStore>> open(const std::string& dir, const Progress& progress = nullptr);
  static bool exists(const std::string& dir);

  ~WorldStore();
  WorldStore(const WorldStore&) = delete;
  WorldStore& operator=(const WorldStore&) = delete;

  const std::string& dir() const { return dir_; }
  const WorldMeta& meta() const { return meta_; }
  FileStatus set_epoch(std::uint64_t epoch);
  // A new border (or none): bounds.validate() must be empty.
  FileStatus set_bounds(const WorldBounds& bounds);

  // The stored chunk, or nullopt if the chunk was never stored.
  FileResult<std::optional<StoredChunk>> load_chunk(Vec3i pos);
  // The coarse entries of region (coarse_region_of): one per stored chunk.
  FileResult<std::vector<CoarseEntry>> load_coarse(Vec3i region);
  // The chunks of region with a quarantine row (their generated content
  // continues above the quarantined revision), and those with a chunks row.
  FileResult<std::vector<Vec3i>> quarantined_in(Vec3i region);
  FileResult<std::vector<Vec3i>> stored_in(Vec3i region);
  // A read transaction around several reads, so they see one state of the
  // world (another connection may commit between them otherwise).
  FileStatus begin_read();
  void end_read();
  // Calls fn(region, entries) for every coarse image (terrane-world check).
  FileStatus for_each_coarse(const std::function<void(Vec3i, const std::vector<CoarseEntry>&)>& fn);
  // Stores all writes in one transaction (all or nothing). With
  // overwrite = false, chunks already stored are left as they are (used to
  // pre-generate without racing a server's edits).
  // log: edits recorded in the same transaction (the edit log).
  FileStatus save_chunks(std::span<const ChunkWrite> writes, bool overwrite = true,
                         std::span<const EditLogEntry> log = {});
  FileResult<std::vector<EditLogEntry>> edit_log(const EditLogQuery& q);
  // Deletes log entries older than before_ms, then the oldest until the
  // entries' voxel bytes are at most max_bytes (0: no bound), at most
  // max_rows in all (a bounded pause; the rest go next time); how many went.
  FileResult<std::int64_t> prune_edit_log(std::int64_t before_ms, std::uint64_t max_bytes,
                                          std::int64_t max_rows = 10000);
  // Entries and the bytes of their before/after voxels.
  FileResult<std::pair<std::int64_t, std::uint64_t>> edit_log_size();
  FileStatus erase_chunk(Vec3i pos);

  // Quarantine: moves the stored row of pos, blob untouched, into the
  // quarantine table, in one transaction with deleting it from chunks, so a
  // later save of the chunk can never overwrite it. Returns the moved row's
  // revision, or nullopt if pos had no stored row (nothing is moved).
  FileResult<std::optional<std::uint64_t>> quarantine_chunk(Vec3i pos, const std::string& reason);
  // The highest revision ever quarantined for pos, or nullopt. A chunk that
  // is not stored but was quarantined continues its revisions above this.
  FileResult<std::optional<std::uint64_t>> quarantined_revision(Vec3i pos);
  // Calls fn for every quarantined row, oldest first.
  FileStatus for_each_quarantined(const std::function<void(const QuarantinedChunk&)>& fn);
  FileResult<std::int64_t> quarantined_count();
  // Calls fn(pos, revision, blob) for every stored chunk, in key order.
  FileStatus for_each_chunk(const std::function<void(Vec3i, std::uint64_t, std::span<const std::uint8_t>)>& fn);
  FileResult<std::int64_t> stored_chunk_count();
  // Copies the whole database to dest_dir/world.sqlite with SQLite's online
  // backup, a few hundred pages at a time, so a running server keeps
  // writing; the copy is a consistent snapshot. dest_dir must not hold a
  // world already. progress(done_pages, total_pages) is called as it goes.
  FileStatus backup_to(const std::string& dest_dir, const std::function<void(int, int)>& progress);
  // The operators' access lists (bans, whitelist: server/ops/access.h), as
  // key -> value text in the table "access", made on the first write.
  FileResult<std::vector<std::pair<std::string, std::string>>> access_entries();
  FileStatus put_access(const std::string& key, const std::string& value);
  FileStatus erase_access(const std::string& key);
  // Runs `PRAGMA name` and returns the first column as text (tests, checks).
  FileResult<std::string> pragma(const std::string& name);

 private:
  WorldStore(std::string dir, sqlite3* db);
  static FileResult<std::unique_ptr<WorldStore>> create_in(const std::string& dir, const WorldMeta& meta);
  FileStatus load_meta();
  FileStatus ensure_quarantine_table();
  FileStatus upgrade_to_coarse(const Progress& progress);
  // A region's entries made from its chunk rows (a damaged image's repair).
  FileResult<std::vector<CoarseEntry>> coarse_from_rows(Vec3i region);
  // Inside a transaction: the images of the regions of entries, changed.
  // set: entries to put; erase: chunks whose entries go.
  FileStatus change_coarse(const std::vector<CoarseEntry>& set, const std::vector<Vec3i>& erase);
  FileStatus write_meta(const WorldMeta& meta);
  FileError error(const std::string& what) const;

  std::string dir_;
  sqlite3* db_ = nullptr;
  sqlite3_stmt* load_stmt_ = nullptr;
  sqlite3_stmt* save_stmt_ = nullptr;
  sqlite3_stmt* log_stmt_ = nullptr;
  sqlite3_stmt* insert_stmt_ = nullptr;
  sqlite3_stmt* quarantined_rev_stmt_ = nullptr;
  sqlite3_stmt* coarse_load_stmt_ = nullptr;
  sqlite3_stmt* coarse_save_stmt_ = nullptr;
  WorldMeta meta_;
};

}  // namespace terrane
