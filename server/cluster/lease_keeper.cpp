#include "server/cluster/lease_keeper.h"

#include <algorithm>

#include <fmt/format.h>

namespace terrane {

StoreResult<std::unique_ptr<LeaseKeeper>> LeaseKeeper::open(const std::string& url, std::uint32_t owner,
                                                            LeaseTimes times, LostFn on_lost,
                                                            DatabaseCounters* counters) {
  if (times.renew >= times.lease)
    return StoreError{StoreError::Kind::kQuery, fmt::format("lease renewal every {} ms cannot keep a {} ms lease",
                                                            times.renew.count(), times.lease.count())};
  auto claims = ClusterStore::open(url);
  if (!claims) return claims.error();
  // A claim no database answers within a lease is given up: the edit
  // waiting for it asks again (a claim answered late is a lease running).
  (*claims)->set_call_timeout(std::max(times.lease, std::chrono::milliseconds(1)));
  auto renewer = ClusterStore::open(url);
  if (!renewer) return renewer.error();
  // Connected: the database is reached (the first round comes a period on).
  if (counters != nullptr)
    counters->lease_renewed_at_ns.store(steady_ns(std::chrono::steady_clock::now()), std::memory_order_relaxed);
  // A first reading of the database's clock, so that edits can be
  // forwarded before the first renewal round (without one they wait for it).
  DatabaseClock clock;
  const bool read = (*renewer)->renew({}, times.lease, &clock).ok();
  std::unique_ptr<LeaseKeeper> keeper(
      new LeaseKeeper(owner, times, std::move(on_lost), std::move(*claims), std::move(*renewer), counters));
  if (read) {
    std::lock_guard lock(keeper->mutex_);
    keeper->clock_ = clock;
  }
  return keeper;
}

LeaseKeeper::LeaseKeeper(std::uint32_t owner, LeaseTimes times, LostFn on_lost, std::unique_ptr<ClusterStore> claims,
                         std::unique_ptr<ClusterStore> renewer, DatabaseCounters* counters)
    : owner_(owner),
      times_(times),
      on_lost_(std::move(on_lost)),
      counters_(counters),
      claims_(std::move(claims)),
      renewer_(std::move(renewer)),
      thread_([this] { renew_loop(); }) {}

LeaseKeeper::~LeaseKeeper() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

StoreResult<std::vector<RegionLease>> LeaseKeeper::held(std::span<const Vec3i> regions) const {
  std::vector<RegionLease> out;
  std::lock_guard lock(mutex_);
  for (const Vec3i region : regions) {
    auto it = held_.find(key_of(region));
    if (it == held_.end())
      return StoreError{StoreError::Kind::kFenced,
                        fmt::format("region ({},{},{}) is not held by server {} (lost or handed over); nothing was "
                                    "written",
                                    region.x, region.y, region.z, owner_)};
    out.push_back(it->second);
  }
  return out;
}

std::shared_ptr<const LeaseSource> LeaseKeeper::held_source() const {
  return std::make_shared<const LeaseSource>([this](std::span<const Vec3i> regions) { return held(regions); });
}

std::shared_ptr<const LeaseSource> LeaseKeeper::claiming_source() {
  return std::make_shared<const LeaseSource>([this](std::span<const Vec3i> regions) { return ensure(regions); });
}

bool LeaseKeeper::holds(Vec3i region) const {
  std::lock_guard lock(mutex_);
  return held_.count(key_of(region)) != 0;
}

StoreResult<std::vector<RegionLease>> LeaseKeeper::ensure(std::span<const Vec3i> regions, ClaimRule rule) {
  std::vector<Vec3i> order(regions.begin(), regions.end());
  std::sort(order.begin(), order.end(), [](Vec3i a, Vec3i b) { return key_of(a) < key_of(b); });
  order.erase(std::unique(order.begin(), order.end()), order.end());
  std::vector<RegionLease> out;
  out.reserve(order.size());
  std::lock_guard claiming(claims_mutex_);
  for (const Vec3i region : order) {
    {
      std::lock_guard lock(mutex_);
      if (auto it = held_.find(key_of(region)); it != held_.end()) {
        out.push_back(it->second);
        continue;
      }
    }
    auto lease = claims_->claim(region, owner_, times_.lease, rule);
    if (!lease) return lease.error();
    {
      std::lock_guard lock(mutex_);
      held_[key_of(region)] = *lease;
    }
    out.push_back(*lease);
  }
  return out;
}

std::vector<RegionLease> LeaseKeeper::held() const {
  std::lock_guard lock(mutex_);
  std::vector<RegionLease> out;
  for (const auto& [key, l] : held_) out.push_back(l);
  return out;
}

std::uint64_t LeaseKeeper::renewals() const {
  std::lock_guard lock(mutex_);
  return rounds_;
}

std::optional<std::int64_t> LeaseKeeper::database_time_at(std::chrono::steady_clock::time_point t) const {
  std::lock_guard lock(mutex_);
  if (!clock_ || std::chrono::steady_clock::now() - clock_->received > times_.lease) return std::nullopt;
  return clock_->at_least_at(t);
}

StoreResult<Ok> LeaseKeeper::release(std::span<const Vec3i> regions) {
  std::vector<RegionLease> going;
  {
    std::lock_guard lock(mutex_);
    for (const Vec3i r : regions)
      if (auto it = held_.find(key_of(r)); it != held_.end()) {
        going.push_back(it->second);
        held_.erase(it);
      }
  }
  if (going.empty()) return Ok{};
  std::lock_guard claiming(claims_mutex_);
  return claims_->release(going);
}

StoreResult<Ok> LeaseKeeper::release_all() {
  bool advertised = false;
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    advertised = advertising_;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  const std::vector<RegionLease> all = held();
  {
    std::lock_guard lock(mutex_);
    held_.clear();
  }
  std::lock_guard claiming(claims_mutex_);
  // No client is sent here any more, then the regions are free (whether or
  // not the row could be withdrawn: it ages out).
  auto gone = advertised ? claims_->withdraw(owner_) : StoreResult<Ok>(Ok{});
  auto released = claims_->release(all);
  if (!released) return released.error();
  return gone;
}

void LeaseKeeper::advertise(std::string address, ClusterDirectory* directory) {
  {
    std::lock_guard lock(mutex_);
    address_ = std::move(address);
    directory_ = directory;
    advertising_ = true;
    round_now_ = true;
  }
  wake_.notify_all();
}

bool LeaseKeeper::exchange_addresses(const std::string& address, ClusterDirectory* directory) {
  // Failures leave the last map in place: it carries the time it was read,
  // and its readers stop trusting it after a lease time.
  auto seen = renewer_->advertise(owner_, address);
  if (!seen || directory == nullptr) return seen.ok();
  auto c = renewer_->cluster(times_.lease);
  if (!c) return true;
  last_map_ = std::make_shared<const ClusterMap>(c->writers, c->servers, std::chrono::steady_clock::now(), last_map_.get());
  directory->publish(last_map_);
  return true;
}

void LeaseKeeper::renew_loop() {
  auto last_ok = std::chrono::steady_clock::now();
  bool failed = false;  // the last round could not renew: the next one comes after the retry pause
  std::unique_lock lock(mutex_);
  for (;;) {
    wake_.wait_for(lock, failed ? std::min(times_.retry, times_.renew) : times_.renew,
                   [&] { return stopping_ || round_now_; });
    if (stopping_) break;
    round_now_ = false;
    const std::string address = address_;
    ClusterDirectory* const directory = directory_;
    const bool advertising = advertising_;
    std::vector<RegionLease> all;
    for (const auto& [key, l] : held_) all.push_back(l);
    lock.unlock();
    std::vector<std::pair<RegionLease, std::string>> lost;
    // A renewal lasts from when the database ran it, which is after this
    // started: counted from here, a lease is never believed held past its
    // end. The call may take what is left of the lease at most (half a
    // lease, at most): a database cut off fails it in time for the leases
    // to be given up here as they run out there.
    const auto started = std::chrono::steady_clock::now();
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(last_ok + times_.lease - started);
    renewer_->set_call_timeout(std::clamp(left, std::chrono::milliseconds(1), std::max(times_.lease / 2, std::chrono::milliseconds(1))));
    DatabaseClock clock;
    auto kept = renewer_->renew(all, times_.lease, &clock);
    const auto now = std::chrono::steady_clock::now();
    failed = !kept;
    if (kept) {
      last_ok = started;
      for (const RegionLease& l : all)
        if (std::find(kept->begin(), kept->end(), l) == kept->end())
          lost.emplace_back(l, "the database no longer extends its lease (it ran out, or another server took it)");
    } else if (now - last_ok >= times_.lease) {
      // Not renewed for a whole lease time: by now it has run out.
      for (const RegionLease& l : all)
        lost.emplace_back(l, fmt::format("not renewed for {} ms: {}", times_.lease.count(), kept.error().message));
    }
    lock.lock();
    if (kept && clock.received != std::chrono::steady_clock::time_point{}) clock_ = clock;
    // Only leases still held as they were: not released meanwhile (handed
    // over) nor claimed again (a newer epoch).
    std::erase_if(lost, [&](const auto& entry) {
      auto it = held_.find(key_of(entry.first.region));
      if (it == held_.end() || !(it->second == entry.first)) return true;
      held_.erase(it);
      return false;
    });
    ++rounds_;
    bool reached = kept.ok();
    if (advertising) {
      lock.unlock();
      reached = exchange_addresses(address, directory) && reached;
      lock.lock();
    }
    if (reached && counters_ != nullptr)
      counters_->lease_renewed_at_ns.store(steady_ns(started), std::memory_order_relaxed);
    if (!lost.empty() && on_lost_) {
      lock.unlock();
      for (const auto& [l, why] : lost) on_lost_(l, why);
      lock.lock();
    }
  }
}

}  // namespace terrane
