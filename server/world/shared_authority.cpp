#include "server/world/shared_authority.h"

#include <algorithm>
#include <map>

#include <fmt/format.h>

#include "server/base/log.h"
#include "server/storage/forwarded_edit.h"
#include "server/world/edits.h"

namespace terrane {

namespace {

// How long a forwarded edit waits at least for its owner to take it (at
// least a lease time) before it is taken back.
constexpr auto kForwardAnswerWait = std::chrono::milliseconds(2000);
constexpr std::size_t kInboxPage = 256;

// How players are told of forwarded edits the database failed: what became
// of the edit, in Terrane's words. A rejection whose outcome is not known
// is RejectReason::kOutcomeUnknown (its EditReject says outcome_unknown)
// and its text ends in "outcome unknown", as the client library's own
// (client/edit_tracker.h); the others are kNotOwner (no reason is closer:
// the region is another server's): the edit was not applied.
constexpr const char* kNotApplied = "the edit was not applied";
constexpr const char* kOutcomeUnknown = "outcome unknown";

}  // namespace

SharedAuthority::SharedAuthority(Strand& strand, World& world, Storage& storage, const WorldOptions& options,
                                 const ClusterOptions& cluster, ServerCounters& counters, const WorldClock& clock,
                                 Residency& residency, FanOut& clients, EditQueue& queue)
    : strand_(strand),
      world_(world),
      storage_(storage),
      options_(options),
      server_id_(cluster.server_id),
      lease_(cluster.lease),
      counters_(counters),
      clock_(clock),
      residency_(residency),
      clients_(clients),
      queue_(queue) {}

Authority::Writable SharedAuthority::writable(const Region& r, std::string* why, std::optional<std::uint32_t>* holder,
                                              ClaimRule rule) {
  if (r.empty()) return Writable::kYes;
  const auto now = std::chrono::steady_clock::now();
  Writable out = Writable::kYes;
  for_each_chunk_in(r, [&](Vec3i cp) {
    const Vec3i region = lease_region_of(cp);
    auto [it, unknown] = leases_.try_emplace(region);
    RegionLeaseState& l = it->second;
    if (unknown ||
        ((l.state == RegionLeaseState::kRefused || l.state == RegionLeaseState::kUnreachable) &&
         now >= l.ask_again) ||
        (l.state == RegionLeaseState::kRefused && l.left && rule == ClaimRule::kAny)) {
      // Another server's lease may have run out since (it died): ask again.
      // A region left to a neighbour's server by preference is taken for
      // what cannot be forwarded (a forwarded edit, undo, a rollback).
      l.state = RegionLeaseState::kClaiming;
      storage_.claim(region, rule, [this, region](Storage::Claimed claimed) {
        asio::post(strand_, [this, region, claimed = std::move(claimed)]() mutable {
          on_claimed(region, std::move(claimed));
        });
      });
    }
    if (l.state == RegionLeaseState::kRefused) {
      out = Writable::kNo;
      *why = l.why;
      if (holder != nullptr) *holder = l.holder;
    } else if (l.state != RegionLeaseState::kHeld && out == Writable::kYes) {
      out = Writable::kWaiting;
    }
  });
  return out;
}

void SharedAuthority::on_claimed(Vec3i region, Storage::Claimed claimed) {
  RegionLeaseState& l = leases_[region];
  if (!claimed.held) {
    l.state = claimed.unreachable ? RegionLeaseState::kUnreachable : RegionLeaseState::kRefused;
    l.left = claimed.left;
    l.holder = claimed.holder;
    l.why = std::move(claimed.why);
    l.ask_again = std::chrono::steady_clock::now() + std::chrono::seconds(1);
    return;
  }
  // What this server holds of the region older than stored was written by
  // the region's earlier owner: read again before anything is written over
  // it (its holders are sent the newer chunks as they land).
  // (A chunk not held is read from the store when wanted, but a load of it
  // under way may have read it before the previous owner's last write.)
  for (const auto& [cp, revision] : claimed.stored)
    if (const auto* held = residency_.find(cp); held == nullptr ? residency_.loading(cp)
                                                                : older_than(*held->current, revision))
      read_again(cp, revision, Storage::Priority::kUrgent);
  l.state = stale_in(region) ? RegionLeaseState::kRefreshing : RegionLeaseState::kHeld;
}

bool SharedAuthority::claiming(const Region& r) const {
  bool any = false;
  for_each_chunk_in(r, [&](Vec3i cp) {
    auto l = leases_.find(lease_region_of(cp));
    any = any || (l != leases_.end() && (l->second.state == RegionLeaseState::kClaiming ||
                                         l->second.state == RegionLeaseState::kRefreshing));
  });
  return any;
}

bool SharedAuthority::older_than(const ChunkVersion& held, std::uint64_t revision) {
  return held.estimate() || held.revision() < revision;
}

bool SharedAuthority::stale_in(Vec3i region) const {
  return std::any_of(stale_.begin(), stale_.end(), [&](const auto& s) { return lease_region_of(s.first) == region; });
}

bool SharedAuthority::writes_region(Vec3i region) const {
  auto it = leases_.find(region);
  return it != leases_.end() &&
         (it->second.state == RegionLeaseState::kHeld || it->second.state == RegionLeaseState::kRefreshing);
}

void SharedAuthority::read_again(Vec3i cp, std::uint64_t revision, Storage::Priority priority) {
  auto [it, fresh] = stale_.try_emplace(cp, revision);
  if (!fresh) it->second = std::max(it->second, revision);
  // A load already under way may have read the store before this revision:
  // landed() reads again when it lands.
  residency_.load_unless_loading(cp, priority);
}

void SharedAuthority::landed(Vec3i cp) {
  auto s = stale_.find(cp);
  if (s == stale_.end()) return;
  if (const auto* held = residency_.find(cp); held != nullptr && older_than(*held->current, s->second)) {
    // The load that landed read the store before the newer revision.
    residency_.load_unless_loading(cp, Storage::Priority::kUrgent);
    return;
  }
  // Held at the stored revision, or no longer held (read from the store when wanted).
  const Vec3i region = lease_region_of(cp);
  stale_.erase(s);
  if (auto l = leases_.find(region);
      l != leases_.end() && l->second.state == RegionLeaseState::kRefreshing && !stale_in(region))
    l->second.state = RegionLeaseState::kHeld;
}

void SharedAuthority::changed_elsewhere(std::vector<ChunkChange> changes) {
  {
    std::map<std::uint64_t, std::vector<VersionPtr>> updated;  // by the writer's tick
    for (const ChunkChange& c : changes) {
      if (writes_region(lease_region_of(c.pos))) continue;  // this server's own commit
      const Residency::Loaded* held = residency_.find(c.pos);
      if (held == nullptr) {
        // Not held; but a load under way may have read the store before
        // this commit: read again if it did.
        if (residency_.loading(c.pos)) read_again(c.pos, c.revision, Storage::Priority::kUrgent);
        continue;
      }
      const Residency::Loaded& l = *held;
      if (!older_than(*l.current, c.revision)) continue;
      counters_.chunks_changed_elsewhere.fetch_add(1, std::memory_order_relaxed);
      if (!clients_.watched(c.pos) && !residency_.busy(c.pos) && stale_.count(c.pos) == 0 &&
          !residency_.loading(c.pos) && l.current == l.published) {
        // No client here holds it and nothing here waits for it: forgotten,
        // not read again (a server beside a busy one would otherwise read
        // every chunk the other writes that it once served); read from the
        // store when next wanted. Its region's coarse image too, which
        // would otherwise say the chunk was never stored.
        residency_.forget(c.pos);
        counters_.chunks_forgotten_elsewhere.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      if (!c.units.empty() && l.current->has_voxels() && !l.current->estimate() &&
          l.current->revision() + 1 == c.revision && !residency_.busy(c.pos) && stale_.count(c.pos) == 0 &&
          !residency_.loading(c.pos) && l.current == l.published) {
        // The notice's units take what is held to the new revision: applied
        // here, and sent to the holders as units, as an edit here would be.
        if (VersionPtr v = apply_units(*l.current, c)) {
          updated[c.tick].push_back(residency_.advance(std::move(v)));
          continue;
        }
        server_log().warn("chunk ({},{},{}): the units of revision {} in another server's notice do not apply; "
                          "reading it again",
                          c.pos.x, c.pos.y, c.pos.z, c.revision);
      }
      // As urgent as an edit of this server's: its holders wait to see it.
      read_again(c.pos, c.revision, Storage::Priority::kUrgent);
    }
    // Sent with the tick of the commit that made them (the tick an edit
    // forwarded there is acknowledged with).
    const auto now = std::chrono::steady_clock::now();
    for (const auto& [tick, versions] : updated) {
      counters_.chunks_updated_elsewhere.fetch_add(versions.size(), std::memory_order_relaxed);
      residency_.publish(versions);
      clients_.publish(tick, versions, now);
    }
  }
}

VersionPtr SharedAuthority::apply_units(const ChunkVersion& prev, const ChunkChange& c) {
  auto chunk = std::make_unique<Chunk>(prev.chunk() != nullptr ? prev.chunk()->clone() : Chunk(kAir));
  auto bits = apply_chunk_update_batch(c.units, c.pos, *chunk, units_scratch_);
  if (!bits) return nullptr;
  return ChunkVersion::after(prev, std::move(chunk), *bits);
}

void SharedAuthority::read_again_elsewhere(std::vector<Vec3i> regions) {
  {
    if (regions.empty()) return;
    Vec3iMap<bool> in;
    for (const Vec3i r : regions) in[r] = true;
    residency_.for_each([&](Vec3i cp, const Residency::Loaded& l) {
      const Vec3i region = lease_region_of(cp);
      // Estimates are replaced by the chunks as they are (their loads read the store).
      if (in.count(region) == 0 || writes_region(region) || l.current->estimate()) return;
      residency_.load_unless_loading(cp, Storage::Priority::kBackground);
    });
  }
}

std::vector<Vec3i> SharedAuthority::hand_over(const Region& box, std::uint32_t to) {
  std::vector<Vec3i> regions;
  for_each_chunk_in(box, [&](Vec3i cp) {
    const Vec3i region = lease_region_of(cp);
    if (!writes_region(region)) return;
    // Being released: edits there wait until the forward is done (a claim
    // now could run before the release).
    RegionLeaseState& l = leases_[region];
    l.state = RegionLeaseState::kHandingOver;
    l.left = false;
    l.wanted_back = false;
    l.holder = to;
    l.why = fmt::format("handed over to server {}", to);
    regions.push_back(region);
  });
  if (!regions.empty()) counters_.regions_handed_over.fetch_add(regions.size(), std::memory_order_relaxed);
  return regions;
}

void SharedAuthority::handed_over(const std::vector<Vec3i>& regions, bool ok) {
  // The regions handed over are the recipient's now: this server's next
  // edits there are forwarded to it too, until asked again a second on,
  // so a region does not bounce back before the recipient has claimed
  // it. Not forwarded: they are asked for again at once. Wanted back by an
  // edit from the recipient that this server wins: asked for again when
  // that edit's turn comes.
  const auto now = std::chrono::steady_clock::now();
  for (const Vec3i region : regions)
    if (auto l = leases_.find(region); l != leases_.end() && l->second.state == RegionLeaseState::kHandingOver) {
      if (l->second.wanted_back) {
        leases_.erase(l);
        continue;
      }
      l->second.state = RegionLeaseState::kRefused;
      l->second.ask_again = ok ? now + std::chrono::seconds(1) : now;
    }
}

bool SharedAuthority::asked_each_other(std::uint32_t from, const Region& box) const {
  const auto shares = [&](const auto& f) { return f.second.to == from && lease_regions_meet(f.second.box, box); };
  return std::any_of(forwarding_.begin(), forwarding_.end(), shares) ||
         std::any_of(forwarded_.begin(), forwarded_.end(), shares);
}

bool SharedAuthority::forward_pending(ClientId id, const Region& r) const {
  auto [first, last] = forwarding_.equal_range(id);
  for (auto it = first; it != last; ++it)
    if (chunks_meet(it->second.box, r)) return true;
  if (std::any_of(unsure_.begin(), unsure_.end(), [&](const Unsure& u) { return u.id == id && chunks_meet(u.box, r); }))
    return true;
  return std::any_of(forwarded_.begin(), forwarded_.end(),
                     [&](const auto& f) { return f.second.id == id && !f.second.answer && chunks_meet(f.second.box, r); });
}

void SharedAuthority::forward(ClientId id, const EditRequestMsg& edit, const std::string& player, const Region& box,
                              std::uint32_t to) {
  counters_.edits_forwarded.fetch_add(1, std::memory_order_relaxed);
  std::vector<Vec3i> regions = hand_over(box, to);
  forwarding_.emplace(id, Forwarding{box, to});
  // The wait counts from now, before the row is sent: its player's does.
  const auto deadline = std::chrono::steady_clock::now() + forward_wait();
  storage_.forward(to, player, edit, regions, deadline,
                   [this, id, edit, box, to, regions, deadline](StoreResult<std::int64_t> row) {
    asio::post(strand_, [this, id, edit, box, to, regions, deadline, row = std::move(row)] {
      handed_over(regions, row.ok());
      auto [first, last] = forwarding_.equal_range(id);
      for (auto it = first; it != last; ++it)
        if (it->second.box == box && it->second.to == to) {
          forwarding_.erase(it);
          break;
        }
      if (!row) {
        forward_failed(id, edit, box, to, deadline, row.error());
        return;
      }
      Outgoing o{Outgoing::kWaiting, id, edit, box, to, deadline, std::nullopt};
      if (auto early = early_answers_.find(*row); early != early_answers_.end()) {
        o.answer = early->second.first;
        early_answers_.erase(early);
      }
      forwarded_.emplace(*row, std::move(o));
      settle_forwarded();
    });
  });
}

void SharedAuthority::forward_failed(ClientId id, const EditRequestMsg& edit, const Region& box, std::uint32_t to,
                                     std::chrono::steady_clock::time_point deadline, const StoreError& e) {
  database_log_.warn(fmt::format("forwarded edits: an edit for server {} not sent: {}", to, e.message));
  if (e.kind == StoreError::Kind::kUnknown) {
    // Committed or not: if its row is there, an owner may take it until
    // its deadline and apply it within a commit's time.
    unsure_.push_back(Unsure{id, edit, box, deadline + answer_wait()});
    return;
  }
  if (clients_.present(id))
    queue_.reject(id, edit, RejectReason::kNotOwner,
                  e.kind == StoreError::Kind::kConnection
                      ? fmt::format("the world's database cannot be reached; {}", kNotApplied)
                      : fmt::format("the edit could not be forwarded to server {}; {}", to, kNotApplied));
}

void SharedAuthority::relay(Forwarded f, const Region& box, std::uint32_t to) {
  counters_.edits_forwarded.fetch_add(1, std::memory_order_relaxed);
  std::vector<Vec3i> regions = hand_over(box, to);
  storage_.relay(f.inbox_id, to, regions, [this, f, to, regions](StoreResult<Ok> done) {
    asio::post(strand_, [this, f, to, regions, done = std::move(done)] {
      handed_over(regions, done.ok());
      if (done) return;
      // Not passed on (the database out of reach, say): refused here. A row
      // no longer this server's (kFenced) is another's to answer; one that
      // may have been passed on (kUnknown) too: unanswered, its sender
      // calls its outcome unknown.
      database_log_.warn(fmt::format("forwarded edits: an edit not relayed to server {}: {}", to, done.error().message));
      if (done.error().kind != StoreError::Kind::kFenced && done.error().kind != StoreError::Kind::kUnknown)
        storage_.answer({ForwardAnswer{f.inbox_id, f.from, false, 0,
                                       fmt::format("it could not be passed on to server {}; {}", to, kNotApplied)}});
    });
  });
}

void SharedAuthority::take_inbox() {
  if (inbox_reading_) {
    inbox_again_ = true;
    return;
  }
  inbox_reading_ = true;
  read_inbox_page(0);
}

void SharedAuthority::read_inbox_page(std::int64_t after) {
  // Each read takes the rows not taken yet and still before their deadline
  // (the database decides both, once), a page at a time.
  storage_.read_inbox(after, kInboxPage, [this](StoreResult<std::vector<InboxEdit>> got) {
    asio::post(strand_, [this, got = std::move(got)] {
      if (!got) {
        database_log_.warn(fmt::format("forwarded edits: cannot read the inbox: {}", got.error().message));
        inbox_reading_ = false;
        if (std::exchange(inbox_again_, false)) take_inbox();
        return;
      }
      std::vector<ForwardAnswer> refused;
      for (const InboxEdit& in : *got) {
        // Another server's bytes, checked as a client's are.
        auto edit = decode_forwarded_edit(in.edit);
        const Region r = edit ? world_.meta().bounds.clamp(edit->reads()) : Region{};
        if (!edit || in.player.empty() || r.empty() || is_history_edit(edit->kind) || clock_.stopping) {
          const std::string why = !edit      ? fmt::format("the forwarded edit does not decode: {}", edit.error().detail)
                                  : in.player.empty() ? std::string("the player's name is missing or too long")
                                  : clock_.stopping ? std::string("the region's server is shutting down")
                                  : r.empty() ? std::string("edit outside the world")
                                              : std::string("undo and redo are not forwarded");
          refused.push_back(ForwardAnswer{in.id, in.from, false, 0, why});
          continue;
        }
        if (!take_forwarded_rate(in.player)) {
          counters_.limit_violations.fetch_add(1, std::memory_order_relaxed);
          refused.push_back(ForwardAnswer{
              in.id, in.from, false, 0,
              fmt::format("edit rate limit: '{}' sent more than {} edits a second through the servers of this world",
                          in.player, options_.edits_per_second)});
          continue;
        }
        counters_.forwarded_edits_received.fetch_add(1, std::memory_order_relaxed);
        residency_.reserve(r);
        // Two servers asking each other for their regions at once (each
        // handed its own over with its client's edit, or is handing them
        // over) would each claim what the other gave up, and refuse the
        // other's edit when they got part of it: the lower id wins. The
        // other claims nothing for the edit and passes it back, with what
        // it holds of it; the winner claims every region of both edits,
        // those it is handing over too, once released.
        const bool duel = in.from != server_id_ && asked_each_other(in.from, r);
        const bool back = duel && in.from < server_id_;
        // What this server knew of the edit's regions held elsewhere may be
        // out of date (the sender may have handed them over): asked again
        // when the edit's turn comes.
        if (!back)
          for_each_chunk_in(r, [&](Vec3i cp) {
            auto l = leases_.find(lease_region_of(cp));
            if (l == leases_.end()) return;
            if (l->second.state == RegionLeaseState::kRefused)
              leases_.erase(l);
            else if (duel && l->second.state == RegionLeaseState::kHandingOver && l->second.holder == in.from)
              l->second.wanted_back = true;
          });
        // Refused by the tick if its turn comes after current_until.
        queue_.queue_forwarded(std::move(*edit), in.player,
                               Forwarded{in.id, in.from, back, in.from == server_id_, in.current_until});
      }
      if (!refused.empty()) storage_.answer(std::move(refused));
      if (got->size() == kInboxPage) {
        read_inbox_page(got->back().id);
        return;
      }
      inbox_reading_ = false;
      if (std::exchange(inbox_again_, false)) take_inbox();
    });
  });
}

bool SharedAuthority::take_forwarded_rate(const std::string& player) {
  if (options_.edits_per_second <= 0) return true;
  // Twice a session's burst: forwarded edits arrive in batches (an inbox
  // read after a reconnect), not as their player sent them.
  const double burst = options_.edits_per_second * 4;
  // Bounded: players idle long enough to have a full bucket are forgotten,
  // and if that is not enough, all are (they start full again).
  if (forwarded_rate_.size() >= kMaxForwardedRates) {
    for (auto it = forwarded_rate_.begin(); it != forwarded_rate_.end();)
      it = it->second.available() >= burst ? forwarded_rate_.erase(it) : std::next(it);
    if (forwarded_rate_.size() >= kMaxForwardedRates / 2) forwarded_rate_.clear();
  }
  auto [it, fresh] = forwarded_rate_.try_emplace(player, options_.edits_per_second, burst);
  return it->second.take(1);
}

std::chrono::milliseconds SharedAuthority::forward_wait() const {
  // An owner silent for a lease time has lost its regions anyway.
  return std::max<std::chrono::milliseconds>(kForwardAnswerWait, lease_);
}

void SharedAuthority::answered(ForwardAnswer answer) {
  {
    auto it = forwarded_.find(answer.id);
    if (it != forwarded_.end())
      it->second.answer = answer;
    else  // before the forward's own callback: kept for it
      early_answers_.emplace(answer.id, std::make_pair(answer, std::chrono::steady_clock::now()));
    settle_forwarded();
  }
}

void SharedAuthority::settle_forwarded() {
  const auto now = std::chrono::steady_clock::now();
  const auto wait = forward_wait();
  std::erase_if(early_answers_, [&](const auto& e) { return now - e.second.second > wait + answer_wait(); });
  std::erase_if(unsure_, [&](const Unsure& u) {
    if (clients_.present(u.id) && now < u.tell_at) return false;
    if (clients_.present(u.id))
      queue_.reject(u.id, u.edit, RejectReason::kOutcomeUnknown,
                    fmt::format("the world's database did not confirm the forwarded edit; {}", kOutcomeUnknown));
    return true;
  });
  for (auto it = forwarded_.begin(); it != forwarded_.end();) {
    const std::int64_t row = it->first;
    Outgoing& o = it->second;
    bool done = !clients_.present(o.id);
    if (!done && o.answer && !o.answer->accepted) {
      queue_.reject(o.id, o.edit, RejectReason::kNotOwner,
             fmt::format("server {} refused the forwarded edit: {}", o.to, o.answer->reason));
      done = true;
    } else if (!done && o.answer) {
      // Acknowledged once this server shows the edit: its chunks are
      // updated or read again here (the owner's notice came with the
      // answer) and sent to the client before the ack, which names the
      // owner's tick, as the UpdateBatch of its units does.
      bool current = true;
      for_each_chunk_in(o.box, [&](Vec3i cp) { current = current && stale_.count(cp) == 0 && !residency_.loading(cp); });
      if (current) {
        clients_.answer(o.id, EditAcked{o.edit.edit_id, o.answer->tick});
        done = true;
      }
    } else if (!done && o.state == Outgoing::kWaiting && now >= o.deadline) {
      // Its deadline has passed by the database's clock too: nobody takes
      // it from now on. Not taken: taken back, never applied.
      o.state = Outgoing::kTakingBack;
      storage_.take_back(row, [this, row](StoreResult<bool> deleted) {
        asio::post(strand_, [this, row, deleted = std::move(deleted)]() mutable { taken_back(row, std::move(deleted)); });
      });
    } else if (!done && o.state == Outgoing::kTaken && now >= o.deadline + answer_wait()) {
      queue_.reject(o.id, o.edit, RejectReason::kOutcomeUnknown,
                    fmt::format("server {} took the forwarded edit but did not answer within {} ms; {}", o.to,
                                (wait + answer_wait()).count(), kOutcomeUnknown));
      done = true;
    }
    it = done ? forwarded_.erase(it) : std::next(it);
  }
}

void SharedAuthority::taken_back(std::int64_t row, StoreResult<bool> deleted) {
  auto it = forwarded_.find(row);
  if (it == forwarded_.end() || it->second.answer) {
    settle_forwarded();  // answered meanwhile (or its client left)
    return;
  }
  Outgoing& o = it->second;
  if (deleted && !*deleted) {
    o.state = Outgoing::kTaken;  // its owner has it: its answer is waited for
    return;
  }
  if (clients_.present(o.id)) {
    if (deleted) {
      queue_.reject(o.id, o.edit, RejectReason::kNotOwner,
                    fmt::format("server {} did not take the forwarded edit within {} ms; {}", o.to,
                                forward_wait().count(), kNotApplied));
    } else {
      database_log_.warn(fmt::format("forwarded edits: cannot take back inbox row {}: {}", row, deleted.error().message));
      queue_.reject(o.id, o.edit, RejectReason::kOutcomeUnknown,
                    fmt::format("the world's database cannot be reached; {}", kOutcomeUnknown));
    }
  }
  forwarded_.erase(it);
}

}  // namespace terrane
