// PostgresStore against a real PostgreSQL started by the test (one per
// suite, a database per test), on 127.0.0.1: the schema, chunk rows and
// their units, and writes fenced by the region leases (taken with the
// cluster store: tests/server/cluster/cluster_store_test.cpp).
#include "server/storage/postgres_store.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <libpq-fe.h>
#include <unistd.h>

#include <algorithm>
#include <map>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>

#include "common/codec/update_batch.h"
#include "common/world/world.h"
#include "server/cluster/cluster_store.h"
#include "server/cluster/lease_keeper.h"
#include "tests/support/eventually.h"
#include "tests/support/postgres.h"
#include "tests/support/postgres_stores.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::eventually;

using testing_support::run_sql;
using testing_support::sql_value;

class PostgresStoreTest : public testing_support::PostgresStoresTest {};

TEST_F(PostgresStoreTest, TheSchemaIsMadeOnceAndChunksRoundTrip) {
  auto a = open();
  ASSERT_TRUE(a);
  auto again = open();  // finds the schema made by the first
  ASSERT_TRUE(again);
  const Vec3i cp{3, -2, 17};
  auto lease = cl(a)->claim(lease_region_of(cp), 1, 60s);
  ASSERT_TRUE(lease.ok()) << lease.error().message;
  const ChunkWrite w = chunk_write(cp, 7, materials::kBrick);
  ASSERT_TRUE(a->save_fenced(std::span(&*lease, 1), std::span(&w, 1)).ok());
  auto got = again->load_chunk(cp);
  ASSERT_TRUE(got.ok()) << got.error().message;
  ASSERT_TRUE(got->has_value());
  EXPECT_EQ((*got)->revision, 7u);
  auto expected = decode_chunk_blob(w.blob);
  ASSERT_TRUE(expected.ok());
  EXPECT_EQ((*got)->chunk.get({31, 9, 4}), expected->get({31, 9, 4}));
  EXPECT_EQ((*got)->chunk.get({31, 9, 4}), make_voxel(materials::kBrick, 248));
  EXPECT_EQ((*got)->chunk.get({0, 10, 0}), Voxel{});
  auto none = again->load_chunk({3, -2, 18});
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
}

// A chunk written with the units that changed since its stored revision
// keeps its blob and gains a row of units, up to kMaxKeptUnits rows; the
// next write, or one that skips a revision, writes the blob whole and
// drops the rows. Every
// reader sees the chunk at its revision: load_chunk, the rows a tool walks,
// and a reader opened after the writer. A missing row of units is an error
// naming the chunk.
// A chunk's voxels (a blob's bytes depend on how its rows were packed, which
// its history decides: the same voxels may pack differently).
Box voxels_of(const Chunk& c) {
  Box b;
  c.read_level(0, b);
  return b;
}

TEST_F(PostgresStoreTest, AChunksUnitsAreKeptInPlaceOfItsBlobAndReadBackThroughThem) {
  auto writer = open();
  auto reader = open();
  ASSERT_TRUE(writer && reader);
  const Vec3i cp{2, 1, -3};
  auto lease = cl(writer)->claim(lease_region_of(cp), 1, 60s);
  ASSERT_TRUE(lease.ok()) << lease.error().message;
  Chunk chunk(materials::kRock);
  std::uint64_t revision = 1;
  auto save = [&](ChunkWrite w) { return writer->save_fenced(std::span(&*lease, 1), std::span(&w, 1)); };
  ASSERT_TRUE(save(ChunkWrite{cp, revision, encode_chunk_blob(chunk)}).ok());
  // The next revision: one voxel of unit `unit` changed, with its units.
  auto next = [&](int unit) {
    const Vec3i base = Vec3i{unit % 8, unit / 64, (unit / 8) % 8} * kUpdateUnitSize;
    chunk.set(base + Vec3i{1, 2, 3}, make_voxel(materials::kBrick, static_cast<std::uint8_t>(unit)));
    UnitUpdate u{cp, static_cast<std::uint16_t>(unit), {}};
    for (int y = 0; y < kUpdateUnitSize; ++y)
      for (int z = 0; z < kUpdateUnitSize; ++z)
        for (int x = 0; x < kUpdateUnitSize; ++x)
          u.voxels[static_cast<std::size_t>((y * kUpdateUnitSize + z) * kUpdateUnitSize + x)] =
              chunk.get(base + Vec3i{x, y, z});
    ChunkWrite w{cp, ++revision, encode_chunk_blob(chunk)};
    net_codec_encode_update_batch(std::span(&u, 1), w.units);
    return w;
  };
  const std::string where = " FROM terrane_chunks WHERE x = 2 AND y = 1 AND z = -3";
  auto rows_kept = [&] { return sql_value(url_, "SELECT count(*) FROM terrane_chunk_units"); };
  auto reads_as_written = [&](const std::string& when) {
    auto got = reader->load_chunk(cp);
    ASSERT_TRUE(got.ok()) << when << ": " << got.error().message;
    ASSERT_TRUE(got->has_value()) << when;
    EXPECT_EQ((*got)->revision, revision) << when;
    EXPECT_EQ(voxels_of((*got)->chunk), voxels_of(chunk)) << when;
  };
  for (int i = 1; i <= kMaxKeptUnits; ++i) {
    ASSERT_TRUE(save(next(i * 7 % 512)).ok());
    ASSERT_EQ(rows_kept(), std::to_string(i));
    ASSERT_EQ(sql_value(url_, "SELECT blob_revision" + where), "1");
    reads_as_written("after " + std::to_string(i) + " writes with units");
  }
  // The rows a tool walks (export, check) hold the chunk at its revision.
  int walked = 0;
  ASSERT_TRUE(reader
                  ->for_each_chunk_row([&](Vec3i pos, std::uint64_t rev, FileResult<std::span<const std::uint8_t>> blob,
                                           const std::optional<CoarseVoxels>& coarse) {
                    ++walked;
                    EXPECT_EQ(pos, cp);
                    EXPECT_EQ(rev, revision);
                    ASSERT_TRUE(blob.ok()) << blob.error().message;
                    auto decoded = decode_chunk_blob(*blob);
                    ASSERT_TRUE(decoded.ok());
                    EXPECT_EQ(voxels_of(*decoded), voxels_of(chunk));
                    ASSERT_TRUE(coarse.has_value());
                    EXPECT_EQ(*coarse, coarse_voxels(&chunk));
                  })
                  .ok());
  EXPECT_EQ(walked, 1);
  // One more row than kept: the blob is written whole, the rows go.
  ASSERT_TRUE(save(next(300)).ok());
  EXPECT_EQ(rows_kept(), "0");
  EXPECT_EQ(sql_value(url_, "SELECT blob_revision IS NULL" + where), "t");
  reads_as_written("after the blob was written again");
  ASSERT_TRUE(save(next(301)).ok());
  EXPECT_EQ(rows_kept(), "1");
  // A revision skipped (a batch of ticks that changed the chunk twice
  // stores the second revision only, with its own units): the blob.
  ++revision;
  ChunkWrite skipped = next(304);
  ASSERT_TRUE(save(skipped).ok());
  EXPECT_EQ(rows_kept(), "0");
  reads_as_written("after a revision skipped");
  // A row of units gone: the chunk cannot be read at its revision.
  ASSERT_TRUE(save(next(305)).ok());
  ASSERT_TRUE(save(next(306)).ok());
  ASSERT_EQ(rows_kept(), "2");
  ASSERT_EQ(run_sql(url_, "DELETE FROM terrane_chunk_units WHERE revision = " + std::to_string(revision - 1)), "");
  auto broken = reader->load_chunk(cp);
  ASSERT_FALSE(broken.ok());
  EXPECT_TRUE(broken.error().decode.has_value());
  EXPECT_NE(broken.error().message.find("chunk (2,1,-3)"), std::string::npos) << broken.error().message;
  EXPECT_NE(broken.error().message.find("units of revision " + std::to_string(revision - 1)), std::string::npos)
      << broken.error().message;
  EXPECT_NE(broken.error().message.find("missing"), std::string::npos) << broken.error().message;
  // A tool's walk names the chunk and goes on; for_each_chunk stops there.
  int unreadable = 0;
  ASSERT_TRUE(reader
                  ->for_each_chunk_row([&](Vec3i, std::uint64_t, FileResult<std::span<const std::uint8_t>> blob,
                                           const std::optional<CoarseVoxels>&) {
                    if (blob.ok()) return;
                    ++unreadable;
                    EXPECT_NE(blob.error().message.find("missing"), std::string::npos) << blob.error().message;
                  })
                  .ok());
  EXPECT_EQ(unreadable, 1);
  EXPECT_FALSE(reader->for_each_chunk([](Vec3i, std::uint64_t, std::span<const std::uint8_t>) {}).ok());
  // Quarantined (as the region's server does with a row it cannot read):
  // the blob and the units left move together, under the chunk's revision,
  // above which a chunk served in its place comes.
  auto moved = writer->quarantine_chunk(cp, "units missing");
  ASSERT_TRUE(moved.ok()) << moved.error().message;
  EXPECT_EQ(moved->value_or(0), revision);
  EXPECT_EQ(rows_kept(), "0");
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM terrane_quarantine"), "2");
  EXPECT_EQ(sql_value(url_, "SELECT reason FROM terrane_quarantine WHERE revision = " + std::to_string(revision) +
                                " ORDER BY id LIMIT 1"),
            "units missing (the blob is of revision " + std::to_string(revision - 2) +
                ", its units after it beside it)");
  EXPECT_EQ(writer->quarantined_revision(cp)->value_or(0), revision);
}

// A write PostgreSQL rolls back to break a deadlock is tried again, and
// stored. The deadlock: another session holds the second region's lease
// row while the write locks the first and waits for the second, then asks
// for the first. The write's session finds the deadlock first (the other
// waits 60 s before it looks) and is rolled back; tried again, it waits
// until the other session gives up its rows, then commits.
TEST_F(PostgresStoreTest, AWriteRolledBackToBreakADeadlockIsTriedAgainAndStored) {
  // Sessions of the write's database look after 5 s of waiting (the
  // default, 1 s, would leave a loaded machine little time to make the
  // cycle before the write's session looks once; its lock_timeout is 10 s).
  const std::string db = sql_value(url_, "SELECT current_database()");
  ASSERT_EQ(run_sql(url_, "ALTER DATABASE \"" + db + "\" SET deadlock_timeout = '5s'"), "");
  auto s = open();
  ASSERT_TRUE(s);
  const Vec3i first{0, 0, 0}, second{1, 0, 0};
  auto a = cl(s)->claim(first, 1, 60s), b = cl(s)->claim(second, 1, 60s);
  ASSERT_TRUE(a.ok() && b.ok());
  const std::vector<RegionLease> leases{*a, *b};
  s->set_lease_source(std::make_shared<const LeaseSource>([&](std::span<const Vec3i> regions) {
    std::vector<RegionLease> out;
    for (const Vec3i r : regions)
      for (const RegionLease& l : leases)
        if (l.region == r) out.push_back(l);
    return StoreResult<std::vector<RegionLease>>(out);
  }));
  PGconn* other = PQconnectdb(url_.c_str());
  ASSERT_EQ(PQstatus(other), CONNECTION_OK) << PQerrorMessage(other);
  const auto exec = [&](const char* sql) { return command(other, sql); };
  ASSERT_EQ(exec("SET deadlock_timeout = '60s'"), "");
  ASSERT_EQ(exec("BEGIN"), "");
  ASSERT_EQ(exec("UPDATE terrane_leases SET seq = seq + 1 WHERE rx = 1 AND ry = 0 AND rz = 0"), "");
  const std::vector<ChunkWrite> writes{chunk_write({1, 0, 2}, 1, materials::kSlate),
                                       chunk_write({9, 0, 2}, 1, materials::kBrick)};
  std::string saved = "not done";
  std::thread write([&] {
    auto st = s->save_chunks(writes, true);
    saved = st.ok() ? "" : st.error().message;
  });
  // The write holds the first row and waits for the second.
  EXPECT_TRUE(eventually([&] {
    return sql_value(url_, "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock'") == "1";
  }));
  // Waits until the write is rolled back (the first row is free then).
  EXPECT_EQ(exec("UPDATE terrane_leases SET seq = seq + 1 WHERE rx = 0 AND ry = 0 AND rz = 0"), "");
  EXPECT_EQ(exec("ROLLBACK"), "");
  write.join();
  PQfinish(other);
  EXPECT_EQ(saved, "");
  for (const ChunkWrite& w : writes) {
    auto got = s->load_chunk(w.pos);
    ASSERT_TRUE(got.ok() && got->has_value());
    EXPECT_EQ((*got)->revision, 1u);
  }
}

TEST_F(PostgresStoreTest, AWriteSpanningRegionsIsAllOrNothing) {
  auto a = open(), b = open();
  ASSERT_TRUE(a && b);
  const Vec3i here{7, 0, 0}, there{8, 0, 0};  // two regions side by side
  ASSERT_NE(lease_region_of(here), lease_region_of(there));
  auto mine = cl(a)->claim(lease_region_of(here), 1, 60s);
  auto theirs = cl(b)->claim(lease_region_of(there), 2, 60s);
  ASSERT_TRUE(mine.ok() && theirs.ok());
  const ChunkWrite both[] = {chunk_write(here, 1, materials::kBrick), chunk_write(there, 1, materials::kBrick)};
  // Without a lease for one of them: refused before anything is written.
  auto outside = a->save_fenced(std::span(&*mine, 1), both);
  ASSERT_FALSE(outside.ok());
  EXPECT_EQ(outside.error().kind, StoreError::Kind::kFenced);
  EXPECT_NE(outside.error().message.find("under none of the leases"), std::string::npos) << outside.error().message;
  // With another server's lease passed off as its own: fenced by the check.
  const RegionLease forged[] = {*mine, RegionLease{theirs->region, 1, theirs->epoch}};
  auto forged_write = a->save_fenced(forged, both);
  ASSERT_FALSE(forged_write.ok());
  EXPECT_EQ(forged_write.error().kind, StoreError::Kind::kFenced);
  for (const Vec3i cp : {here, there}) {
    auto got = a->load_chunk(cp);
    ASSERT_TRUE(got.ok());
    EXPECT_FALSE(got->has_value()) << "a fenced transaction wrote a chunk";
  }
}

TEST_F(PostgresStoreTest, BadDatabasesAreClearErrors) {
  // Nothing listening: the error names the address.
  const std::string nowhere =
      "postgresql://terrane@127.0.0.1:" + std::to_string(testing_support::free_loopback_port()) + "/none";
  auto unreachable = PostgresStore::open(nowhere);
  ASSERT_FALSE(unreachable.ok());
  EXPECT_EQ(unreachable.error().kind, StoreError::Kind::kConnection);
  EXPECT_NE(unreachable.error().message.find("cannot connect to " + nowhere), std::string::npos)
      << unreachable.error().message;
  // A password never appears in an error.
  const std::string secret = "postgresql://terrane:s3cret@127.0.0.1:" +
                             std::to_string(testing_support::free_loopback_port()) + "/none";
  auto with_password = PostgresStore::open(secret);
  ASSERT_FALSE(with_password.ok());
  EXPECT_EQ(with_password.error().message.find("s3cret"), std::string::npos) << with_password.error().message;
  EXPECT_NE(with_password.error().message.find("terrane:***@127.0.0.1"), std::string::npos)
      << with_password.error().message;
  const std::string keywords = "host=127.0.0.1 port=" + std::to_string(testing_support::free_loopback_port()) +
                               " password = 'open sesame' dbname=none";
  auto with_keyword = PostgresStore::open(keywords);
  ASSERT_FALSE(with_keyword.ok());
  EXPECT_EQ(with_keyword.error().message.find("sesame"), std::string::npos) << with_keyword.error().message;
  EXPECT_NE(with_keyword.error().message.find("password=***"), std::string::npos) << with_keyword.error().message;
  // A schema of another version is refused, naming both versions.
  ASSERT_TRUE(open());
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_schema SET version = 99"), "");
  auto newer = PostgresStore::open(url_);
  ASSERT_FALSE(newer.ok());
  EXPECT_NE(newer.error().message.find("version 99"), std::string::npos) << newer.error().message;
  EXPECT_NE(newer.error().message.find("reads version " + std::to_string(PostgresStore::kSchemaVersion)),
            std::string::npos)
      << newer.error().message;
  const std::string current_version = "DO $$ BEGIN IF (SELECT version FROM terrane_schema) <> " +
                                      std::to_string(PostgresStore::kSchemaVersion) +
                                      " THEN RAISE 'not the current version'; END IF; END $$";
  // A database of version 1 (before terrane_servers, terrane_answers and
  // the leases' seq) is brought up to date once no region is leased: its
  // servers of version 1 would write without the new rules.
  ASSERT_EQ(run_sql(url_, "DROP TABLE terrane_servers; DROP TABLE terrane_answers;"
                          " ALTER TABLE terrane_leases DROP COLUMN seq; UPDATE terrane_schema SET version = 1;"
                          " INSERT INTO terrane_leases VALUES (0, 0, 0, 1, 1, clock_timestamp() + interval '1 hour')"),
            "");
  auto running = PostgresStore::open(url_);
  ASSERT_FALSE(running.ok());
  EXPECT_NE(running.error().message.find("version 1 with 1 regions leased now: stop its servers"), std::string::npos)
      << running.error().message;
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_leases SET expires_at = clock_timestamp()"), "");
  {
    auto upgraded = open();
    ASSERT_TRUE(upgraded);
    ASSERT_TRUE(cl(upgraded)->advertise(1, "127.0.0.1:7001").ok());
    auto lease = cl(upgraded)->claim({0, 0, 0}, 1, 60s);
    ASSERT_TRUE(lease.ok()) << lease.error().message;
    const ChunkWrite w = chunk_write({0, 0, 0}, 1, materials::kBrick);
    ASSERT_TRUE(upgraded->save_fenced(std::span(&*lease, 1), std::span(&w, 1)).ok());
    EXPECT_EQ(*cl(upgraded)->region_seqs(), (std::vector<RegionSeq>{{{0, 0, 0}, 1}}));
    const ForwardAnswer a{5, 1, true, 1, ""};
    ASSERT_TRUE(cl(upgraded)->answer(std::span(&a, 1)).ok());
    EXPECT_EQ(*cl(upgraded)->take_answers(1), std::vector<ForwardAnswer>{a});
    ASSERT_TRUE(cl(upgraded)->release(std::span(&*lease, 1)).ok());
    ASSERT_TRUE(cl(upgraded)->withdraw(1).ok());
  }
  EXPECT_EQ(run_sql(url_, current_version),
            "");
  // A database of version 2 (whose servers refuse notices with units) is
  // brought up to date the same way, once its servers are stopped.
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_schema SET version = 2;"
                          " UPDATE terrane_leases SET expires_at = clock_timestamp() + interval '1 hour'"),
            "");
  auto v2_running = PostgresStore::open(url_);
  ASSERT_FALSE(v2_running.ok());
  EXPECT_NE(v2_running.error().message.find("schema of version 2 with 1 regions leased now"), std::string::npos)
      << v2_running.error().message;
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_leases SET expires_at = clock_timestamp()"), "");
  ASSERT_TRUE(open());
  EXPECT_EQ(run_sql(url_, current_version),
            "");
  // A database of version 3 (whose servers would read a blob without the
  // units kept after it) too; its chunk rows, each blob at its chunk's
  // revision, read as they were.
  ASSERT_EQ(run_sql(url_, "DROP TABLE terrane_chunk_units; ALTER TABLE terrane_chunks DROP COLUMN blob_revision;"
                          " UPDATE terrane_schema SET version = 3;"
                          " UPDATE terrane_leases SET expires_at = clock_timestamp() + interval '1 hour'"),
            "");
  auto v3_running = PostgresStore::open(url_);
  ASSERT_FALSE(v3_running.ok());
  EXPECT_NE(v3_running.error().message.find("schema of version 3 with 1 regions leased now"), std::string::npos)
      << v3_running.error().message;
  // A server of version 3 running without a lease (its clients only
  // watch) would read blobs without their units, and may write later.
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_leases SET expires_at = clock_timestamp();"
                          " INSERT INTO terrane_servers VALUES (3, '127.0.0.1:7003', clock_timestamp())"),
            "");
  auto v3_watching = PostgresStore::open(url_);
  ASSERT_FALSE(v3_watching.ok());
  EXPECT_NE(v3_watching.error().message.find("version 3 with 1 servers running (seen in the last 10 s): stop its servers"),
            std::string::npos)
      << v3_watching.error().message;
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_servers SET seen_at = clock_timestamp() - interval '11 seconds'"), "");
  {
    auto upgraded = open();
    ASSERT_TRUE(upgraded);
    auto kept = upgraded->load_chunk({0, 0, 0});
    ASSERT_TRUE(kept.ok() && kept->has_value()) << (kept.ok() ? "no row" : kept.error().message);
    EXPECT_EQ((*kept)->revision, 1u);
    EXPECT_EQ((*kept)->chunk.get({0, 0, 0}).material, materials::kBrick);
  }
  EXPECT_EQ(run_sql(url_, current_version), "");
  // A database of version 4 (whose servers forward edits without a
  // deadline and apply them however late; no terrane_commits) too; its
  // inbox rows get a deadline long past: never taken.
  ASSERT_EQ(run_sql(url_, "DROP TABLE terrane_commits;"
                          " ALTER TABLE terrane_inbox DROP COLUMN expires_at, DROP COLUMN taken;"
                          " INSERT INTO terrane_inbox (to_server, from_server, player, edit, created_at)"
                          "  VALUES (2, 1, 'ann', '\\x01', clock_timestamp());"
                          " UPDATE terrane_schema SET version = 4;"
                          " UPDATE terrane_leases SET expires_at = clock_timestamp() + interval '1 hour'"),
            "");
  auto v4_running = PostgresStore::open(url_);
  ASSERT_FALSE(v4_running.ok());
  EXPECT_NE(v4_running.error().message.find("schema of version 4 with 1 regions leased now"), std::string::npos)
      << v4_running.error().message;
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_leases SET expires_at = clock_timestamp()"), "");
  {
    auto upgraded = open();
    ASSERT_TRUE(upgraded);
    auto taken = cl(upgraded)->inbox(2, 0, 10);
    ASSERT_TRUE(taken.ok()) << taken.error().message;
    EXPECT_TRUE(taken->empty()) << "a row of version 4 was taken";
  }
  EXPECT_EQ(run_sql(url_, current_version), "");
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM terrane_commits"), "0");
  // A damaged blob is a decode error naming the chunk.
  ASSERT_EQ(run_sql(url_, "INSERT INTO terrane_chunks VALUES (1, 2, 3, 4, '\\x0102', '\\x')"), "");
  auto store = open();
  ASSERT_TRUE(store);
  auto damaged = store->load_chunk({1, 2, 3});
  ASSERT_FALSE(damaged.ok());
  EXPECT_TRUE(damaged.error().decode.has_value());
  EXPECT_NE(damaged.error().message.find("chunk (1,2,3)"), std::string::npos) << damaged.error().message;
}

TEST_F(PostgresStoreTest, AsAWorldStoreItKeepsMetadataCoarseMipsQuarantineEditLogAndAccessLists) {
  auto s = open();
  ASSERT_TRUE(s);
  EXPECT_FALSE(s->has_world());
  // Writes without a lease source are refused, naming what is missing.
  const ChunkWrite a = chunk_write({1, 0, 2}, 3, materials::kBrick);
  auto unleased = s->save_chunks(std::span(&a, 1));
  ASSERT_FALSE(unleased.ok());
  EXPECT_NE(unleased.error().message.find("--server-id"), std::string::npos) << unleased.error().message;
  // The metadata: made once; a second maker finds the first's.
  WorldMeta meta = default_world_meta(42);
  meta.bounds.min_y = -96;
  ASSERT_TRUE(s->create_world(meta).ok());
  ASSERT_TRUE(s->has_world());
  WorldMeta other = default_world_meta(7);
  auto second = open();
  ASSERT_TRUE(second && second->has_world());
  ASSERT_TRUE(second->create_world(other).ok());
  EXPECT_EQ(second->meta().generator_params, meta.generator_params);
  EXPECT_EQ(second->meta().bounds.min_y, -96);
  ASSERT_TRUE(second->set_epoch(9).ok());
  auto third = s->reopen();
  ASSERT_TRUE(third.ok());
  EXPECT_EQ((*third)->meta().epoch, 9u);
  // Two servers starting from the same metadata each get an epoch of their own.
  ASSERT_TRUE(s->set_epoch(10).ok());
  ASSERT_TRUE(second->set_epoch(10).ok());
  EXPECT_EQ(s->meta().epoch, 10u);
  EXPECT_EQ(second->meta().epoch, 11u);
  EXPECT_EQ((*third)->meta().materials, meta.materials);
  // The world's id: the first server to name it wins, the rest read it.
  auto first_name = s->name_world(1111);
  ASSERT_TRUE(first_name.ok());
  EXPECT_EQ(*first_name, 1111u);
  auto second_name = second->name_world(2222);
  ASSERT_TRUE(second_name.ok());
  EXPECT_EQ(*second_name, 1111u);
  EXPECT_EQ(second->meta().world_id, 1111u);

  // Chunks with their coarse mips and the edit log in one fenced write,
  // through the lease source (which reopened connections share).
  std::vector<Vec3i> asked;
  s->set_lease_source(std::make_shared<const LeaseSource>([&](std::span<const Vec3i> regions) {
    std::vector<RegionLease> out;
    for (Vec3i r : regions) {
      asked.push_back(r);
      auto l = cl(s)->claim(r, 4, 60s);
      if (!l) return StoreResult<std::vector<RegionLease>>(l.error());
      out.push_back(*l);
    }
    return StoreResult<std::vector<RegionLease>>(out);
  }));
  const ChunkWrite b = chunk_write({9, 0, 2}, 1, materials::kSlate);  // the next region in x
  const std::vector<ChunkWrite> writes{a, b};
  EditLogEntry e{0, 12, 1000, "ann", Region{{32, 0, 64}, {36, 4, 68}}, {1, 2, 3}, {4, 5}};
  EditLogEntry f{0, 13, 2000, "bob", Region{{300, 0, 64}, {301, 1, 65}}, {6}, {7}};
  const std::vector<EditLogEntry> log{e, f};
  ASSERT_TRUE(s->save_chunks(writes, true, log).ok());
  EXPECT_EQ(asked, (std::vector<Vec3i>{{0, 0, 0}, {1, 0, 0}}));
  auto coarse = s->load_coarse({0, 0, 0});
  ASSERT_TRUE(coarse.ok()) << coarse.error().message;
  ASSERT_EQ(coarse->size(), 1u);
  auto decoded = decode_chunk_blob(a.blob);
  ASSERT_TRUE(decoded.ok());
  EXPECT_EQ((*coarse)[0], (CoarseEntry{{1, 0, 2}, 3, coarse_voxels(&*decoded)}));
  auto stored = s->stored_in({1, 0, 0});
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(*stored, (std::vector<Vec3i>{Vec3i{9, 0, 2}}));
  EXPECT_EQ(*s->stored_chunk_count(), 2);
  // Without overwrite a stored chunk stays as it is.
  const ChunkWrite a2 = chunk_write({1, 0, 2}, 4, materials::kGrass);
  ASSERT_TRUE(s->save_chunks(std::span(&a2, 1), false).ok());
  EXPECT_EQ((*s->load_chunk({1, 0, 2}))->revision, 3u);
  std::vector<std::pair<Vec3i, std::uint64_t>> each;
  ASSERT_TRUE(s->for_each_chunk([&](Vec3i p, std::uint64_t rev, std::span<const std::uint8_t> blob) {
                 EXPECT_TRUE(decode_chunk_blob(blob).ok());
                 each.emplace_back(p, rev);
               }).ok());
  EXPECT_EQ(each, (std::vector<std::pair<Vec3i, std::uint64_t>>{{{1, 0, 2}, 3}, {{9, 0, 2}, 1}}));

  // The edit log: newest first, filtered by player and box, voxels on request.
  EditLogQuery q;
  auto all = s->edit_log(q);
  ASSERT_TRUE(all.ok()) << all.error().message;
  ASSERT_EQ(all->size(), 2u);
  EXPECT_EQ((*all)[0].player, "bob");
  EXPECT_TRUE((*all)[0].after.empty());
  q.player = "ann";
  q.with_voxels = true;
  auto ann = s->edit_log(q);
  ASSERT_TRUE(ann.ok() && ann->size() == 1u);
  EXPECT_EQ((*ann)[0].box, e.box);
  EXPECT_EQ((*ann)[0].tick, 12u);
  EXPECT_EQ((*ann)[0].before, e.before);
  EXPECT_EQ((*ann)[0].after, e.after);
  q = EditLogQuery{};
  q.box = Region{{299, 0, 60}, {400, 10, 70}};
  auto in_box = s->edit_log(q);
  ASSERT_TRUE(in_box.ok() && in_box->size() == 1u);
  EXPECT_EQ((*in_box)[0].player, "bob");
  // Its size: the entries and their voxels' bytes before and after (ann's
  // 3 + 2, bob's 1 + 1), whichever connection wrote them.
  auto size = s->edit_log_size();
  ASSERT_TRUE(size.ok()) << size.error().message;
  EXPECT_EQ(*size, (EditLogSize{2, 7}));
  EXPECT_EQ(*(*third)->edit_log_size(), (EditLogSize{2, 7}));  // another connection
  auto pruned = s->prune_edit_log(1500, 0);
  ASSERT_TRUE(pruned.ok());
  EXPECT_EQ(*pruned, 1);
  EXPECT_EQ(s->edit_log(EditLogQuery{})->size(), 1u);
  EXPECT_EQ(*(*third)->edit_log_size(), (EditLogSize{1, 2}));  // bob's, after ann's went

  // Quarantine: the row moves aside, blob untouched, and its revision is
  // the floor of the chunk's next ones.
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_chunks SET blob = '\\x0107' WHERE x = 9"), "");
  auto damaged = s->load_chunk({9, 0, 2});
  ASSERT_FALSE(damaged.ok());
  ASSERT_TRUE(damaged.error().decode.has_value());
  auto moved = s->quarantine_chunk({9, 0, 2}, damaged.error().decode->describe());
  ASSERT_TRUE(moved.ok()) << moved.error().message;
  EXPECT_EQ(*moved, (std::optional<std::uint64_t>{1}));
  EXPECT_EQ(*s->quarantined_revision({9, 0, 2}), (std::optional<std::uint64_t>{1}));
  EXPECT_EQ(*s->quarantined_in({1, 0, 0}), (std::vector<Vec3i>{Vec3i{9, 0, 2}}));
  EXPECT_TRUE(s->stored_in({1, 0, 0})->empty());
  EXPECT_EQ(*s->quarantine_chunk({9, 0, 2}, "again"), std::nullopt);  // nothing left to move

  // The access lists.
  ASSERT_TRUE(s->put_access("ban:name:eve", "0 griefing").ok());
  ASSERT_TRUE(s->put_access("whitelist", "on").ok());
  ASSERT_TRUE(s->put_access("whitelist", "off").ok());
  ASSERT_TRUE(s->erase_access("ban:name:eve").ok());
  auto access = s->access_entries();
  ASSERT_TRUE(access.ok());
  const std::vector<std::pair<std::string, std::string>> want{{"whitelist", "off"}};
  EXPECT_EQ(*access, want);
}

TEST_F(PostgresStoreTest, WritesInARegionAnotherServerHoldsAreRefusedWithTheHolder) {
  auto mine = open(), theirs = open();
  ASSERT_TRUE(mine && theirs);
  ASSERT_TRUE(mine->create_world(default_world_meta()).ok());
  ASSERT_TRUE(cl(theirs)->claim({0, 0, 0}, 2, 60s).ok());
  auto keeper = LeaseKeeper::open(url_, 1, LeaseTimes{}, nullptr);
  ASSERT_TRUE(keeper.ok()) << keeper.error().message;
  mine->set_lease_source(std::make_shared<const LeaseSource>(
      [k = keeper->get()](std::span<const Vec3i> regions) { return k->ensure(regions); }));
  const ChunkWrite w = chunk_write({1, 1, 1}, 1, materials::kBrick);
  auto refused = mine->save_chunks(std::span(&w, 1));
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("leased to server 2"), std::string::npos) << refused.error().message;
  EXPECT_FALSE(mine->load_chunk({1, 1, 1})->has_value());
}

// A lease source of fixed leases (those of regions found among them).
std::shared_ptr<const LeaseSource> fixed_leases(std::vector<RegionLease> leases) {
  return std::make_shared<const LeaseSource>([leases = std::move(leases)](std::span<const Vec3i> regions) {
    std::vector<RegionLease> out;
    for (const Vec3i r : regions)
      for (const RegionLease& l : leases)
        if (l.region == r) out.push_back(l);
    return StoreResult<std::vector<RegionLease>>(out);
  });
}

// One edit log entry of player at tick.
EditLogEntry log_entry(std::uint64_t tick, const std::string& player) {
  return EditLogEntry{0, tick, 1000, player, Region{{32, 0, 64}, {33, 1, 65}}, {1, 2}, {3, 4}};
}

TEST_F(PostgresStoreTest, ACommitTriedAgainAfterItsAnswerWasLostIsStoredOnce) {
  auto s = open();
  ASSERT_TRUE(s);
  auto lease = cl(s)->claim({0, 0, 0}, 1, 60s);
  ASSERT_TRUE(lease.ok()) << lease.error().message;
  s->set_lease_source(fixed_leases({*lease}), 10s);
  // The first COMMIT is done in the database and its answer lost (the
  // connection given up), as when the network or the database fails just
  // then: the write is tried again on a new connection.
  int lost = 0;
  s->connection().set_lose_answer([&](const char* sql) { return std::string_view(sql) == "COMMIT" && lost++ == 0; });
  const ChunkWrite w = chunk_write({1, 0, 2}, 1, materials::kBrick);
  const EditLogEntry e = log_entry(7, "ann");
  auto saved = s->save_chunks(std::span(&w, 1), true, std::span(&e, 1));
  ASSERT_TRUE(saved.ok()) << saved.error().message;
  EXPECT_EQ(lost, 1) << "the try after the lost answer sent a COMMIT again";
  // Stored once: its edit log entry once, the region's write sequence
  // moved once, the chunk at its revision.
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM terrane_edit_log"), "1");
  EXPECT_EQ(sql_value(url_, "SELECT seq FROM terrane_leases"), "1");
  auto got = s->load_chunk({1, 0, 2});
  ASSERT_TRUE(got.ok() && got->has_value());
  EXPECT_EQ((*got)->revision, 1u);
  // The next commit is stored as usual.
  const ChunkWrite w2 = chunk_write({1, 0, 2}, 2, materials::kSand);
  const EditLogEntry e2 = log_entry(8, "ann");
  ASSERT_TRUE(s->save_chunks(std::span(&w2, 1), true, std::span(&e2, 1)).ok());
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM terrane_edit_log"), "2");
  EXPECT_EQ(sql_value(url_, "SELECT string_agg(tick::text, ',' ORDER BY id) FROM terrane_edit_log"), "7,8");
}

TEST_F(PostgresStoreTest, ACommitThatCannotFindOutWhetherItWasStoredSaysItsOutcomeIsUnknown) {
  auto s = open();
  ASSERT_TRUE(s);
  auto lease = cl(s)->claim({0, 0, 0}, 1, 60s);
  ASSERT_TRUE(lease.ok()) << lease.error().message;
  s->set_lease_source(fixed_leases({*lease}), 300ms);
  const std::string refuse = "ALTER DATABASE " + db_ + " WITH ALLOW_CONNECTIONS false";
  const std::string allow = "ALTER DATABASE " + db_ + " WITH ALLOW_CONNECTIONS true";
  // A statement before the COMMIT loses its answer, and the database takes
  // no connection until the write gives up: nothing was stored, and the
  // write fails as a refusal.
  s->connection().set_lose_answer([&](const char* sql) {
    if (std::string_view(sql).find("INSERT INTO terrane_edit_log") == std::string_view::npos) return false;
    EXPECT_EQ(run_sql(pg_->url(), refuse), "");
    return true;
  });
  const ChunkWrite w = chunk_write({1, 0, 2}, 1, materials::kBrick);
  const EditLogEntry e = log_entry(7, "ann");
  auto refused = s->save_chunks(std::span(&w, 1), true, std::span(&e, 1));
  ASSERT_FALSE(refused.ok());
  EXPECT_FALSE(refused.error().outcome_unknown) << refused.error().message;
  ASSERT_EQ(run_sql(pg_->url(), allow), "");
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM terrane_edit_log"), "0");
  // The COMMIT's answer is lost, and then the database cannot be asked:
  // the outcome is unknown, and the error says so (it was stored here).
  s->connection().set_lose_answer([&](const char* sql) {
    if (std::string_view(sql) != "COMMIT") return false;
    EXPECT_EQ(run_sql(pg_->url(), refuse), "");
    return true;
  });
  auto unknown = s->save_chunks(std::span(&w, 1), true, std::span(&e, 1));
  ASSERT_FALSE(unknown.ok());
  EXPECT_TRUE(unknown.error().outcome_unknown) << unknown.error().message;
  EXPECT_NE(unknown.error().message.find("may have been stored"), std::string::npos) << unknown.error().message;
  ASSERT_EQ(run_sql(pg_->url(), allow), "");
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM terrane_edit_log"), "1");
}

}  // namespace
}  // namespace terrane
