// WorldStore: where a world is kept, as one connection to it. Two backends
// implement it: SqliteStore (a directory holding world.sqlite, the default
// for one server: common/world/WORLD_FORMAT.md) and PostgresStore (a world
// shared by several servers: server/storage/STORE_POSTGRESQL.md). Both keep
// the same things:
//   - the metadata: format version, generator kind and parameters, bounds,
//     material table, epoch;
//   - one row per stored 32³ chunk: its coordinates, a revision that only
//     ever grows, and the voxels as a chunk blob (below);
//   - per 256³ region, the 4³ mip and revision of every stored chunk in it
//     (common/world/coarse_image.h), so a distant view seldom decodes them;
//     written with the chunks, or after them (set_coarse_behind), never
//     read behind them;
//   - the quarantine (damaged chunk rows moved aside), the edit log and the
//     operators' access lists.
// Chunks never stored are generated on demand from the metadata (see World).
//
// Errors are returned as FileError naming the world and, for chunk data,
// the chunk's coordinates (with decode set when the stored bytes do not
// decode); a damaged blob never crashes the reader.
// Thread-safety: one owner thread per object (one connection); reopen()
// gives another connection to the same world for another thread.
#pragma once

#include <chrono>
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

namespace terrane {

// Format 2 added the coarse images (SqliteStore: a format-1 world gains
// them the first time it is opened); format 3 added chunk blobs of codec 2
// (chunk images, below), which a format-2 reader cannot read: an older world
// becomes format 3 the first time it is opened (PostgreSQL: by the first
// server or tool that opens it), its codec-1 blobs kept as they are.
inline constexpr std::uint32_t kWorldFormatVersion = 3;

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
  // The world's identity, which clients key the chunks they keep across
  // sessions by (PROTOCOL.md, "Resuming after a reconnect"): random, named
  // by the first server start (WorldStore::name_world); 0 until then. A
  // copy (a backup, a migration) gets 0, so the first server start on it
  // names it anew: its revisions may go on from the original's differently.
  std::uint64_t world_id = 0;
};

// The default material table, with generic names for ids the table lacks.
std::vector<std::string> default_material_names();

// Chunk blob (WORLD_FORMAT.md, "Chunk blobs"), version 1, written as codec 2:
//   [version u8 = 1][codec u8 = 2][CRC-32 of the image, u32 LE]
//   [LZ4 block of the chunk's image (Chunk::write_image)]
// so a load copies the chunk's row-packed level 0 and its mip units as they
// were in memory, checked, instead of packing 32³ voxels and building the
// mips again. Codec 1, [version 1][codec 1][LZ4 block of the byte RLE of
// the 32³ voxels in Box order], is still read (worlds written before
// format 3 hold it).
std::vector<std::uint8_t> encode_chunk_blob(const Chunk& chunk);
// The same from a 32³ box of voxels (precondition: box is 32³).
std::vector<std::uint8_t> encode_chunk_blob(const Box& box);
// Codec 1 of a 32³ box, as worlds before format 3 hold it (for tests and
// tools that make such worlds).
std::vector<std::uint8_t> encode_chunk_blob_byte_rle(const Box& box);
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
  // The 4^3 units that changed from revision - 1 to revision, as one update
  // batch (common/codec/update_batch.h), and the world tick that changed
  // them; empty when not known. A shared world's store passes them on to
  // the other servers (PostgreSQL's change notices); SQLite has no readers
  // to tell and ignores them.
  std::vector<std::uint8_t> units = {};
  std::uint64_t tick = 0;
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

// The edit log's size: its entries and the bytes of their voxels before
// and after (what terrane-server --edit-log-mb bounds).
struct EditLogSize {
  std::int64_t entries = 0;
  std::uint64_t bytes = 0;
  bool operator==(const EditLogSize&) const = default;
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
  virtual ~WorldStore() = default;
  WorldStore() = default;
  WorldStore(const WorldStore&) = delete;
  WorldStore& operator=(const WorldStore&) = delete;

  // Where the world is, as messages name it: a directory, or a database
  // address without its password.
  virtual const std::string& where() const = 0;
  // Another connection to the same world (one per thread).
  virtual FileResult<std::unique_ptr<WorldStore>> reopen() const = 0;

  virtual const WorldMeta& meta() const = 0;
  virtual FileStatus set_epoch(std::uint64_t epoch) = 0;
  // The world's id (WorldMeta::world_id): the stored one, or candidate
  // (non-zero) stored when there is none (one statement: servers starting
  // at once on one database agree on the first's).
  virtual FileResult<std::uint64_t> name_world(std::uint64_t candidate) = 0;
  // A new border (or none): bounds.validate() must be empty.
  virtual FileStatus set_bounds(const WorldBounds& bounds) = 0;

  // The stored chunk, or nullopt if the chunk was never stored. A blob that
  // does not decode is an error with decode set.
  virtual FileResult<std::optional<StoredChunk>> load_chunk(Vec3i pos) = 0;
  // The coarse entries of region (coarse_region_of): one per stored chunk.
  virtual FileResult<std::vector<CoarseEntry>> load_coarse(Vec3i region) = 0;
  // The same as the store keeps them, without reading past a lag (a store
  // writing coarse mips after the chunks may be behind: missing or older
  // entries). One read; for approximate uses (horizon images).
  virtual FileResult<std::vector<CoarseEntry>> load_coarse_as_kept(Vec3i region) { return load_coarse(region); }
  // The chunks of region with a quarantine row (their generated content
  // continues above the quarantined revision), and those with a chunk row.
  virtual FileResult<std::vector<Vec3i>> quarantined_in(Vec3i region) = 0;
  virtual FileResult<std::vector<Vec3i>> stored_in(Vec3i region) = 0;
  // A read transaction around several reads, so they see one state of the
  // world (another connection may commit between them otherwise).
  virtual FileStatus begin_read() = 0;
  virtual void end_read() = 0;
  // Stores all writes in one transaction (all or nothing). With
  // overwrite = false, chunks already stored are left as they are (used to
  // pre-generate without racing a server's edits).
  // log: edits recorded in the same transaction (the edit log).
  virtual FileStatus save_chunks(std::span<const ChunkWrite> writes, bool overwrite = true,
                                 std::span<const EditLogEntry> log = {}) = 0;
  // Coarse mips written after the chunks they describe instead of with
  // them (a server's writer; SqliteStore, whose images per region cost a
  // commit most of its time, does so; a store that keeps a chunk's coarse
  // mip in its row writes it with the row and ignores this). Loads are
  // never behind: they read past whatever is pending.
  virtual void set_coarse_behind(bool) {}
  // Writes pending coarse changes: those at least min_age old, of up to
  // max_regions regions; returns how many regions still wait.
  virtual FileResult<std::size_t> catch_up_coarse(std::size_t /*max_regions*/,
                                                  std::chrono::steady_clock::duration /*min_age*/) {
    return std::size_t{0};
  }
  virtual std::size_t coarse_pending() const { return 0; }
  // Whether the last load_coarse found the image behind the rows (and read
  // past it), and a writer's request to rewrite a region's image from its
  // rows at its next catch-up.
  virtual bool coarse_read_behind() const { return false; }
  virtual void repair_coarse(Vec3i /*region*/) {}
  virtual FileResult<std::vector<EditLogEntry>> edit_log(const EditLogQuery& q) = 0;
  // Deletes log entries older than before_ms, then the oldest until the
  // entries' voxel bytes are at most max_bytes (0: no bound), at most
  // max_rows in all (a bounded pause; the rest go next time); how many went.
  virtual FileResult<std::int64_t> prune_edit_log(std::int64_t before_ms, std::uint64_t max_bytes,
                                                  std::int64_t max_rows = 10000) = 0;
  // The edit log's size. SqliteStore counts it once (a scan of the log)
  // and then keeps it through this connection's own writes and prunes (a
  // world directory has one writer); PostgresStore counts it at each call
  // (COUNT and SUM over a table every server of the world writes): call
  // it where a scan may wait, not per commit.
  virtual FileResult<EditLogSize> edit_log_size() = 0;

  // Quarantine: moves the stored row of pos, blob untouched, into the
  // quarantine, in one transaction with deleting it from the chunks, so a
  // later save of the chunk can never overwrite it. Returns the moved row's
  // revision, or nullopt if pos had no stored row (nothing is moved).
  virtual FileResult<std::optional<std::uint64_t>> quarantine_chunk(Vec3i pos, const std::string& reason) = 0;
  // The highest revision ever quarantined for pos, or nullopt. A chunk that
  // is not stored but was quarantined continues its revisions above this.
  virtual FileResult<std::optional<std::uint64_t>> quarantined_revision(Vec3i pos) = 0;
  // Calls fn(pos, revision, blob) for every stored chunk, in key order.
  virtual FileStatus for_each_chunk(
      const std::function<void(Vec3i, std::uint64_t, std::span<const std::uint8_t>)>& fn) = 0;
  virtual FileResult<std::int64_t> stored_chunk_count() = 0;
  // The operators' access lists (bans, whitelist: server/ops/access.h), as
  // key -> value text.
  virtual FileResult<std::vector<std::pair<std::string, std::string>>> access_entries() = 0;
  virtual FileStatus put_access(const std::string& key, const std::string& value) = 0;
  virtual FileStatus erase_access(const std::string& key) = 0;
};

// The metadata as key -> value text (both backends store it so), and back;
// where names the world in errors.
std::vector<std::pair<std::string, std::string>> meta_to_keys(const WorldMeta& meta);
// The world_id key's value: a decimal number (nullopt when it is not one).
std::optional<std::uint64_t> parse_world_id(const std::string& text);
FileResult<WorldMeta> meta_from_keys(const std::vector<std::pair<std::string, std::string>>& keys,
                                     const std::string& where);

}  // namespace terrane
