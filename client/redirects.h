// Redirects: which Redirect a connection follows (a world shared by several
// servers, PROTOCOL.md "Redirect"): the one pending, the resume token the
// next Hello carries, and the target that could not be reached a moment
// ago (not followed again for kUnreachableFor, so a client does not bounce
// between a server that redirects and one that is down).
// Owned by the connection's io side (the owned thread or the strand).
#pragma once

#include <chrono>
#include <optional>
#include <string>

#include "protocol/messages.h"

namespace terrane {

class Redirects {
 public:
  using Clock = std::chrono::steady_clock;
  static constexpr std::chrono::seconds kUnreachableFor{60};

  // follow: ClientOptions::follow_redirects (false: never offered one).
  explicit Redirects(bool follow) : follow_(follow) {}

  // A Redirect arrived at now: true when it is to be followed (following
  // is on, none is pending, and its target did not just fail).
  bool offer(RedirectMsg r, Clock::time_point now);
  bool pending() const { return pending_.has_value(); }
  // The pending Redirect is being followed: it is no longer pending, and
  // its token goes with the next Hello.
  RedirectMsg follow();
  // A pending Redirect is forgotten (its connection went).
  void cancel() { pending_.reset(); }
  // The target just followed could not be reached at now.
  void unreachable(const std::string& target, Clock::time_point now);
  // The resume token for the next Hello (empty: a fresh session), used once.
  std::string take_token();

  // "host:port", how targets are compared.
  static std::string target_of(const RedirectMsg& r) { return r.host + ":" + std::to_string(r.port); }

 private:
  bool follow_;
  std::optional<RedirectMsg> pending_;
  std::string token_;
  std::string unreachable_;
  Clock::time_point unreachable_until_{};
};

}  // namespace terrane
