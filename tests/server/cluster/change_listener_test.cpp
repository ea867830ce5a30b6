// ChangeListener against a real PostgreSQL started by the test: answers to
// forwarded edits reach their sender by notice, and one whose notice went
// out while the sender's listener was reconnecting is read from the
// database once it is back (STORE_POSTGRESQL.md, "Forwarded edits").
#include "server/cluster/change_listener.h"

#include <gtest/gtest.h>
#include <libpq-fe.h>

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <string>
#include <vector>

#include "common/world/world.h"
#include "server/storage/postgres_store.h"
#include "tests/support/eventually.h"
#include "tests/support/postgres.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::eventually;
using testing_support::run_sql;

class ChangeListenerTest : public testing_support::PostgresTest {
 protected:
  // The first value of a one-row answer ("" on any error).
  std::string value(const std::string& sql) {
    PGconn* c = PQconnectdb(url_.c_str());
    std::string out;
    PGresult* r = PQexec(c, sql.c_str());
    if (PQresultStatus(r) == PGRES_TUPLES_OK && PQntuples(r) == 1) out = PQgetvalue(r, 0, 0);
    PQclear(r);
    PQfinish(c);
    return out;
  }
};

TEST_F(ChangeListenerTest, AnAnswerSentWhileTheListenerReconnectsIsReadFromTheDatabase) {
  auto store = PostgresStore::open(url_);  // another server's chunk writes
  ASSERT_TRUE(store.ok()) << store.error().message;
  auto cluster = ClusterStore::open(url_);  // its leases and answers
  ASSERT_TRUE(cluster.ok()) << cluster.error().message;
  std::mutex m;
  std::vector<ForwardAnswer> got;
  int missed = 0;
  std::vector<Vec3i> missed_regions;
  ChangeListener::Handlers on;
  on.changes = [](std::vector<ChunkChange>) {};
  on.inbox = [] {};
  on.answer = [&](ForwardAnswer a) {
    std::lock_guard lock(m);
    got.push_back(std::move(a));
  };
  on.missed = [&](std::vector<Vec3i> regions) {
    std::lock_guard lock(m);
    ++missed;
    missed_regions = std::move(regions);
  };
  // Two regions of another server, written once before the listener
  // starts: none is read again unless written while it is away.
  auto lease_a = (*cluster)->claim({0, 0, 0}, 9, 60s), lease_b = (*cluster)->claim({1, 0, 0}, 9, 60s);
  ASSERT_TRUE(lease_a.ok() && lease_b.ok());
  const ChunkWrite write_a{{0, 0, 0}, 1, encode_chunk_blob(Box({kChunkSize, kChunkSize, kChunkSize}))},
      write_b{{8, 0, 0}, 1, encode_chunk_blob(Box({kChunkSize, kChunkSize, kChunkSize}))};
  ASSERT_TRUE((*store)->save_fenced(std::span(&*lease_a, 1), std::span(&write_a, 1)).ok());
  ASSERT_TRUE((*store)->save_fenced(std::span(&*lease_b, 1), std::span(&write_b, 1)).ok());
  auto listener = ChangeListener::open(url_, 7, on);
  ASSERT_TRUE(listener.ok()) << listener.error().message;
  // Written while listening: its notice comes, in sequence.
  ASSERT_TRUE((*store)->save_fenced(std::span(&*lease_b, 1), std::span(&write_b, 1)).ok());
  auto has = [&](std::int64_t id) {
    std::lock_guard lock(m);
    return std::any_of(got.begin(), got.end(), [&](const ForwardAnswer& a) { return a.id == id; });
  };
  // Listening: the answer comes by its notice, and its row is forgotten.
  const ForwardAnswer first{11, 7, true, 5, ""};
  ASSERT_TRUE((*cluster)->answer(std::span(&first, 1)).ok());
  ASSERT_TRUE(eventually([&] { return has(11); }, 30s));
  ASSERT_TRUE(eventually([&] { return value("SELECT count(*) FROM terrane_answers") == "0"; }, 30s));
  // The listener's connection is cut, and its new one waits for a lock the
  // test holds: an answer committed meanwhile has nobody to notify.
  PGconn* holder = PQconnectdb(url_.c_str());
  ASSERT_EQ(PQstatus(holder), CONNECTION_OK);
  PQclear(PQexec(holder, "BEGIN"));
  // (A new connection reads the schema's version first.)
  PGresult* locked = PQexec(holder, "LOCK TABLE terrane_schema IN ACCESS EXCLUSIVE MODE");
  ASSERT_EQ(PQresultStatus(locked), PGRES_COMMAND_OK) << PQresultErrorMessage(locked);
  PQclear(locked);
  ASSERT_EQ(value("SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity WHERE application_name = '" +
                  ChangeListener::name_of(7) + "'"),
            "1");
  ASSERT_TRUE(eventually(
      [&] {
        return value("SELECT count(*) FROM pg_stat_activity WHERE datname = current_database()"
                     " AND wait_event_type = 'Lock'") == "1";
      },
      30s));
  const ForwardAnswer answers[] = {{12, 7, false, 0, "refused: a region held by server 9"}, {13, 8, true, 4, ""}};
  ASSERT_TRUE((*cluster)->answer(answers).ok());
  // A region written meanwhile (its sequence moves on; its notice is lost).
  ASSERT_TRUE((*store)->save_fenced(std::span(&*lease_a, 1), std::span(&write_a, 1)).ok());
  PQclear(PQexec(holder, "COMMIT"));
  PQfinish(holder);
  // Connected again: what may have been missed is read again, and the
  // answer to this server comes from its row, the other server's is left.
  ASSERT_TRUE(eventually([&] { return has(12); }, 30s)) << "the answer sent while reconnecting never arrived";
  {
    std::lock_guard lock(m);
    EXPECT_EQ(missed, 1);
    EXPECT_EQ(missed_regions, (std::vector<Vec3i>{{0, 0, 0}}));
    const auto it = std::find_if(got.begin(), got.end(), [](const ForwardAnswer& a) { return a.id == 12; });
    EXPECT_EQ(*it, answers[0]);
    EXPECT_FALSE(std::any_of(got.begin(), got.end(), [](const ForwardAnswer& a) { return a.id == 13; }));
  }
  EXPECT_EQ(value("SELECT string_agg(id::text, ',') FROM terrane_answers"), "13");
  // A notice whose region skips a write (which PostgreSQL's delivery never
  // does on a live connection) has the region read again.
  ASSERT_EQ(run_sql(url_, "SELECT pg_notify('terrane_changes', 'r,5,0,0,7 40,0,0,3')"), "");
  ASSERT_TRUE(eventually(
      [&] {
        std::lock_guard lock(m);
        return missed == 2;
      },
      30s));
  std::lock_guard lock(m);
  EXPECT_EQ(missed_regions, (std::vector<Vec3i>{{5, 0, 0}}));
}

}  // namespace
}  // namespace terrane
