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
    // A damaged row must not take the server down: serve the generated
    // chunk and say so (the next save of this chunk replaces the row).
    server_log().error("chunk ({},{},{}): {}; serving it as generated", cp.x, cp.y, cp.z, stored.error().message);
  } else if (stored->has_value()) {
    StoredChunk& sc = **stored;
    revisions_.emplace(cp, sc.revision);
    if (!sc.chunk.empty()) grid_.put_chunk(cp, std::move(sc.chunk));
    ++from_store_;
    return true;
  }
  if (pending_.size() >= kMaxPendingGenerations) return false;
  pending_.insert(cp);
  asio::post(workers_, [this, cp] {
    auto chunk = std::make_shared<Chunk>(world_.generate_chunk(cp));
    asio::post(owner_, [this, cp, chunk] {
      pending_.erase(cp);
      revisions_.emplace(cp, 0);
      if (!chunk->empty()) grid_.put_chunk(cp, std::move(*chunk));
      ++generated_;
      if (on_loaded_) on_loaded_();
    });
  });
  return false;
}

}  // namespace terrane
