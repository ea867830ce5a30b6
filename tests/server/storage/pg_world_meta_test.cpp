// PgWorldMeta against a real PostgreSQL (tests/support/postgres.h): the
// world's metadata as several servers sharing one database write it.
#include "server/storage/pg_world_meta.h"

#include <gtest/gtest.h>

#include "common/world/world.h"
#include "tests/support/postgres.h"
#include "tests/support/postgres_stores.h"

namespace terrane {
namespace {

using testing_support::run_sql;

class PgWorldMetaTest : public testing_support::PostgresStoresTest {};

TEST_F(PgWorldMetaTest, TwoServersShareOneMetadataEachWithItsOwnEpochAndTheFirstsName) {
  auto ca = connect(), cb = connect();
  ASSERT_TRUE(ca && cb);
  PgWorldMeta a, b;
  ASSERT_TRUE(a.read(*ca).ok());
  EXPECT_FALSE(a.has_world());
  WorldMeta meta = default_world_meta(42);
  meta.bounds.min_y = -96;
  ASSERT_TRUE(a.create(*ca, meta).ok());
  ASSERT_TRUE(a.has_world());
  // The second maker finds the first's.
  ASSERT_TRUE(b.create(*cb, default_world_meta(7)).ok());
  EXPECT_EQ(b.meta().generator_params, meta.generator_params);
  EXPECT_EQ(b.meta().bounds.min_y, -96);
  EXPECT_EQ(b.meta().world_id, 0u);
  // Epochs: each start above whatever is stored.
  ASSERT_TRUE(a.set_epoch(*ca, 10).ok());
  ASSERT_TRUE(b.set_epoch(*cb, 10).ok());
  EXPECT_EQ(a.meta().epoch, 10u);
  EXPECT_EQ(b.meta().epoch, 11u);
  // The world's id: the first name kept, the second server reads it.
  auto first = a.name_world(*ca, 1111);
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(*first, 1111u);
  auto second = b.name_world(*cb, 2222);
  ASSERT_TRUE(second.ok());
  EXPECT_EQ(*second, 1111u);
  // A border writes the bounds' keys only: the epoch b wrote stays.
  WorldBounds border = a.meta().bounds;
  border.bounded_xz = true;
  border.min_x = -64;
  border.max_x = 64;
  border.min_z = -32;
  border.max_z = 32;
  ASSERT_TRUE(a.set_bounds(*ca, border).ok());
  PgWorldMeta fresh;
  ASSERT_TRUE(fresh.read(*connect()).ok());
  EXPECT_TRUE(fresh.meta().bounds.bounded_xz);
  EXPECT_EQ(fresh.meta().bounds.max_x, 64);
  EXPECT_EQ(fresh.meta().epoch, 11u);
  EXPECT_EQ(fresh.meta().world_id, 1111u);
}

TEST_F(PgWorldMetaTest, AMalformedWorldIdIsAnErrorNamingTheKey) {
  auto c = connect();
  ASSERT_TRUE(c);
  PgWorldMeta m;
  ASSERT_TRUE(m.create(*c, default_world_meta(1)).ok());
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_meta SET value = 'twelve' WHERE key = 'world_id'"), "");
  PgWorldMeta again;
  auto r = again.read(*c);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("world_id"), std::string::npos) << r.error().message;
  auto named = m.name_world(*c, 5);
  ASSERT_FALSE(named.ok());
  EXPECT_NE(named.error().message.find("world_id"), std::string::npos) << named.error().message;
}

}  // namespace
}  // namespace terrane
