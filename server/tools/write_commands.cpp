// terrane-world generate and import: the commands that fill a world
// (server/tools/world_tool.h has what they share).
#include "server/tools/world_tool.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "common/cli/cli.h"
#include "common/codec/lz4_block.h"
#include "common/vxraw/vxraw.h"
#include "common/world/sqlite_store.h"
#include "common/world/world.h"
#include "common/world/world_lock.h"
#include "server/storage/postgres_store.h"

namespace terrane::world_tool {

namespace {

constexpr const char* kGenerateHelp =
    "usage: terrane-world generate (--world DIR | --store URL [--server-id N]) [--box x0,y0,z0,x1,y1,z1]\n"
    "                              [--seed N] [--threads N]\n"
    "\n"
    "Creates a world with Terrane's terrain generator (unless the directory or database already\n"
    "holds one) and stores every generated chunk of the box, all-Air ones too (a few dozen\n"
    "bytes each), so a server neither generates nor estimates any of them. Chunks already\n"
    "stored are left alone, so running it twice is safe (and fills in what an older version\n"
    "left out: it stored no all-Air chunk).\n"
    "\n"
    "  --world DIR    world directory (created if missing), or a postgresql:// URL\n"
    "  --store URL    the world in PostgreSQL (libpq URL; the database must exist, Terrane's\n"
    "                 tables are made in it), or a directory\n"
    "  --server-id N  required with a PostgreSQL world: the server id, 0 to 2147483647, whose\n"
    "                 region leases the writes take, as a server's do. Use an id no running\n"
    "                 server uses (taking a running server's id takes its regions from it, and\n"
    "                 it stops). A region a running server holds is refused, naming it; while\n"
    "                 the tool runs, servers cannot edit the regions it holds. The leases are\n"
    "                 given up at the end.\n"
    "  --box B        half-open box x0,y0,z0,x1,y1,z1 (default -256,-64,-256,256,192,256)\n"
    "  --seed N       generator seed for a new world (default 1)\n"
    "  --threads N    generator threads (default: all cores)\n";

constexpr const char* kImportHelp =
    "usage: terrane-world import (--world DIR | --store URL [--server-id N]) FILE\n"
    "\n"
    "Writes the voxels of a VXRAW file (plain or gzip) at the box's origin. A new world made\n"
    "this way has no generator: everything outside imported boxes is Air, and material ids\n"
    "beyond the default table get generic names (Material23, ...). Chunks are written in\n"
    "batches; if a batch fails, the batches before it stay imported (the error says how far).\n"
    "\n"
    "  --world DIR    world directory (created if missing), or a postgresql:// URL\n"
    "  --store URL    the world in PostgreSQL (libpq URL; the database must exist), or a\n"
    "                 directory; a database that holds no world is given one\n"
    "  --server-id N  required with a PostgreSQL world: the server id, 0 to 2147483647, whose\n"
    "                 region leases the writes take, as a server's do. Use an id no running\n"
    "                 server uses (taking a running server's id takes its regions from it, and\n"
    "                 it stops). A region a running server holds is refused, naming it. The\n"
    "                 leases are given up at the end.\n";

}  // namespace

int cmd_generate(int argc, char** argv) {
  CommandLine cl({"world", "store", "server-id", "box", "seed", "threads"}, {"help"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kGenerateHelp);
  if (cl.flag("help")) return std::printf("%s", kGenerateHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kGenerateHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kGenerateHelp);
  std::string err;
  const Region box = cl.get_region("box", &err).value_or(kDefaultWorldBox);
  const auto seed = cl.get_int("seed", 1, 0, INT64_MAX, &err);
  const auto threads = cl.get_int("threads", std::max(1u, std::thread::hardware_concurrency()), 1, 256, &err);
  const auto writer = writer_id(cl, place, std::nullopt, &err);
  if (!err.empty()) return usage_error(err, kGenerateHelp);

  ToolWorld opened;
  if (auto s = open_tool_world(place, writer, [&] { return default_world_meta(static_cast<std::uint64_t>(seed)); },
                               opened, "terrane-world generate");
      !s)
    return failure(s.error().message);
  std::unique_ptr<World>& world = opened.world;
  const std::string where = world->store().where();
  if (opened.created) {
    std::fprintf(stderr, "created world %s (seed %lld)\n", where.c_str(), static_cast<long long>(seed));
  } else {
    if (!world->generator()) return failure("world " + where + " has no generator (it was made by import)");
    if (cl.has("seed") && world->generator()->params().seed != static_cast<std::uint64_t>(seed))
      return failure("world " + where + " exists with seed " + std::to_string(world->generator()->params().seed) +
                     ", not " + std::to_string(seed) + " (use another --world or --store to make a new one)");
    std::fprintf(stderr, "world %s exists; filling in missing chunks\n", where.c_str());
  }

  const Region clipped = world->meta().bounds.clamp(box);
  if (clipped.empty()) return failure("--box lies entirely outside the world's bounds");
  std::vector<Vec3i> todo;
  // Revision to store each with: 0, or above a quarantined row's so that
  // revisions only grow (common/world/WORLD_FORMAT.md, quarantine).
  std::vector<std::uint64_t> todo_revision;
  for (Vec3i c : chunks_in(clipped)) {
    auto stored = world->store().load_chunk(c);
    if (!stored) return failure(stored.error().message);
    if (stored->has_value()) continue;
    auto floor = world->store().quarantined_revision(c);
    if (!floor) return failure(floor.error().message);
    todo.push_back(c);
    todo_revision.push_back(floor->has_value() ? **floor + 1 : 0);
  }

  // Workers generate and encode; this thread stores in batches. The mutex
  // guards only the hand-over queue between them.
  std::atomic<std::size_t> next{0};
  std::atomic<std::uint64_t> air_chunks{0};
  std::mutex mu;
  std::condition_variable cv;
  std::deque<ChunkWrite> ready;
  std::size_t finished = 0;
  auto worker = [&] {
    Box box32;
    std::vector<ChunkWrite> local;
    for (;;) {
      const std::size_t i = next.fetch_add(1);
      if (i >= todo.size()) break;
      world->generate_chunk_box(todo[i], box32);
      // Stored even when all Air: a chunk without a row is the generator's,
      // and a server would estimate it and generate it again whenever a
      // client looks at it (the sky above the terrain, most of a view).
      ChunkWrite w{todo[i], todo_revision[i], encode_chunk_blob(box32), coarse_voxels(box32)};
      if (all_air(box32.voxels())) air_chunks.fetch_add(1, std::memory_order_relaxed);
      std::lock_guard lock(mu);
      ready.push_back(std::move(w));
      cv.notify_one();
    }
    std::lock_guard lock(mu);
    ++finished;
    cv.notify_one();
  };
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t) pool.emplace_back(worker);

  Progress progress("generate", todo.size());
  std::uint64_t done = 0;
  std::string save_error;
  std::vector<ChunkWrite> batch;
  for (;;) {
    {
      std::unique_lock lock(mu);
      cv.wait(lock, [&] { return !ready.empty() || finished == pool.size(); });
      while (!ready.empty()) {
        batch.push_back(std::move(ready.front()));
        ready.pop_front();
      }
    }
    const bool last = [&] { std::lock_guard lock(mu); return finished == pool.size() && ready.empty(); }();
    if (batch.size() >= 64 || (last && !batch.empty())) {
      done += batch.size();
      if (save_error.empty()) {
        // Never overwrite: a server may have stored an edit of the chunk meanwhile.
        if (auto s = world->store().save_chunks(batch, /*overwrite=*/false); !s) save_error = s.error().message;
      }
      batch.clear();
      progress.update(done);
    }
    if (last && batch.empty()) break;
  }
  for (auto& t : pool) t.join();
  if (!save_error.empty()) return failure(save_error);
  if (todo.empty()) progress.update(0);
  opened.leases.release();
  std::printf("generated and stored %llu chunks (%llu of them all Air) in box %d,%d,%d..%d,%d,%d of world %s\n",
              static_cast<unsigned long long>(done), static_cast<unsigned long long>(air_chunks.load()), clipped.min.x,
              clipped.min.y, clipped.min.z, clipped.max.x, clipped.max.y, clipped.max.z, where.c_str());
  return 0;
}

int cmd_import(int argc, char** argv) {
  CommandLine cl({"world", "store", "server-id"}, {"help"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kImportHelp);
  if (cl.flag("help")) return std::printf("%s", kImportHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kImportHelp);
  if (cl.positional().size() != 1) return usage_error("expected exactly one FILE", kImportHelp);
  std::string err;
  const auto writer = writer_id(cl, place, std::nullopt, &err);
  if (!err.empty()) return usage_error(err, kImportHelp);
  const std::string path = cl.positional()[0];
  auto file = vxraw_read_file(path, VxrawLimits{});
  if (!file) return failure(file.error().message);
  if (file->repaired_air)
    std::fprintf(stderr, "%s: %llu Air voxels had non-zero occupancy; stored as 0\n", path.c_str(),
                 static_cast<unsigned long long>(file->repaired_air));

  // A new world: no generator, the default materials and generic names for
  // the ids the file uses beyond them.
  const auto new_meta = [&] {
    WorldMeta meta;
    meta.generator = GeneratorKind::kNone;
    meta.materials = default_material_names();
    // An imported box sets the vertical bounds when it reaches beyond the defaults.
    meta.bounds.min_y = std::min(meta.bounds.min_y, file->origin.y);
    meta.bounds.max_y = std::max(meta.bounds.max_y, file->origin.y + file->box.size().y);
    bool used[kMaterialCount] = {};
    for (const Voxel v : file->box.voxels()) used[v.material] = true;
    for (int m = static_cast<int>(meta.materials.size()); m < kMaterialCount; ++m)
      if (used[m]) {
        meta.materials.resize(static_cast<std::size_t>(m) + 1);
      }
    for (std::size_t m = kDefaultMaterialNames.size(); m < meta.materials.size(); ++m)
      meta.materials[m] = "Material" + std::to_string(m);
    return meta;
  };
  ToolWorld opened;
  if (auto s = open_tool_world(place, writer, new_meta, opened, "terrane-world import"); !s)
    return failure(s.error().message);
  std::unique_ptr<World>& world = opened.world;
  const std::string where = world->store().where();
  if (opened.created) std::fprintf(stderr, "created world %s (no generator)\n", where.c_str());
  const Region target = Region::from_min_size(file->origin, file->box.size());
  const Region clipped = world->meta().bounds.clamp(target);
  if (!(clipped == target))
    std::fprintf(stderr, "warning: part of the box lies outside the world's bounds and was not imported\n");
  // Import a slab of chunk layers at a time so progress shows and memory stays bounded.
  const std::vector<Vec3i> chunks = chunks_in(clipped);
  Progress progress("import", chunks.size());
  std::uint64_t done = 0;
  for (std::size_t i = 0; i < chunks.size(); i += 64) {
    std::vector<ChunkWrite> writes;
    for (std::size_t k = i; k < std::min(chunks.size(), i + 64); ++k) {
      const Vec3i cp = chunks[k];
      auto chunk = world->load_chunk(cp);
      if (!chunk) return failure(chunk.error().message);
      const Vec3i origin = chunk_origin(cp);
      chunk->chunk.modify(Region{clipped.min - origin, clipped.max - origin},
                          [&](Vec3i l, Voxel) { return file->box.get(l + origin - file->origin); });
      writes.push_back(
        ChunkWrite{cp, chunk->revision + 1, encode_chunk_blob(chunk->chunk), coarse_voxels(&chunk->chunk)});
    }
    if (auto s = world->store().save_chunks(writes); !s)
      return failure(s.error().message + " (" + std::to_string(done) + " of " + std::to_string(chunks.size()) +
                     " chunks were imported before the failure)");
    done += writes.size();
    progress.update(done);
  }
  opened.leases.release();
  std::printf("imported %s: box %d,%d,%d..%d,%d,%d (%llu chunks) into world %s\n", path.c_str(), clipped.min.x,
              clipped.min.y, clipped.min.z, clipped.max.x, clipped.max.y, clipped.max.z,
              static_cast<unsigned long long>(done), where.c_str());
  return 0;
}

}  // namespace terrane::world_tool
