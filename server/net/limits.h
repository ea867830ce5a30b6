// Limits and authentication helpers for the server: a token bucket for
// rates (edits, bytes), a rate-limited log for violations (a flood of bad
// clients must not become a flood of log lines), and the tokens file.
//
// Thread-safety: TokenBucket is single-threaded (each lives on one strand);
// RateLimitedLog is thread-safe.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>
#include <unordered_map>

#include "common/world/world_store.h"

namespace terrane {

class TokenBucket {
 public:
  using Clock = std::chrono::steady_clock;
  // rate per second; burst: the most that can be taken at once. rate 0
  // means unlimited.
  TokenBucket(double rate = 0, double burst = 0) : rate_(rate), burst_(burst), tokens_(burst) {}
  bool unlimited() const { return rate_ <= 0; }
  // Takes n if available; false (and nothing taken) otherwise.
  bool take(double n, Clock::time_point now = Clock::now());
  // Takes n even if that leaves a debt (used for bytes already sent).
  void spend(double n, Clock::time_point now = Clock::now());
  double available(Clock::time_point now = Clock::now());

 private:
  void refill(Clock::time_point now);
  double rate_, burst_, tokens_;
  Clock::time_point last_ = Clock::now();
};

// At most `per_second` lines a second; the rest are counted and reported
// with the next line that gets through.
class RateLimitedLog {
 public:
  explicit RateLimitedLog(int per_second = 10) : per_second_(per_second) {}
  // Logs a warning unless over the limit.
  void warn(const std::string& line);

 private:
  std::mutex mutex_;
  int per_second_;
  int used_ = 0;
  std::uint64_t suppressed_ = 0;
  std::chrono::steady_clock::time_point window_ = std::chrono::steady_clock::now();
};

// The server's shared log for client misbehaviour.
RateLimitedLog& violations();

struct PlayerToken {
  std::string token;
  bool admin = false;  // may run terrane-admin commands
};

// A tokens file: one player per line, "NAME TOKEN [ROLE]" separated by
// whitespace, ROLE being player (the default) or admin; blank lines and
// lines starting with '#' are ignored. Errors name the file and line (a
// line without a token, an unknown role, a duplicate name, a name or token
// over the protocol's limits).
FileResult<std::unordered_map<std::string, PlayerToken>> load_tokens_file(const std::string& path);

// An IP address as the server prints and compares it (lower case, IPv4
// for v4-mapped IPv6, so "::FFFF:1.2.3.4" is "1.2.3.4"); text that is not
// an address comes back as it is.
std::string canonical_address(const std::string& text);

// True for 127.0.0.0/8, ::1 and localhost.
bool is_loopback_address(const std::string& address);
// 0.0.0.0 or :: (every address of the machine: not one a client can be sent to).
bool is_any_address(const std::string& address);

}  // namespace terrane
