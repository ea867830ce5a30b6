// Test support: runs the real bin/terrane-server in a child process on
// 127.0.0.1 with --port 0, captures its output and reads the port from the
// "listening on 127.0.0.1:PORT" log line. Header-only; used by the client
// integration tests and the bots tests.
#pragma once

#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <future>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace terrane::testing_support {

// Generous: sanitizer builds on a shared 2-core machine generate slowly.
inline constexpr auto kServerStartDeadline = std::chrono::seconds(20);

// Runs bin/terrane-server in a child process, capturing its output.
class ServerProcess {
 public:
  ServerProcess(const std::string& world, const std::vector<std::string>& extra) {
    int fds[2];
    if (pipe(fds) != 0) return;
    std::vector<std::string> args = {std::string(TERRANE_BIN_DIR) + "/terrane-server", "--world", world, "--port", "0",
                                     "--worker-threads", "2"};
    args.insert(args.end(), extra.begin(), extra.end());
    pid_ = fork();
    if (pid_ == 0) {
      dup2(fds[1], 1);
      dup2(fds[1], 2);
      close(fds[0]);
      close(fds[1]);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(fds[1]);
    fd_ = fds[0];
    std::promise<int> port;
    auto port_future = port.get_future();
    reader_ = std::thread([this, p = std::move(port)]() mutable {
      bool found = false;
      char buf[4096];
      while (true) {
        const ssize_t n = read(fd_, buf, sizeof buf);
        if (n <= 0) break;
        std::lock_guard lock(mutex_);
        output_.append(buf, static_cast<std::size_t>(n));
        grew_.notify_all();
        const auto at = output_.find("listening on 127.0.0.1:");
        if (!found && at != std::string::npos && output_.find('\n', at) != std::string::npos) {
          found = true;
          p.set_value(std::stoi(output_.substr(at + 23)));
        }
      }
      if (!found) p.set_value(0);
    });
    if (port_future.wait_for(kServerStartDeadline) == std::future_status::ready) port_ = static_cast<std::uint16_t>(port_future.get());
  }
  ~ServerProcess() { stop(); }

  std::uint16_t port() const { return port_; }
  // SIGTERM, then the exit status (the server saves on the way out).
  int stop() {
    if (pid_ <= 0) return exit_code_;
    kill(pid_, SIGTERM);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
    if (reader_.joinable()) reader_.join();
    close(fd_);
    exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return exit_code_;
  }
  // Waits for it to exit by itself: its exit status, or -1 if it had not
  // within timeout (it is then stopped).
  int wait_exit(std::chrono::seconds timeout) {
    if (pid_ <= 0) return exit_code_;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    int status = 0;
    while (waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > deadline) {
        stop();
        return -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    pid_ = -1;
    if (reader_.joinable()) reader_.join();
    close(fd_);
    exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return exit_code_;
  }
  // SIGKILL: a crash, nothing runs on the way out. Waits for the process and
  // its output; returns true if the signal is what ended it.
  bool kill_hard() {
    if (pid_ <= 0) return false;
    ::kill(pid_, SIGKILL);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
    if (reader_.joinable()) reader_.join();
    close(fd_);
    exit_code_ = -1;
    return WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL;
  }
  std::string output() {
    std::lock_guard lock(mutex_);
    return output_;
  }
  bool wait_for_output(const std::string& text, std::chrono::seconds timeout) {
    std::unique_lock lock(mutex_);
    return grew_.wait_for(lock, timeout, [&] { return output_.find(text) != std::string::npos; });
  }

 private:
  pid_t pid_ = -1;
  int fd_ = -1;
  std::uint16_t port_ = 0;
  int exit_code_ = -1;
  std::thread reader_;
  std::mutex mutex_;
  std::condition_variable grew_;
  std::string output_;
};

}  // namespace terrane::testing_support
