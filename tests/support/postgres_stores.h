// A fixture for tests of the PostgreSQL stores (tests/server/storage and
// tests/server/cluster): a chunk store opened on the test's database, the
// cluster store beside each one (its leases, servers and inbox, on a
// connection of its own), a statement on a session of the test's own, and
// a chunk write to store.
#pragma once

#include <gtest/gtest.h>
#include <libpq-fe.h>

#include <map>
#include <memory>
#include <string>

#include "common/world/world_store.h"
#include "server/cluster/cluster_store.h"
#include "server/storage/postgres_store.h"
#include "tests/support/postgres.h"

namespace terrane::testing_support {

class PostgresStoresTest : public PostgresTest {
 protected:
  // Runs a statement on a session of the test's own: "" or PostgreSQL's error.
  static std::string command(PGconn* conn, const char* sql) {
    PGresult* r = PQexec(conn, sql);
    const bool ok = PQresultStatus(r) == PGRES_COMMAND_OK;
    std::string error = ok ? "" : PQresultErrorMessage(r);
    PQclear(r);
    return error;
  }
  std::unique_ptr<PostgresStore> open() {
    auto s = PostgresStore::open(url_);
    EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message);
    return s.ok() ? std::move(*s) : nullptr;
  }
  // A bare connection on the test's database (the schema made).
  std::unique_ptr<PgConnection> connect() {
    auto c = PgConnection::open(url_);
    EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
    return c.ok() ? std::move(*c) : nullptr;
  }
  // The cluster store beside chunk store s (one each, opened when first
  // asked, on a connection of its own): its leases, servers and inbox.
  ClusterStore* cl(const std::unique_ptr<PostgresStore>& s) {
    auto& c = beside_[s.get()];
    if (!c) {
      auto opened = ClusterStore::open(url_);
      EXPECT_TRUE(opened.ok()) << (opened.ok() ? "" : opened.error().message);
      if (opened.ok()) c = std::move(*opened);
    }
    return c.get();
  }
  // Chunk cp at revision: its lowest 10 layers of material m.
  static ChunkWrite chunk_write(Vec3i cp, std::uint64_t revision, Material m) {
    Box box({kChunkSize, kChunkSize, kChunkSize});
    for (int y = 0; y < 10; ++y)
      for (int z = 0; z < kChunkSize; ++z)
        for (int x = 0; x < kChunkSize; ++x) box.set(x, y, z, make_voxel(m, static_cast<std::uint8_t>(x * 8)));
    return ChunkWrite{cp, revision, encode_chunk_blob(box)};
  }

 private:
  std::map<const PostgresStore*, std::unique_ptr<ClusterStore>> beside_;
};

// The database's clock now, in microseconds since 1970 (a forwarded
// edit's deadline is written in it).
inline std::int64_t database_now_us(const std::string& url) {
  return std::stoll(sql_value(url, "SELECT (extract(epoch FROM clock_timestamp()) * 1000000)::bigint"));
}

}  // namespace terrane::testing_support
