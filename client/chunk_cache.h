// ChunkCache: the chunks a client held, kept on disk across sessions and
// processes (terrane-bots --chunk-cache, terrane-view --chunk-cache,
// terrane.connect(..., chunk_cache=...)). A client that joins a world again
// loads what it kept of the regions in its view, claims it in Holdings
// (region claims: a few bytes a region) and is sent only what changed: the
// server's revision decides, so a changed chunk is never kept stale.
//
// One file per world and region of 8^3 chunks:
//     DIR/<world id, 16 hex digits>/<rx>_<ry>_<rz>.region
// holding that region's chunks as stream records (PROTOCOL.md, "Stream
// batches"), exact forms only (Full, Mip 1..3, Empty), behind a header
// with a checksum (the format: client/CHUNK_CACHE.md). A file that does not read back whole (a bad
// header, another world or region, a checksum or a record that does not
// decode, a record outside its region or of another kind) is a miss and
// is removed: a damaged cache never gives a wrong voxel.
//
// The cache holds at most max_bytes of files; saving beyond it removes the
// files least recently loaded or saved first.
//
// Thread-safety: every member may be called from any thread (one mutex);
// the replicas of many bots in one process share one cache.
#pragma once

#include <asio/post.hpp>
#include <asio/thread_pool.hpp>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/vec3.h"
#include "protocol/stream_batch.h"

namespace terrane {

struct ChunkCacheCounters {
  std::uint64_t regions_loaded = 0;   // files read back whole
  std::uint64_t regions_missing = 0;  // asked for, no file
  std::uint64_t regions_damaged = 0;  // files that did not read back (removed)
  std::uint64_t regions_saved = 0;
  std::uint64_t regions_evicted = 0;  // removed to stay within max_bytes
  std::uint64_t chunks_loaded = 0;
  std::uint64_t chunks_saved = 0;
  std::uint64_t bytes = 0;            // files held now
};

class ChunkCache {
 public:
  // The header's size, and the format's version (client/CHUNK_CACHE.md):
  // version 1 holds records of protocol version 2; another protocol's
  // records get another version, so a cache of an older build is a miss.
  static constexpr std::size_t kHeaderBytes = 48;
  static constexpr std::uint32_t kFormatVersion = 1;
  // A region file holds at most this many payload bytes (512 Full chunks'
  // worst case is far below it; a larger file is damaged).
  static constexpr std::size_t kMaxPayloadBytes = 64u << 20;

  // Opens (creating) dir and counts the files it holds (those named as
  // its own: DIR/<16 hex digits>/<x>_<y>_<z>.region). Error: dir cannot be
  // made or read (the message names it). The size is kept by this process:
  // processes sharing a directory each count what they saw and saved.
  static FileResult<std::shared_ptr<ChunkCache>> open(const std::string& dir, std::uint64_t max_bytes);

  const std::string& dir() const { return dir_; }
  std::uint64_t max_bytes() const { return max_bytes_; }

  // Calls fn for each record of the region's file of world_id, in order,
  // decoding them once the header and the checksum have been checked.
  // Returns the records delivered (0: no file), or nullopt when the file is
  // damaged (and removed): fn may have had some of its records, which the
  // caller drops (load_view does).
  std::optional<std::size_t> load(std::uint64_t world_id, Vec3i region,
                                  const std::function<void(const StreamRecord&)>& fn);

  // Replaces the region's file of world_id with records (their bytes, as in
  // a StreamBatch, count of them; none: the file is removed), then removes
  // the least recently used files while the cache is over max_bytes.
  // Returns false (and logs nothing: the caller may) when the file cannot
  // be written.
  bool save(std::uint64_t world_id, Vec3i region, std::span<const std::uint8_t> records, std::size_t count);

  ChunkCacheCounters counters() const;

  // Runs job on the cache's own threads (as many as the machine has cores,
  // made on the first call): loads a client should not make on its io
  // side, where they would hold up every client sharing it. Jobs still
  // queued when the cache goes are dropped unrun.
  void post(std::function<void()> job);

  // The file of a region (tests damage it).
  std::string path_of(std::uint64_t world_id, Vec3i region) const;
  // dir as the cache names it: lexically normal, no trailing slash.
  static std::string normal_dir(const std::string& dir);

  // A region file's bytes for records (the format; tests write their own).
  static std::vector<std::uint8_t> file_bytes(std::uint64_t world_id, Vec3i region,
                                              std::span<const std::uint8_t> records, std::size_t count);
  // The records of a region file's bytes, checked whole: each record's kind
  // is 0..4 and its chunk in region. Errors name what is wrong.
  static Status check_file(std::span<const std::uint8_t> bytes, std::uint64_t world_id, Vec3i region,
                           const std::function<void(const StreamRecord&)>& fn);

 private:
  ChunkCache(std::string dir, std::uint64_t max_bytes) : dir_(std::move(dir)), max_bytes_(max_bytes) {}
  void scan();
  void forget(const std::string& path);
  void touch(const std::string& path, std::uint64_t size);
  void evict();

  const std::string dir_;
  const std::uint64_t max_bytes_;
  mutable std::mutex mutex_;
  struct File {
    std::uint64_t size = 0;
    std::uint64_t used = 0;  // use order: higher is more recent
  };
  std::map<std::string, File> files_;
  std::uint64_t use_clock_ = 0;
  ChunkCacheCounters counters_;
  std::unique_ptr<asio::thread_pool> loaders_;  // last: joined first (post)
};

class Replica;
struct StreamedView;
struct WorldBounds;

// Loads into replica the cached chunks of world_id in view (a client's first
// session: the replica holds nothing yet), those of the view's regions
// whose chunks are in view; returns the chunks loaded.
std::size_t load_view(ChunkCache& cache, std::uint64_t world_id, const StreamedView& view, const WorldBounds& bounds,
                      Replica& replica);
// Saves replica's chunks held in exact forms but those skip names (a chunk
// whose hash did not match the server's), region by region (each region's
// file replaced by what the replica holds of it; regions it holds nothing
// of are left as they are); returns the chunks saved, or nullopt when a
// file could not be written.
std::optional<std::size_t> save_replica(ChunkCache& cache, std::uint64_t world_id, const Replica& replica,
                                        const std::function<bool(Vec3i)>& skip = nullptr);

}  // namespace terrane
