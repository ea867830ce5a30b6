// Test support: a real PostgreSQL of the test's own. initdb runs in a
// scratch directory, the server listens on 127.0.0.1 only (and on a Unix
// socket in that directory), and it is stopped by pid when the object goes.
// As root, both run as the "postgres" user (PostgreSQL refuses root).
// Header-only.
//
//   ScratchPostgres pg(scratch_dir("terrane-pg"));
//   if (!pg.available()) GTEST_SKIP() << pg.why();
//   ASSERT_TRUE(pg.start()) << pg.why();
//   PostgresStore::open(pg.url())...
#pragma once

#include <gtest/gtest.h>
#include <libpq-fe.h>
#include <pwd.h>
#include <signal.h>
#include <unistd.h>

#include <cctype>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "tests/support/child_process.h"
#include "tests/support/scratch_dir.h"

namespace terrane::testing_support {

class ScratchPostgres {
 public:
  // dir: emptied first, removed at the end (a suite's set-up has no test
  // name for scratch_dir: name it after the process).
  explicit ScratchPostgres(std::filesystem::path dir) : dir_(std::move(dir)) {
    std::filesystem::remove_all(dir_);
    bin_ = find_bin();
  }
  ~ScratchPostgres() {
    if (server_) server_->stop();
    std::filesystem::remove_all(dir_);
  }

  // False where PostgreSQL is not installed (why() says so).
  bool available() {
    if (bin_.empty()) why_ = "PostgreSQL is not installed (scripts/install-deps.sh installs postgresql-15)";
    return !bin_.empty();
  }
  const std::string& why() const { return why_; }

  // initdb, then the server; true once it accepts connections.
  bool start() {
    if (!available()) return false;
    std::filesystem::create_directories(dir_);
    const bool root = ::geteuid() == 0;
    if (root) {
      const passwd* pw = ::getpwnam("postgres");
      if (pw == nullptr) {
        why_ = "running as root and there is no 'postgres' user to run PostgreSQL as";
        return false;
      }
      if (::chown(dir_.c_str(), pw->pw_uid, pw->pw_gid) != 0) {
        why_ = "cannot hand " + dir_.string() + " to the postgres user";
        return false;
      }
    }
    const std::string data = (dir_ / "data").string();
    std::vector<std::string> initdb = as_postgres(root, {bin_ + "/initdb", "-D", data, "-U", "terrane",
                                                         "--auth=trust", "--encoding=UTF8", "--no-sync"});
    ChildProcess init(initdb);
    if (const int st = init.wait(std::chrono::seconds(120)); st != 0) {
      why_ = "initdb failed (" + std::to_string(st) + "): " + init.output();
      return false;
    }
    port_ = free_loopback_port();
    argv_ = as_postgres(root, {bin_ + "/postgres", "-D", data, "-p", std::to_string(port_), "-c",
                               "listen_addresses=127.0.0.1", "-c", "unix_socket_directories=" + dir_.string(), "-c",
                               "fsync=off", "-c", "max_connections=50"});
    return run_server();
  }

  // Stops the database (a fast shutdown: sessions are cut) and starts it
  // again on the same port and data; true once it accepts connections.
  bool restart() { return stop() && start_again(); }
  // The two halves of restart(), for tests of a database that stays away:
  // stop() returns once it has stopped, start_again() once it accepts
  // connections again.
  bool stop() {
    if (!server_) return false;
    // To the postmaster itself (its pid is the first line of
    // postmaster.pid): as root, the child is runuser, which passes no signal on.
    std::ifstream pid_file(dir_ / "data" / "postmaster.pid");
    long pid = 0;
    if (!(pid_file >> pid) || pid <= 0 || ::kill(static_cast<pid_t>(pid), SIGINT) != 0) {
      why_ = "cannot signal the postmaster (data/postmaster.pid)";
      return false;
    }
    if (server_->wait(std::chrono::seconds(60)) != 0) {
      why_ = "postgres did not stop: " + server_->output();
      return false;
    }
    server_.reset();
    return true;
  }
  bool start_again() { return !server_ && !argv_.empty() && run_server(); }

  // The test database (created by the first call).
  std::string url() const { return "postgresql://terrane@127.0.0.1:" + std::to_string(port_) + "/postgres"; }
  std::uint16_t port() const { return port_; }
  // SIGSTOP / SIGCONT / restart, for tests of a database that pauses or
  // goes away.
  ChildProcess* server() { return server_.get(); }

 private:
  static std::string find_bin() {
    for (const char* v : {"17", "16", "15", "14", "13"}) {
      const std::string d = std::string("/usr/lib/postgresql/") + v + "/bin";
      if (std::filesystem::exists(d + "/initdb") && std::filesystem::exists(d + "/postgres")) return d;
    }
    return {};
  }
  static std::vector<std::string> as_postgres(bool root, std::vector<std::string> argv) {
    if (!root) return argv;
    std::vector<std::string> out{"runuser", "-u", "postgres", "--"};
    out.insert(out.end(), argv.begin(), argv.end());
    return out;
  }

  bool run_server() {
    server_ = std::make_unique<ChildProcess>(argv_);
    if (!server_->wait_for_output("database system is ready to accept connections", std::chrono::seconds(120))) {
      why_ = "postgres did not start: " + server_->output();
      return false;
    }
    return true;
  }

  std::filesystem::path dir_;
  std::vector<std::string> argv_;
  std::string bin_, why_;
  std::uint16_t port_ = 0;
  std::unique_ptr<ChildProcess> server_;
};

// Runs one statement on a connection of its own; "" or the error.
inline std::string run_sql(const std::string& url, const std::string& statement) {
  PGconn* c = PQconnectdb(url.c_str());
  std::string error;
  if (PQstatus(c) != CONNECTION_OK) {
    error = PQerrorMessage(c);
  } else {
    PGresult* r = PQexec(c, statement.c_str());
    if (PQresultStatus(r) != PGRES_COMMAND_OK && PQresultStatus(r) != PGRES_TUPLES_OK) error = PQresultErrorMessage(r);
    PQclear(r);
  }
  PQfinish(c);
  return error;
}

// Runs one query on a connection of its own: its first row's first value
// as text ("" for none), or "error: " and the error.
inline std::string sql_value(const std::string& url, const std::string& query) {
  PGconn* c = PQconnectdb(url.c_str());
  std::string out;
  if (PQstatus(c) != CONNECTION_OK) {
    out = std::string("error: ") + PQerrorMessage(c);
  } else {
    PGresult* r = PQexec(c, query.c_str());
    if (PQresultStatus(r) != PGRES_TUPLES_OK)
      out = std::string("error: ") + PQresultErrorMessage(r);
    else if (PQntuples(r) > 0 && PQnfields(r) > 0)
      out = PQgetvalue(r, 0, 0);
    PQclear(r);
  }
  PQfinish(c);
  return out;
}

// A fixture: one PostgreSQL per test process (started by the suite's first
// test), and a database of each test's own at url_. Skips where PostgreSQL
// is not installed.
class PostgresTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    pg_ = new ScratchPostgres(std::filesystem::temp_directory_path() /
                              ("terrane-pg-" + std::to_string(::getpid())));
    if (pg_->available()) started_ = pg_->start();
  }
  static void TearDownTestSuite() {
    delete pg_;
    pg_ = nullptr;
  }
  void SetUp() override {
    if (!pg_->available()) GTEST_SKIP() << pg_->why();
    ASSERT_TRUE(started_) << pg_->why();
    db_ = std::string("t_") + ::testing::UnitTest::GetInstance()->current_test_info()->name();
    for (char& ch : db_) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    db_.resize(std::min<std::size_t>(db_.size(), 63));  // PostgreSQL's longest name
    ASSERT_EQ(run_sql(pg_->url(), "CREATE DATABASE " + db_), "");
    url_ = "postgresql://terrane@127.0.0.1:" + std::to_string(pg_->port()) + "/" + db_;
  }

  static inline ScratchPostgres* pg_ = nullptr;
  static inline bool started_ = false;
  std::string db_, url_;
};

}  // namespace terrane::testing_support
