// DecodedChunks: chunks packed from Full stream records, shared by the
// replicas of one process, so bytes many clients receive are packed once.
//
// A server sends every client the same encoding of a chunk version (one
// per version, made once), and a process running many clients (the
// terrane-bots load test) receives the same Full record once per client
// that comes near the chunk. A replica holds the chunk taken from here
// itself, shared (Grid::put_shared_chunk), until an update changes it in
// that replica (the replica's grid then copies it): a Full record taken
// from here costs a client neither the packing of rows and mips
// (Chunk::from_box) nor their bytes (terrane-bench-replica, BM_Full
// against BM_FullShared).
// Keyed by the record's bytes, compared whole: equal bytes decode to
// equal voxels, so a replica that takes a chunk from here holds exactly
// what its own bytes say; nothing is trusted across clients but the codec.
//
// Bounded: the least recently used entries go first (capacity entries).
// Beside them, the replicas' mips and horizon images (mips(),
// client/decoded_mips.h), which live as long as some replica holds them,
// and the chunks updates made of shared chunks (updates(),
// client/shared_updates.h).
// Thread-safety: every member may be called from any thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <span>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "client/decoded_mips.h"
#include "client/shared_updates.h"
#include "common/voxel/chunk.h"
#include "protocol/stream_batch.h"

namespace terrane {

class DecodedChunks {
 public:
  static constexpr std::size_t kDefaultCapacity = 4096;
  explicit DecodedChunks(std::size_t capacity = kDefaultCapacity);

  // The chunk packed from exactly these bytes, or null.
  std::shared_ptr<const Chunk> find(std::span<const std::uint8_t> payload);
  // Keeps chunk as what payload decodes to (in place of another entry
  // whose bytes hash alike).
  void add(std::span<const std::uint8_t> payload, std::shared_ptr<const Chunk> chunk);

  // Before decoding a Full record: the chunk kept here of a payload that
  // rest (a batch's bytes from the record's payload on) begins with, and
  // that payload's length; before decoding a Mip or Estimate record, the
  // mip in unit form that mips() keeps of it (DecodedMips::known_unit);
  // {0, null} for other kinds and when none. The bytes are compared whole:
  // a payload found is exactly the record's.
  static constexpr std::size_t kPrefixBytes = 16;
  KnownPayload known(StreamRecordKind kind, std::span<const std::uint8_t> rest);

  // The chunk hash (protocol/messages.h) of a shared chunk at revision,
  // made once for all the replicas holding that very chunk object (while
  // it lives; kMaxHashes of them at most, then made again).
  static constexpr std::size_t kMaxHashes = 1 << 16;
  std::uint64_t hash_of(const std::shared_ptr<const Chunk>& chunk, std::uint64_t revision);

  struct Stats {
    std::uint64_t hits = 0, misses = 0;
    std::uint64_t known_chunks = 0;  // of the hits: Full records not decoded at all (known())
    std::uint64_t hashes_made = 0, hashes_shared = 0;  // hash_of: made / taken as made by another replica
    std::size_t entries = 0;
    std::size_t bytes = 0;  // the entries' bytes and chunks (heap)
  };
  Stats stats() const;

  // The mips and horizon images the replicas sharing this hold.
  DecodedMips& mips() { return mips_; }
  const DecodedMips& mips() const { return mips_; }
  // What updates made of the chunks the replicas sharing this hold.
  SharedUpdates& updates() { return updates_; }
  const SharedUpdates& updates() const { return updates_; }

 private:
  struct Entry {
    std::vector<std::uint8_t> bytes;
    std::shared_ptr<const Chunk> chunk;
    std::list<std::size_t>::iterator lru;  // this entry's place; its value is the key
  };
  static std::size_t key_of(std::span<const std::uint8_t> payload);
  // The key of a payload's first kPrefixBytes, by record kind.
  static std::size_t prefix_key(StreamRecordKind kind, std::span<const std::uint8_t> bytes);
  // Drops prefix_'s key of an entry leaving (under m_).
  void unindex(std::size_t key, const Entry& e);

  const std::size_t capacity_;
  mutable std::mutex m_;
  // By hash of the bytes (one entry per hash: of two whose bytes hash
  // alike, the newer is kept).
  std::unordered_map<std::size_t, Entry> entries_;
  std::list<std::size_t> lru_;  // keys, most recently used first
  // Full records' entries by prefix_key: the keys of entries_ whose bytes
  // begin alike (a few: the newest kept).
  std::unordered_map<std::size_t, std::vector<std::size_t>> prefix_;
  struct KnownHash {
    std::weak_ptr<const Chunk> chunk;  // the very object (a dead one's address may be reused)
    std::uint64_t revision = 0, hash = 0;
  };
  std::unordered_map<const Chunk*, KnownHash> hashes_;
  Stats stats_;
  DecodedMips mips_;
  SharedUpdates updates_;
};

}  // namespace terrane
