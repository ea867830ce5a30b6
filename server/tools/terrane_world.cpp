// terrane-world: create, fill, inspect and convert Terrane worlds.
//
//   terrane-world generate --world DIR [--box x0,y0,z0,x1,y1,z1] [--seed N]
//   terrane-world import   --world DIR FILE.vxraw[.gz]
//   terrane-world export   --world DIR --box x0,y0,z0,x1,y1,z1 FILE.vxraw[.gz]
//   terrane-world stats    --world DIR [--box ...] [--json]
//   terrane-world check    --world DIR [--quarantine]
//   terrane-world backup   --world DIR --to DEST
//
// Exit status: 0 on success, 1 on a failure of the work (I/O, damaged data),
// 2 on bad usage. Every error names what and where.
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <deque>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "common/cli/cli.h"
#include "common/codec/lz4_block.h"
#include "common/vxraw/vxraw.h"
#include "common/world/sqlite_store.h"
#include "common/world/world.h"
#include "server/storage/lease_keeper.h"
#include "server/storage/postgres_store.h"
#include "server/tools/enhance_command.h"
#include "server/tools/world_stats.h"

namespace terrane {
namespace {

constexpr const char* kUsage =
    "usage: terrane-world COMMAND --world DIR [options]\n"
    "\n"
    "Commands:\n"
    "  generate   create a generated world (if DIR holds none) and pre-generate a box of it\n"
    "  import     write a VXRAW box (plain or .gz) into a world, creating an empty world if needed\n"
    "  export     write a box of a world to a VXRAW file (.gz: gzip-compressed)\n"
    "  stats      the storage results table for a box: voxels, codecs, memory\n"
    "  check      decode every stored chunk, list quarantined ones (exit 1 on any of either)\n"
    "  backup     copy a world, consistently, even while a server is writing to it\n"
    "  enhance    voxel detail enhancement of a VXRAW box (subdivision or resampling, lighting)\n"
    "\n"
    "Run 'terrane-world COMMAND --help' for a command's options.\n";

constexpr const char* kGenerateHelp =
    "usage: terrane-world generate --world DIR [--box x0,y0,z0,x1,y1,z1] [--seed N] [--threads N]\n"
    "\n"
    "Creates a world with Terrane's terrain generator in DIR (unless DIR already holds one) and\n"
    "stores the generated chunks of the box, so a server starts without generating them.\n"
    "Chunks already stored are left alone, so running it twice is safe.\n"
    "\n"
    "  --world DIR    world directory (created if missing)\n"
    "  --box B        half-open box x0,y0,z0,x1,y1,z1 (default -256,-64,-256,256,192,256)\n"
    "  --seed N       generator seed for a new world (default 1)\n"
    "  --threads N    generator threads (default: all cores)\n";

constexpr const char* kImportHelp =
    "usage: terrane-world import --world DIR FILE\n"
    "\n"
    "Writes the voxels of a VXRAW file (plain or gzip) at the box's origin. A new world made\n"
    "this way has no generator: everything outside imported boxes is Air, and material ids\n"
    "beyond the default table get generic names (Material23, ...). Chunks are written in\n"
    "batches; if a batch fails, the batches before it stay imported (the error says how far).\n";

constexpr const char* kExportHelp =
    "usage: terrane-world export --world DIR --box x0,y0,z0,x1,y1,z1 [--raw] FILE\n"
    "\n"
    "Writes the box to FILE as VXRAW, gzip-compressed unless --raw is given or FILE does not\n"
    "end in .gz. The file is written to a temporary name and renamed when complete.\n";

constexpr const char* kStatsHelp =
    "usage: terrane-world stats --world DIR [--box x0,y0,z0,x1,y1,z1] [--json]\n"
    "\n"
    "Measures a box of the world (default: the default box for generated worlds, the box of\n"
    "the stored chunks otherwise): voxels, non-empty voxels, partial occupancy, materials,\n"
    "then bytes for disk byte RLE (32^3 units), byte RLE + LZ4, network bit-packed RLE in\n"
    "16^3 and 4^3 units, memory unpacked and row-packed, with encode/decode MB/s.\n"
    "--json prints one JSON object instead of the table.\n";

constexpr const char* kCheckHelp =
    "usage: terrane-world check --world DIR [--quarantine]\n"
    "\n"
    "Reads the metadata and decodes every stored chunk. Each damaged chunk is reported with\n"
    "its chunk coordinates and what is wrong. Chunks already in the quarantine table (damaged\n"
    "rows a server or an earlier check moved aside) are listed with their coordinates, revision,\n"
    "time and reason. Every coarse image entry (each chunk's 4^3 mip, what distant views are\n"
    "served from) is compared with its chunk. Exit status 1 if any chunk is damaged or\n"
    "quarantined or any coarse entry is wrong or missing.\n"
    "\n"
    "  --quarantine   move each damaged row to the quarantine table (one transaction per chunk;\n"
    "                 its blob is kept byte for byte) so a server serves the chunk as generated\n"
    "                 instead of failing to read it\n";

constexpr const char* kBackupHelp =
    "usage: terrane-world backup --world DIR --to DEST\n"
    "\n"
    "Copies the world to DEST (a new directory) with SQLite's online backup: safe while a\n"
    "server runs; the copy is the state of one moment.\n";

int usage_error(const std::string& message, const char* help) {
  std::fprintf(stderr, "terrane-world: %s\n\n%s", message.c_str(), help);
  return 2;
}

int failure(const std::string& message) {
  std::fprintf(stderr, "terrane-world: %s\n", message.c_str());
  return 1;
}

// A progress line on stderr: redrawn in place on a terminal, a line every
// 10% otherwise.
class Progress {
 public:
  Progress(std::string what, std::uint64_t total)
      : what_(std::move(what)), total_(total), tty_(isatty(2) != 0), start_(std::chrono::steady_clock::now()) {}
  void update(std::uint64_t done) {
    const int pct = total_ ? static_cast<int>(done * 100 / total_) : 100;
    if (tty_) {
      const auto now = std::chrono::steady_clock::now();
      if (done != total_ && now - last_draw_ < std::chrono::milliseconds(100)) return;
      last_draw_ = now;
      const int width = 30;
      const int filled = pct * width / 100;
      std::fprintf(stderr, "\r%s [%.*s%*s] %3d%% %llu/%llu %.1fs", what_.c_str(), filled,
                   "##############################", width - filled, "", pct, static_cast<unsigned long long>(done),
                   static_cast<unsigned long long>(total_), elapsed());
      if (done == total_) std::fputc('\n', stderr);
    } else if (elapsed() >= 2.0 && (pct / 10 != last_decile_ || done == total_)) {
      // Off a terminal, stay quiet for short jobs, then a line every 10%.
      last_decile_ = pct / 10;
      std::fprintf(stderr, "%s: %d%% (%llu/%llu) %.1fs\n", what_.c_str(), pct, static_cast<unsigned long long>(done),
                   static_cast<unsigned long long>(total_), elapsed());
    }
  }

 private:
  double elapsed() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  std::string what_;
  std::uint64_t total_;
  bool tty_;
  int last_decile_ = -1;
  std::chrono::steady_clock::time_point start_, last_draw_{};
};

std::vector<Vec3i> chunks_in(const Region& r) {
  std::vector<Vec3i> out;
  for_each_chunk_in(r, [&](Vec3i c) { out.push_back(c); });
  return out;
}

int cmd_generate(int argc, char** argv) {
  CommandLine cl({"world", "box", "seed", "threads"}, {"help"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kGenerateHelp);
  if (cl.flag("help")) return std::printf("%s", kGenerateHelp), 0;
  if (!cl.has("world")) return usage_error("--world DIR is required", kGenerateHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kGenerateHelp);
  std::string err;
  const Region box = cl.get_region("box", &err).value_or(kDefaultWorldBox);
  const auto seed = cl.get_int("seed", 1, 0, INT64_MAX, &err);
  const auto threads = cl.get_int("threads", std::max(1u, std::thread::hardware_concurrency()), 1, 256, &err);
  if (!err.empty()) return usage_error(err, kGenerateHelp);
  const std::string dir = cl.get("world");

  std::unique_ptr<World> world;
  if (SqliteStore::exists(dir)) {
    auto w = World::open(dir);
    if (!w) return failure(w.error().message);
    world = std::move(*w);
    if (!world->generator()) return failure("world " + dir + " has no generator (it was made by import)");
    if (cl.has("seed") && world->generator()->params().seed != static_cast<std::uint64_t>(seed))
      return failure("world " + dir + " exists with seed " + std::to_string(world->generator()->params().seed) +
                     ", not " + std::to_string(seed) + " (use another --world to make a new one)");
    std::fprintf(stderr, "world %s exists; filling in missing chunks\n", dir.c_str());
  } else {
    auto w = World::create(dir, default_world_meta(static_cast<std::uint64_t>(seed)));
    if (!w) return failure(w.error().message);
    world = std::move(*w);
    std::fprintf(stderr, "created world %s (seed %lld)\n", dir.c_str(), static_cast<long long>(seed));
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
      ChunkWrite w{todo[i], todo_revision[i], {}, {}};
      bool empty = true;
      for (const Voxel v : box32.voxels()) empty &= v.material == kAir;
      if (!empty) {
        w.blob = encode_chunk_blob(box32);
        w.coarse = coarse_voxels(box32);
      }
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
  std::uint64_t done = 0, stored_chunks = 0;
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
      std::vector<ChunkWrite> non_empty;
      for (auto& w : batch)
        if (!w.blob.empty()) non_empty.push_back(std::move(w));
      done += batch.size();
      stored_chunks += non_empty.size();
      batch.clear();
      if (save_error.empty() && !non_empty.empty()) {
        // Never overwrite: a server may have stored an edit of the chunk meanwhile.
        if (auto s = world->store().save_chunks(non_empty, /*overwrite=*/false); !s) save_error = s.error().message;
      }
      progress.update(done);
    }
    if (last && batch.empty()) break;
  }
  for (auto& t : pool) t.join();
  if (!save_error.empty()) return failure(save_error);
  if (todo.empty()) progress.update(0);
  std::printf("generated %llu chunks (%llu stored, the rest all Air) in box %d,%d,%d..%d,%d,%d of world %s\n",
              static_cast<unsigned long long>(done), static_cast<unsigned long long>(stored_chunks), clipped.min.x,
              clipped.min.y, clipped.min.z, clipped.max.x, clipped.max.y, clipped.max.z, dir.c_str());
  return 0;
}

int cmd_import(int argc, char** argv) {
  CommandLine cl({"world"}, {"help"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kImportHelp);
  if (cl.flag("help")) return std::printf("%s", kImportHelp), 0;
  if (!cl.has("world")) return usage_error("--world DIR is required", kImportHelp);
  if (cl.positional().size() != 1) return usage_error("expected exactly one FILE", kImportHelp);
  const std::string dir = cl.get("world");
  const std::string path = cl.positional()[0];
  auto file = vxraw_read_file(path, VxrawLimits{});
  if (!file) return failure(file.error().message);
  if (file->repaired_air)
    std::fprintf(stderr, "%s: %llu Air voxels had non-zero occupancy; stored as 0\n", path.c_str(),
                 static_cast<unsigned long long>(file->repaired_air));

  std::unique_ptr<World> world;
  if (SqliteStore::exists(dir)) {
    auto w = World::open(dir);
    if (!w) return failure(w.error().message);
    world = std::move(*w);
  } else {
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
    auto w = World::create(dir, meta);
    if (!w) return failure(w.error().message);
    world = std::move(*w);
    std::fprintf(stderr, "created world %s (no generator)\n", dir.c_str());
  }
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
  std::printf("imported %s: box %d,%d,%d..%d,%d,%d (%llu chunks) into world %s\n", path.c_str(), clipped.min.x,
              clipped.min.y, clipped.min.z, clipped.max.x, clipped.max.y, clipped.max.z,
              static_cast<unsigned long long>(done), dir.c_str());
  return 0;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Reads a box of the world; refuses boxes too large to hold in memory.
FileResult<Box> read_world_box(World& world, const Region& box) {
  constexpr std::int64_t kMaxVoxels = std::int64_t{1} << 31;
  if (box.volume() > kMaxVoxels)
    return FileError{"box of " + std::to_string(box.volume()) + " voxels is over the limit of " +
                         std::to_string(kMaxVoxels), {}};
  Box out(box.size());
  if (auto s = world.read_box(box.min, out); !s) return s.error();
  return out;
}

int cmd_export(int argc, char** argv) {
  CommandLine cl({"world", "box"}, {"help", "raw"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kExportHelp);
  if (cl.flag("help")) return std::printf("%s", kExportHelp), 0;
  if (!cl.has("world")) return usage_error("--world DIR is required", kExportHelp);
  if (!cl.has("box")) return usage_error("--box x0,y0,z0,x1,y1,z1 is required", kExportHelp);
  if (cl.positional().size() != 1) return usage_error("expected exactly one FILE", kExportHelp);
  std::string err;
  const auto box = cl.get_region("box", &err);
  if (!err.empty()) return usage_error(err, kExportHelp);
  auto world = World::open(cl.get("world"));
  if (!world) return failure(world.error().message);
  auto content = read_world_box(**world, *box);
  if (!content) return failure(content.error().message);
  const std::string path = cl.positional()[0];
  const bool gzip = !cl.flag("raw") && ends_with(path, ".gz");
  if (auto s = vxraw_write_file(path, *content, box->min, gzip); !s) return failure(s.error().message);
  std::printf("exported box %d,%d,%d..%d,%d,%d to %s\n", box->min.x, box->min.y, box->min.z, box->max.x, box->max.y,
              box->max.z, path.c_str());
  return 0;
}

int cmd_stats(int argc, char** argv) {
  CommandLine cl({"world", "box"}, {"help", "json"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kStatsHelp);
  if (cl.flag("help")) return std::printf("%s", kStatsHelp), 0;
  if (!cl.has("world")) return usage_error("--world DIR is required", kStatsHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kStatsHelp);
  std::string err;
  auto box = cl.get_region("box", &err);
  if (!err.empty()) return usage_error(err, kStatsHelp);
  auto world = World::open(cl.get("world"));
  if (!world) return failure(world.error().message);
  if (!box) {
    if ((*world)->generator()) {
      box = (*world)->meta().bounds.clamp(kDefaultWorldBox);
    } else {
      // The bounding box of the stored chunks.
      bool any = false;
      Region r{};
      auto s = (*world)->store().for_each_chunk([&](Vec3i pos, std::uint64_t, std::span<const std::uint8_t>) {
        const Region c = chunk_region(pos);
        r = any ? Region{min3(r.min, c.min), max3(r.max, c.max)} : c;
        any = true;
      });
      if (!s) return failure(s.error().message);
      if (!any) return failure("world " + cl.get("world") + " is empty; give --box");
      box = r;
    }
  }
  auto content = read_world_box(**world, *box);
  if (!content) return failure(content.error().message);
  const BoxStats stats = measure_box(*box, *content);
  std::fputs(cl.flag("json") ? stats_json(stats).c_str() : stats_table(stats).c_str(), stdout);
  return 0;
}

int cmd_check(int argc, char** argv) {
  CommandLine cl({"world"}, {"help", "quarantine"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kCheckHelp);
  if (cl.flag("help")) return std::printf("%s", kCheckHelp), 0;
  if (!cl.has("world")) return usage_error("--world DIR is required", kCheckHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kCheckHelp);
  if (PostgresStore::is_url(cl.get("world")))
    return usage_error("check reads a world directory; a PostgreSQL world's rows are checked as a server "
                       "loads them (a damaged one is quarantined)", kCheckHelp);
  auto opened = SqliteStore::open(cl.get("world"));
  if (!opened) return failure(opened.error().message);
  SqliteStore& store = **opened;
  auto total = store.stored_chunk_count();
  if (!total) return failure(total.error().message);
  Progress progress("check", static_cast<std::uint64_t>(*total));
  std::uint64_t done = 0;
  std::vector<std::pair<Vec3i, std::string>> damaged;
  // Each chunk's coarse entry as its blob implies, to compare with the images.
  std::map<std::tuple<int, int, int>, CoarseEntry> expected;
  auto s = store.for_each_chunk([&](Vec3i pos, std::uint64_t revision, std::span<const std::uint8_t> blob) {
    if (auto chunk = decode_chunk_blob(blob); !chunk) {
      damaged.emplace_back(pos, chunk.error().describe());
      std::fprintf(stderr, "chunk (%d, %d, %d): damaged: %s\n", pos.x, pos.y, pos.z, chunk.error().describe().c_str());
    } else {
      expected[{pos.x, pos.y, pos.z}] = CoarseEntry{pos, revision, coarse_voxels(&*chunk)};
    }
    progress.update(++done);
  });
  if (!s) return failure(s.error().message);
  // The coarse images: one entry per good chunk, equal to it.
  std::uint64_t coarse_bad = 0, images = 0;
  const auto bad_entry = [&](Vec3i p, const char* what) {
    if (++coarse_bad <= 20) std::fprintf(stderr, "chunk (%d, %d, %d): coarse image %s\n", p.x, p.y, p.z, what);
  };
  s = store.for_each_coarse([&](Vec3i, const std::vector<CoarseEntry>& entries) {
    ++images;
    for (const CoarseEntry& e : entries) {
      auto it = expected.find({e.chunk_pos.x, e.chunk_pos.y, e.chunk_pos.z});
      if (it == expected.end()) {
        bad_entry(e.chunk_pos, "entry without a stored chunk");
        continue;
      }
      if (it->second.revision != e.revision) bad_entry(e.chunk_pos, "revision differs from the chunk's");
      else if (it->second.voxels != e.voxels) bad_entry(e.chunk_pos, "voxels differ from the chunk's mip");
      expected.erase(it);
    }
  });
  if (!s) return failure(s.error().message);
  for (const auto& [key, e] : expected) bad_entry(e.chunk_pos, "entry missing");
  std::uint64_t moved = 0;
  if (cl.flag("quarantine")) {
    for (const auto& [pos, reason] : damaged) {
      auto m = store.quarantine_chunk(pos, reason);
      if (!m) return failure(m.error().message);
      if (m->has_value()) ++moved;
    }
  }
  std::uint64_t quarantined = 0;
  s = store.for_each_quarantined([&](const QuarantinedChunk& q) {
    ++quarantined;
    char when[32] = "?";
    const std::time_t t = static_cast<std::time_t>(q.time_unix_s);
    if (std::tm tm{}; gmtime_r(&t, &tm) != nullptr) std::strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S UTC", &tm);
    std::fprintf(stderr, "chunk (%d, %d, %d): quarantined at %s, revision %llu, %zu bytes: %s\n", q.pos.x, q.pos.y,
                 q.pos.z, when, static_cast<unsigned long long>(q.revision), q.blob.size(), q.reason.c_str());
  });
  if (!s) return failure(s.error().message);
  std::printf("checked %llu chunks and %llu coarse images of world %s: %zu damaged",
              static_cast<unsigned long long>(done), static_cast<unsigned long long>(images), cl.get("world").c_str(),
              damaged.size());
  if (cl.flag("quarantine")) std::printf(" (%llu moved to quarantine)", static_cast<unsigned long long>(moved));
  std::printf(", %llu quarantined, %llu coarse entries wrong\n", static_cast<unsigned long long>(quarantined),
              static_cast<unsigned long long>(coarse_bad));
  if (quarantined > 0)
    std::fprintf(stderr,
                 "terrane-world: world %s has %llu quarantined chunk rows: damaged data set aside in its quarantine "
                 "table (common/world/WORLD_FORMAT.md); the chunks are served as generated until restored\n",
                 cl.get("world").c_str(), static_cast<unsigned long long>(quarantined));
  if (!damaged.empty() && !cl.flag("quarantine"))
    std::fprintf(stderr,
                 "terrane-world: world %s has %zu damaged chunks; 'check --quarantine' moves them aside (a server "
                 "does so when it loads them)\n",
                 cl.get("world").c_str(), damaged.size());
  if (coarse_bad > 0)
    std::fprintf(stderr, "terrane-world: world %s has %llu wrong coarse image entries (a server would serve distant "
                 "views from them)\n", cl.get("world").c_str(), static_cast<unsigned long long>(coarse_bad));
  return damaged.empty() && quarantined == 0 && coarse_bad == 0 ? 0 : 1;
}

int cmd_backup(int argc, char** argv) {
  CommandLine cl({"world", "to"}, {"help"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kBackupHelp);
  if (cl.flag("help")) return std::printf("%s", kBackupHelp), 0;
  if (!cl.has("world")) return usage_error("--world DIR is required", kBackupHelp);
  if (!cl.has("to")) return usage_error("--to DEST is required", kBackupHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kBackupHelp);
  auto store = SqliteStore::open(cl.get("world"));
  if (!store) return failure(store.error().message);
  std::unique_ptr<Progress> progress;
  auto s = (*store)->backup_to(cl.get("to"), [&](int done, int total) {
    if (!progress) progress = std::make_unique<Progress>("backup", static_cast<std::uint64_t>(total));
    progress->update(static_cast<std::uint64_t>(done));
  });
  if (!s) return failure(s.error().message);
  std::printf("backed up world %s to %s\n", cl.get("world").c_str(), cl.get("to").c_str());
  return 0;
}

}  // namespace
}  // namespace terrane

int main(int argc, char** argv) {
  using namespace terrane;
  if (argc < 2) return usage_error("no command given", kUsage);
  const std::string cmd = argv[1];
  if (cmd == "--help" || cmd == "-h" || cmd == "help") return std::printf("%s", kUsage), 0;
  if (cmd == "generate") return cmd_generate(argc, argv);
  if (cmd == "import") return cmd_import(argc, argv);
  if (cmd == "export") return cmd_export(argc, argv);
  if (cmd == "stats") return cmd_stats(argc, argv);
  if (cmd == "check") return cmd_check(argc, argv);
  if (cmd == "backup") return cmd_backup(argc, argv);
  if (cmd == "enhance") return run_enhance_command(argc, argv);
  return usage_error("unknown command '" + cmd + "'", kUsage);
}
