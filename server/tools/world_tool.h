// The world tool's shared parts (terrane-world, server/tools/): how a
// command reports (usage_error, failure, Progress), where its world is
// (WorldPlace, --world or --store), and the world it opens (ToolWorld: for
// a PostgreSQL world it writes, the region leases its writes take). The
// commands themselves are in their groups' files: write_commands.cpp
// (generate, import), read_commands.cpp (export, stats, check),
// copy_commands.cpp (backup, migrate); terrane_world.cpp dispatches.
//
// Threading: the tool's main thread (generate's worker threads hand their
// chunks to it under a mutex of its own).
#pragma once

#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/cli/cli.h"
#include "common/world/world.h"
#include "common/world/world_lock.h"
#include "server/cluster/lease_keeper.h"
#include "server/storage/postgres_store.h"

namespace terrane::world_tool {

// Prints "terrane-world: message", a blank line and help on stderr: exit status 2.
int usage_error(const std::string& message, const char* help);
// Prints "terrane-world: message" on stderr: exit status 1.
int failure(const std::string& message);

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

// The chunks a box touches.
std::vector<Vec3i> chunks_in(const Region& r);

// Where a command's world is: --world or --store (exactly one), a
// directory or a postgresql:// URL.
struct WorldPlace {
  std::string where;  // as given (a URL may hold a password: never print it)
  bool postgres = false;
};


// "" and *out set, or the usage error.
std::string world_place(const CommandLine& cl, WorldPlace* out);

// The server id whose leases a write to a PostgreSQL world takes:
// --server-id, else fallback, else a usage error in *error. nullopt for a
// directory (where --server-id is a usage error).
std::optional<std::uint32_t> writer_id(const CommandLine& cl, const WorldPlace& place,
                                       std::optional<std::uint32_t> fallback, std::string* error);

// The region leases of a tool that writes a PostgreSQL world, kept alive by
// a LeaseKeeper; release() gives them up (the destructor does, if not done).
class ToolLeases {
 public:
  ToolLeases() = default;
  ToolLeases(const ToolLeases&) = delete;
  ToolLeases& operator=(const ToolLeases&) = delete;
  ~ToolLeases() { release(); }

  // Opens the keeper for server id on url's database and makes store's
  // writes take their leases from it.
  FileStatus attach(const std::string& url, std::uint32_t id, PostgresStore& store) {
    const LeaseTimes times{};
    auto keeper = LeaseKeeper::open(url, id, times, [shown = store.where()](const RegionLease& lost,
                                                                               const std::string& why) {
      std::fprintf(stderr, "terrane-world: world %s: lost the lease of region (%d, %d, %d): %s; writes there are "
                   "refused\n", shown.c_str(), lost.region.x, lost.region.y, lost.region.z, why.c_str());
    });
    if (!keeper) return FileError{keeper.error().message, std::nullopt};
    keeper_ = std::move(*keeper);
    where_ = store.where();
    store.set_lease_source(keeper_->claiming_source(), times.lease);  // a database restart is waited for a lease time
    return Ok{};
  }
  // Gives every lease up (they would otherwise run out within a lease time).
  void release() {
    if (!keeper_ || released_) return;
    released_ = true;
    if (auto r = keeper_->release_all(); !r)
      std::fprintf(stderr, "terrane-world: warning: world %s: giving the region leases up: %s (they run out by "
                   "themselves within %lld ms)\n", where_.c_str(), r.error().message.c_str(),
                   static_cast<long long>(LeaseTimes{}.lease.count()));
  }

 private:
  std::unique_ptr<LeaseKeeper> keeper_;
  std::string where_;
  bool released_ = false;
};

// A world a command works on. The leases and the lock are declared first,
// so the world's store (whose writes ask them) goes before them.
struct ToolWorld {
  ToolLeases leases;
  WorldLock lock;  // a world directory the command writes
  std::unique_ptr<World> world;
  bool created = false;  // made by this command
};

// Opens the world at place. make: the metadata of a new world where place
// holds none (World::create for a directory, create_world for a database);
// without it, no world there is an error. writer: for a PostgreSQL world
// that the command writes, the server id whose leases the writes take
// (nullopt: read only). writing: for a world directory the command writes,
// the command's name: its one-writer lock is taken (WorldLock), so a
// server serving it, or another tool writing it, refuses the command.
FileStatus open_tool_world(const WorldPlace& place, std::optional<std::uint32_t> writer,
                           const std::function<WorldMeta()>& make, ToolWorld& out, const char* writing = nullptr);

// The commands: argv[1] is the command, its options start at argv[2].
// Each returns the exit status (0, 1 a failure of the work, 2 bad usage).
int cmd_generate(int argc, char** argv);
int cmd_import(int argc, char** argv);
int cmd_export(int argc, char** argv);
int cmd_stats(int argc, char** argv);
int cmd_check(int argc, char** argv);
int cmd_backup(int argc, char** argv);
int cmd_migrate(int argc, char** argv);

}  // namespace terrane::world_tool
