// Test support: runs the real bin/terrane-server in a child process on
// 127.0.0.1 with --port 0, captures its output and reads the port from the
// "listening on 127.0.0.1:PORT" log line. Header-only; used by the client
// integration tests and the bots tests. The process itself is a
// ChildProcess (tests/support/child_process.h).
#pragma once

#include <signal.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "tests/support/child_process.h"

namespace terrane::testing_support {

// Generous: sanitizer builds on a shared 2-core machine generate slowly.
inline constexpr auto kServerStartDeadline = std::chrono::seconds(20);

class ServerProcess {
 public:
  // world: a directory, or a postgresql:// URL (give --server-id in extra).
  ServerProcess(const std::string& world, const std::vector<std::string>& extra) : child_(argv(world, extra)) {
    const std::string rest = child_.wait_for_line("listening on 127.0.0.1:", kServerStartDeadline);
    if (!rest.empty()) port_ = static_cast<std::uint16_t>(std::stoi(rest));
  }

  std::uint16_t port() const { return port_; }
  // The metrics endpoint's port, when started with --metrics 127.0.0.1:0
  // (0 if it said none).
  std::uint16_t metrics_port() {
    const std::string rest = child_.wait_for_line("metrics on http://127.0.0.1:", kServerStartDeadline);
    return rest.empty() ? 0 : static_cast<std::uint16_t>(std::stoi(rest));
  }
  // SIGTERM, then the exit status (the server saves on the way out).
  int stop() { return child_.stop(std::chrono::seconds(120)); }
  // SIGKILL: a crash, nothing runs on the way out. True if the signal is
  // what ended it.
  bool kill_hard() { return child_.kill_hard() == -SIGKILL; }
  // SIGSTOP / SIGCONT: the server paused and resumed (nothing runs between).
  bool pause() { return child_.signal(SIGSTOP); }
  bool resume() { return child_.signal(SIGCONT); }
  // SIGHUP: the server reads its tokens file, bans and whitelist again.
  bool hangup() { return child_.signal(SIGHUP); }
  // Waits for it to exit by itself: its exit status, or -1 if it had not
  // within timeout (it is then stopped).
  int wait_exit(std::chrono::seconds timeout) { return child_.wait(timeout); }
  std::string output() { return child_.output(); }
  bool wait_for_output(const std::string& text, std::chrono::seconds timeout) {
    return child_.wait_for_output(text, timeout);
  }

 private:
  static std::vector<std::string> argv(const std::string& world, const std::vector<std::string>& extra) {
    std::vector<std::string> args = {std::string(TERRANE_BIN_DIR) + "/terrane-server", "--world", world, "--port", "0",
                                     "--worker-threads", "2"};
    args.insert(args.end(), extra.begin(), extra.end());
    return args;
  }

  ChildProcess child_;
  std::uint16_t port_ = 0;
};

}  // namespace terrane::testing_support
