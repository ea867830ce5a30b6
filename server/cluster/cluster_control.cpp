#include "server/cluster/cluster_control.h"

#include <chrono>
#include <span>

#include <fmt/format.h>

#include "server/base/log.h"
#include "server/storage/forwarded_edit.h"

namespace terrane {

namespace {
// A failure this quick found the connection closed; a database out of
// reach takes a statement's deadline (seconds) to fail.
constexpr auto kAtOnce = std::chrono::milliseconds(500);
}  // namespace

StoreResult<std::unique_ptr<ClusterControl>> ClusterControl::open(const std::string& url, LeaseKeeper& keeper,
                                                                  DatabaseCounters* counters) {
  auto store = ClusterStore::open(url);
  if (!store) return store.error();
  return std::unique_ptr<ClusterControl>(new ClusterControl(keeper, std::move(*store), counters));
}

ClusterControl::ClusterControl(LeaseKeeper& keeper, std::unique_ptr<ClusterStore> store, DatabaseCounters* counters)
    : keeper_(keeper), counters_(counters), store_(std::move(store)) {}

ClusterControl::~ClusterControl() { stop(); }

void ClusterControl::stop() { thread_.join(); }

void ClusterControl::post(std::function<void(ClusterStore&)> fn) {
  asio::post(thread_, [this, fn = std::move(fn)] { fn(*store_); });
}

void ClusterControl::claim(Vec3i region, ClaimRule rule, std::function<void(RegionClaim)> done) {
  post([this, region, rule, done = std::move(done)](ClusterStore& cs) {
    RegionClaim out;
    auto held = keeper_.ensure(std::span(&region, 1), rule);
    if (!held) {
      const StoreError& e = held.error();
      out.unreachable = e.kind == StoreError::Kind::kConnection;
      out.left = e.kind == StoreError::Kind::kLeft;
      out.holder = e.holder;
      // Players may be shown why (an edit refused): the holder in Terrane's
      // words, or what became of the database; its own text goes to the log.
      if (e.kind == StoreError::Kind::kOwned || e.kind == StoreError::Kind::kLeft) {
        out.why = e.message;
      } else {
        out.why = out.unreachable ? "the world's database cannot be reached" : "the world's database refused the claim";
        claim_log_.warn(fmt::format("region ({},{},{}): claim failed: {}", region.x, region.y, region.z, e.message));
      }
      done(std::move(out));
      return;
    }
    // Revisions only (no voxels: nothing there can fail to decode).
    auto revisions = cs.stored_revisions(region);
    if (!revisions) {
      // Held, but what is stored there is not known: not written until it is.
      out.why = "cannot read what the region holds from the world's database";
      claim_log_.warn(fmt::format("region ({},{},{}): cannot read what it holds: {}", region.x, region.y, region.z,
                                  revisions.error().message));
      out.unreachable = true;
      done(std::move(out));
      return;
    }
    out.held = true;
    out.stored = std::move(*revisions);
    done(std::move(out));
  });
}

void ClusterControl::forward(std::uint32_t to, std::string player, EditRequestMsg edit, std::vector<Vec3i> hand_over,
                             std::chrono::steady_clock::time_point deadline,
                             std::function<void(StoreResult<std::int64_t>)> done) {
  post([this, to, player = std::move(player), edit = std::move(edit), hand_over = std::move(hand_over), deadline,
        done = std::move(done)](ClusterStore& cs) {
    if (!hand_over.empty())
      if (auto released = keeper_.release(hand_over); !released) return done(released.error());
    // The row's deadline: where the database's clock is at least when the
    // sender's wait runs out here. Nothing is sent once that has passed
    // (this thread was held up) or without a recent reading of the clock.
    const auto expires_us = keeper_.database_time_at(deadline);
    if (!expires_us)
      return done(StoreError{StoreError::Kind::kConnection,
                             "forward edit: the database's clock has not been read within a lease (no lease renewal "
                             "answered); nothing was sent"});
    if (std::chrono::steady_clock::now() >= deadline)
      return done(StoreError{StoreError::Kind::kConnection,
                             "forward edit: its wait ran out before it could be sent; nothing was sent"});
    done(cs.forward(keeper_.owner(), to, player, encode_forwarded_edit(edit), *expires_us));
  });
}

void ClusterControl::take_back(std::int64_t row, std::function<void(StoreResult<bool>)> done) {
  post([row, done = std::move(done)](ClusterStore& cs) { done(cs.take_back(row)); });
}

void ClusterControl::relay(std::int64_t row, std::uint32_t to, std::vector<Vec3i> hand_over,
                           std::function<void(StoreResult<Ok>)> done) {
  post([this, row, to, hand_over = std::move(hand_over), done = std::move(done)](ClusterStore& cs) {
    if (!hand_over.empty())
      if (auto released = keeper_.release(hand_over); !released) return done(released.error());
    done(cs.relay(row, keeper_.owner(), to));
  });
}

void ClusterControl::read_inbox(std::int64_t after, std::size_t limit,
                                std::function<void(StoreResult<std::vector<InboxEdit>>)> done) {
  post([this, after, limit, done = std::move(done)](ClusterStore& cs) {
    const auto started = std::chrono::steady_clock::now();
    auto got = cs.inbox(keeper_.owner(), after, limit);
    // A connection the database ended while it was idle (it restarted)
    // fails its next statement at once: the read is tried once more on the
    // connection opened again, or the inbox would wait for the next notice.
    // Not after a deadline (a database cut off costs one, not two).
    if (!got && got.error().kind == StoreError::Kind::kConnection &&
        std::chrono::steady_clock::now() - started < kAtOnce)
      got = cs.inbox(keeper_.owner(), after, limit);
    if (counters_ != nullptr) counters_->inbox_failing.store(got ? 0 : 1, std::memory_order_relaxed);
    done(std::move(got));
  });
}

void ClusterControl::answer(std::vector<ForwardAnswer> answers) {
  post([answers = std::move(answers)](ClusterStore& cs) {
    if (auto a = cs.answer(answers); !a)
      server_log().warn("forwarded edits: {} answers not sent: {}", answers.size(), a.error().message);
  });
}

}  // namespace terrane
