#include "server/world/tick.h"

#include <algorithm>

#include <fmt/format.h>

#include "common/codec/byte_rle.h"
#include "common/world/view.h"
#include "server/base/log.h"

namespace terrane {

namespace {

// Edits applied per tick at most: bounds a tick's work on the strand (each
// edit touches at most kMaxEditVolume voxels).
constexpr std::size_t kMaxEditsPerTick = 256;
// Edits set aside to wait, per tick, before the rest wait for the next.
constexpr std::size_t kMaxEditsWaitingPerTick = 1024;

}  // namespace

Tick::Tick(Strand& strand, World& world, Storage& storage, const WorldOptions& options, ServerCounters& counters,
           WorldClock& clock, Residency& residency, FanOut& clients, Authority& authority)
    : strand_(strand),
      world_(world),
      storage_(storage),
      options_(options),
      counters_(counters),
      clock_(clock),
      residency_(residency),
      clients_(clients),
      authority_(authority),
      timer_(strand),
      parked_(options.parked_history_bytes) {}

void Tick::start() {
  next_tick_ = std::chrono::steady_clock::now();
  arm_tick();
}

void Tick::join(ClientId id, std::string name, bool identified) {
  std::optional<History> kept = identified ? parked_.take(name) : std::nullopt;
  History history = kept ? std::move(*kept) : History(options_.history_bytes_per_client);
  editors_.emplace(id, Editor{std::move(name), 0, std::move(history), identified});
}

void Tick::leave(ClientId id) {
  auto it = editors_.find(id);
  if (it == editors_.end()) return;
  Editor left = std::move(it->second);
  editors_.erase(it);
  if (!left.identified) return;
  // The player's other session, if it joined before this one left (a
  // reconnect that raced the old connection's end): a scan, once per
  // identified leave, over the editors.
  for (auto& [other_id, other] : editors_)
    if (other.identified && other.name == left.name) {
      if (other.history.steps(false) == 0 && other.history.steps(true) == 0) other.history = std::move(left.history);
      return;
    }
  parked_.park(left.name, std::move(left.history));
}

void Tick::stop() {
  std::promise<void> applied;
  auto drained = drained_.get_future();
  asio::post(strand_, [this, &applied] {
    clock_.stopping = true;
    timer_.cancel();
    // Edits received but not yet applied are applied now so nothing
    // acknowledged-to-be is lost (unless the store already failed).
    if (!storage_failed_) {
      while (!edits_.empty()) {
        const std::size_t before = edits_.size();
        apply_edits();
        if (edits_.size() == before) break;
      }
    }
    fail_rollbacks("the server is stopping");  // any the store's failure left queued
    drain_wanted_ = true;
    if (commits_pending_ == 0) drained_.set_value();
    applied.set_value();
  });
  applied.get_future().wait();
  drained.wait();
}

void Tick::retry_pending() {
  residency_.retry_unreadable();
  // Reads and hashes whose chunks have arrived.
  std::size_t kept = 0;
  for (auto& [id, req] : reads_) {
    if (!clients_.present(id)) continue;
    Box box(req.box.size());
    if (!residency_.read_current(req.box, box)) {
      // Asked again: a chunk of the box may have been lightened meanwhile.
      for_each_chunk_in(req.box, [&](Vec3i cp) { residency_.request(cp); });
      reads_[kept++] = {id, req};
      continue;
    }
    const auto voxels = box.voxels();
    clients_.answer(id, ReadBoxResultMsg{req.request_id, req.box, {}, {voxels.begin(), voxels.end()}});
  }
  reads_.resize(kept);
  kept = 0;
  for (auto& [id, cp] : hashes_) {
    if (!clients_.present(id)) continue;
    if (!residency_.request(cp)) {
      hashes_[kept++] = {id, cp};
      continue;
    }
    const VersionPtr& v = residency_.find(cp)->published;
    clients_.answer(id, ChunkHashMsg{cp, v->revision(), v->hash()});
  }
  hashes_.resize(kept);
}

void Tick::reject(ClientId id, const EditRequestMsg& edit, RejectReason why, const std::string& reason) {
  counters_.rejected(why);
  if (!clients_.present(id)) return;
  // The true state of what the edit would have touched, when it is at hand:
  // on the data queue, after every change already sent, so it is the state
  // the client's replica reaches once it has read that far.
  const bool unknown = why == RejectReason::kOutcomeUnknown;
  const Region r = world_.meta().bounds.clamp(edit.bounds());
  if (!r.empty() && r.volume() <= kMaxEditVolume) {
    Box box(r.size());
    if (residency_.read_current(r, box)) {
      const auto voxels = box.voxels();
      clients_.answer(id, EditRejectMsg{edit.edit_id, reason, r, {voxels.begin(), voxels.end()}, unknown});
      return;
    }
  }
  clients_.answer(id, EditRejectMsg{edit.edit_id, reason, {}, {}, unknown});
}

void Tick::edit(ClientId id, EditRequestMsg e, std::chrono::steady_clock::time_point received) {
  {
    auto it = editors_.find(id);
    if (it == editors_.end() || clock_.stopping) return;
    Editor& c = it->second;
    if (c.edits_queued >= options_.max_edits_queued_per_client) return reject(id, e, RejectReason::kQueueFull, "too many edits queued");
    if (!is_history_edit(e.kind)) {
      const Region r = world_.meta().bounds.clamp(e.reads());
      if (r.empty()) return reject(id, e, RejectReason::kOutsideWorld, "edit outside the world");
      residency_.reserve(r);
    }
    ++c.edits_queued;
    edits_.push_back(PendingEdit{id, std::move(e), c.name, nullptr, std::nullopt, received});
  }
}

void Tick::rollback(std::string actor, std::vector<EditLogEntry> entries, std::optional<Region> within,
                    std::function<void(RollbackResult)> done) {
  {
    if (clock_.stopping) return done(RollbackResult{false, "the server is stopping", 0, 0});
    const WorldBounds& bounds = world_.meta().bounds;
    for (const EditLogEntry& e : entries)
      residency_.reserve(bounds.clamp(e.box));
    auto job = std::make_shared<Rollback>();
    job->actor = std::move(actor);
    job->entries = std::move(entries);
    job->within = within;
    job->done = std::move(done);
    edits_.push_back(PendingEdit{0, EditRequestMsg{}, job->actor, std::move(job), std::nullopt});
  }
}

void Tick::queue_forwarded(EditRequestMsg edit, std::string player, Forwarded from) {
  if (!from.own) {
    edits_.push_back(PendingEdit{0, std::move(edit), std::move(player), nullptr, from});
    return;
  }
  // This server's own edit, back: ahead of the edits waiting (its player's
  // later edits on its chunks wait for its answer), behind those back before.
  const auto at = std::find_if(edits_.begin(), edits_.end(),
                               [](const PendingEdit& e) { return !e.forwarded || !e.forwarded->own; });
  edits_.insert(at, PendingEdit{0, std::move(edit), std::move(player), nullptr, from});
}

// One tick's edits as they apply (Tick::apply_edits): copies of the
// chunks they touch, what they changed, and whom to tell once committed.
struct Tick::TickEdits {
  std::uint64_t tick = 0;
  std::int64_t now_ms = 0;
  Grid scratch;
  std::unordered_set<Vec3i, Vec3iHash> copied;
  ChangedUnits changed;
  std::vector<Ack> acks;
  std::vector<ForwardAnswer> answers, refused;  // to forwarded edits: applied (in the commit), refused (at once)
  std::vector<EditLogEntry> log;
  std::vector<std::shared_ptr<Rollback>> rollbacks;
  // An edit that must wait (for its chunks, a claim) is set aside and the
  // edits behind it go on, except those that touch a chunk of a waiting
  // edit or are a waiting edit's player's: those keep arrival order. The
  // edits set aside go back to the queue's front after the tick.
  std::deque<PendingEdit> waiting;
  std::unordered_set<Vec3i, Vec3iHash> waiting_chunks;
  std::unordered_set<std::string> waiting_players;

  void refuse(const Forwarded& f, std::string why) {
    refused.push_back(ForwardAnswer{f.inbox_id, f.from, false, 0, std::move(why)});
  }
  void log_step(const std::string& player, const Region& box, std::vector<std::uint8_t> before,
                std::vector<std::uint8_t> after) {
    if (before == after) return;  // nothing changed: nothing to log
    log.push_back(EditLogEntry{0, tick, now_ms, player, box, std::move(before), std::move(after)});
  }
  bool behind_waiting(const Region& r) const {
    bool meets = false;
    for_each_chunk_in(r, [&](Vec3i cp) { meets = meets || waiting_chunks.count(cp) != 0; });
    return meets;
  }
  void mark_waiting(const Region& r) {
    for_each_chunk_in(r, [&](Vec3i cp) { waiting_chunks.insert(cp); });
  }
};

void Tick::apply_edits() {
  ++clock_.tick;
  counters_.ticks.fetch_add(1, std::memory_order_relaxed);
  // The tick's edits apply to copies of the chunks they touch; each changed
  // chunk then becomes a new version.
  TickEdits t;
  t.tick = clock_.tick;
  t.now_ms =
      std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
  while (!edits_.empty() && t.acks.size() + t.rollbacks.size() < kMaxEditsPerTick &&
         t.waiting.size() < kMaxEditsWaitingPerTick)
    if ((edits_.front().rollback ? apply_rollback(t) : apply_player_edit(t)) == EditStep::kStop) break;
  for (; !t.waiting.empty(); t.waiting.pop_back()) edits_.push_front(std::move(t.waiting.back()));
  if (!t.refused.empty()) storage_.answer(std::move(t.refused));

  std::vector<VersionPtr> versions;
  versions.reserve(t.changed.size());
  for (const auto& [cp, bits] : t.changed) {
    if (bits.none()) continue;
    versions.push_back(residency_.advance(ChunkVersion::after(*residency_.find(cp)->current, t.scratch.take_chunk(cp), bits)));
  }
  if (versions.empty() && t.acks.empty() && t.rollbacks.empty() && t.answers.empty()) return;
  ++commits_pending_;
  const std::uint64_t tick = clock_.tick;
  // Counted once stored: a failed tick's edits are rejected, not applied.
  const std::uint64_t applied = t.acks.size() + t.answers.size();
  storage_.commit(
      versions, std::move(t.log),
      [this, tick, applied, versions, acks = std::move(t.acks), rollbacks = std::move(t.rollbacks)](const FileStatus& st) {
        asio::post(strand_, [this, tick, applied, versions, acks, rollbacks, st] {
          if (st) counters_.edits_applied.fetch_add(applied, std::memory_order_relaxed);
          on_committed(tick, versions, acks, st);
          for (const auto& job : rollbacks)
            job->done(st ? RollbackResult{true, "", tick, job->restored}
                         : RollbackResult{false,
                                          st.error().outcome_unknown
                                              ? "storage failure: outcome unknown (the rollback may have been saved)"
                                              : "storage failure: rollback not saved",
                                          tick, 0});
        });
      },
      std::move(t.answers), tick);
}

void Tick::set_aside(TickEdits& t) {
  t.waiting.push_back(std::move(edits_.front()));
  edits_.pop_front();
}

Tick::EditStep Tick::apply_rollback(TickEdits& t) {
  const WorldBounds& bounds = world_.meta().bounds;
  PendingEdit& pe = edits_.front();
  Rollback& job = *pe.rollback;
  bool behind = false;
  for (const EditLogEntry& e : job.entries) behind = behind || t.behind_waiting(bounds.clamp(e.box));
  if (behind) {
    for (const EditLogEntry& e : job.entries) t.mark_waiting(bounds.clamp(e.box));
    set_aside(t);
    return EditStep::kNext;
  }
  bool ready = true;
  for (const EditLogEntry& e : job.entries)
    for_each_chunk_in(bounds.clamp(e.box), [&](Vec3i cp) { ready = residency_.request(cp) && ready; });
  std::string not_ours;
  Writable w = Writable::kYes;
  for (const EditLogEntry& e : job.entries)
    if (w != Writable::kNo)
      if (const Writable here = authority_.writable(bounds.clamp(e.box), &not_ours, nullptr, ClaimRule::kAny);
          here != Writable::kYes)
        w = here;
  if ((!ready || w == Writable::kWaiting) && !clock_.stopping) {  // wait for its chunks and leases
    for (const EditLogEntry& e : job.entries) t.mark_waiting(bounds.clamp(e.box));
    set_aside(t);
    return EditStep::kNext;
  }
  for (const EditLogEntry& e : job.entries) residency_.unbusy(bounds.clamp(e.box));
  if (!ready || w != Writable::kYes) {
    job.done(RollbackResult{false, w == Writable::kNo ? not_ours : std::string("the server is stopping"), 0, 0});
    edits_.pop_front();
    return EditStep::kNext;
  }
  for (const EditLogEntry& e : job.entries) residency_.copy_into(t.scratch, bounds.clamp(e.box), t.copied);
  UnitMarker marker(t.changed);
  std::unordered_map<Vec3i, Voxel, Vec3iHash> first;  // each restored voxel's value before the rollback
  for (const EditLogEntry& e : job.entries) {
    Region b = bounds.clamp(e.box);
    if (job.within) b = intersect(b, *job.within);
    if (b.empty()) continue;
    const auto n = static_cast<std::size_t>(e.box.volume());
    std::vector<Voxel> before(n), after(n);
    if (!byte_rle_decode(e.before, before) || !byte_rle_decode(e.after, after)) continue;  // damaged entry
    auto was = snapshot(t.scratch, b);
    const Vec3i size = e.box.size();
    t.scratch.modify(b, [&](Vec3i p, Voxel cur) {
      const Vec3i l = p - e.box.min;
      const auto i = static_cast<std::size_t>((l.y * size.z + l.z) * size.x + l.x);
      if (cur != after[i] || before[i] == cur) return cur;
      marker.mark(p);
      first.emplace(p, cur);
      return before[i];
    });
    t.log_step(job.actor, b, std::move(was), snapshot(t.scratch, b));
  }
  for (const auto& [p, v] : first) job.restored += t.scratch.get(p) != v ? 1 : 0;
  t.rollbacks.push_back(std::move(pe.rollback));
  edits_.pop_front();
  return EditStep::kNext;
}

// A client's edit (an undo or redo too) or one forwarded from another
// server's inbox.
Tick::EditStep Tick::apply_player_edit(TickEdits& t) {
  const WorldBounds& bounds = world_.meta().bounds;
  PendingEdit& pe = edits_.front();
  auto cit = editors_.find(pe.id);
  Editor* client = cit != editors_.end() ? &cit->second : nullptr;
  const bool history = is_history_edit(pe.edit.kind);
  const bool redo = pe.edit.kind == EditKind::kRedo;
  Region r;
  if (history) {
    const HistoryEntry* top = client != nullptr ? client->history.top(redo) : nullptr;
    if (top != nullptr) r = bounds.clamp(top->box);
  } else {
    r = bounds.clamp(pe.edit.reads());
  }
  // (r, what the edit reads, holds what it writes.)
  if (pe.forwarded && std::chrono::steady_clock::now() >= pe.forwarded->current_until) {
    // Its deadline may have passed by the database's clock: its sender
    // tells its player it was not applied, or that its outcome is unknown;
    // applied now, it could land after the player's next edit.
    t.refuse(*pe.forwarded, "it came too late (its deadline passed); it was not applied");
    residency_.unbusy(r);
    edits_.pop_front();
    return EditStep::kNext;
  }
  const auto wait = [&] {
    t.mark_waiting(r);
    t.waiting_players.insert(pe.player);
    set_aside(t);
  };
  // A client's edit also waits while one of its edits whose chunks it
  // meets is forwarded and not answered: another server may apply that.
  if (t.waiting_players.count(pe.player) != 0 || t.behind_waiting(r) ||
      (client != nullptr && !pe.forwarded && authority_.forward_pending(pe.id, r))) {
    wait();
    return EditStep::kNext;
  }
  bool ready = true;
  for_each_chunk_in(r, [&](Vec3i cp) { ready = residency_.request(cp) && ready; });
  if (!ready) {
    if (!clock_.stopping) {  // wait for its chunks
      wait();
      return EditStep::kNext;
    }
    // Shutting down: chunks still loading will not be waited for.
    if (client != nullptr) reject(pe.id, pe.edit, RejectReason::kShutdown, "server shutting down");
    if (pe.forwarded) t.refuse(*pe.forwarded, "the region's server is shutting down");
    if (!history) residency_.unbusy(r);
    if (client != nullptr && client->edits_queued > 0) --client->edits_queued;
    edits_.pop_front();
    return EditStep::kNext;
  }
  // In a shared world, only regions this server holds are written; a
  // client's edit in another server's is forwarded to it. A forwarded edit
  // whose sender wins (the two asked each other for their regions at once)
  // goes back to it, and nothing is claimed for it here.
  std::string not_ours;
  std::optional<std::uint32_t> holder;
  const Region writes = history ? r : bounds.clamp(pe.edit.bounds());
  const bool back = pe.forwarded && pe.forwarded->back;
  if (back) {
    holder = pe.forwarded->from;
    not_ours = fmt::format("server {}, which sent it, takes its regions", *holder);
  }
  const Writable w =
      back ? Writable::kNo
           : authority_.writable(writes, &not_ours, &holder,
                                 client != nullptr && !history && !pe.forwarded ? ClaimRule::kPreferNeighbours
                                                                                : ClaimRule::kAny);
  // Another server's region in it: which of the others are this server's
  // decides what goes with the edit, so claims under way are waited for.
  if ((w == Writable::kWaiting || (w == Writable::kNo && !history && authority_.claiming(writes))) && !clock_.stopping) {
    wait();  // for the claims
    return EditStep::kNext;
  }
  if (w != Writable::kYes) {
    // An edit across a border also writes regions of this server's: they
    // are handed over with it to the server holding the rest, once nothing
    // of them is in flight. A forwarded edit goes on so too (relayed: its
    // inbox row readdressed, its sender and deadline kept), with regions
    // of this server's or none (they moved on since its sender looked); a
    // row past its deadline is taken nowhere, so no relay goes on longer.
    // Back to its sender only when the sender wins (a lower id: back),
    // where it goes ahead of its player's next edits (which wait for its
    // answer); otherwise t.refused (the player tries again), so no edit
    // goes back and forth.
    std::unordered_set<Vec3i, Vec3iHash> mine;
    const bool may_go_on =
        w == Writable::kNo && holder && !history && !clock_.stopping &&
        (client != nullptr || (pe.forwarded && (*holder != pe.forwarded->from || back ||
                                                authority_.passes_back_to(pe.forwarded->from))));
    if (may_go_on)
      for_each_chunk_in(writes, [&](Vec3i cp) {
        if (authority_.writes_region(lease_region_of(cp))) mine.insert(lease_region_of(cp));
      });
    if (may_go_on) {
      // Handed over only with nothing of this server's in flight: no commit
      // under way, nothing applied yet this tick, no edit set aside in the
      // regions. Nothing behind it is applied meanwhile, so that comes
      // within a commit's time (or an edit's wait).
      const bool in_flight = commits_pending_ > 0 || !t.changed.empty() ||
                             std::any_of(t.waiting_chunks.begin(), t.waiting_chunks.end(),
                                         [&](Vec3i cp) { return mine.count(lease_region_of(cp)) != 0; });
      if (!mine.empty() && in_flight) return EditStep::kStop;
      if (pe.forwarded)
        authority_.relay(*pe.forwarded, writes, *holder);
      else
        authority_.forward(pe.id, pe.edit, pe.player, writes, *holder);
    } else if (pe.forwarded) {
      t.refuse(*pe.forwarded, w == Writable::kNo ? "not held by the server it was sent to: " + not_ours
                                               : std::string("the region's server is shutting down"));
    } else if (client != nullptr) {
      if (w == Writable::kNo)
        reject(pe.id, pe.edit, RejectReason::kNotOwner,
               std::string(history ? "undo and redo only where this server writes; " : "") +
                   "not this server's region: " + not_ours);
      else
        reject(pe.id, pe.edit, RejectReason::kShutdown, "server shutting down");
    }
    if (!history) residency_.unbusy(r);
    if (client != nullptr && client->edits_queued > 0) --client->edits_queued;
    edits_.pop_front();
    return EditStep::kNext;
  }
  residency_.copy_into(t.scratch, r, t.copied);
  if (client != nullptr && client->edits_queued > 0) --client->edits_queued;
  if (history) {
    std::string why = "client gone";
    if (client != nullptr && client->history.top(redo) == nullptr) {
      why = redo ? "nothing to redo" : "nothing to undo";
    } else if (client != nullptr && !clients_.within_full_res(pe.id, r)) {
      why = std::string(redo ? "redo" : "undo") + " outside the full-resolution region";
      client->history.drop(redo);  // its box may be stale by the time the client is back
    } else if (auto was = client != nullptr ? snapshot(t.scratch, r) : std::vector<std::uint8_t>{};
               client != nullptr && client->history.apply(t.scratch, redo, t.changed, &why)) {
      t.log_step(pe.player, r, std::move(was), snapshot(t.scratch, r));
      t.acks.push_back(Ack{pe.id, pe.edit.edit_id, pe.received});
      edits_.pop_front();
      return EditStep::kNext;
    }
    if (client != nullptr) reject(pe.id, pe.edit, RejectReason::kHistory, why);
    edits_.pop_front();
    return EditStep::kNext;
  }
  const Region box = bounds.clamp(pe.edit.bounds());
  HistoryEntry entry{box, snapshot(t.scratch, box), {}};
  apply_edit(t.scratch, pe.edit, box, t.changed);
  entry.after = snapshot(t.scratch, box);
  t.log_step(pe.player, box, entry.before, entry.after);
  if (client != nullptr) client->history.record(std::move(entry));
  residency_.unbusy(r);
  if (pe.forwarded)
    t.answers.push_back(ForwardAnswer{pe.forwarded->inbox_id, pe.forwarded->from, true, clock_.tick, ""});
  else
    t.acks.push_back(Ack{pe.id, pe.edit.edit_id, pe.received});
  edits_.pop_front();
  return EditStep::kNext;
}

void Tick::on_committed(std::uint64_t tick, const std::vector<VersionPtr>& versions, const std::vector<Ack>& acks,
                              const FileStatus& status) {
  --commits_pending_;
  if (!status) {
    if (!storage_failed_) {
      server_log().critical("tick {}: saving {} chunks failed: {}; rejecting the tick's edits and stopping", tick,
                            versions.size(), status.error().message);
    }
    // Nothing of this tick may be acknowledged or shown: it is not known to
    // be on disk. A commit whose answer was lost may be stored all the same:
    // its editors are told that the outcome is unknown, not a refusal.
    const bool unknown = status.error().outcome_unknown;
    const char* why = unknown ? "storage failure: outcome unknown (the edit may have been saved)"
                              : "storage failure: edit not saved";
    for (const Ack& a : acks)
      clients_.answer(a.id, EditRejectMsg{a.edit_id, why, {}, {}, unknown});
    counters_.rejected(unknown ? RejectReason::kOutcomeUnknown : RejectReason::kStorageFailure, acks.size());
    fatal_storage(status.error().message);
  } else {
    const auto t0 = std::chrono::steady_clock::now();
    // Publish, then tell each holder once about all of its changed chunks,
    // then acknowledge: on a client's strand the news is handled before the
    // ack is queued, so whatever the client asks after reading its ack (a
    // chunk hash, a read) is answered from the new versions.
    // Holders at full resolution hear of every tick; the others' news is
    // gathered and handed over every mip_refresh_ms (deliver_mip_news).
    residency_.publish(versions);
    clients_.publish(tick, versions, t0);
    const auto acked_at = std::chrono::steady_clock::now();
    for (const Ack& a : acks) {
      if (!clients_.present(a.id)) continue;  // gone: nothing acknowledged
      // Counted before the ack leaves, so a client that read it sees it counted.
      counters_.edit_ack_duration.observe(acked_at - a.received);
      clients_.answer(a.id, EditAcked{a.edit_id, tick});
    }
    counters_.fanout_duration.observe(std::chrono::steady_clock::now() - t0);
  }
  if (status) last_committed_tick_ = std::max(last_committed_tick_, tick);
  for (auto it = flush_waiters_.begin(); it != flush_waiters_.end();) {
    if (commits_pending_ == 0 || it->first <= last_committed_tick_) {
      it->second(it->first, !storage_failed_);
      it = flush_waiters_.erase(it);
    } else {
      ++it;
    }
  }
  if (drain_wanted_ && commits_pending_ == 0) {
    drain_wanted_ = false;
    drained_.set_value();
  }
}

void Tick::fail_rollbacks(const std::string& why) {
  for (auto it = edits_.begin(); it != edits_.end();) {
    if (it->rollback) {
      it->rollback->done(RollbackResult{false, why, 0, 0});
      it = edits_.erase(it);
    } else {
      ++it;
    }
  }
}

void Tick::fatal_storage(const std::string& why) {
  if (storage_failed_) return;
  (void)why;
  fail_rollbacks("storage failure: rollback not applied");
  storage_failed_ = true;
  storage_failed_flag_ = true;
  // The owner hears of the failure before any client does: a client that reads
  // "server storage failure" may ask the server, and finds it failed.
  if (options_.on_fatal) options_.on_fatal();
  clients_.close_all(CloseReason::kStorageFailure, "server storage failure");
  clock_.stopping = true;
  timer_.cancel();
}

void Tick::read_box(ClientId id, const ReadBoxMsg& req) {
  if (!clients_.present(id)) return;
  for_each_chunk_in(req.box, [&](Vec3i cp) { residency_.request(cp); });
  reads_.emplace_back(id, req);
  retry_pending();
}

void Tick::hash(ClientId id, Vec3i cp) {
  hashes_.emplace_back(id, cp);
  retry_pending();
}

void Tick::arm_tick() {
  if (clock_.stopping) return;
  // A fixed schedule: the next tick is due one period after the last one was
  // due, however long the work took; a tick more than a period late starts
  // the schedule again from now (counted) rather than bunching ticks up.
  const auto period = std::chrono::microseconds(1'000'000 / std::max<std::uint32_t>(1, options_.tick_hz));
  next_tick_ += period;
  const auto now = std::chrono::steady_clock::now();
  if (next_tick_ + period < now) {
    counters_.ticks_late.fetch_add(1, std::memory_order_relaxed);
    next_tick_ = now;
  }
  timer_.expires_at(next_tick_);
  timer_.async_wait([this](const asio::error_code& ec) {
    if (ec || clock_.stopping) return;
    on_tick();
    arm_tick();
  });
}

void Tick::on_tick() {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  residency_.replace_estimates();
  counters_.tick_lag_ns.store(
      static_cast<std::uint64_t>(std::max<std::int64_t>(0, std::chrono::nanoseconds(t0 - next_tick_).count())),
      std::memory_order_relaxed);
  residency_.lighten_some();
  clients_.deliver_mip_news(std::chrono::steady_clock::now());
  const auto t_edits = Clock::now();
  apply_edits();
  authority_.settle();
  const auto t_presence = Clock::now();
  const std::uint32_t hz = std::max<std::uint32_t>(1, options_.tick_hz);
  if (options_.presence_hz > 0) clients_.send_presence(clock_.tick);
  const auto t_unload = Clock::now();
  residency_.unload_unwatched();
  if (clock_.tick % hz == 0) retry_pending();
  const auto t1 = Clock::now();
  counters_.tick_duration.observe(t1 - t0);
  counters_.last_tick_at_ns.store(steady_ns(t1), std::memory_order_relaxed);
  // A tick longer than half its period delays every edit that arrives
  // meanwhile: said, with its parts, at most once every 10 s.
  const auto period = std::chrono::microseconds(1'000'000 / hz);
  if (t1 - t0 > period / 2) {
    ++slow_ticks_;
    if (t1 >= next_slow_tick_report_) {
      const auto ms = [](Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); };
      server_log().warn(
          "tick {} took {:.1f} ms (period {:.1f}): loads and lightening {:.1f}, edits {:.1f}, presence {:.1f}, "
          "unloading {:.1f}; {} such ticks since the last report",
          clock_.tick, ms(t1 - t0), ms(period), ms(t_edits - t0), ms(t_presence - t_edits), ms(t_unload - t_presence),
          ms(t1 - t_unload), slow_ticks_);
      slow_ticks_ = 0;
      next_slow_tick_report_ = t1 + std::chrono::seconds(10);
    }
  }
}

void Tick::flush(std::function<void(std::uint64_t tick, bool stored)> done) {
  if (commits_pending_ == 0) return done(clock_.tick, !storage_failed_);
  flush_waiters_.emplace_back(clock_.tick, std::move(done));
}

}  // namespace terrane
