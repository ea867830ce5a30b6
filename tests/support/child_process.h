// Test support: any program in a child process, its output (stdout and
// stderr together) captured, stopped by pid (SIGTERM, then SIGKILL after a
// grace period). For real components the tests start themselves
// (Prometheus, the Docker images' command lines). Header-only.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <condition_variable>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace terrane::testing_support {

class ChildProcess {
 public:
  // argv[0] is looked up in PATH (execvp); env entries are added to (or
  // replace those of) the test's environment.
  ChildProcess(const std::vector<std::string>& argv, const std::map<std::string, std::string>& env = {}) {
    int fds[2];
    if (pipe(fds) != 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      dup2(fds[1], 1);
      dup2(fds[1], 2);
      close(fds[0]);
      close(fds[1]);
      setpgid(0, 0);  // its own group: a stop reaches what it starts too
      for (const auto& [k, v] : env) setenv(k.c_str(), v.c_str(), 1);
      std::vector<std::string> args = argv;
      std::vector<char*> cargv;
      for (auto& a : args) cargv.push_back(a.data());
      cargv.push_back(nullptr);
      execvp(cargv[0], cargv.data());
      _exit(127);
    }
    close(fds[1]);
    fd_ = fds[0];
    reader_ = std::thread([this] {
      char buf[4096];
      while (true) {
        const ssize_t n = read(fd_, buf, sizeof buf);
        if (n <= 0) break;
        std::lock_guard lock(mutex_);
        output_.append(buf, static_cast<std::size_t>(n));
        changed_.notify_all();
      }
      std::lock_guard lock(mutex_);
      eof_ = true;
      changed_.notify_all();
    });
    // Waits for the exit (blocking waitpid) and says so: stop() and wait()
    // wait on that, never poll.
    waiter_ = std::thread([this] {
      int st = 0;
      waitpid(pid_, &st, 0);
      std::lock_guard lock(mutex_);
      status_ = WIFEXITED(st) ? WEXITSTATUS(st) : (WIFSIGNALED(st) ? -WTERMSIG(st) : -1);
      exited_ = true;
      changed_.notify_all();
    });
  }
  ~ChildProcess() { stop(); }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  bool started() const { return pid_ > 0; }

  // SIGTERM to its group, SIGKILL if it has not exited after grace; the exit
  // status (or -signal).
  int stop(std::chrono::seconds grace = std::chrono::seconds(20)) { return end(SIGTERM, grace); }
  // SIGKILL: a crash, nothing runs on the way out.
  int kill_hard() { return end(SIGKILL, std::chrono::seconds(60)); }
  // Sends sig to the process alone (SIGSTOP / SIGCONT: a pause); true if sent.
  bool signal(int sig) {
    std::lock_guard lock(mutex_);
    return started() && !exited_ && ::kill(pid_, sig) == 0;
  }
  // Waits for it to exit by itself (at most timeout; then it is stopped).
  int wait(std::chrono::seconds timeout) {
    if (!started()) return status_;
    {
      std::unique_lock lock(mutex_);
      if (!changed_.wait_for(lock, timeout, [&] { return exited_; })) {
        lock.unlock();
        stop(std::chrono::seconds(1));
        return -1;
      }
    }
    return finish();
  }
  std::string output() {
    std::lock_guard lock(mutex_);
    return output_;
  }
  // The rest of the first output line holding text, once that whole line
  // is there ("" at the deadline or EOF).
  std::string wait_for_line(const std::string& text, std::chrono::seconds timeout) {
    std::unique_lock lock(mutex_);
    auto complete = [&] {
      const auto at = output_.find(text);
      return at != std::string::npos && output_.find('\n', at) != std::string::npos;
    };
    if (!changed_.wait_for(lock, timeout, [&] { return eof_ || complete(); }) || !complete()) return {};
    const auto at = output_.find(text) + text.size();
    return output_.substr(at, output_.find('\n', at) - at);
  }
  // True once text appears in the output (false at the deadline or EOF).
  bool wait_for_output(const std::string& text, std::chrono::seconds timeout) {
    std::unique_lock lock(mutex_);
    changed_.wait_for(lock, timeout, [&] { return eof_ || output_.find(text) != std::string::npos; });
    return output_.find(text) != std::string::npos;
  }

 private:
  int end(int sig, std::chrono::seconds grace) {
    if (!started()) return status_;
    std::unique_lock lock(mutex_);
    if (!exited_) {
      ::kill(-pid_, sig);
      if (!changed_.wait_for(lock, grace, [&] { return exited_; })) {
        ::kill(-pid_, SIGKILL);
        changed_.wait(lock, [&] { return exited_; });
      }
    }
    lock.unlock();
    return finish();
  }
  int finish() {
    if (waiter_.joinable()) waiter_.join();
    if (reader_.joinable()) reader_.join();
    if (fd_ >= 0) close(fd_);
    fd_ = -1;
    pid_ = -1;
    return status_;
  }

  pid_t pid_ = -1;
  int fd_ = -1;
  int status_ = -1;
  bool exited_ = false;
  bool eof_ = false;
  std::thread reader_, waiter_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::string output_;
};

// A TCP port on 127.0.0.1 free a moment ago (for programs that cannot be
// told to pick one and say which).
inline std::uint16_t free_loopback_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof addr;
  std::uint16_t port = 0;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0 &&
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0)
    port = ntohs(addr.sin_port);
  ::close(fd);
  return port;
}

}  // namespace terrane::testing_support
