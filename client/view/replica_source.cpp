#include "client/view/replica_source.h"

#include <algorithm>

#include "common/voxel/chunk.h"

namespace terrane::view {

int ReplicaSource::level(Vec3i chunk_pos) const {
  const Holding* c = replica_.holding(chunk_pos);
  if (c == nullptr) return -1;
  return c->level();
}

std::uint64_t ReplicaSource::revision(Vec3i chunk_pos) const {
  const Holding* c = replica_.holding(chunk_pos);
  return c == nullptr ? 0 : c->revision;
}

int ReplicaSource::read(Vec3i chunk_pos, int want, Box& out) const {
  const Holding* c = replica_.holding(chunk_pos);
  const int level = std::clamp(want, 0, kMipLevels - 1);
  const int n = kChunkSize >> level;
  if (c == nullptr || c->form == HoldingForm::kEmpty) {
    out.resize({n, n, n});
    return level;
  }
  if (!c->full_resolution()) {
    if (replica_.read_mip(chunk_pos, out)) return c->level();
    out.resize({n, n, n});
    return level;
  }
  if (const Chunk* chunk = replica_.grid().find_chunk(chunk_pos)) {
    chunk->read_level(level, out);
  } else {
    out.resize({n, n, n});
  }
  return level;
}

int ReplicaSource::read_part(Vec3i chunk_pos, int want, const Region& part, Box& out) const {
  const Holding* c = replica_.holding(chunk_pos);
  if (c != nullptr && c->form != HoldingForm::kEmpty && !c->full_resolution()) return read(chunk_pos, want, out);
  const Chunk* chunk = c == nullptr || c->form == HoldingForm::kEmpty ? nullptr : replica_.grid().find_chunk(chunk_pos);
  if (chunk != nullptr) {
    read_chunk_part(*chunk, want, part, out);
  } else {
    out.resize(part.size());
  }
  return want;
}

}  // namespace terrane::view
