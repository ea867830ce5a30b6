#include "server/chunk_cache.h"

#include <memory>

#include "server/log.h"

namespace terrane {

ChunkCache::ChunkCache(World& world, Strand owner, asio::thread_pool& workers, std::function<void()> on_loaded)
    : world_(world), owner_(std::move(owner)), workers_(workers), on_loaded_(std::move(on_loaded)) {}

bool ChunkCache::request(Vec3i cp) {
  if (loaded(cp)) return true;
  if (pending_.count(cp) != 0) return false;
  if (!world_.meta().bounds.touches_chunk(cp)) {
    revisions_.emplace(cp, 0);  // outside the world: Air forever
    return true;
  }
  auto stored = world_.store().load_chunk(cp);
  if (!stored) {
    if (!stored.error().decode) {
      // SQLite could not read the row (I/O error, locked): nothing says the
      // data is bad, so neither quarantine nor generate over it. The chunk
      // stays unloaded; the next request tries again.
      if (unreadable_.insert(cp).second)
        server_log().error("chunk ({},{},{}): cannot be read, not served until it can: {}", cp.x, cp.y, cp.z,
                           stored.error().message);
      return false;
    }
    // A damaged blob: move the row aside (never regenerate over it), then
    // serve the chunk as generated with a revision above the damaged one.
    auto moved = world_.store().quarantine_chunk(cp, stored.error().decode->describe());
    if (!moved) {
      if (unreadable_.insert(cp).second)
        server_log().error("chunk ({},{},{}): {}; quarantine failed, not served: {}", cp.x, cp.y, cp.z,
                           stored.error().message, moved.error().message);
      return false;
    }
    ++quarantined_;
    server_log().error("chunk ({},{},{}): {}; row (revision {}) moved to the quarantine table, serving the chunk as "
                       "generated",
                       cp.x, cp.y, cp.z, stored.error().message, moved->value_or(0));
  } else if (stored->has_value()) {
    StoredChunk& sc = **stored;
    unreadable_.erase(cp);
    revisions_.emplace(cp, sc.revision);
    if (!sc.chunk.empty()) grid_.put_chunk(cp, std::move(sc.chunk));
    ++from_store_;
    return true;
  }
  if (pending_.size() >= kMaxPendingGenerations) return false;
  // Not stored: generated. A chunk whose row was quarantined (now or by an
  // earlier run) continues its revisions above the quarantined one.
  auto floor = world_.store().quarantined_revision(cp);
  if (!floor) {
    if (unreadable_.insert(cp).second)
      server_log().error("chunk ({},{},{}): cannot read its quarantine record, not served: {}", cp.x, cp.y, cp.z,
                         floor.error().message);
    return false;
  }
  unreadable_.erase(cp);
  const std::uint64_t revision = floor->has_value() ? **floor + 1 : 0;
  pending_.insert(cp);
  asio::post(workers_, [this, cp, revision] {
    auto chunk = std::make_shared<Chunk>(world_.generate_chunk(cp));
    asio::post(owner_, [this, cp, chunk, revision] {
      pending_.erase(cp);
      revisions_.emplace(cp, revision);
      if (!chunk->empty()) grid_.put_chunk(cp, std::move(*chunk));
      ++generated_;
      if (on_loaded_) on_loaded_();
    });
  });
  return false;
}

}  // namespace terrane
