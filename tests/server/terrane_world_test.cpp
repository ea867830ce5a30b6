// End-to-end tests of the terrane-world tool: runs the built binary.
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/vxraw/vxraw.h"
#include "common/world/sqlite_store.h"
#include "common/world/world_lock.h"
#include "tests/support/server_process.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

struct RunResult {
  int exit_code;
  std::string output;  // stdout and stderr
};

RunResult run(const std::string& args) {
  const std::string cmd = std::string(TERRANE_BIN_DIR) + "/terrane-world " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  RunResult r{-1, {}};
  if (!p) return r;
  std::array<char, 4096> buf;
  std::size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) r.output.append(buf.data(), n);
  const int status = pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

class WorldToolTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-tool-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

TEST_F(WorldToolTest, GenerateThenStatsJsonReportsEveryCodec) {
  const std::string w = path("gen");
  auto g = run("generate --world " + w + " --box -32,0,-32,32,64,32");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  // Twice is safe: nothing left to generate.
  auto g2 = run("generate --world " + w + " --box -32,0,-32,32,64,32");
  ASSERT_EQ(g2.exit_code, 0) << g2.output;
  EXPECT_NE(g2.output.find("exists"), std::string::npos);
  auto s = run("stats --world " + w + " --box -32,0,-32,32,64,32 --json");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  EXPECT_NE(s.output.find("\"voxels\": 262144"), std::string::npos) << s.output;
  for (const char* key : {"disk_rle", "disk_rle_lz4", "network_16", "network_4", "memory_unpacked",
                          "memory_row_packed", "bytes_per_non_empty_voxel", "encode_mb_s", "decode_mb_s"})
    EXPECT_NE(s.output.find(key), std::string::npos) << key << " missing in " << s.output;
  auto table = run("stats --world " + w + " --box -32,0,-32,32,64,32");
  ASSERT_EQ(table.exit_code, 0);
  EXPECT_NE(table.output.find("non-empty voxels"), std::string::npos);
}

// A pre-generated box leaves nothing to the generator: the sky above the
// terrain is stored too, so a server reading the region's coarse image
// knows every chunk of it (none estimated, none generated when looked at).
TEST_F(WorldToolTest, GenerateStoresEveryChunkOfTheBoxAllAirOnesToo) {
  const std::string w = path("gen");
  // 2 x 8 x 2 chunks of region (0, 0, 0), from the ground up to y 256: the
  // top row lies above the highest terrain the default parameters make.
  auto g = run("generate --world " + w + " --box 0,0,0,64,256,64");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  EXPECT_NE(g.output.find("stored 32 chunks"), std::string::npos) << g.output;
  auto store = SqliteStore::open(w);
  ASSERT_TRUE(store.ok()) << store.error().message;
  int air = 0;
  for (int y = 0; y < 8; ++y)
    for (int z = 0; z < 2; ++z)
      for (int x = 0; x < 2; ++x) {
        auto c = (*store)->load_chunk({x, y, z});
        ASSERT_TRUE(c.ok()) << c.error().message;
        ASSERT_TRUE(c->has_value()) << "chunk " << x << "," << y << "," << z << " has no row";
        air += (*c)->chunk.empty() ? 1 : 0;
      }
  EXPECT_GE(air, 4) << "the top row of chunks is sky";
  EXPECT_NE(g.output.find("(" + std::to_string(air) + " of them all Air)"), std::string::npos) << g.output;
  auto coarse = (*store)->load_coarse({0, 0, 0});
  ASSERT_TRUE(coarse.ok()) << coarse.error().message;
  EXPECT_EQ(coarse->size(), 32u) << "every chunk of the box has its coarse entry";
}

TEST_F(WorldToolTest, ExportImportExportRoundTrips) {
  const std::string w = path("src");
  ASSERT_EQ(run("generate --world " + w + " --box -40,0,-8,8,48,40").exit_code, 0);
  const std::string box = "-37,3,-5,5,45,36";  // not chunk-aligned
  auto e1 = run("export --world " + w + " --box " + box + " " + path("a.vxraw.gz"));
  ASSERT_EQ(e1.exit_code, 0) << e1.output;
  auto im = run("import --world " + path("copy") + " " + path("a.vxraw.gz"));
  ASSERT_EQ(im.exit_code, 0) << im.output;
  auto e2 = run("export --world " + path("copy") + " --box " + box + " " + path("b.vxraw"));
  ASSERT_EQ(e2.exit_code, 0) << e2.output;
  auto a = vxraw_read_file(path("a.vxraw.gz"), VxrawLimits{});
  auto b = vxraw_read_file(path("b.vxraw"), VxrawLimits{});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->origin, (Vec3i{-37, 3, -5}));
  EXPECT_EQ(a->origin, b->origin);
  EXPECT_EQ(a->box, b->box);
  std::size_t solid = 0;
  for (const Voxel v : a->box.voxels()) solid += v.material != kAir;
  EXPECT_GT(solid, 0u);
}

TEST_F(WorldToolTest, BadUsageExitsTwoNamingTheProblem) {
  auto r = run("frobnicate");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("unknown command 'frobnicate'"), std::string::npos);
  r = run("stats");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--world"), std::string::npos);
  r = run("generate --world " + path("w") + " --box 1,2,3");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--box"), std::string::npos);
  r = run("generate --world " + path("w") + " --box 0,0,0,0,5,5");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("empty"), std::string::npos);
  r = run("generate --world " + path("w") + " --seed banana");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--seed"), std::string::npos);
  r = run("export --world " + path("w") + " --frob 3 x.vxraw");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("unknown option --frob"), std::string::npos);
  EXPECT_EQ(run("--help").exit_code, 0);
  EXPECT_EQ(run("stats --help").exit_code, 0);
}

// Usage errors of PostgreSQL worlds come before any connection: these need
// no database (tests/server/terrane_world_postgres_test.cpp runs on one).
TEST_F(WorldToolTest, StoreUsageErrorsNameWhatToGiveOrUseInstead) {
  const std::string url = "postgresql://terrane@127.0.0.1:1/nowhere";
  const std::string file = path("box.vxraw");
  ASSERT_TRUE(vxraw_write_file(file, Box({2, 2, 2}, solid(materials::kRock)), {0, 0, 0}, false).ok());
  for (const std::string& cmd : {"import --store " + url + " " + file, "import --world " + url + " " + file,
                                "generate --store " + url}) {
    auto r = run(cmd);
    EXPECT_EQ(r.exit_code, 2) << cmd << ": " << r.output;
    EXPECT_NE(r.output.find("--server-id N is required"), std::string::npos) << cmd << ": " << r.output;
  }
  auto r = run("import --world " + path("w") + " --server-id 4 " + file);
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--server-id is for a PostgreSQL world"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(path("w")));
  r = run("stats --world " + path("w") + " --store " + url);
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("not both"), std::string::npos) << r.output;
  r = run("export --store mysql://u:pw@host/db --box 0,0,0,1,1,1 " + path("x.vxraw"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("neither a postgresql:// URL nor a world directory"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("pw"), std::string::npos) << r.output;
  r = run("check --store " + url + " --quarantine");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--quarantine is for world directories"), std::string::npos) << r.output;
  r = run("check --store " + url);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot connect to postgresql://terrane@127.0.0.1:1/nowhere"), std::string::npos) << r.output;
  r = run("backup --world " + url + " --to " + path("copy"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("pg_dump"), std::string::npos) << r.output;
  r = run("migrate --world " + path("w"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--to"), std::string::npos) << r.output;
  r = run("migrate --world " + path("w") + " --to " + url + " --server-id -1");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--server-id"), std::string::npos) << r.output;
}

TEST_F(WorldToolTest, BadFilesAndMissingWorldsExitOneNamingThem) {
  auto r = run("import --world " + path("w") + " " + path("missing.vxraw"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("missing.vxraw"), std::string::npos) << r.output;

  // A VXRAW file with material 64 at the first voxel.
  std::vector<std::uint8_t> bytes = vxraw_encode(Box({2, 1, 1}, solid(materials::kRock)), {0, 0, 0});
  bytes[kVxrawHeaderSize + 2] = 64;
  {
    std::ofstream f(path("bad.vxraw"), std::ios::binary);
    f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  }
  r = run("import --world " + path("w") + " " + path("bad.vxraw"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("bad.vxraw"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("34"), std::string::npos) << r.output;  // offset of the bad byte

  r = run("stats --world " + path("nowhere"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("no world here"), std::string::npos) << r.output;
}

TEST_F(WorldToolTest, CheckFindsDamagedChunkAndBackupCopiesTheWorld) {
  const std::string w = path("w");
  ASSERT_EQ(run("generate --world " + w + " --box 0,0,0,64,64,64").exit_code, 0);
  auto ok = run("check --world " + w);
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_NE(ok.output.find("0 damaged"), std::string::npos) << ok.output;

  auto b = run("backup --world " + w + " --to " + path("copy"));
  ASSERT_EQ(b.exit_code, 0) << b.output;
  auto e1 = run("export --world " + w + " --box 0,0,0,64,64,64 " + path("a.vxraw"));
  auto e2 = run("export --world " + path("copy") + " --box 0,0,0,64,64,64 " + path("b.vxraw"));
  ASSERT_EQ(e1.exit_code, 0);
  ASSERT_EQ(e2.exit_code, 0);
  EXPECT_EQ(vxraw_read_file(path("a.vxraw"), {})->box, vxraw_read_file(path("b.vxraw"), {})->box);
  EXPECT_EQ(run("backup --world " + w + " --to " + path("copy")).exit_code, 1);  // never overwrites

  {
    auto store = SqliteStore::open(w);
    ASSERT_TRUE(store.ok());
    std::vector<ChunkWrite> bad = {{{1, 1, 0}, 9, {1, 1, 0x10, 0x20}}};
    ASSERT_TRUE((*store)->save_chunks(bad).ok());
  }
  auto damaged = run("check --world " + w);
  EXPECT_EQ(damaged.exit_code, 1) << damaged.output;
  EXPECT_NE(damaged.output.find("chunk (1, 1, 0)"), std::string::npos) << damaged.output;
  EXPECT_NE(damaged.output.find("1 damaged"), std::string::npos) << damaged.output;
}

TEST_F(WorldToolTest, CheckComparesEveryCoarseImageEntryWithItsChunk) {
  const std::string w = path("w");
  ASSERT_EQ(run("generate --world " + w + " --box 0,0,0,64,64,64").exit_code, 0);
  auto good = run("check --world " + w);
  EXPECT_EQ(good.exit_code, 0) << good.output;
  EXPECT_NE(good.output.find("0 coarse entries wrong, 0 behind their chunks"), std::string::npos) << good.output;
  std::size_t stored_entries = 0;
  {
    // An image that says Brick everywhere, and lacks every other chunk.
    auto store = SqliteStore::open(w);
    ASSERT_TRUE(store.ok());
    auto entries = (*store)->load_coarse({0, 0, 0});
    ASSERT_TRUE(entries.ok());
    ASSERT_GE(entries->size(), 2u);
    stored_entries = entries->size();
    CoarseEntry wrong = entries->front();
    wrong.voxels.fill(solid(materials::kBrick));
    const auto image = encode_coarse_image({0, 0, 0}, {wrong});
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((w + "/world.sqlite").c_str(), &db), SQLITE_OK);
    sqlite3_stmt* st = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db, "UPDATE coarse SET image = ? WHERE rx = 0 AND ry = 0 AND rz = 0", -1, &st, nullptr),
              SQLITE_OK);
    sqlite3_bind_blob(st, 1, image.data(), static_cast<int>(image.size()), SQLITE_STATIC);
    ASSERT_EQ(sqlite3_step(st), SQLITE_DONE);
    sqlite3_finalize(st);
    sqlite3_close(db);
  }
  auto bad = run("check --world " + w);
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("coarse image voxels differ from the chunk's mip"), std::string::npos) << bad.output;
  // The others are missing: behind their chunks (a server that stopped
  // before writing them leaves that), not wrong.
  EXPECT_NE(bad.output.find("1 coarse entries wrong, " + std::to_string(stored_entries - 1) + " behind their chunks"),
            std::string::npos)
      << bad.output;
}

TEST_F(WorldToolTest, CheckReportsQuarantinedChunksAndQuarantineMovesDamagedOnesAside) {
  const std::string w = path("w");
  ASSERT_EQ(run("generate --world " + w + " --box 0,0,0,64,64,64").exit_code, 0);
  const std::vector<std::uint8_t> bad_blob = {1, 1, 0x10, 0x20};
  {
    auto store = SqliteStore::open(w);
    ASSERT_TRUE(store.ok());
    std::vector<ChunkWrite> bad = {{{1, 0, 1}, 4, bad_blob}};
    ASSERT_TRUE((*store)->save_chunks(bad).ok());
  }
  // Damaged, not yet moved: exit 1, named, and how to move it aside.
  auto damaged = run("check --world " + w);
  EXPECT_EQ(damaged.exit_code, 1) << damaged.output;
  EXPECT_NE(damaged.output.find("chunk (1, 0, 1): damaged"), std::string::npos) << damaged.output;
  EXPECT_NE(damaged.output.find("1 damaged, 0 quarantined"), std::string::npos) << damaged.output;
  EXPECT_NE(damaged.output.find("--quarantine"), std::string::npos) << damaged.output;

  auto moved = run("check --world " + w + " --quarantine");
  EXPECT_EQ(moved.exit_code, 1) << moved.output;
  EXPECT_NE(moved.output.find("1 damaged (1 moved to quarantine), 1 quarantined"), std::string::npos) << moved.output;

  // Afterwards nothing fails to decode, but the quarantine is still reported
  // (coordinates, revision, reason) and still fails the check.
  auto after = run("check --world " + w);
  EXPECT_EQ(after.exit_code, 1) << after.output;
  EXPECT_NE(after.output.find("0 damaged, 1 quarantined"), std::string::npos) << after.output;
  EXPECT_NE(after.output.find("chunk (1, 0, 1): quarantined at "), std::string::npos) << after.output;
  EXPECT_NE(after.output.find("revision 4"), std::string::npos) << after.output;
  EXPECT_NE(after.output.find("quarantined chunk rows"), std::string::npos) << after.output;
  {
    auto store = SqliteStore::open(w);
    ASSERT_TRUE(store.ok());
    std::vector<QuarantinedChunk> q;
    ASSERT_TRUE((*store)->for_each_quarantined([&](const QuarantinedChunk& c) { q.push_back(c); }).ok());
    ASSERT_EQ(q.size(), 1u);
    EXPECT_EQ(q[0].blob, bad_blob);
  }
  // The world reads again: the chunk comes from the generator.
  auto e = run("export --world " + w + " --box 0,0,0,64,64,64 " + path("a.vxraw"));
  EXPECT_EQ(e.exit_code, 0) << e.output;
  // Pre-generating it again stores it above the quarantined revision.
  auto g = run("generate --world " + w + " --box 0,0,0,64,64,64");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  auto store = SqliteStore::open(w);
  ASSERT_TRUE(store.ok());
  auto regenerated = (*store)->load_chunk({1, 0, 1});
  ASSERT_TRUE(regenerated.ok()) << regenerated.error().message;
  ASSERT_TRUE(regenerated->has_value()) << "ground at y 0..31: the chunk is stored";
  EXPECT_EQ((*regenerated)->revision, 5u);
  EXPECT_EQ(*(*store)->quarantined_count(), 1);
}

TEST_F(WorldToolTest, EnhanceSubdividesAndResamplesAVxrawBox) {
  const std::string w = path("w");
  ASSERT_EQ(run("generate --world " + w + " --box 0,0,0,32,64,32").exit_code, 0);
  ASSERT_EQ(run("export --world " + w + " --box 0,16,0,16,32,16 " + path("in.vxraw")).exit_code, 0);
  auto sub = run("enhance --in " + path("in.vxraw") + " --out " + path("sub.vxraw") + " --method subdivide --factor 4");
  ASSERT_EQ(sub.exit_code, 0) << sub.output;
  auto out = vxraw_read_file(path("sub.vxraw"), {});
  ASSERT_TRUE(out.ok()) << out.error().message;
  EXPECT_EQ(out->box.size(), (Vec3i{64, 64, 64}));
  EXPECT_EQ(out->origin, (Vec3i{0, 64, 0}));
  auto res = run("enhance --in " + path("in.vxraw") + " --out " + path("res.vxraw.gz") +
                 " --method resample --factor 3 --probes 16");
  ASSERT_EQ(res.exit_code, 0) << res.output;
  EXPECT_EQ(vxraw_read_file(path("res.vxraw.gz"), {})->box.size(), (Vec3i{48, 48, 48}));
  auto bad = run("enhance --in " + path("in.vxraw") + " --out " + path("x.vxraw") + " --method melt");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("--method"), std::string::npos) << bad.output;
  auto missing = run("enhance --in " + path("nope.vxraw") + " --out " + path("x.vxraw") + " --method subdivide");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.output.find("nope.vxraw"), std::string::npos) << missing.output;
}

TEST_F(WorldToolTest, HeavyImportsRealRegionAndReportsIt) {
  const std::string w = path("mc");
  auto im = run("import --world " + w + " " + std::string(TERRANE_TEST_DATA_DIR) + "/mc-1.9.vxraw.gz");
  ASSERT_EQ(im.exit_code, 0) << im.output;
  auto s = run("stats --world " + w + " --box -384,0,-512,0,256,-304 --json");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  EXPECT_NE(s.output.find("\"non_empty_voxels\": 4941334"), std::string::npos) << s.output;
}

// One world, one writer: a served world directory (the data-losing case: a
// second server wrote its stale chunks back over the first's acknowledged
// edits) refuses a second server, through a symlink too, and every
// command that writes; its readers run beside the server; the lock dies
// with a server killed with SIGKILL.
TEST_F(WorldToolTest, AServedWorldRefusesASecondServerAndEveryWriterButNotItsReaders) {
  const std::string w = path("w");
  ASSERT_EQ(run("generate --world " + w + " --box 0,0,0,64,64,64").exit_code, 0);
  fs::create_directory_symlink(w, path("link"));
  ASSERT_EQ(run("export --world " + w + " --box 0,0,0,32,32,32 " + path("box.vxraw")).exit_code, 0);

  testing_support::ServerProcess server(w, {});
  ASSERT_NE(server.port(), 0) << server.output();
  const std::string held_by = "in use by pid ";
  const std::string names_server = "(terrane-server on 127.0.0.1:0), since 20";

  for (const std::string& where : {w, path("link")}) {
    testing_support::ServerProcess second(where, {});
    EXPECT_EQ(second.port(), 0) << "a second server started on " << where;
    EXPECT_EQ(second.wait_exit(std::chrono::seconds(60)), 1) << second.output();
    const std::string out = second.output();
    EXPECT_NE(out.find(held_by), std::string::npos) << out;
    EXPECT_NE(out.find(names_server), std::string::npos) << out;
  }
  const std::pair<const char*, std::string> writers[] = {
      {"generate", "generate --world " + path("link") + " --box 0,0,0,96,64,64"},
      {"import", "import --world " + w + " " + path("box.vxraw")},
      {"check --quarantine", "check --world " + w + " --quarantine"},
      {"migrate", "migrate --world " + w + " --to postgresql://127.0.0.1:1/none"},
  };
  for (const auto& [name, args] : writers) {
    auto r = run(args);
    EXPECT_EQ(r.exit_code, 1) << name << ": " << r.output;
    EXPECT_NE(r.output.find("world " + (args.find("link") != std::string::npos ? path("link") : w) + ": " + held_by),
              std::string::npos)
        << name << ": " << r.output;
    EXPECT_NE(r.output.find(names_server), std::string::npos) << name << ": " << r.output;
  }
  const std::pair<const char*, std::string> readers[] = {
      {"check", "check --world " + w},
      {"stats", "stats --world " + w + " --box 0,0,0,64,64,64 --json"},
      {"export", "export --world " + path("link") + " --box 0,0,0,64,64,64 " + path("out.vxraw")},
      {"backup", "backup --world " + w + " --to " + path("copy")},
  };
  for (const auto& [name, args] : readers) {
    auto r = run(args);
    EXPECT_EQ(r.exit_code, 0) << name << ": " << r.output;
  }

  ASSERT_TRUE(server.kill_hard());
  EXPECT_EQ(WorldLock::holder(w), "");
  auto after = run("import --world " + path("link") + " " + path("box.vxraw"));
  EXPECT_EQ(after.exit_code, 0) << after.output;
  testing_support::ServerProcess next(w, {});
  EXPECT_NE(next.port(), 0) << next.output();
}

}  // namespace
}  // namespace terrane
