// WorldLock: the one writer of a world directory.
//
// A world directory has one writer at a time: a terrane-server serving it,
// or a terrane-world command that writes it (generate, import, migrate,
// check --quarantine). Two writers would each keep their own copies of
// chunks and write them back over the other's acknowledged edits. The
// writer takes the lock before it opens the world and holds it for the
// life of the process; anyone else who tries is refused with the holder's
// pid, host, program and start time. Readers (check, stats, export,
// backup) take no lock and may read a served world.
//
// The lock is flock(2) LOCK_EX on the file `world.lock` in the directory
// (WORLD_FORMAT.md, "The lock"):
//   - it belongs to the open file, so it dies with the process however the
//     process ends (kill -9 included), and a stale file never blocks anyone;
//   - it is on the file's inode, so a second path to the directory (a
//     symlink, a bind mount, "dir/./") meets the same lock;
//   - it is separate from SQLite's own locks, which are per transaction:
//     SQLite's locking_mode=EXCLUSIVE would lock out the readers the world
//     keeps online (check, backup, the server's own worker connections),
//     takes the lock only at the first write, and says only "database is
//     locked" without naming who holds it.
// The file holds one line naming the holder (written after the lock is
// taken; a reader of a locked file may see it empty for an instant). It is
// never deleted: deleting it would let a new file be locked beside the old
// one. A lock taken on a file that was since replaced is taken again on
// the new one.
//
// Thread-safety: a WorldLock is a value owned by one thread; locking the
// same directory twice in one process is refused as from another process.
#pragma once

#include <string>

#include "common/codec/decode_error.h"

namespace terrane {

inline constexpr const char* kWorldLockName = "world.lock";

class WorldLock {
 public:
  WorldLock() = default;
  ~WorldLock();
  WorldLock(WorldLock&& other) noexcept;
  WorldLock& operator=(WorldLock&& other) noexcept;
  WorldLock(const WorldLock&) = delete;
  WorldLock& operator=(const WorldLock&) = delete;

  // Takes the lock of world directory dir for this process, naming it as
  // program (e.g. "terrane-server on 127.0.0.1:7777"; one line, no control
  // characters). The directory must exist. The error names dir and, when
  // another process holds the lock, that holder ("pid 1234 on host h,
  // terrane-server on ..., since 2026-11-28 15:06:19 UTC").
  static FileResult<WorldLock> take(const std::string& dir, const std::string& program);

  // Who holds dir's lock now, as the text take()'s error gives, or "" when
  // nobody does (or dir has no lock file). Does not take the lock.
  static std::string holder(const std::string& dir);

  bool held() const { return fd_ >= 0; }
  // Gives the lock up (the destructor does).
  void release();

 private:
  explicit WorldLock(int fd) : fd_(fd) {}
  int fd_ = -1;
};

}  // namespace terrane
