// Redirector: whether one client should go to another server of a shared
// world, the one writing the regions around it (STORE_POSTGRESQL.md,
// "Redirects"), judged by the latest map of writers (ClusterDirectory). It
// owns the client's redirect state: whether it was sent a Redirect and
// when, and the back-off of a client that did not go.
//
//   [here] --every region within redirect_margin written by one other
//      ^      server, each lease seen for kRedirectStable--> [redirected]
//      |                                                        |
//      +---- kRedirectGrace passed, the client still here ------+
//            (not redirected again for kRedirectBackoff)
//
// Threading: the client's session strand (one replicator's).
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

#include "common/voxel/vec3.h"
#include "server/base/cluster_options.h"
#include "server/storage/cluster_map.h"

namespace terrane {

class Redirector {
 public:
  using Clock = std::chrono::steady_clock;
  // A redirected client that is still here this long after is served again
  // (streaming goes on) and not redirected for kRedirectBackoff.
  static constexpr std::chrono::seconds kRedirectGrace{10};
  static constexpr std::chrono::seconds kRedirectBackoff{60};
  // A client is not redirected in its first seconds on a server: the map
  // of writers it is judged by may be a renewal round old.
  static constexpr std::chrono::seconds kRedirectSettle{3};
  // How often a client's place is judged again (the map of writers changes).
  static constexpr std::chrono::seconds kRedirectCheck{1};
  // Nor to a server that has written the region for less than this (a
  // region handed back and forth across a busy border would send its
  // clients back and forth).
  static constexpr std::chrono::seconds kRedirectStable{10};

  // Where a client goes, and the region that decided it.
  struct Move {
    ServerAddress to;
    Vec3i region;
  };

  // cluster: null in a world of one server (nothing is ever redirected).
  // options: server_id, redirect_margin, lease. Both outlive this.
  Redirector(const ClusterDirectory* cluster, const ClusterOptions& options);

  // The client joined (now): the settling time starts.
  void joined(Clock::time_point now) { joined_at_ = now; }
  // A client at position, if it should go now: it then counts as
  // redirected (until expire()).
  std::optional<Move> check(Vec3f position, Clock::time_point now);
  bool redirected() const { return redirected_; }
  // "server ID at HOST:PORT" of the last Redirect (for the log).
  const std::string& target() const { return target_; }
  // True once (the client is served again) when a redirected client is
  // still here kRedirectGrace after its Redirect.
  bool expire(Clock::time_point now);
  // When the replicator should next call check() or expire(): the grace's
  // end while redirected, else kRedirectCheck from now once the client has
  // a plan (planned), else never (time_point::max()).
  Clock::time_point next_wake(Clock::time_point now, bool planned) const;

 private:
  bool enabled() const { return cluster_ != nullptr && options_.redirect_margin > 0; }

  const ClusterDirectory* const cluster_;
  const ClusterOptions& options_;
  Clock::time_point joined_at_;
  bool redirected_ = false;
  Clock::time_point redirected_at_;
  Clock::time_point no_redirect_until_{};
  std::string target_;
};

}  // namespace terrane
