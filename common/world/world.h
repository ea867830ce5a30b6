// World: a WorldStore (SQLite or PostgreSQL) plus the generator its metadata names. Reads come from
// stored chunks where they exist and from the generator elsewhere (inside
// the world's bounds; Air outside them). Used by the world tool and the
// server's loader.
// Thread-safety: generate_chunk is const and thread-safe; everything that
// touches the store belongs to one owner thread.
#pragma once

#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/world/horizon.h"
#include "common/world/terrain_generator.h"
#include "common/world/world_store.h"

namespace terrane {

// The default generated world: what `terrane-world generate` and the server
// create when given no other parameters.
WorldMeta default_world_meta(std::uint64_t seed = 1);
// The default box to pre-generate and measure: 512 × 256 × 512 around the
// origin, y in [-64, 192): surface, mountains and caves.
inline constexpr Region kDefaultWorldBox{{-256, -64, -256}, {256, 192, 256}};

class World {
 public:
  // A world directory (SqliteStore).
  static FileResult<std::unique_ptr<World>> open(const std::string& dir);
  static FileResult<std::unique_ptr<World>> create(const std::string& dir, const WorldMeta& meta);
  // A world in a store already open (any backend).
  static FileResult<std::unique_ptr<World>> open(std::unique_ptr<WorldStore> store);

  WorldStore& store() { return *store_; }
  const WorldMeta& meta() const { return store_->meta(); }
  // Null when the world has no generator (GeneratorKind::kNone).
  const TerrainGenerator* generator() const { return generator_ ? &*generator_ : nullptr; }

  // The chunk as generated (ignoring the store), clipped to the bounds.
  // Thread-safe.
  void generate_chunk_box(Vec3i chunk_pos, Box& out) const;
  Chunk generate_chunk(Vec3i chunk_pos) const;
  // True only if generate_chunk would be all Air, known without generating
  // it (TerrainGenerator::all_air; always true without a generator).
  bool generates_air(Vec3i chunk_pos) const;
  // Estimates of chunks' coarsest mip (4^3), made from the generator at the
  // mip's resolution (TerrainGenerator::coarse_sample, one evaluation per
  // coarse voxel: 64 a chunk instead of 32,768; a column stack shares its
  // 2D fields). Not the chunk's mip: the two differ where the terrain has
  // detail finer than 8 voxels. Outside the bounds Air, as generate_chunk;
  // all Air without a generator. One estimate per chunk of chunks, in that
  // order. Thread-safe.
  std::vector<CoarseVoxels> estimate_coarse(std::span<const Vec3i> chunks) const;
  // The same at a horizon image's resolution (8 evaluations a chunk at
  // level 4, 1 at level 5), put into it (precondition: chunks of out's
  // region). Nothing without a generator (the image stays Air). Thread-safe.
  void estimate_horizon(std::span<const Vec3i> chunks, HorizonBuilder& out) const;

  // The stored chunk, or the generated one with revision 0 (or, if the
  // chunk's row was quarantined, the highest quarantined revision + 1).
  // A damaged stored row is an error naming the chunk.
  FileResult<StoredChunk> load_chunk(Vec3i chunk_pos);
  // Reads [min, min + out.size()) chunk by chunk.
  FileStatus read_box(Vec3i min, Box& out);
  // Writes src at min (clipped to the bounds), storing every touched chunk
  // with its revision + 1, in one transaction.
  FileStatus write_box(Vec3i min, const Box& src);

 private:
  explicit World(std::unique_ptr<WorldStore> store);
  FileStatus init_generator();

  std::unique_ptr<WorldStore> store_;
  std::optional<TerrainGenerator> generator_;
};

}  // namespace terrane
