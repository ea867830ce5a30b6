#include "server/replication/redirector.h"

#include <cmath>

#include "common/world/coarse_image.h"
#include "common/world/view.h"

namespace terrane {

Redirector::Redirector(const ClusterDirectory* cluster, const ClusterOptions& options)
    : cluster_(cluster), options_(options) {}

std::optional<Redirector::Move> Redirector::check(Vec3f p, Clock::time_point now) {
  if (!enabled() || redirected_) return std::nullopt;
  if (now - joined_at_ < kRedirectSettle || now < no_redirect_until_) return std::nullopt;
  const auto map = cluster_->current();
  // A map older than a lease may name a writer that is gone.
  if (!map || now - map->read_at() > options_.lease) return std::nullopt;
  const Vec3i region = coarse_region_of(view_chunk(p));
  const ServerAddress* to = map->writer_of(region);
  if (to == nullptr || to->id == options_.server_id) return std::nullopt;
  // Well inside that server's territory: every region within the margin
  // of the client (the cube of that half-width around it; at most 2 x 2 x 2
  // regions, the margin being at most 128) written by it, each lease seen
  // for a while. A client by a border with another server's region, or a
  // free one, stays, so it does not go back and forth; one by a border
  // between two of that server's regions goes.
  constexpr double kRegionVoxels = kCoarseRegionChunks * kChunkSize;
  const double m = options_.redirect_margin;
  const auto region_at = [&](double v) { return static_cast<int>(std::floor(v / kRegionVoxels)); };
  for (int y = region_at(p.y - m); y <= region_at(p.y + m); ++y)
    for (int z = region_at(p.z - m); z <= region_at(p.z + m); ++z)
      for (int x = region_at(p.x - m); x <= region_at(p.x + m); ++x) {
        const Vec3i r{x, y, z};
        const ServerAddress* w = map->writer_of(r);
        if (w == nullptr || w->id != to->id) return std::nullopt;
        if (now - map->written_since(r).value_or(now) < kRedirectStable) return std::nullopt;
      }
  redirected_ = true;
  redirected_at_ = now;
  target_ = "server " + std::to_string(to->id) + " at " + to->text();
  return Move{*to, region};
}

bool Redirector::expire(Clock::time_point now) {
  if (!redirected_ || now - redirected_at_ < kRedirectGrace) return false;
  // It did not go (it cannot reach the other server, or does not follow
  // redirects): served here again, and not redirected for a while.
  redirected_ = false;
  no_redirect_until_ = now + kRedirectBackoff;
  return true;
}

Redirector::Clock::time_point Redirector::next_wake(Clock::time_point now, bool planned) const {
  if (redirected_) return redirected_at_ + kRedirectGrace;
  if (enabled() && planned) return now + kRedirectCheck;
  return Clock::time_point::max();
}

}  // namespace terrane
