// ChunkCache: the server's authoritative copy of loaded chunks — a Grid plus
// the revision of every loaded chunk (all-Air chunks are loaded but have no
// Grid entry). Chunks come from the world store on the owner strand (one
// SQLite connection) or, when never stored, are generated on a worker pool
// and handed back to the owner strand.
//
// Damaged rows: a stored blob that does not decode is moved, in one
// transaction, to the store's quarantine table and logged with its chunk
// coordinates; the chunk is then served as generated (Air for worlds without
// a generator) at the quarantined revision + 1, so revisions only grow and
// later saves write a fresh row instead of over the damaged one. A row SQLite
// cannot read at all is neither quarantined nor generated over: the chunk is
// not served until a later request reads it.
//
// Threading: every member runs on the owner strand, except the generation
// jobs, which touch only the World's thread-safe generate_chunk.
// Invariant: a chunk is in at most one of loaded / pending.
#pragma once

#include <asio.hpp>
#include <cstdint>
#include <functional>
#include <optional>
#include <unordered_map>
#include <unordered_set>

#include "common/grid.h"
#include "common/world.h"

namespace terrane {

class ChunkCache {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;

  // on_loaded runs on the owner strand after generated chunks arrive.
  ChunkCache(World& world, Strand owner, asio::thread_pool& workers, std::function<void()> on_loaded);

  bool loaded(Vec3i chunk_pos) const { return revisions_.count(chunk_pos) != 0; }
  // Revision of a loaded chunk (precondition: loaded).
  std::uint64_t revision(Vec3i chunk_pos) const { return revisions_.at(chunk_pos); }
  void set_revision(Vec3i chunk_pos, std::uint64_t revision) { revisions_[chunk_pos] = revision; }
  // The chunk's voxels, or null when it is all Air (precondition: loaded).
  const Chunk* chunk(Vec3i chunk_pos) const { return grid_.find_chunk(chunk_pos); }
  Grid& grid() { return grid_; }
  const Grid& grid() const { return grid_; }

  // Starts loading the chunk unless it is loaded or pending. Returns true if
  // the chunk is loaded when the call returns (store hits load at once).
  // At most kMaxPendingGenerations generations run at a time; beyond that
  // the request is ignored and must be repeated.
  bool request(Vec3i chunk_pos);
  // Forgets a loaded chunk (the store or the generator has it).
  void unload(Vec3i chunk_pos) {
    grid_.erase_chunk(chunk_pos);
    revisions_.erase(chunk_pos);
  }
  template <class F>
  void for_each_loaded(F&& f) const {
    for (const auto& [cp, rev] : revisions_) f(cp);
  }
  std::size_t pending() const { return pending_.size(); }
  std::size_t loaded_count() const { return revisions_.size(); }
  std::uint64_t generated_count() const { return generated_; }
  std::uint64_t stored_loaded_count() const { return from_store_; }
  // Damaged rows this cache moved to the store's quarantine table.
  std::uint64_t quarantined_count() const { return quarantined_; }

  // Generation jobs queued on the worker pool at most (bounds owner memory
  // and keeps nearest-first order meaningful).
  static constexpr std::size_t kMaxPendingGenerations = 64;

 private:
  World& world_;
  Strand owner_;
  asio::thread_pool& workers_;
  std::function<void()> on_loaded_;
  Grid grid_;
  std::unordered_map<Vec3i, std::uint64_t, Vec3iHash> revisions_;
  std::unordered_set<Vec3i, Vec3iHash> pending_;
  std::uint64_t generated_ = 0;
  std::uint64_t from_store_ = 0;
  std::uint64_t quarantined_ = 0;
  // Chunks whose row could not be read (logged once each until they load).
  std::unordered_set<Vec3i, Vec3iHash> unreadable_;
};

}  // namespace terrane
