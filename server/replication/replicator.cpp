#include "server/replication/replicator.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstdlib>
#include <limits>
#include <tuple>

#include "common/world/view.h"
#include "server/base/log.h"
#include "server/replication/world_answers.h"

namespace terrane {

namespace {

// Granted chunks waiting for room in the window or budget are tried again
// this soon.
constexpr auto kPumpRetry = std::chrono::milliseconds(20);

}  // namespace

Replicator::Replicator(ClientId id, WorldOwner& world, const ReplicationOptions& options,
                       const ClusterOptions& cluster_options, ServerCounters& counters, const WelcomeTemplate& welcome,
                       const StreamGate& gate, const ClusterDirectory* cluster, UpdateFaults* faults)
    : id_(id),
      world_(world),
      options_(options),
      counters_(counters),
      welcome_(welcome),
      faults_(faults),
      yield_(gate, id, counters),
      redirect_(cluster, cluster_options),
      move_limit_(options.max_speed),
      plan_(welcome.bounds),
      slots_(&counters.memory[MemoryPart::kChunkSlots]),
      hashes_(std::chrono::milliseconds(options.hash_push_ms)) {
  state_.view_distance = options_.default_view_distance;
  state_.full_res_radius = options_.default_full_res_radius;
}

void Replicator::attach(std::shared_ptr<Session> session) {
  session_ = std::move(session);
  weak_session_ = session_;
  executor_ = session_->executor();
  timer_ = std::make_unique<asio::steady_timer>(executor_);
}

// --- from the world (world strand: post to ours) --------------------------------

void Replicator::granted(std::vector<VersionPtr> versions) {
  asio::post(executor_, [self = shared_from_this(), v = std::move(versions)]() mutable {
    self->on_granted(std::move(v));
  });
}

void Replicator::horizons(std::vector<HorizonPtr> images) {
  asio::post(executor_, [self = shared_from_this(), i = std::move(images)]() mutable {
    self->on_horizons(std::move(i));
  });
}

void Replicator::committed(std::uint64_t tick, std::vector<VersionPtr> changed) {
  asio::post(executor_, [self = shared_from_this(), tick, c = std::move(changed)]() mutable {
    self->on_committed(tick, std::move(c));
  });
}

void Replicator::mips_changed(std::uint64_t tick, std::vector<VersionPtr> changed) {
  asio::post(executor_, [self = shared_from_this(), tick, c = std::move(changed)]() mutable {
    self->on_committed(tick, std::move(c), true);
  });
}

void Replicator::answer(WorldAnswer answer) {
  // The frame is made here, on the client's strand, after what the world
  // posted before (a tick's changes before its ack).
  asio::post(executor_, [self = shared_from_this(), a = std::move(answer)] {
    if (self->session_) self->session_->send(answer_frame(a), answer_send_class(a));
  });
}

void Replicator::close(CloseReason why, const std::string& text) {
  if (auto s = weak_session_.lock()) s->close(why, text);
}

// --- messages ------------------------------------------------------------------

void Replicator::join(const std::string& name, bool identified, std::uint32_t features) {
  mip_patches_ = (features & kFeatureMipPatches) != 0 && options_.mip_patches;
  outer_horizon_ = (features & kFeatureOuterHorizon) != 0 && options_.outer_horizon;
  codec1_ = (features & kFeatureCodec2) == 0;
  out_.set_codec1(codec1_);
  edit_rate_ = TokenBucket(world_.options().edits_per_second, world_.options().edits_per_second * 2);
  outbound_ = TokenBucket(options_.outbound_bytes_per_second, options_.outbound_bytes_per_second / 4);
  name_ = name;
  joined_ = true;
  redirect_.joined(std::chrono::steady_clock::now());
  state_.position = welcome_.welcome.spawn;
  world_.join(id_, name_, shared_from_this(), identified,
              (features & kFeaturePresenceRecords) != 0 && options_.presence_records);
  hashes_.start(std::chrono::steady_clock::now());
  arm_timer();
}

void Replicator::closed() {
  if (closed_) return;
  closed_ = true;
  if (timer_) timer_->cancel();
  if (joined_) {
    // Everything held or asked for, so nothing stays registered.
    std::vector<Vec3i> all;
    for (const auto& [cp, s] : slots_)
      if (s.held() || s.request()) all.push_back(cp);
    world_.release(id_, std::move(all));
    world_.leave(id_);
  }
  slots_.clear();
  horizon_.clear();
  session_.reset();  // breaks the cycle with the session's callbacks
}

bool Replicator::move(const ClientStateMsg& state) {
  const auto now = std::chrono::steady_clock::now();
  const double allowed = move_limit_.allowed(now);
  if (const auto d = move_limit_.too_far(state_.position, state.position, now)) {
    counters_.limit_violations.fetch_add(1, std::memory_order_relaxed);
    violations().warn("session " + std::to_string(id_) + " (" + name_ + "): moved " +
                      std::to_string(static_cast<long long>(*d)) + " voxels at once; dropping");
    // A budget, not a speed: what this move was allowed, and why.
    session_->close(CloseReason::kMovingTooFast,
                    fmt::format("moving too fast: moved {:.0f} voxels at once, over the {:.0f} allowed then (the "
                                "budget: {:.0f} voxels a second since the last move, plus {:.0f})",
                                *d, allowed, move_limit_.max_speed(), kSpeedSlackVoxels));
    return false;
  }
  // 0 asks for the server's default; everything is capped.
  state_ = state;
  const std::int32_t view = state.view_distance == 0 ? options_.default_view_distance : state.view_distance;
  const std::int32_t full = state.full_res_radius == 0 ? options_.default_full_res_radius : state.full_res_radius;
  state_.view_distance = std::min(view, options_.max_view_distance);
  state_.full_res_radius = std::min({full, options_.max_full_res_radius, state_.view_distance});
  world_.moved(id_, state_.position, state_.view_distance, state_.full_res_radius);
  const Vec3i c = view_chunk(state_.position);
  const Vec3i center_before = plan_.center();
  const bool new_plan = !plan_.valid() || plan_.table().view_distance() != state_.view_distance ||
                        plan_.table().full_res_radius() != state_.full_res_radius;
  if (new_plan) {
    replan();
  } else if (c != plan_.center()) {
    const Vec3i d = c - plan_.center();
    if (std::abs(d.x) <= 1 && std::abs(d.y) <= 1 && std::abs(d.z) <= 1)
      move_by(d);
    else
      replan();
  }
  // Only a new centre or radii bring chunks within full resolution.
  if (new_plan || c != center_before) send_parked_near();
  maybe_redirect();
  pump();
  return true;
}

void Replicator::maybe_redirect() {
  const auto move = redirect_.check(state_.position, std::chrono::steady_clock::now());
  if (!move) return;
  counters_.redirects_sent.fetch_add(1, std::memory_order_relaxed);
  server_log().info("session {} ({}): redirected to {}, which writes region ({},{},{})", id_, name_,
                    redirect_.target(), move->region.x, move->region.y, move->region.z);
  flush_stream();
  // In order with the data: everything sent before it is the client's to keep.
  session_->send(build_redirect(RedirectMsg{move->to.id, move->to.host, move->to.port,
                                            std::to_string(welcome_.welcome.server_id) + "/" + std::to_string(id_)}));
}

void Replicator::send_parked_near() {
  if (slots_.mips_pending() == 0) return;
  std::vector<Vec3i> near;
  for (const Vec3i cp : mips_.order()) {
    const ChunkSlot* s = slots_.find(cp);
    if (s == nullptr || !s->mip_pending()) continue;
    const auto h = s->held();
    if (h && h->form == HoldingForm::kEmpty && plan_.desired(cp) == 0) near.push_back(cp);
  }
  for (const Vec3i cp : near) {
    // A copy of the pointer: send_whole drops the change it comes from.
    const ChunkSlot* s = slots_.find(cp);
    if (s == nullptr || !s->mip_pending()) continue;  // listed twice
    send_whole(cp, VersionPtr(s->mip_pending()));
  }
}

void Replicator::send_whole(Vec3i cp, const VersionPtr& v) {
  send_chunk(v, 0);
  hold(cp, Holding{form_sent(*v, 0), v->revision()}, v);
  slots_.change_if(cp, [](ChunkSlot& s) { s.take_mip(); });  // older than v: nothing left to refresh
  if (slots_.mips_pending() == 0) mips_.forget();
}

void Replicator::edit(EditRequestMsg edit) {
  if (!edit_rate_.take(1)) {
    counters_.limit_violations.fetch_add(1, std::memory_order_relaxed);
    violations().warn("session " + std::to_string(id_) + " (" + name_ + "): edit flood; dropping");
    session_->close(CloseReason::kEditRate, "edit rate limit: more than " + std::to_string(static_cast<long long>(world_.options().edits_per_second)) +
                    " edits/s");
    return;
  }
  if (is_history_edit(edit.kind)) return world_.edit(id_, std::move(edit));
  // Only materials the world defines (the Welcome's table).
  const std::size_t defined = welcome_.welcome.materials.size();
  Material unknown = kAir;
  if ((edit.kind == EditKind::kFillBox || edit.kind == EditKind::kFillSphere || edit.kind == EditKind::kPaint) &&
      edit.material >= defined)
    unknown = edit.material;
  if (edit.kind == EditKind::kWriteBox)
    for (const Voxel v : edit.voxels)
      if (v.material >= defined) {
        unknown = v.material;
        break;
      }
  if (unknown != kAir)
    return world_.refuse(id_, std::move(edit), RejectReason::kUnknownMaterial,
                         "unknown material " + std::to_string(unknown) + ": this world defines " +
                             std::to_string(defined) + " (0.." + std::to_string(defined - 1) + ")");
  if (edit.bounds().volume() > options_.max_edit_voxels)
    return world_.refuse(id_, std::move(edit), RejectReason::kTooLarge, "edit larger than " + std::to_string(options_.max_edit_voxels) + " voxels");
  const Region r = welcome_.bounds.clamp(edit.reads());
  if (r.empty()) return world_.refuse(id_, std::move(edit), RejectReason::kOutsideWorld, "edit outside the world");
  // Edits are valid only where the client holds the world at full
  // resolution: it can see what it changes. A resuming client's claims
  // count within its full-resolution radius: the edits it queued while
  // away come right after its Holdings, before the claims are checked.
  bool full = true;
  for_each_chunk_in(r, [&](Vec3i cp) {
    if (!full) return;
    const ChunkSlot* s = slots_.find(cp);
    if (s != nullptr && s->held()) {
      full = s->held()->full_resolution();
    } else {
      full = s != nullptr && s->claim() && s->claim()->full_resolution() && plan_.valid() && plan_.desired(cp) == 0;
    }
  });
  if (!full) return world_.refuse(id_, std::move(edit), RejectReason::kOutsideFullRes, "edit outside the full-resolution region");
  world_.edit(id_, std::move(edit));
}

void Replicator::read_box(const ReadBoxMsg& req) {
  // Only chunks the client holds (at any resolution): a read must never make
  // the server load chunks nobody is looking at.
  bool held = true;
  for_each_chunk_in(req.box, [&](Vec3i cp) { held = held && slots_.holds(cp); });
  if (!held) {
    session_->send(build_read_box_error(req.request_id, req.box, "box outside the chunks this client holds"));
    return;
  }
  flush_stream();  // the result follows every record already sent
  world_.read_box(id_, req);
}

void Replicator::holdings(const HoldingsMsg& held) {
  // Another world's chunks (a client kept them from a server of another
  // world on this address): equal revisions say nothing of their voxels.
  if (held.world_id != 0 && held.world_id != welcome_.welcome.world_id) return;
  for (const HeldChunkMsg& c : held.chunks) {
    if (slots_.claims() >= options_.max_claims_per_client) break;
    if (slots_.holds(c.chunk_pos)) continue;  // already streamed this session
    slots_.change(c.chunk_pos, [&](ChunkSlot& s) { s.set_claim(c.holding); });
  }
  // Claims outside the view are released at the next plan.
  if (plan_.valid()) {
    replan();
    pump();
  }
}

void Replicator::hash_request(Vec3i cp) {
  // Only chunks this client holds: a hash request must not make the server
  // load or generate arbitrary chunks.
  const ChunkSlot* s = slots_.find(cp);
  if (s == nullptr || (!s->held() && !s->claim() && !s->request())) return;
  if (!s->held()) {
    // Claimed by a resuming client but not yet adopted or resent: answered
    // once it is, so the hash follows the data it describes.
    if (hash_requests_.size() >= 1024) {
      session_->close(CloseReason::kRequestRate, "too many chunk hash requests");
      return;
    }
    hash_requests_.push_back(cp);
    return;
  }
  answer_hash(cp);
}

void Replicator::answer_hash(Vec3i cp) {
  const ChunkSlot& s = *slots_.find(cp);
  const Holding h = *s.held();
  if (h.form == HoldingForm::kEmpty) {
    flush_stream();
    session_->send(build_chunk_hash(ChunkHashMsg{cp, h.revision, chunk_hash(nullptr, h.revision)}));
  } else if (const VersionPtr& v = s.full()) {
    flush_stream();
    session_->send(build_chunk_hash(ChunkHashMsg{cp, v->revision(), v->hash()}));
  } else {
    flush_stream();
    world_.hash(id_, cp);  // a mip holder: the world has the chunk
  }
}

// --- the plan ------------------------------------------------------------------

bool Replicator::needs_refining(Vec3i cp) const {
  const ChunkSlot* s = slots_.find(cp);
  const auto h = s != nullptr ? s->held() : std::nullopt;
  // (Beyond the view plan_.desired() is kMipLevels: nothing is finer.)
  return h && h->form != HoldingForm::kEmpty && plan_.desired(cp) < h->level();
}

void Replicator::release_outside_view() {
  // (A slot with only a change for the refresh of mips has nothing to
  // leave: leave() leaves it be.)
  std::vector<Vec3i> leaving;
  for (const auto& [cp, s] : slots_)
    if (!plan_.in_view(cp)) leaving.push_back(cp);
  std::vector<Vec3i> released;
  for (const Vec3i cp : leaving) leave(cp, released);
  if (!released.empty()) world_.release(id_, std::move(released));
}

void Replicator::leave(Vec3i cp, std::vector<Vec3i>& released) {
  ChunkSlot::Left left;
  if (!slots_.change_if(cp, [&](ChunkSlot& s) { left = s.leave(); })) return;
  if (left.claim) stream(StreamRecordKind::kReleased, cp, *left.claim);
  if (left.had) stream(StreamRecordKind::kReleased, cp, *left.had);
  // (A request still on its way is cancelled: its grant comes to nothing, on_granted.)
  if (left.registered) released.push_back(cp);
}

void Replicator::replan() {
  plan_.reset(state_.view_distance, state_.full_res_radius, kKeepMargin, view_chunk(state_.position));
  release_outside_view();
  std::vector<Vec3i> refine;
  std::vector<Vec3i> now_full;  // held Empty, within full resolution
  for (const auto& [cp, s] : slots_) {
    const auto h = s.held();
    if (!h) continue;
    if (h->form != HoldingForm::kEmpty && plan_.desired(cp) < h->level())
      refine.push_back(cp);
    if (h->form == HoldingForm::kEmpty && plan_.desired(cp) == 0) now_full.push_back(cp);
  }
  if (!now_full.empty()) world_.holds_full(id_, std::move(now_full));
  plan_.refill_refine(refine);
  plan_horizon();
  flush_stream();
}

void Replicator::plan_horizon() {
  horizon_.clear();
  if (!options_.horizon_images) return;
  // Each region with a chunk in view that the client has nothing of, nearest
  // first (the table's order: a region's first chunk met is about its
  // nearest), at 2^3 per chunk when that chunk is within a quarter of the
  // view distance, else 1 voxel per chunk; to a client that takes level 6,
  // 2^3 per chunk only within kHorizonNearMax too, and beyond
  // kHorizonFarMax 1 voxel per 2^3 chunks.
  std::int64_t near = state_.view_distance / 4;
  std::int64_t far = std::numeric_limits<std::int32_t>::max();
  if (outer_horizon_) {
    near = std::min(near, kHorizonNearMax);
    far = kHorizonFarMax;
  }
  std::vector<HorizonWant> wants;
  const auto regions = plan_.unknown_regions([this](Vec3i region) { return slots_.any_in_region(region); },
                                             [this](Vec3i cp) { return slots_.known(cp); });
  for (const ViewPlan::RegionStart& r : regions) {
    const std::int64_t d2 = offset_dist2(r.first - plan_.center());
    const int level = d2 <= near * near ? kHorizonNearLevel : d2 <= far * far ? kHorizonFarLevel : kHorizonOuterLevel;
    if (horizon_.want(r.region, level)) wants.push_back(HorizonWant{r.region, level});
  }
  if (!wants.empty()) world_.want_horizon(id_, std::move(wants));
}

void Replicator::on_horizons(std::vector<HorizonPtr> images) {
  if (closed_) return;
  // The world hands images over as they are made (in parallel, some kept
  // from before): they wait here for their turn, so the client gets them
  // nearest region first.
  horizon_.arrive(std::move(images), [this](const HorizonPtr& image) { send_horizon(image); });
  if (!horizon_.waiting()) flush_stream();
  pump();
}

void Replicator::send_horizon(const HorizonPtr& shared) {
  const HorizonImage& image = *shared;
  if (image.unit.empty()) return;  // not made: the chunks' own records follow
  const int level = image.level;
  // The region's chunks in view that the client has nothing of yet.
  HorizonMask mask = plan_.in_view_mask(image.region);
  const std::size_t covered = slots_.see_images(image.region, mask, level);
  if (covered == 0) return;
  counters_.horizons_sent.fetch_add(1, std::memory_order_relaxed);
  out_.horizon(image.region, level, covered == kHorizonRegionSlots ? nullptr : &mask, image.unit, shared);
}

void Replicator::move_by(Vec3i d) {
  const Vec3i old = plan_.center();
  plan_.shift(d);
  std::vector<Vec3i> released;
  // Released only beyond the view and its margin: a client stepping back
  // and forth across a chunk's edge does not release and ask again the
  // shell of the view each time.
  for (const Vec3i o : plan_.keep_table().leaving(d)) leave(old + o, released);
  if (!released.empty()) world_.release(id_, std::move(released));
  std::vector<Vec3i> now_full;  // held Empty, now within full resolution
  const ViewTable& table = plan_.table();
  for (const Vec3i o : table.finer(d)) {
    const Vec3i cp = plan_.center() + o;
    const ChunkSlot* s = slots_.find(cp);
    const auto h = s != nullptr ? s->held() : std::nullopt;
    if (!h) continue;
    if (h->form != HoldingForm::kEmpty && table.level(o) < h->level()) plan_.push_refine(cp);
    if (h->form == HoldingForm::kEmpty && table.level(o) == 0) now_full.push_back(cp);
  }
  if (!now_full.empty()) world_.holds_full(id_, std::move(now_full));
  flush_stream();
}

// --- streaming -----------------------------------------------------------------

void Replicator::pump() {
  if (!joined_ || !plan_.valid() || closed_) return;
  if (redirect_.redirected()) return flush_stream();  // the client goes on elsewhere: nothing more to stream
  if (yield_.streaming_waits(std::chrono::steady_clock::now())) {
    // The server is behind: live traffic first; the timer pumps again.
    flush_stream();
    arm_timer();
    return;
  }
  send_ready();
  request_more();
  flush_stream();
}

void Replicator::request_more() {
  // The horizon images first: chunks' own records wait until all are sent.
  if (horizon_.waiting()) return;
  if (slots_.requests() + ready_.size() >= kMaxRequests) return;
  std::vector<ChunkWant> wants;
  auto want = [&](Vec3i cp, ChunkIntent intent, int level, bool exact = false) {
    slots_.change(cp, [&](ChunkSlot& s) { s.ask(ChunkRequest{intent, level}); });
    // Held at full resolution: sent so, or (all Air) sent Empty where the
    // plan wants full resolution.
    wants.push_back(ChunkWant{cp, level == 0 || plan_.desired(cp) == 0, level, exact});
  };
  auto room = [&] { return slots_.requests() + ready_.size() < kMaxRequests; };
  // Pass 1: the whole view at its coarsest, nearest first. With horizon
  // images the client sees the whole view already: a chunk within full
  // resolution is sent at full resolution at once instead (its 4^3 mip
  // would be replaced moments later).
  auto coarse = [&](Vec3i cp) {
    if (!plan_.in_view(cp)) return;
    const ChunkSlot* s = slots_.find(cp);
    if (s != nullptr && (s->held() || s->request())) return;
    if (s != nullptr && s->claim()) {
      const Holding c = *s->claim();
      const bool empty = c.form == HoldingForm::kEmpty;
      // A claim of Empty is checked against the chunk's own emptiness (an
      // estimate is never Empty; without estimates the coarse image says);
      // a claimed mip's revision says enough.
      return want(cp, ChunkIntent::kClaim, empty ? kMipLevels - 1 : c.level(), empty && options_.horizon_estimates);
    }
    want(cp, ChunkIntent::kCoarse, options_.horizon_images && plan_.desired(cp) == 0 ? 0 : kMipLevels - 1);
  };
  while (room()) {
    const auto cp = plan_.next_coarse();
    if (!cp) break;
    coarse(*cp);
  }
  // Pass 2: refine nearest first, once the coarse view is complete (asked
  // for and sent: a grant waiting for a load would otherwise be overtaken).
  const bool coarse_done = plan_.coarse_walked() && slots_.coarse_pass_requests() == 0;
  const auto needs = [this](Vec3i cp) { return needs_refining(cp); };
  while (coarse_done && room()) {
    const auto next = plan_.pop_refine(needs);
    if (!next) break;
    const Vec3i cp = *next;
    if (const ChunkSlot* s = slots_.find(cp); (s != nullptr && s->request()) || !needs_refining(cp)) continue;
    want(cp, ChunkIntent::kRefine, plan_.desired(cp));
  }
  if (!wants.empty()) {
    counters_.chunks_asked.fetch_add(wants.size(), std::memory_order_relaxed);
    world_.want(id_, std::move(wants));
  }
}

void Replicator::on_granted(std::vector<VersionPtr> versions) {
  if (closed_) return;
  std::vector<Vec3i> unwanted;
  for (VersionPtr& v : versions) {
    const Vec3i cp = v->pos();
    const ChunkSlot* s = slots_.find(cp);
    const std::optional<ChunkRequest> rq = s != nullptr ? s->request() : std::nullopt;
    if (!rq || rq->cancelled || !plan_.in_view(cp)) {
      // Not wanted now. The world registered this client as a holder when
      // it granted the chunk, after any release the client had sent for
      // it: it is released again.
      if (rq) slots_.change_if(cp, [](ChunkSlot& slot) { slot.take_request(); });
      if (slots_.holds(cp)) continue;
      unwanted.push_back(cp);
      // It left the view and came back while this grant was on its way
      // (the coarse pass passed it over, as asked for): asked again, after
      // the release.
      if (rq && rq->cancelled && plan_.in_view(cp)) plan_.enter_again(cp);
      continue;
    }
    bool kept = false;
    slots_.change_if(cp, [&](ChunkSlot& slot) { kept = slot.set_ready(std::move(v)); });
    if (kept) ready_.push_back(cp);
  }
  if (!unwanted.empty()) world_.release(id_, std::move(unwanted));
  pump();
}

void Replicator::send_ready() {
  const auto now = std::chrono::steady_clock::now();
  const double budget = outbound_.unlimited() ? 1e18 : outbound_.available(now);
  const std::size_t queued = session_->queued_bytes();
  auto room = [&] {
    return budget > 0 && queued + out_.pending_bytes() < options_.stream_window_bytes &&
           static_cast<double>(out_.pending_bytes()) < budget;
  };
  while (!ready_.empty() && room()) {
    const Vec3i cp = ready_.front();
    ready_.pop_front();
    // The grant and its request leave the slot together (an entry left by
    // a chunk that left the view finds neither, or a request asked since,
    // dropped with it; its grant is then released as unwanted).
    VersionPtr v;
    std::optional<ChunkRequest> req;
    std::optional<Holding> claim;
    slots_.change_if(cp, [&](ChunkSlot& s) {
      v = s.take_ready();
      req = s.take_request();
      if (v && req && req->intent == ChunkIntent::kClaim) claim = s.take_claim();
    });
    if (!v || !req) continue;
    if (req->intent == ChunkIntent::kClaim) {
      // Same revision means same voxels: revisions of a stored chunk only
      // grow, and a never-stored chunk (revision 0) is what the generator
      // makes.
      if (claim && claim->revision == v->revision() && (claim->form == HoldingForm::kEmpty) == v->empty()) {
        hold(cp, *claim, v);
        counters_.chunks_resumed.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      send_chunk(v, kMipLevels - 1);
      hold(cp, Holding{form_sent(*v, kMipLevels - 1), v->revision()}, v);
      continue;
    }
    send_chunk(v, req->level);
    hold(cp, Holding{form_sent(*v, req->level), v->revision()}, v);
  }
  if (!ready_.empty()) arm_timer();
}

void Replicator::send_chunk(const VersionPtr& version, int level) {
  const ChunkVersion& v = *version;
  if (v.empty()) {
    stream(StreamRecordKind::kEmpty, v.pos(), v.revision());
    counters_.empties_sent.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (v.estimate()) {
    // Only level 3 exists of an estimate (the world grants it for no finer).
    stream(StreamRecordKind::kEstimate, v.pos(), v.revision(), v.encoded(kMipLevels - 1), version);
    counters_.estimates_sent.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  stream(record_kind(level), v.pos(), v.revision(), v.encoded(level), version);
  (level == 0 ? counters_.chunks_sent : counters_.mips_sent).fetch_add(1, std::memory_order_relaxed);
}

void Replicator::hold(Vec3i cp, Holding h, const VersionPtr& v) {
  bool new_full = false;
  slots_.change(cp, [&](ChunkSlot& s) { new_full = s.hold(h, v); });
  if (new_full) hashes_.add(cp);
  if (h.form != HoldingForm::kFull && h.form != HoldingForm::kEmpty && plan_.desired(cp) < h.level()) plan_.push_refine(cp);
  // Hash requests waiting for this chunk.
  if (!hash_requests_.empty()) {
    auto it = std::find(hash_requests_.begin(), hash_requests_.end(), cp);
    if (it != hash_requests_.end()) {
      hash_requests_.erase(it);
      answer_hash(cp);
    }
  }
}

void Replicator::on_committed(std::uint64_t tick, std::vector<VersionPtr> changed, bool mips_due) {
  if (closed_) return;
  TickUpdate update;  // the units of chunks held at full resolution
  const bool mips_were_dirty = slots_.mips_pending() != 0;
  if (mips_due) {
    // Gathered over several ticks: a chunk may come more than once; its
    // newest version is all that counts (and one piece per chunk goes in
    // an UpdateBatch).
    std::sort(changed.begin(), changed.end(), [](const VersionPtr& a, const VersionPtr& b) {
      const Vec3i u = a->pos(), w = b->pos();
      return std::make_tuple(u.x, u.y, u.z, b->revision()) < std::make_tuple(w.x, w.y, w.z, a->revision());
    });
    changed.erase(std::unique(changed.begin(), changed.end(),
                              [](const VersionPtr& a, const VersionPtr& b) { return a->pos() == b->pos(); }),
                  changed.end());
  }
  for (VersionPtr& v : changed) {
    const Vec3i cp = v->pos();
    const ChunkSlot* s = slots_.find(cp);
    if (s == nullptr) continue;
    // Granted, not sent yet: the newest is sent.
    if (s->ready()) {
      slots_.change_if(cp, [&](ChunkSlot& slot) { slot.refresh_ready(v); });
      continue;
    }
    if (!s->held()) continue;
    const Holding h = *s->held();
    // Gathered news may be older than a grant since (refresh_mip checks
    // the levels it refreshes).
    if (mips_due && v->revision() <= h.revision && h.full_resolution()) continue;
    const bool near = plan_.desired(cp) == 0;
    // A tick's units change the version before it (revision - 1): they are
    // sent only to a client holding exactly that. Anything else is sent
    // whole: a chunk loaded again at another revision (a damaged row
    // quarantined; no units), or any holder left behind the units' base (a
    // chunk held Empty with a change parked for the refresh of mips was
    // one, before moves sent those whole: send_parked_near).
    const bool holds_base = v->changed_units().any() && h.revision + 1 == v->revision();
    const bool full = h.form == HoldingForm::kFull || (h.form == HoldingForm::kEmpty && near);
    if (full && !holds_base) {
      flush_stream();
      send_whole(cp, v);
      continue;
    }
    if (full) {
      // (Its version kept for hashes unless all Air.)
      bool new_full = false;
      const Holding now_full{HoldingForm::kFull, v->revision()};
      slots_.change_if(cp, [&](ChunkSlot& slot) { new_full = slot.hold(now_full, v); });
      if (new_full) hashes_.add(cp);
      update.add(std::move(v));
      continue;
    }
    // A chunk held coarser than full resolution: refreshed with the next
    // flush of mips, the newest version by then (changes coalesce).
    const std::chrono::milliseconds refresh_after(world_.options().mip_refresh_ms);
    if (refresh_after.count() == 0) {
      refresh_mip(cp, v);
    } else {
      if (slots_.mips_pending() == 0) {
        mips_.first_change(std::chrono::steady_clock::now() + refresh_after);
      }
      bool first = false;
      slots_.change_if(cp, [&](ChunkSlot& slot) { first = slot.park_mip(std::move(v)); });
      if (first) mips_.add(cp);
    }
  }
  if (mips_due && slots_.mips_pending() != 0) {
    // Due now (the world waited for them): the oldest change's time kept.
    const auto now = std::chrono::steady_clock::now();
    mips_.due_now(now, !mips_were_dirty);
    flush_mips_when_due(now);
  }
  // Records first, so an update never overtakes the data it applies to.
  flush_stream();
  std::size_t units = 0;
  if (auto frame = update.empty() ? std::nullopt : update.finish(tick, faults_, units, codec1_)) {
    session_->send(std::move(*frame));
    counters_.update_batches_sent.fetch_add(1, std::memory_order_relaxed);
    counters_.update_units_sent.fetch_add(units, std::memory_order_relaxed);
  }
  counters_.tick_frames.fetch_add(1, std::memory_order_relaxed);
  pump();
  if (slots_.mips_pending() != 0) arm_timer();
}

void Replicator::refresh_mip(Vec3i cp, const VersionPtr& v) {
  const ChunkSlot* s = slots_.find(cp);
  if (s == nullptr || !s->held()) return;
  const Holding h = *s->held();
  if (h.form == HoldingForm::kFull || v->estimate()) return;
  // Refined since, with newer data (an estimate is replaced by the chunk's
  // mip at the same revision: the world tells only when the two differ).
  if (h.revision >= v->revision() && h.form != HoldingForm::kEstimate) return;
  if (v->empty()) {
    // Sent even to a holder of Empty: its revision must move on too (a
    // chunk changed and emptied again between two flushes of mips looks
    // unchanged to it, and its hash would never match again).
    stream(StreamRecordKind::kEmpty, cp, v->revision());
    slots_.change_if(cp, [&](ChunkSlot& slot) { slot.hold(Holding{HoldingForm::kEmpty, v->revision()}, v); });
    return;
  }
  const int level = h.form == HoldingForm::kEmpty ? kMipLevels - 1 : h.level();
  if (h.mip() && v->level_since(level) <= h.revision) {
    // The level held did not change: nothing to tell the client.
    counters_.refreshes_skipped.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (mip_patches_ && level < kMipLevels - 1 && h.form == mip_form(level) && out_.mip_patch(cp, level, h.revision, *v))
    counters_.mip_patches.fetch_add(1, std::memory_order_relaxed);  // (the changed sub-units only)
  else
    stream(record_kind(level), cp, v->revision(), v->encoded(level), v);
  counters_.mip_refreshes.fetch_add(1, std::memory_order_relaxed);
  slots_.change_if(cp, [&](ChunkSlot& slot) { slot.hold(Holding{mip_form(level), v->revision()}, v); });
  if (plan_.desired(cp) < level) plan_.push_refine(cp);
}

void Replicator::flush_mips() {
  // In the order of their first change; a chunk listed twice (its change
  // sent whole, then parked again) once.
  for (const Vec3i cp : mips_.take()) {
    VersionPtr v;
    slots_.change_if(cp, [&](ChunkSlot& s) { v = s.take_mip(); });
    if (v) refresh_mip(cp, v);
  }
  flush_stream();
}

void Replicator::flush_mips_when_due(std::chrono::steady_clock::time_point now) {
  if (slots_.mips_pending() == 0 || now < mips_.next_flush()) return;
  // Refreshes of mips are streaming too: while the gate is closed they
  // wait (and coalesce), kYieldAtMost past their time at most.
  if (yield_.mips_wait(now, mips_.due()))
    mips_.put_off(yield_.retry_at(now));
  else
    flush_mips();
}

void Replicator::flush_stream() { out_.flush(); }

void Replicator::drained() {
  if (closed_) return;
  pump();
}

// --- timer: budget retries and pushed hashes ---------------------------------------

void Replicator::arm_timer() {
  if (closed_) return;
  // Soon while granted chunks wait for room in the window or budget;
  // otherwise at the next mip flush or pushed hash.
  const auto now = std::chrono::steady_clock::now();
  auto at = std::chrono::steady_clock::time_point::max();
  if (!ready_.empty()) at = now + kPumpRetry;
  if (yield_.yielding()) at = std::min(at, yield_.retry_at(now));
  if (slots_.mips_pending() != 0) at = std::min(at, mips_.next_flush());
  // Hashes are pushed only once there is a plan (a first ClientState): a
  // session that never sends one (terrane-admin) must not wake for them.
  if (plan_.valid()) at = std::min(at, hashes_.next_push());
  // In a shared world: whether the client stands in another server's
  // region is checked again each second (the map of writers changes), and
  // a redirected client that has not gone is served again after its grace.
  at = std::min(at, redirect_.next_wake(now, plan_.valid()));
  if (at == std::chrono::steady_clock::time_point::max()) return;
  if (timer_armed_) {
    if (timer_->expiry() <= at) return;
    timer_->cancel();  // re-armed sooner below (the cancelled wait sees operation_aborted)
  }
  timer_armed_ = true;
  timer_->expires_at(at);
  timer_->async_wait([self = shared_from_this(), at](const asio::error_code& ec) {
    if (ec || self->closed_) return;
    if (self->timer_->expiry() != at) return;  // superseded
    self->timer_armed_ = false;
    self->on_timer();
  });
}

void Replicator::on_timer() {
  const auto now = std::chrono::steady_clock::now();
  if (redirect_.expire(now))
    server_log().info("session {} ({}): did not go to {}; served here again", id_, name_, redirect_.target());
  if (plan_.valid()) maybe_redirect();
  flush_mips_when_due(now);
  // The next chunk this client holds at full resolution.
  const auto full = [this](Vec3i cp) {
    const ChunkSlot* s = slots_.find(cp);
    return s != nullptr ? s->full() : nullptr;
  };
  const auto next = plan_.valid() && hashes_.due(now) ? hashes_.next(full) : std::nullopt;
  if (next) {
    const auto& [cp, v] = *next;
    flush_stream();
    session_->send(build_chunk_hash(ChunkHashMsg{cp, v->revision(), v->hash()}));
    counters_.hashes_pushed.fetch_add(1, std::memory_order_relaxed);
  }
  pump();
  arm_timer();
}

}  // namespace terrane
