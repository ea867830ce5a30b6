// terrane-world export, stats and check: the commands that read a world
// (check --quarantine also moves damaged rows aside; server/tools/
// world_tool.h has what they share).
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
#include "server/tools/world_stats.h"

namespace terrane::world_tool {

namespace {

constexpr const char* kExportHelp =
    "usage: terrane-world export (--world DIR | --store URL) --box x0,y0,z0,x1,y1,z1 [--raw] FILE\n"
    "\n"
    "Writes the box to FILE as VXRAW, gzip-compressed unless --raw is given or FILE does not\n"
    "end in .gz. The file is written to a temporary name and renamed when complete.\n"
    "A PostgreSQL world is only read: no --server-id, no leases.\n";

constexpr const char* kStatsHelp =
    "usage: terrane-world stats (--world DIR | --store URL) [--box x0,y0,z0,x1,y1,z1] [--json]\n"
    "\n"
    "Measures a box of the world (default: the default box for generated worlds, the box of\n"
    "the stored chunks otherwise): voxels, non-empty voxels, partial occupancy, materials,\n"
    "then bytes for disk byte RLE (32^3 units), byte RLE + LZ4, network bit-packed RLE in\n"
    "16^3 and 4^3 units, memory unpacked and row-packed, with encode/decode MB/s.\n"
    "--json prints one JSON object instead of the table.\n"
    "A PostgreSQL world is only read: no --server-id, no leases.\n";

constexpr const char* kCheckHelp =
    "usage: terrane-world check (--world DIR [--quarantine] | --store URL)\n"
    "\n"
    "Reads the metadata and decodes every stored chunk. Each damaged chunk is reported with\n"
    "its chunk coordinates and what is wrong. Chunks already in the quarantine table (damaged\n"
    "rows a server or an earlier check moved aside) are listed with their coordinates, revision,\n"
    "time and reason. Every coarse image entry (each chunk's 4^3 mip, what distant views are\n"
    "served from) is compared with its chunk: one newer than its chunk, or with other voxels at\n"
    "the same revision, is wrong; one older, or missing, is behind (a server writes the images\n"
    "after the chunks, and readers read past that), counted but not an error. Exit status 1 if\n"
    "any chunk is damaged or quarantined or any coarse entry is wrong.\n"
    "\n"
    "A PostgreSQL world (--store URL) is read in one read-only snapshot, beside running servers:\n"
    "each chunk row is decoded and its coarse mip column compared with its blob's (wrong if it\n"
    "differs: rows and mips are written together); quarantined rows are listed. Its damaged\n"
    "rows are quarantined by the server writing their region, as it loads them.\n"
    "\n"
    "  --quarantine   move each damaged row to the quarantine table (one transaction per chunk;\n"
    "                 its blob is kept byte for byte) so a server serves the chunk as generated\n"
    "                 instead of failing to read it (world directories only). This writes the\n"
    "                 world, so it takes the directory's lock: refused while a server serves it\n"
    "                 (which quarantines damaged rows itself as it loads them)\n";

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

}  // namespace

int cmd_export(int argc, char** argv) {
  CommandLine cl({"world", "store", "box"}, {"help", "raw"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kExportHelp);
  if (cl.flag("help")) return std::printf("%s", kExportHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kExportHelp);
  if (!cl.has("box")) return usage_error("--box x0,y0,z0,x1,y1,z1 is required", kExportHelp);
  if (cl.positional().size() != 1) return usage_error("expected exactly one FILE", kExportHelp);
  std::string err;
  const auto box = cl.get_region("box", &err);
  if (!err.empty()) return usage_error(err, kExportHelp);
  ToolWorld opened;  // read only: no leases
  if (auto s = open_tool_world(place, std::nullopt, nullptr, opened); !s) return failure(s.error().message);
  auto content = read_world_box(*opened.world, *box);
  if (!content) return failure(content.error().message);
  const std::string path = cl.positional()[0];
  const bool gzip = !cl.flag("raw") && ends_with(path, ".gz");
  if (auto s = vxraw_write_file(path, *content, box->min, gzip); !s) return failure(s.error().message);
  std::printf("exported box %d,%d,%d..%d,%d,%d to %s\n", box->min.x, box->min.y, box->min.z, box->max.x, box->max.y,
              box->max.z, path.c_str());
  return 0;
}

int cmd_stats(int argc, char** argv) {
  CommandLine cl({"world", "store", "box"}, {"help", "json"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kStatsHelp);
  if (cl.flag("help")) return std::printf("%s", kStatsHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kStatsHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kStatsHelp);
  std::string err;
  auto box = cl.get_region("box", &err);
  if (!err.empty()) return usage_error(err, kStatsHelp);
  ToolWorld opened;  // read only: no leases
  if (auto s = open_tool_world(place, std::nullopt, nullptr, opened); !s) return failure(s.error().message);
  World& world = *opened.world;
  if (!box) {
    if (world.generator()) {
      box = world.meta().bounds.clamp(kDefaultWorldBox);
    } else {
      // The bounding box of the stored chunks.
      bool any = false;
      Region r{};
      auto s = world.store().for_each_chunk([&](Vec3i pos, std::uint64_t, std::span<const std::uint8_t>) {
        const Region c = chunk_region(pos);
        r = any ? Region{min3(r.min, c.min), max3(r.max, c.max)} : c;
        any = true;
      });
      if (!s) return failure(s.error().message);
      if (!any) return failure("world " + world.store().where() + " is empty; give --box");
      box = r;
    }
  }
  auto content = read_world_box(world, *box);
  if (!content) return failure(content.error().message);
  const BoxStats stats = measure_box(*box, *content);
  std::fputs(cl.flag("json") ? stats_json(stats).c_str() : stats_table(stats).c_str(), stdout);
  return 0;
}

namespace {

// Prints a quarantined row as check lists it.
void print_quarantined(const QuarantinedChunk& q);

// Lists a store's quarantined rows (SqliteStore or PostgresStore); how many.
template <class Store>
FileResult<std::uint64_t> list_quarantined(Store& store) {
  std::uint64_t n = 0;
  auto s = store.for_each_quarantined([&](const QuarantinedChunk& q) {
    ++n;
    print_quarantined(q);
  });
  if (!s) return s.error();
  return n;
}

void print_quarantined(const QuarantinedChunk& q) {
  char when[32] = "?";
  const std::time_t t = static_cast<std::time_t>(q.time_unix_s);
  if (std::tm tm{}; gmtime_r(&t, &tm) != nullptr) std::strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S UTC", &tm);
  std::fprintf(stderr, "chunk (%d, %d, %d): quarantined at %s, revision %llu, %zu bytes: %s\n", q.pos.x, q.pos.y,
               q.pos.z, when, static_cast<unsigned long long>(q.revision), q.blob.size(), q.reason.c_str());
}

// check of a PostgreSQL world: every chunk row decoded and its coarse mip
// column compared with its blob's, in one read-only snapshot; quarantined
// rows listed.
int check_postgres(const WorldPlace& place) {
  auto opened = PostgresStore::open(place.where);
  if (!opened) return failure(opened.error().message);
  PostgresStore& store = **opened;
  const std::string& shown = store.where();  // no password
  auto total = store.stored_chunk_count();
  if (!total) return failure(total.error().message);
  Progress progress("check", static_cast<std::uint64_t>(*total));
  std::uint64_t done = 0, coarse_bad = 0;
  std::vector<std::pair<Vec3i, std::string>> damaged;
  auto s = store.for_each_chunk_row([&](Vec3i pos, std::uint64_t, FileResult<std::span<const std::uint8_t>> blob,
                                        const std::optional<CoarseVoxels>& coarse) {
    progress.update(++done);
    if (!blob) {  // its units after its blob do not make it
      damaged.emplace_back(pos, blob.error().message);
      std::fprintf(stderr, "chunk (%d, %d, %d): damaged: %s\n", pos.x, pos.y, pos.z, blob.error().message.c_str());
      return;
    }
    auto chunk = decode_chunk_blob(*blob);
    if (!chunk) {
      damaged.emplace_back(pos, chunk.error().describe());
      std::fprintf(stderr, "chunk (%d, %d, %d): damaged: %s\n", pos.x, pos.y, pos.z, chunk.error().describe().c_str());
      return;
    }
    if (!coarse || *coarse != coarse_voxels(&*chunk))
      if (++coarse_bad <= 20)
        std::fprintf(stderr, "chunk (%d, %d, %d): coarse mip %s\n", pos.x, pos.y, pos.z,
                     coarse ? "differs from the chunk's" : "does not decode");
  });
  if (!s) return failure(s.error().message);
  auto quarantined = list_quarantined(store);
  if (!quarantined) return failure(quarantined.error().message);
  std::printf("checked %llu chunks of world %s: %zu damaged, %llu quarantined, %llu coarse mips wrong\n",
              static_cast<unsigned long long>(done), shown.c_str(), damaged.size(),
              static_cast<unsigned long long>(*quarantined), static_cast<unsigned long long>(coarse_bad));
  if (!damaged.empty())
    std::fprintf(stderr,
                 "terrane-world: world %s has %zu damaged chunk rows; the server writing each region quarantines "
                 "them as it loads them\n",
                 shown.c_str(), damaged.size());
  return damaged.empty() && *quarantined == 0 && coarse_bad == 0 ? 0 : 1;
}

}  // namespace

int cmd_check(int argc, char** argv) {
  CommandLine cl({"world", "store"}, {"help", "quarantine"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e, kCheckHelp);
  if (cl.flag("help")) return std::printf("%s", kCheckHelp), 0;
  WorldPlace place;
  if (auto e = world_place(cl, &place); !e.empty()) return usage_error(e, kCheckHelp);
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'", kCheckHelp);
  if (place.postgres) {
    if (cl.flag("quarantine"))
      return usage_error("--quarantine is for world directories; in a PostgreSQL world the server writing a "
                         "region quarantines its damaged rows as it loads them", kCheckHelp);
    return check_postgres(place);
  }
  const std::string& dir = place.where;
  // Moving rows aside writes the world: not beside its server (which
  // quarantines damaged rows itself as it loads them). Checking only reads.
  WorldLock lock;
  if (cl.flag("quarantine")) {
    if (!SqliteStore::exists(dir)) return failure("world " + dir + ": no world here (" + kWorldDatabaseName + " missing)");
    auto taken = WorldLock::take(dir, "terrane-world check --quarantine");
    if (!taken) return failure(taken.error().message);
    lock = std::move(*taken);
  }
  auto opened = SqliteStore::open(dir);
  if (!opened) return failure(opened.error().message);
  SqliteStore& store = **opened;
  auto total = store.stored_chunk_count();
  if (!total) return failure(total.error().message);
  Progress progress("check", static_cast<std::uint64_t>(*total));
  std::uint64_t done = 0;
  std::vector<std::pair<Vec3i, std::string>> damaged;
  // Each chunk's coarse entry as its blob implies, to compare with the images.
  std::map<std::tuple<int, int, int>, CoarseEntry> expected;
  // The chunks and the images as of one moment (a server may be writing).
  if (auto r = store.begin_read(); !r) return failure(r.error().message);
  struct EndRead {
    SqliteStore& s;
    bool open = true;
    void end() {
      if (open) s.end_read();
      open = false;
    }
    ~EndRead() { end(); }
  } read{store};
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
  // An entry older than its chunk, or missing for a chunk, is behind: a
  // server writes the images after the chunks (loads read past that), and
  // one that stopped before catching up leaves them so until the next
  // write into their region. Not wrong; counted.
  std::uint64_t coarse_bad = 0, images = 0, coarse_behind = 0;
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
      if (e.revision < it->second.revision) ++coarse_behind;
      else if (it->second.revision != e.revision) bad_entry(e.chunk_pos, "revision newer than the chunk's");
      else if (it->second.voxels != e.voxels) bad_entry(e.chunk_pos, "voxels differ from the chunk's mip");
      expected.erase(it);
    }
  });
  if (!s) return failure(s.error().message);
  coarse_behind += expected.size();  // good chunks without an entry
  read.end();
  std::uint64_t moved = 0;
  if (cl.flag("quarantine")) {
    for (const auto& [pos, reason] : damaged) {
      auto m = store.quarantine_chunk(pos, reason);
      if (!m) return failure(m.error().message);
      if (m->has_value()) ++moved;
    }
  }
  auto listed = list_quarantined(store);
  if (!listed) return failure(listed.error().message);
  const std::uint64_t quarantined = *listed;
  std::printf("checked %llu chunks and %llu coarse images of world %s: %zu damaged",
              static_cast<unsigned long long>(done), static_cast<unsigned long long>(images), dir.c_str(),
              damaged.size());
  if (cl.flag("quarantine")) std::printf(" (%llu moved to quarantine)", static_cast<unsigned long long>(moved));
  std::printf(", %llu quarantined, %llu coarse entries wrong, %llu behind their chunks\n",
              static_cast<unsigned long long>(quarantined), static_cast<unsigned long long>(coarse_bad),
              static_cast<unsigned long long>(coarse_behind));
  if (quarantined > 0)
    std::fprintf(stderr,
                 "terrane-world: world %s has %llu quarantined chunk rows: damaged data set aside in its quarantine "
                 "table (common/world/WORLD_FORMAT.md); the chunks are served as generated until restored\n",
                 dir.c_str(), static_cast<unsigned long long>(quarantined));
  if (!damaged.empty() && !cl.flag("quarantine"))
    std::fprintf(stderr,
                 "terrane-world: world %s has %zu damaged chunks; 'check --quarantine' moves them aside (a server "
                 "does so when it loads them)\n",
                 dir.c_str(), damaged.size());
  if (coarse_bad > 0)
    std::fprintf(stderr, "terrane-world: world %s has %llu wrong coarse image entries (a server would serve distant "
                 "views from them)\n", dir.c_str(), static_cast<unsigned long long>(coarse_bad));
  return damaged.empty() && quarantined == 0 && coarse_bad == 0 ? 0 : 1;
}

}  // namespace terrane::world_tool
