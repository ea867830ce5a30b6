// ReplicaSource: the VoxelSource over a client's Replica. Full and Empty
// chunks read at any level (a Full chunk carries its own mips); Mip chunks
// at the level the server sent. Use it under the Client's lock
// (Client::with_replica): it holds a reference into the replica.
#pragma once

#include "client/replica.h"
#include "client/view/render_chunk.h"

namespace terrane::view {

class ReplicaSource final : public VoxelSource {
 public:
  explicit ReplicaSource(const Replica& replica) : replica_(replica) {}
  int level(Vec3i chunk_pos) const override;
  std::uint64_t revision(Vec3i chunk_pos) const override;
  int read(Vec3i chunk_pos, int want, Box& out) const override;
  int read_part(Vec3i chunk_pos, int want, const Region& part, Box& out) const override;

 private:
  const Replica& replica_;
};

}  // namespace terrane::view
