// End-to-end tests of the terrane-world tool on PostgreSQL worlds: runs the
// built binary against a real PostgreSQL started by the test (one per test
// process, a database per test; skipped where PostgreSQL is not installed).
#include <gtest/gtest.h>
#include <libpq-fe.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include "common/vxraw/vxraw.h"
#include "common/world/sqlite_store.h"
#include "common/world/world.h"
#include "server/cluster/cluster_store.h"
#include "server/storage/postgres_store.h"
#include "tests/support/postgres.h"
#include "tests/support/run_command.h"
#include "tests/support/scratch_dir.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

struct RunResult {
  int exit_code;
  std::string output;  // stdout and stderr
};

RunResult run(const std::string& args) {
  RunResult r{-1, {}};
  r.exit_code = testing_support::run_command(std::string(TERRANE_BIN_DIR) + "/terrane-world " + args, &r.output);
  return r;
}

std::string file_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

// Every chunk row of a store: position -> (revision, blob).
using Rows = std::map<std::tuple<int, int, int>, std::pair<std::uint64_t, std::vector<std::uint8_t>>>;
Rows rows_of(WorldStore& store) {
  Rows rows;
  EXPECT_TRUE(store
                  .for_each_chunk([&](Vec3i p, std::uint64_t rev, std::span<const std::uint8_t> blob) {
                    rows[{p.x, p.y, p.z}] = {rev, std::vector<std::uint8_t>(blob.begin(), blob.end())};
                  })
                  .ok());
  return rows;
}

class TerraneWorldPostgresTest : public testing_support::PostgresTest {
 protected:
  void SetUp() override {
    PostgresTest::SetUp();
    if (IsSkipped() || HasFatalFailure()) return;
    dir_ = testing_support::scratch_dir("terrane-tool-pg");
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!dir_.empty()) fs::remove_all(dir_);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  // url_ with a password in it (the test database trusts every connection,
  // so it is never checked): messages must never show it.
  std::string url_with_password() const {
    std::string u = url_;
    u.replace(u.find("terrane@"), 8, "terrane:pw-sekrit@");
    return u;
  }
  std::unique_ptr<PostgresStore> open_store() {
    auto s = PostgresStore::open(url_);
    EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message);
    return s.ok() ? std::move(*s) : nullptr;
  }
  // The leases and servers of the test's database.
  std::unique_ptr<ClusterStore> open_cluster() {
    auto s = ClusterStore::open(url_);
    EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message);
    return s.ok() ? std::move(*s) : nullptr;
  }
  // A VXRAW file: a brick pillar with varied occupancy, at origin.
  std::string write_vxraw(const std::string& name, Vec3i origin, Vec3i size) {
    Box box(size);
    for (int y = 0; y < size.y; ++y)
      for (int z = 0; z < size.z; ++z)
        for (int x = 0; x < size.x; ++x)
          if ((x + y + z) % 3 != 0)
            box.set(x, y, z, make_voxel(materials::kBrick, static_cast<std::uint8_t>(1 + (x * 7 + y) % 255)));
    const std::string p = path(name);
    EXPECT_TRUE(vxraw_write_file(p, box, origin, /*gzip=*/false).ok());
    return p;
  }

  fs::path dir_;
};

TEST_F(TerraneWorldPostgresTest, MigrateCopiesAWorldDirectoryThatThenExportsTheSame) {
  const std::string w = path("w");
  auto g = run("generate --world " + w + " --box 0,0,0,64,64,64");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  // An edit on top (revisions 1 and up), and an access list entry.
  auto im = run("import --world " + w + " " + write_vxraw("pillar.vxraw", {5, 20, 40}, {30, 40, 9}));
  ASSERT_EQ(im.exit_code, 0) << im.output;
  {
    auto src = SqliteStore::open(w);
    ASSERT_TRUE(src.ok()) << src.error().message;
    ASSERT_TRUE((*src)->put_access("ban:griefer", "0 testing").ok());
  }

  auto m = run("migrate --world " + w + " --to " + url_with_password());
  ASSERT_EQ(m.exit_code, 0) << m.output;
  EXPECT_NE(m.output.find("1 access entries of world " + w + " to "), std::string::npos) << m.output;
  EXPECT_NE(m.output.find("(edit log and quarantine not copied)"), std::string::npos) << m.output;
  EXPECT_EQ(m.output.find("pw-sekrit"), std::string::npos) << "the password is printed: " << m.output;

  // The same bytes out of both, stored chunks and generated ones around them.
  for (const std::string box : {"0,0,0,64,64,64", "-20,-10,-20,90,80,70"}) {
    auto a = run("export --world " + w + " --box " + box + " " + path("dir.vxraw"));
    ASSERT_EQ(a.exit_code, 0) << a.output;
    auto b = run("export --store " + url_ + " --box " + box + " " + path("pg.vxraw"));
    ASSERT_EQ(b.exit_code, 0) << b.output;
    const std::string from_dir = file_bytes(path("dir.vxraw")), from_pg = file_bytes(path("pg.vxraw"));
    ASSERT_FALSE(from_dir.empty());
    EXPECT_TRUE(from_dir == from_pg) << "box " << box << " differs after migrate";
  }
  // --world takes a URL too.
  auto e = run("export --world " + url_ + " --box -20,-10,-20,90,80,70 " + path("pg2.vxraw"));
  ASSERT_EQ(e.exit_code, 0) << e.output;
  EXPECT_TRUE(file_bytes(path("pg2.vxraw")) == file_bytes(path("dir.vxraw")));
  // stats reads it without a server id, and measures what the directory's does.
  auto s = run("stats --store " + url_ + " --box 0,0,0,64,64,64 --json");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  auto sd = run("stats --world " + w + " --box 0,0,0,64,64,64 --json");
  ASSERT_EQ(sd.exit_code, 0) << sd.output;
  for (const std::string key : {"\"voxels\"", "\"non_empty_voxels\""}) {
    const auto line_of = [&](const std::string& out) {
      const auto at = out.find(key);
      return at == std::string::npos ? std::string() : out.substr(at, out.find(',', at) - at);
    };
    EXPECT_FALSE(line_of(s.output).empty()) << key << " missing in " << s.output;
    EXPECT_EQ(line_of(s.output), line_of(sd.output));
  }

  // Row for row: metadata, revisions, blobs, coarse mips, access lists; and
  // the migration's leases were given up.
  auto src = SqliteStore::open(w);
  ASSERT_TRUE(src.ok());
  auto dst = open_store();
  ASSERT_TRUE(dst);
  ASSERT_TRUE(dst->has_world());
  EXPECT_EQ(meta_to_keys(dst->meta()), meta_to_keys((*src)->meta()));
  const Rows from = rows_of(**src), to = rows_of(*dst);
  EXPECT_GT(from.size(), 2u);
  EXPECT_TRUE(from == to) << from.size() << " rows in the directory, " << to.size() << " in the database";
  bool edited = false;
  for (const auto& [key, row] : to) edited |= row.first > 0;
  EXPECT_TRUE(edited) << "the import's revisions were not copied";
  EXPECT_NE(m.output.find("migrated " + std::to_string(from.size()) + " chunks"), std::string::npos) << m.output;
  // The coarse mips (each backend lists a region's entries in its own order).
  const auto coarse_of = [](WorldStore& store) {
    std::map<std::tuple<int, int, int>, std::pair<std::uint64_t, CoarseVoxels>> out;
    auto entries = store.load_coarse({0, 0, 0});
    EXPECT_TRUE(entries.ok()) << entries.error().message;
    if (entries.ok())
      for (const CoarseEntry& c : *entries) out[{c.chunk_pos.x, c.chunk_pos.y, c.chunk_pos.z}] = {c.revision, c.voxels};
    return out;
  };
  const auto coarse_src = coarse_of(**src), coarse_dst = coarse_of(*dst);
  EXPECT_EQ(coarse_src.size(), from.size());
  EXPECT_TRUE(coarse_src == coarse_dst);
  auto access = dst->access_entries();
  ASSERT_TRUE(access.ok());
  EXPECT_EQ(*access, *(*src)->access_entries());
  auto holder = open_cluster()->holder({0, 0, 0});
  ASSERT_TRUE(holder.ok()) << holder.error().message;
  EXPECT_FALSE(holder->has_value()) << "server " << (*holder)->owner << " still holds region (0, 0, 0)";
}

TEST_F(TerraneWorldPostgresTest, MigrateRefusesADatabaseThatHoldsAWorld) {
  const std::string w = path("w");
  ASSERT_EQ(run("generate --world " + w + " --seed 2 --box 0,0,0,32,32,32").exit_code, 0);
  // generate makes the database's world (with a server id of its own).
  auto g = run("generate --store " + url_ + " --server-id 7 --box 0,0,0,64,32,32");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  EXPECT_NE(g.output.find("created world"), std::string::npos) << g.output;
  auto again = run("generate --store " + url_ + " --server-id 7 --box 0,0,0,64,32,32");
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_NE(again.output.find("exists"), std::string::npos) << again.output;

  auto before = open_store();
  ASSERT_TRUE(before);
  const Rows rows_before = rows_of(*before);
  EXPECT_FALSE(rows_before.empty());
  before.reset();

  auto m = run("migrate --world " + w + " --to " + url_with_password());
  EXPECT_EQ(m.exit_code, 1) << m.output;
  EXPECT_NE(m.output.find("already holds a world"), std::string::npos) << m.output;
  std::string shown = url_with_password();
  shown.replace(shown.find("pw-sekrit"), 9, "***");
  EXPECT_NE(m.output.find(shown), std::string::npos) << "the database is not named: " << m.output;
  EXPECT_EQ(m.output.find("pw-sekrit"), std::string::npos) << m.output;
  // Nothing of the directory's (seed 2) was written.
  auto dst = open_store();
  ASSERT_TRUE(dst);
  EXPECT_TRUE(rows_of(*dst) == rows_before);
  EXPECT_EQ(meta_to_keys(dst->meta()), meta_to_keys(default_world_meta(1)));
}

TEST_F(TerraneWorldPostgresTest, MigrateStopsAtADamagedChunkAndRunsAgainOnceItIsQuarantined) {
  const std::string w = path("w");
  ASSERT_EQ(run("generate --world " + w + " --box 0,0,0,64,64,64").exit_code, 0);
  {
    auto store = SqliteStore::open(w);
    ASSERT_TRUE(store.ok());
    std::vector<ChunkWrite> bad = {{{1, 1, 0}, 9, {1, 1, 0x10, 0x20}}};
    ASSERT_TRUE((*store)->save_chunks(bad).ok());
  }
  auto m = run("migrate --world " + w + " --to " + url_);
  EXPECT_EQ(m.exit_code, 1) << m.output;
  EXPECT_NE(m.output.find("chunk (1, 1, 0) does not decode"), std::string::npos) << m.output;
  EXPECT_NE(m.output.find("check --world " + w + " --quarantine"), std::string::npos) << m.output;
  {
    auto dst = open_store();
    ASSERT_TRUE(dst);
    EXPECT_FALSE(dst->has_world()) << "a world that is half a copy";
  }
  ASSERT_EQ(run("check --world " + w + " --quarantine").exit_code, 1);  // 1: a quarantined row
  auto again = run("migrate --world " + w + " --to " + url_);
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_NE(again.output.find("1 quarantined chunk rows"), std::string::npos) << again.output;
  auto a = run("export --world " + w + " --box 0,0,0,64,64,64 " + path("dir.vxraw"));
  auto b = run("export --store " + url_ + " --box 0,0,0,64,64,64 " + path("pg.vxraw"));
  ASSERT_EQ(a.exit_code, 0) << a.output;
  ASSERT_EQ(b.exit_code, 0) << b.output;
  EXPECT_TRUE(file_bytes(path("dir.vxraw")) == file_bytes(path("pg.vxraw")));
}

TEST_F(TerraneWorldPostgresTest, ImportToADatabaseNeedsAServerIdAndGivesItsLeasesUp) {
  const std::string file = write_vxraw("box.vxraw", {-10, 3, 7}, {40, 20, 12});
  auto no_id = run("import --store " + url_ + " " + file);
  EXPECT_EQ(no_id.exit_code, 2) << no_id.output;
  EXPECT_NE(no_id.output.find("--server-id"), std::string::npos) << no_id.output;
  auto bad_id = run("import --store " + url_ + " --server-id 2147483648 " + file);
  EXPECT_EQ(bad_id.exit_code, 2) << bad_id.output;
  EXPECT_NE(bad_id.output.find("--server-id"), std::string::npos) << bad_id.output;
  auto dir_id = run("import --world " + path("w") + " --server-id 3 " + file);
  EXPECT_EQ(dir_id.exit_code, 2) << dir_id.output;
  EXPECT_NE(dir_id.output.find("--server-id is for a PostgreSQL world"), std::string::npos) << dir_id.output;
  auto both = run("export --world " + path("w") + " --store " + url_ + " --box 0,0,0,1,1,1 " + path("x.vxraw"));
  EXPECT_EQ(both.exit_code, 2) << both.output;
  EXPECT_NE(both.output.find("not both"), std::string::npos) << both.output;

  // Reading a database that holds no world is an error naming it.
  auto empty = run("stats --store " + url_);
  EXPECT_EQ(empty.exit_code, 1) << empty.output;
  EXPECT_NE(empty.output.find("holds no world"), std::string::npos) << empty.output;

  // A region another server holds is refused, naming it.
  {
    auto other = open_cluster();
    ASSERT_TRUE(other);
    ASSERT_TRUE(other->claim(lease_region_of({0, 0, 0}), 1, 600s).ok());
    auto held = run("import --store " + url_ + " --server-id 5 " + file);
    EXPECT_EQ(held.exit_code, 1) << held.output;
    EXPECT_NE(held.output.find("server 1"), std::string::npos) << held.output;
    const RegionLease lease{lease_region_of({0, 0, 0}), 1, 1};
    ASSERT_TRUE(other->release(std::span(&lease, 1)).ok());
  }

  auto im = run("import --store " + url_ + " --server-id 5 " + file);
  ASSERT_EQ(im.exit_code, 0) << im.output;
  auto ex = run("export --store " + url_ + " --box -10,3,7,30,23,19 --raw " + path("back.vxraw"));
  ASSERT_EQ(ex.exit_code, 0) << ex.output;
  auto in = vxraw_read_file(file, {});
  auto out = vxraw_read_file(path("back.vxraw"), {});
  ASSERT_TRUE(in.ok() && out.ok());
  EXPECT_EQ(in->origin, out->origin);
  EXPECT_EQ(in->box, out->box);
  auto leases = open_cluster();
  ASSERT_TRUE(leases);
  for (const Vec3i region : {Vec3i{-1, 0, 0}, Vec3i{0, 0, 0}}) {
    auto holder = leases->holder(region);
    ASSERT_TRUE(holder.ok()) << holder.error().message;
    EXPECT_FALSE(holder->has_value()) << "the import still holds a region";
  }
}

TEST_F(TerraneWorldPostgresTest, CheckReadsEveryRowOfADatabaseAndNamesDamagedRowsAndWrongMips) {
  const std::string w = path("w");
  ASSERT_EQ(run("generate --world " + w + " --box 0,0,0,64,64,64").exit_code, 0);
  ASSERT_EQ(run("migrate --world " + w + " --to " + url_).exit_code, 0);
  auto good = run("check --store " + url_);
  EXPECT_EQ(good.exit_code, 0) << good.output;
  EXPECT_NE(good.output.find(": 0 damaged, 0 quarantined, 0 coarse mips wrong"), std::string::npos) << good.output;
  // One row's blob damaged, another's coarse mip column changed (a valid
  // mip, other voxels: Brick at occupancy 8 throughout).
  PGconn* conn = PQconnectdb(url_.c_str());
  ASSERT_EQ(PQstatus(conn), CONNECTION_OK) << PQerrorMessage(conn);
  const auto changed = [&](const char* set, int offset) {
    const std::string q = std::string("UPDATE terrane_chunks SET ") + set +
                          " WHERE (x, y, z) IN (SELECT x, y, z FROM terrane_chunks ORDER BY x, y, z LIMIT 1 OFFSET " +
                          std::to_string(offset) + ") RETURNING x, y, z";
    PGresult* r = PQexec(conn, q.c_str());
    std::string at = "none";
    if (PQresultStatus(r) == PGRES_TUPLES_OK && PQntuples(r) == 1)
      at = std::string("(") + PQgetvalue(r, 0, 0) + ", " + PQgetvalue(r, 0, 1) + ", " + PQgetvalue(r, 0, 2) + ")";
    PQclear(r);
    return at;
  };
  const std::string damaged = changed("blob = '\\x01011020'::bytea", 0);
  const std::string wrong = changed("coarse = decode(repeat('0508', 64), 'hex')", 1);
  PQfinish(conn);
  ASSERT_NE(damaged, "none");
  ASSERT_NE(wrong, "none");
  auto bad = run("check --store " + url_);
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("chunk " + damaged + ": damaged"), std::string::npos) << bad.output;
  EXPECT_NE(bad.output.find("chunk " + wrong + ": coarse mip differs from the chunk's"), std::string::npos)
      << bad.output;
  EXPECT_NE(bad.output.find(": 1 damaged, 0 quarantined, 1 coarse mips wrong"), std::string::npos) << bad.output;
  // The damaged row quarantined (as its region's server does when it
  // loads it): listed with its reason, and no longer damaged.
  {
    auto store = open_store();
    ASSERT_TRUE(store);
    std::optional<Vec3i> first;
    ASSERT_TRUE(store->for_each_chunk([&](Vec3i p, std::uint64_t, std::span<const std::uint8_t>) {
                       if (!first) first = p;
                     }).ok());
    ASSERT_TRUE(first.has_value());
    auto moved = store->quarantine_chunk(*first, "a test's reason");
    ASSERT_TRUE(moved.ok() && moved->has_value());
  }
  auto listed = run("check --store " + url_);
  EXPECT_EQ(listed.exit_code, 1) << listed.output;
  EXPECT_NE(listed.output.find("chunk " + damaged + ": quarantined at "), std::string::npos) << listed.output;
  EXPECT_NE(listed.output.find("a test's reason"), std::string::npos) << listed.output;
  EXPECT_NE(listed.output.find(": 0 damaged, 1 quarantined, 1 coarse mips wrong"), std::string::npos) << listed.output;
  // Quarantining is the region's server's, as it loads a row.
  auto quarantine = run("check --store " + url_ + " --quarantine");
  EXPECT_EQ(quarantine.exit_code, 2) << quarantine.output;
  EXPECT_NE(quarantine.output.find("--quarantine is for world directories"), std::string::npos) << quarantine.output;
}

TEST_F(TerraneWorldPostgresTest, BackupOfADatabaseSaysWhatToUseInstead) {
  auto backup = run("backup --store " + url_ + " --to " + path("copy"));
  EXPECT_EQ(backup.exit_code, 2) << backup.output;
  EXPECT_NE(backup.output.find("pg_dump"), std::string::npos) << backup.output;
  EXPECT_FALSE(fs::exists(path("copy")));
  auto backup_to = run("backup --world " + path("w") + " --to " + url_);
  EXPECT_EQ(backup_to.exit_code, 2) << backup_to.output;
  EXPECT_NE(backup_to.output.find("migrate"), std::string::npos) << backup_to.output;
  auto migrate_to_dir = run("migrate --world " + path("w") + " --to " + path("other"));
  EXPECT_EQ(migrate_to_dir.exit_code, 2) << migrate_to_dir.output;
  EXPECT_NE(migrate_to_dir.output.find("--to takes a postgresql:// URL"), std::string::npos) << migrate_to_dir.output;
  auto usage = run("--help");
  EXPECT_EQ(usage.exit_code, 0);
  EXPECT_NE(usage.output.find("migrate"), std::string::npos) << usage.output;
  auto help = run("migrate --help");
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.output.find("NOT copied: the edit log"), std::string::npos) << help.output;
  EXPECT_NE(help.output.find("default 2147483647"), std::string::npos) << help.output;
}

}  // namespace
}  // namespace terrane
