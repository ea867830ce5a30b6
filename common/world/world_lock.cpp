#include "common/world/world_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>
#include <utility>

namespace terrane {

namespace {

// What a holder's line may be at most; the file is read as untrusted.
constexpr std::size_t kMaxHolderLine = 1024;

std::string lock_path(const std::string& dir) { return dir + "/" + kWorldLockName; }

std::string utc_now() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S UTC", &tm);
  return buf;
}

std::string host_name() {
  char buf[256] = {};
  if (::gethostname(buf, sizeof buf - 1) != 0) return "?";
  return buf;
}

// Control characters (a newline above all) would break the one-line file.
std::string one_line(std::string s) {
  for (char& c : s)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = ' ';
  return s;
}

// The holder's line as written by take(): "pid=N host=H since=T program=P"
// (T and P may hold spaces; the keys come in this order). Read back into
// the words of an error.
std::string describe(const std::string& line) {
  const std::size_t host = line.find(" host="), since = line.find(" since="), program = line.find(" program=");
  if (line.rfind("pid=", 0) != 0 || host == std::string::npos || since == std::string::npos ||
      program == std::string::npos || !(host < since && since < program))
    return "another process (its lock file names it as '" + one_line(line) + "')";
  const auto part = [&](std::size_t from, std::size_t to) { return one_line(line.substr(from, to - from)); };
  return "pid " + part(4, host) + " on host " + part(host + 6, since) + " (" +
         part(program + 9, line.size()) + "), since " + part(since + 7, program);
}

// The holder's line of an open lock file, or "" if none is written yet.
std::string read_line(int fd) {
  char buf[kMaxHolderLine];
  const ssize_t n = ::pread(fd, buf, sizeof buf, 0);
  if (n <= 0) return {};
  std::string s(buf, static_cast<std::size_t>(n));
  if (const std::size_t nl = s.find('\n'); nl != std::string::npos) s.resize(nl);
  return s;
}

std::string holder_of(int fd) {
  const std::string line = read_line(fd);
  return line.empty() ? "another process (it has not written its name yet)" : describe(line);
}

}  // namespace

WorldLock::~WorldLock() { release(); }

WorldLock::WorldLock(WorldLock&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}

WorldLock& WorldLock::operator=(WorldLock&& other) noexcept {
  if (this != &other) {
    release();
    fd_ = std::exchange(other.fd_, -1);
  }
  return *this;
}

void WorldLock::release() {
  if (fd_ < 0) return;
  // The name goes first, while the lock still keeps others out.
  if (::ftruncate(fd_, 0) != 0) {
    // Nothing to do: a stale name in an unlocked file misleads nobody,
    // holder() reads it only while the file is locked.
  }
  ::close(fd_);
  fd_ = -1;
}

FileResult<WorldLock> WorldLock::take(const std::string& dir, const std::string& program) {
  const std::string path = lock_path(dir);
  const std::string fail = "world " + dir + ": ";
  // A lock file replaced between open and flock is locked again; a few
  // rounds cover any sane race, a loop that never settles is an error.
  for (int round = 0; round < 8; ++round) {
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0)
      return FileError{fail + "cannot open the lock file " + path + ": " + std::strerror(errno), {}};
    int r;
    do r = ::flock(fd, LOCK_EX | LOCK_NB);
    while (r != 0 && errno == EINTR);
    if (r != 0) {
      const int err = errno;
      std::string msg;
      if (err == EWOULDBLOCK)
        msg = fail + "in use by " + holder_of(fd) +
              ". A world directory has one writer at a time: stop that process first (readers such as "
              "'terrane-world check', 'stats', 'export' and 'backup' may run beside it)";
      else
        msg = fail + "cannot lock " + path + ": " + std::strerror(err);
      ::close(fd);
      return FileError{msg, {}};
    }
    struct stat by_fd{}, by_path{};
    if (::fstat(fd, &by_fd) != 0 || ::stat(path.c_str(), &by_path) != 0 || by_fd.st_dev != by_path.st_dev ||
        by_fd.st_ino != by_path.st_ino) {
      ::close(fd);  // the file was replaced or removed after open: lock the one there now
      continue;
    }
    WorldLock lock(fd);
    const std::string line = "pid=" + std::to_string(::getpid()) + " host=" + one_line(host_name()) +
                             " since=" + utc_now() + " program=" + one_line(program) + "\n";
    if (::ftruncate(fd, 0) != 0 || ::pwrite(fd, line.data(), line.size(), 0) != static_cast<ssize_t>(line.size()))
      return FileError{fail + "cannot write the lock file " + path + ": " + std::strerror(errno), {}};
    return lock;
  }
  return FileError{fail + "the lock file " + path + " keeps being replaced; is another program deleting it?", {}};
}

std::string WorldLock::holder(const std::string& dir) {
  const int fd = ::open(lock_path(dir).c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return {};
  std::string who;
  if (::flock(fd, LOCK_SH | LOCK_NB) != 0) {
    if (errno == EWOULDBLOCK) who = holder_of(fd);
  }
  ::close(fd);  // drops the shared lock if it was taken
  return who;
}

}  // namespace terrane
