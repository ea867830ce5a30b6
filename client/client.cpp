#include "client/client.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "client/client_log.h"

namespace terrane {

const char* message_type_name(std::size_t type) {
  if (type >= kMessageTypeCount) return "unknown";
  return wire::EnumNameBody(static_cast<wire::Body>(type));
}

const char* byte_cause_name(std::size_t cause) {
  static constexpr const char* kNames[kByteCauseCount] = {"stream",   "refresh",   "update", "presence",
                                                          "hash",     "keepalive", "other"};
  return cause < kByteCauseCount ? kNames[cause] : "unknown";
}

namespace {
// The cause of a whole frame of this type (StreamBatch: split by record).
ByteCause frame_cause(wire::Body type) {
  switch (type) {
    case wire::Body::StreamBatch: return ByteCause::kStream;
    case wire::Body::UpdateBatch: return ByteCause::kUpdate;
    case wire::Body::Presence:
    case wire::Body::PresenceRecords: return ByteCause::kPresence;
    case wire::Body::ChunkHash: return ByteCause::kHash;
    case wire::Body::Ping:
    case wire::Body::Pong: return ByteCause::kKeepalive;
    default: return ByteCause::kOther;
  }
}
}  // namespace

Client::Client(ClientOptions options, ClientCallbacks callbacks)
    : options_(std::move(options)),
      callbacks_(std::move(callbacks)),
      movement_(options_),
      connection_(options_, *this) {
  set_up(replica_);
}

void Client::set_up(Replica& r) const {
  r.share_decoded(options_.shared_chunks);
  r.set_full_chunk_mips(options_.full_chunk_mips);
}

Client::~Client() { disconnect(); }

bool Client::connect(std::string* error) {
  {
    std::lock_guard lock(mutex_);
    movement_.start();
  }
  return connection_.connect(error);
}

void Client::disconnect() {
  connection_.disconnect();
  save_cache();
}

bool Client::save_cache() {
  if (!options_.chunk_cache) return false;
  std::lock_guard lock(mutex_);
  if (!welcome_ || welcome_->world_id == 0 || cache_saved_) return false;
  cache_saved_ = true;
  // A chunk whose hash did not match the server's is not kept: the next
  // session would claim it at the same revision.
  const auto saved = save_replica(*options_.chunk_cache, welcome_->world_id, replica_, [&](Vec3i cp) {
    const auto it = hash_checks_.find(cp);
    return it != hash_checks_.end() && !it->second;
  });
  if (!saved) {
    client_log().warn("'{}': chunk cache {}: a region could not be written", options_.name,
                      options_.chunk_cache->dir());
    return false;
  }
  counters_.cache_chunks_saved += *saved;
  return true;
}

bool Client::start_cache_load(const WelcomeMsg& w) {
  const auto view = movement_.view(w);
  if (w.world_id == 0 || !view) return false;
  // Reading and decoding the files is the cache's threads' work: on the io
  // side it would hold up every client sharing it (the bots). The token
  // keeps the io side from finishing (disconnect() waits) until the answer
  // is posted back.
  options_.chunk_cache->post([this, id = w.world_id, view = *view, bounds = w.bounds(), session = sessions_,
                              work = std::make_shared<Connection::OffsideWork>(connection_.offside_work())] {
    auto loaded = std::make_shared<Replica>();
    set_up(*loaded);
    const std::size_t chunks = load_view(*options_.chunk_cache, id, view, bounds, *loaded);
    connection_.post([this, loaded, chunks, session] { loaded_cache(std::move(*loaded), chunks, session); });
  });
  return true;
}

void Client::loaded_cache(Replica loaded, std::size_t chunks, std::uint64_t session) {
  std::unique_lock lock(mutex_);
  // A reconnect since sent the replica's claims and the position itself.
  if (session != sessions_ || !state_held_) return;
  state_held_ = false;
  // Nothing is streamed before the first position: the replica holds
  // nothing of this session's world yet. (Dropped meanwhile: the reconnect
  // claims what it holds now.)
  replica_ = std::move(loaded);
  counters_.cache_chunks_loaded += chunks;
  std::vector<Frame> claims;
  std::optional<Frame> state;
  if (linked_) {
    claims = claim_frames();
    state = movement_.session_frame();
  }
  std::vector<HoldingChange> changes;
  std::vector<Vec3i> full;
  if (tells_holdings() || callbacks_.on_chunks_loaded)
    replica_.for_each_holding([&](Vec3i cp, const Holding& h) {
      changes.push_back(HoldingChange{cp, h});
      if (h.full_resolution()) full.push_back(cp);
    });
  // Sent under the lock (send only queues): a position the application
  // sets from now on goes after them.
  for (Frame& f : claims) connection_.send(std::move(f), wire::Body::Holdings);
  if (state) connection_.send(std::move(*state), wire::Body::ClientState);
  lock.unlock();
  changed_.notify_all();
  tell_holdings(changes);
  if (callbacks_.on_chunks_loaded && !full.empty()) callbacks_.on_chunks_loaded(full);
}

void Client::tell_holdings(std::span<const HoldingChange> changes) const {
  if (changes.empty()) return;
  if (callbacks_.on_holding)
    for (const HoldingChange& c : changes) callbacks_.on_holding(c.chunk_pos, c.now ? &*c.now : nullptr);
  if (callbacks_.on_holdings) callbacks_.on_holdings(changes);
}

std::vector<Frame> Client::claim_frames() {
  std::vector<HeldChunkMsg> held;
  replica_.for_each_holding([&](Vec3i cp, const Holding& h) {
    // Not the chunk's own voxels (an estimate, a horizon image): streamed again.
    if (claimable(h.form)) held.push_back(HeldChunkMsg{cp, h});
  });
  for (const HeldChunkMsg& c : held) unconfirmed_.insert(c.chunk_pos);
  return build_region_holdings(held, welcome_ ? welcome_->world_id : 0);
}

// --- the connection's calls (io side) ------------------------------------------

std::vector<Outbound> Client::session_frames(SessionStart start) {
  std::vector<Outbound> frames;
  std::lock_guard lock(mutex_);
  if (start == SessionStart::kReconnect) ++counters_.reconnects;
  unconfirmed_.clear();
  state_held_ = false;  // a cache load still under way sends nothing (loaded_cache)
  if (start != SessionStart::kFirst) {
    // What the replica still holds, so current chunks are not resent.
    for (Frame& f : claim_frames()) frames.push_back({std::move(f), wire::Body::Holdings});
  } else if (options_.chunk_cache && options_.stream) {
    // The first position waits for the Welcome: the world's id picks the
    // chunks kept, claimed before it (Welcome below). Positions set
    // meanwhile wait too.
    state_held_ = true;
    return frames;
  }
  if (auto state = movement_.session_frame()) frames.push_back({std::move(*state), wire::Body::ClientState});
  return frames;
}

void Client::on_bytes_read(std::size_t n) {
  std::lock_guard lock(mutex_);
  counters_.bytes_in += n;
}

void Client::on_framing_error() {
  std::lock_guard lock(mutex_);
  ++counters_.protocol_errors;
  ++counters_.by_message_type[static_cast<std::size_t>(wire::Body::NONE)].frames_in;
}

void Client::on_written(const Outbound& sent) {
  std::lock_guard lock(mutex_);
  ++counters_.frames_out;
  counters_.bytes_out += sent.frame.size();
  auto& t = counters_.by_message_type[static_cast<std::size_t>(sent.type)];
  ++t.frames_out;
  t.bytes_out += sent.frame.size();
  if (sent.edit_id != 0) edits_.written(sent.edit_id);
}

bool Client::awaiting_answers() {
  std::lock_guard lock(mutex_);
  return edits_.awaiting_written();
}

void Client::report(const SettledEdits& settled) {
  if (callbacks_.on_edit_result)
    for (const auto& [id, o] : settled) callbacks_.on_edit_result(id, o);
}

void Client::on_reconnecting(const std::string& reason) {
  SettledEdits unknown;
  {
    std::lock_guard lock(mutex_);
    linked_ = false;
    unknown = edits_.settle_unanswered();
  }
  changed_.notify_all();
  if (callbacks_.on_connection_lost) callbacks_.on_connection_lost(reason);
  report(unknown);
}

void Client::on_redirected(const RedirectMsg& to, std::uint32_t cut_edit) {
  // Edits the old server has not answered may or may not be applied.
  SettledEdits unknown;
  {
    std::lock_guard lock(mutex_);
    linked_ = false;
    if (cut_edit != 0) edits_.written(cut_edit);
    unknown = edits_.settle_written();
    ++counters_.redirects;
  }
  changed_.notify_all();
  if (callbacks_.on_redirected) callbacks_.on_redirected(to);
  report(unknown);
}

void Client::on_closed(const std::string& reason) {
  std::string r;
  // Edits sent and never answered get their outcome now: unknown.
  SettledEdits unknown;
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    if (disconnect_reason_.empty()) disconnect_reason_ = reason;
    r = disconnect_reason_;
    unknown = edits_.settle_unanswered();
  }
  changed_.notify_all();
  report(unknown);
  if (callbacks_.on_disconnected) callbacks_.on_disconnected(r);
}

namespace {
// The boxes a StreamBatch's records decode into (about 90 KiB): one set per
// thread, not per client (a process of many clients decodes on a few io
// threads, and a set per client stayed with each of them). Valid during
// one record's callback, which never decodes another batch.
thread_local StreamDecodeScratch stream_scratch;
}  // namespace

Status Client::apply_stream_batch(const wire::StreamBatch& batch, std::size_t frame_bytes,
                                  std::function<void()>* after) {
  auto records = parse_stream_batch(batch);
  if (!records) return records.error();
  // Record bytes by cause; the frame's own bytes go with the larger share.
  std::uint64_t stream_bytes = 0, refresh_bytes = 0;
  // (chunk, its holding now; nullopt: released), for on_holding(s).
  std::vector<HoldingChange> changes;
  const bool tell = tells_holdings();
  std::vector<Vec3i> loaded;  // for on_chunks_loaded
  const bool tell_loaded = static_cast<bool>(callbacks_.on_chunks_loaded);
  // A Full, Mip or Estimate record's bytes this process's replicas decoded
  // before are not decoded again (passed to decode_stream_batch below).
  KnownPayloadFn known;
  if (const std::shared_ptr<DecodedChunks>& shared = options_.shared_chunks)
    known = [&shared](StreamRecordKind kind, std::span<const std::uint8_t> rest) { return shared->known(kind, rest); };
  const auto st = decode_stream_batch(*records, stream_scratch, [&](const StreamRecord& r) -> Status {
    {
      // A refresh gives the chunk the form it already holds; anything else
      // (a new chunk, a finer form, an exact mip for an Estimate, a horizon
      // image, a release) is streaming.
      const Holding* held = gives_form(r.kind) ? replica_.holding(r.chunk_pos) : nullptr;
      const bool refresh = r.kind == StreamRecordKind::kMipPatch || (held != nullptr && held->form == r.form());
      (refresh ? refresh_bytes : stream_bytes) += r.bytes;
    }
    if (r.kind == StreamRecordKind::kMipPatch && !replica_.patchable(r))
      return DecodeError{DecodeErrorCode::kInvalidValue, 0, "stream batch: mip patch of a chunk not held as that mip"};
    if (r.kind == StreamRecordKind::kHorizon) {
      // A whole region: each chunk it newly covers is a change.
      horizon_covered_.clear();
      replica_.apply_horizon(r, horizon_covered_);
      counters_.horizon_chunks += horizon_covered_.size();
      if (tell)
        for (const Vec3i cp : horizon_covered_) changes.push_back(HoldingChange{cp, Holding{horizon_form(r.level), 0}});
      return Ok{};
    }
    if (tell_loaded && (r.kind == StreamRecordKind::kFull || r.kind == StreamRecordKind::kEmpty)) {
      const Holding* before = replica_.holding(r.chunk_pos);
      if (before == nullptr || !before->full_resolution()) loaded.push_back(r.chunk_pos);
    }
    replica_.apply_stream_record(r);
    unconfirmed_.erase(r.chunk_pos);  // streamed again (or released): current
    switch (r.kind) {
      case StreamRecordKind::kEmpty:
        ++counters_.empty_records;
        break;
      case StreamRecordKind::kReleased:
        ++counters_.released;
        break;
      case StreamRecordKind::kFull:
        ++counters_.full_records;
        counters_.chunk_units += 8;
        break;
      case StreamRecordKind::kEstimate:
        ++counters_.mips;
        ++counters_.estimates;
        break;
      case StreamRecordKind::kMipPatch:
        ++counters_.mip_patches;
        break;
      default:
        ++counters_.mips;
        break;
    }
    if (tell) {
      std::optional<Holding> now;
      if (gives_form(r.kind)) now = Holding{r.form(), r.revision};
      else if (r.kind == StreamRecordKind::kMipPatch) now = Holding{mip_form(r.level), r.revision};
      changes.push_back(HoldingChange{r.chunk_pos, now});
    }
    return Ok{};
  }, known);
  const std::uint64_t overhead = frame_bytes - std::min<std::uint64_t>(frame_bytes, stream_bytes + refresh_bytes);
  (refresh_bytes > stream_bytes ? refresh_bytes : stream_bytes) += overhead;
  counters_.bytes_in_by_cause[static_cast<std::size_t>(ByteCause::kStream)] += stream_bytes;
  counters_.bytes_in_by_cause[static_cast<std::size_t>(ByteCause::kRefresh)] += refresh_bytes;
  // Records before a bad one were applied: the replica stays consistent;
  // their changes are not reported (the connection closes).
  if (!st) return st.error();
  if (!changes.empty() || !loaded.empty())
    *after = [this, ch = std::move(changes), loaded = std::move(loaded)] {
      tell_holdings(ch);
      if (!loaded.empty()) callbacks_.on_chunks_loaded(loaded);
    };
  return Ok{};
}

void Client::on_frame(std::span<const std::uint8_t> body) {
  auto verified = verify_message(body);
  std::unique_lock lock(mutex_);
  ++counters_.frames_in;
  {
    const auto type = verified ? static_cast<std::size_t>((*verified)->body_type()) : std::size_t{0};
    auto& t = counters_.by_message_type[type < kMessageTypeCount ? type : 0];
    ++t.frames_in;
    t.bytes_in += body.size() + kFrameHeaderBytes;
    // (A StreamBatch's bytes are counted by cause as its records are read.)
    if (!verified || (*verified)->body_type() != wire::Body::StreamBatch)
      counters_.bytes_in_by_cause[static_cast<std::size_t>(
          verified ? frame_cause((*verified)->body_type()) : ByteCause::kOther)] += body.size() + kFrameHeaderBytes;
  }
  auto fail = [&](const DecodeError& e) {
    ++counters_.protocol_errors;
    lock.unlock();
    client_log().warn("'{}': bad message from server: {}", options_.name, e.describe());
    connection_.close(std::string("protocol error: ") + e.detail);
  };
  if (!verified) return fail(verified.error());
  const wire::Message& m = **verified;
  std::function<void()> after;  // callback to run without the lock
  switch (m.body_type()) {
    case wire::Body::Welcome: {
      auto w = parse_welcome(*m.body_as_Welcome());
      if (!w) return fail(w.error());
      if (w->protocol_version != kProtocolVersion)
        return fail(DecodeError{DecodeErrorCode::kBadVersion, 0, "welcome: protocol version mismatch"});
      // Another world on this address (a reconnect, a Redirect): the
      // replica's chunks are of the old one, and the new server ignored
      // their claims (Holdings.world_id); they are not its voxels.
      std::vector<HoldingChange> dropped;
      if (welcome_ && welcome_->world_id != 0 && welcome_->world_id != w->world_id) {
        if (tells_holdings())
          replica_.for_each_holding([&](Vec3i cp, const Holding&) { dropped.push_back(HoldingChange{cp, std::nullopt}); });
        replica_ = Replica();
        set_up(replica_);
        unconfirmed_.clear();
        hash_checks_.clear();
      }
      welcome_ = *w;
      cache_saved_ = false;
      // A new session's list starts empty (its first records or list name
      // every entry): the last session's entries are no longer known.
      presence_list_.clear();
      presence_.clear();
      linked_ = true;
      ++sessions_;
      server_not_returning_ = false;
      if (connection_.session() != SessionStart::kFirst) {
        if (callbacks_.on_reconnected || !dropped.empty())
          after = [this, dropped = std::move(dropped)] {
            tell_holdings(dropped);
            if (callbacks_.on_reconnected) callbacks_.on_reconnected();
          };
        break;
      }
      std::optional<Frame> state = movement_.welcomed(*w);
      if (options_.chunk_cache && options_.stream) {
        // The position was held back for the cache's claims (session_frames):
        // sent with them once loaded (loaded_cache), or now if nothing is.
        if (start_cache_load(*w)) {
          state.reset();
        } else {
          state_held_ = false;
          if (!state) state = movement_.session_frame();
        }
      }
      if (state) {
        lock.unlock();
        connection_.send(std::move(*state), wire::Body::ClientState);
        lock.lock();
      }
      if (callbacks_.on_welcome) after = [this, w = *w] { callbacks_.on_welcome(w); };
      break;
    }
    case wire::Body::Disconnect: {
      auto r = parse_disconnect(*m.body_as_Disconnect());
      const std::string reason = r ? *r : std::string("(bad reason)");
      // Only a server going away (and saying it comes back) is waited for.
      const bool may_return = reason == "server shutting down" && !server_not_returning_;
      lock.unlock();
      connection_.lost(reason, may_return);
      return;
    }
    case wire::Body::StreamBatch: {
      const auto st = apply_stream_batch(*m.body_as_StreamBatch(), body.size() + kFrameHeaderBytes, &after);
      if (!st) return fail(st.error());
      break;
    }
    case wire::Body::UpdateBatch: {
      auto b = parse_update_batch(*m.body_as_UpdateBatch());
      if (!b) return fail(b.error());
      std::vector<Region> changed;
      VoxelChanges voxels{voxel_change_cap_, {}, false};
      const bool record = callbacks_.on_update && voxel_change_cap_ > 0;
      auto n = replica_.apply_update_batch(*b, callbacks_.on_update ? &changed : nullptr, record ? &voxels : nullptr);
      if (!n) return fail(n.error());
      ++counters_.update_batches;
      counters_.units_updated += *n;
      if (callbacks_.on_update_batch || callbacks_.on_update)
        after = [this, info = UpdateInfo{b->tick, std::move(b->revisions), std::move(changed), record,
                                         std::move(voxels.changes), voxels.truncated}] {
          if (callbacks_.on_update_batch) callbacks_.on_update_batch(info.tick, info.revisions);
          if (callbacks_.on_update) callbacks_.on_update(info);
        };
      break;
    }
    case wire::Body::EditAck: {
      const auto* a = m.body_as_EditAck();
      EditOutcome o{true, a->tick(), {}, {}, {}};
      edits_.answered(a->edit_id(), o);
      ++counters_.edits_acked;
      if (callbacks_.on_edit_result) after = [this, id = a->edit_id(), o] { callbacks_.on_edit_result(id, o); };
      break;
    }
    case wire::Body::EditReject: {
      auto r = parse_edit_reject(*m.body_as_EditReject());
      if (!r) return fail(r.error());
      EditOutcome o{false, 0, std::move(r->reason), r->box, std::move(r->voxels), r->outcome_unknown};
      ++counters_.edits_rejected;
      if (callbacks_.on_edit_result) after = [this, id = r->edit_id, o] { callbacks_.on_edit_result(id, o); };
      edits_.answered(r->edit_id, std::move(o));
      break;
    }
    case wire::Body::ReadBoxResult: {
      auto r = parse_read_box_result(*m.body_as_ReadBoxResult());
      if (!r) return fail(r.error());
      ++counters_.read_results;
      // Bounded: a server cannot grow this past the ids we asked for.
      if (r->request_id == 0 || r->request_id >= next_request_id_) break;
      if (callbacks_.on_read_result) after = [this, id = r->request_id] { callbacks_.on_read_result(id); };
      read_results_[r->request_id] = std::move(*r);
      break;
    }
    case wire::Body::Presence: {
      auto p = parse_presence(*m.body_as_Presence());
      if (!p) return fail(p.error());
      // A name comes with an entry only when it enters the list
      // (PROTOCOL.md, "Presence"): the others keep the one told before.
      for (PresenceEntryMsg& e : *p)
        if (e.name.empty())
          for (const PresenceEntryMsg& before : presence_)
            if (before.client_id == e.client_id) {
              e.name = before.name;
              break;
            }
      presence_ = std::move(*p);
      ++counters_.presence_updates;
      if (callbacks_.on_presence) after = [this, p = presence_] { callbacks_.on_presence(p); };
      break;
    }
    case wire::Body::PresenceRecords: {
      auto records = decode_presence_records(parse_presence_records(*m.body_as_PresenceRecords()));
      if (!records) return fail(records.error());
      if (auto applied = presence_list_.apply(*records); !applied) return fail(applied.error());
      // Nearest first, as Presence lists them: from the position last sent
      // (the server's distances are from the last it received).
      const Vec3f from = movement_.last() ? movement_.last()->position : Vec3f{};
      presence_ = presence_list_.nearest_first(from);
      ++counters_.presence_updates;
      if (callbacks_.on_presence) after = [this, p = presence_] { callbacks_.on_presence(p); };
      break;
    }
    case wire::Body::ChunkHash: {
      auto h = parse_chunk_hash(*m.body_as_ChunkHash());
      if (!h) return fail(h.error());
      const auto mine = replica_.hash(h->chunk_pos);
      const auto rev = replica_.revision(h->chunk_pos);
      const bool match = mine && rev && *rev == h->revision && *mine == h->hash;
      hash_checks_[h->chunk_pos] = match;
      unconfirmed_.erase(h->chunk_pos);  // the server holds the replica's copy as current
      ++(match ? counters_.hash_matches : counters_.hash_mismatches);
      const Holding* held = replica_.holding(h->chunk_pos);
      const HashCheck check{h->chunk_pos, h->revision, rev, held != nullptr && held->full_resolution(), match};
      if (callbacks_.on_hash_checked || callbacks_.on_chunk_hash)
        after = [this, check] {
          if (callbacks_.on_hash_checked) callbacks_.on_hash_checked(check.chunk_pos, check.match);
          if (callbacks_.on_chunk_hash) callbacks_.on_chunk_hash(check);
        };
      break;
    }
    case wire::Body::Pong: {
      ++counters_.pongs;
      // Only a nonce this client could have sent (a time not in the future).
      const std::uint64_t nonce = m.body_as_Pong()->nonce();
      const auto now_us = static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::microseconds>(
                                                         std::chrono::steady_clock::now().time_since_epoch())
                                                         .count());
      if (nonce == 0 || nonce > now_us) break;
      const double ms = static_cast<double>(now_us - nonce) / 1000.0;
      counters_.last_round_trip_ms = ms;
      if (callbacks_.on_round_trip) after = [this, ms] { callbacks_.on_round_trip(ms); };
      break;
    }
    case wire::Body::ServerNotice: {
      auto n = parse_server_notice(*m.body_as_ServerNotice());
      if (!n) return fail(n.error());
      if (n->kind == wire::NoticeKind::Shutdown) server_not_returning_ = !n->reconnect;
      client_log().info("'{}': server notice: {}", options_.name, n->text);
      notices_.push_back(*n);
      if (notices_.size() > kMaxNotices) notices_.pop_front();
      if (callbacks_.on_notice) after = [this, n = *n] { callbacks_.on_notice(n); };
      break;
    }
    case wire::Body::Redirect: {
      auto r = parse_redirect(*m.body_as_Redirect());
      if (!r) return fail(r.error());
      // Followed (once nothing written waits for an answer) by the connection.
      lock.unlock();
      connection_.offer_redirect(std::move(*r));
      lock.lock();
      break;
    }
    case wire::Body::AdminResult: {
      auto r = parse_admin_result(*m.body_as_AdminResult());
      if (!r) return fail(r.error());
      // Bounded: a server cannot grow this past the ids we asked for.
      if (r->request_id == 0 || r->request_id >= next_request_id_) break;
      admin_results_[r->request_id] = *r;
      if (callbacks_.on_admin_result) after = [this, r = *r] { callbacks_.on_admin_result(r); };
      break;
    }
    case wire::Body::Ping: {
      const std::uint64_t nonce = m.body_as_Ping()->nonce();
      lock.unlock();
      connection_.send(build_pong(nonce), wire::Body::Pong);
      lock.lock();
      break;
    }
    default:
      return fail(DecodeError{DecodeErrorCode::kInvalidValue, 0, "message not accepted from a server"});
  }
  lock.unlock();
  changed_.notify_all();
  if (after) after();
}

bool Client::set_state(const ClientStateMsg& state) {
  Frame frame;
  {
    std::lock_guard lock(mutex_);
    frame = movement_.move(state);
    // The latest position goes after the cache's claims (loaded_cache).
    if (state_held_) return !connection_.closed();
  }
  return connection_.send(std::move(frame), wire::Body::ClientState);
}

std::uint32_t Client::fill_box(const Region& box, Voxel v) {
  EditRequestMsg e;
  e.kind = EditKind::kFillBox;
  e.box = box;
  e.material = v.material;
  e.occupancy = v.occupancy;
  return send_edit(std::move(e));
}

std::uint32_t Client::fill_sphere(Vec3f center, float radius, Material material) {
  EditRequestMsg e;
  e.kind = EditKind::kFillSphere;
  e.center = center;
  e.radius = radius;
  e.material = material;
  return send_edit(std::move(e));
}

namespace {
EditRequestMsg sphere_edit(EditKind kind, Vec3f center, float radius, Material material, std::uint8_t occupancy) {
  EditRequestMsg e;
  e.kind = kind;
  e.center = center;
  e.radius = radius;
  e.material = material;
  e.occupancy = occupancy;
  return e;
}
}  // namespace

std::uint32_t Client::send_edit(EditRequestMsg e) {
  {
    std::lock_guard lock(mutex_);
    e.edit_id = edits_.begin();
  }
  if (connection_.send(build_edit_request(e), wire::Body::EditRequest, e.edit_id)) return e.edit_id;
  std::lock_guard lock(mutex_);
  edits_.abandon(e.edit_id);
  return 0;
}

std::uint32_t Client::dig(Vec3f center, float radius) {
  return send_edit(sphere_edit(EditKind::kDig, center, radius, kAir, 0));
}

std::uint32_t Client::paint(Vec3f center, float radius, Material material) {
  return send_edit(sphere_edit(EditKind::kPaint, center, radius, material, 0));
}

std::uint32_t Client::smooth(Vec3f center, float radius, float strength) {
  const float s = std::clamp(strength, 1.0f / 255.0f, 1.0f);
  return send_edit(sphere_edit(EditKind::kSmooth, center, radius, kAir, static_cast<std::uint8_t>(std::lround(s * 255.0f))));
}

std::uint32_t Client::write_box(const Region& box, std::span<const Voxel> voxels) {
  if (box.empty() || box.volume() > kMaxRawBoxVolume || voxels.size() != static_cast<std::size_t>(box.volume())) return 0;
  EditRequestMsg e;
  e.kind = EditKind::kWriteBox;
  e.box = box;
  e.voxels.assign(voxels.begin(), voxels.end());
  return send_edit(std::move(e));
}

std::uint32_t Client::undo() {
  EditRequestMsg e;
  e.kind = EditKind::kUndo;
  return send_edit(std::move(e));
}

std::uint32_t Client::redo() {
  EditRequestMsg e;
  e.kind = EditKind::kRedo;
  return send_edit(std::move(e));
}

std::uint32_t Client::request_read_box(const Region& box) {
  if (box.empty() || box.volume() > kMaxRawBoxVolume) return 0;
  std::uint32_t id = 0;
  {
    std::lock_guard lock(mutex_);
    id = next_request_id_++;
  }
  return connection_.send(build_read_box(id, box), wire::Body::ReadBox) ? id : 0;
}

std::vector<PresenceEntryMsg> Client::presence() const {
  std::lock_guard lock(mutex_);
  return presence_;
}

std::uint32_t Client::admin(const std::string& command, const std::vector<std::string>& args) {
  if (command.empty() || command.size() > kMaxAdminCommandBytes || args.size() > kMaxAdminArgs) return 0;
  for (const auto& a : args)
    if (a.size() > kMaxAdminArgBytes) return 0;
  std::uint32_t id = 0;
  {
    std::lock_guard lock(mutex_);
    id = next_request_id_++;
  }
  return connection_.send(build_admin_request(AdminRequestMsg{id, command, args}), wire::Body::AdminRequest) ? id : 0;
}

std::optional<ClientStateMsg> Client::last_state() const {
  std::lock_guard lock(mutex_);
  return movement_.last();
}

std::optional<StreamedView> Client::streamed_view() const {
  std::lock_guard lock(mutex_);
  if (!welcome_) return std::nullopt;
  return movement_.view(*welcome_);
}

std::optional<ViewCoverage> Client::coverage() const {
  std::lock_guard lock(mutex_);
  if (!welcome_) return std::nullopt;
  const auto view = movement_.view(*welcome_);
  if (!view) return std::nullopt;
  return terrane::coverage(replica_, *view, welcome_->bounds());
}

std::vector<ServerNoticeMsg> Client::notices() const {
  std::lock_guard lock(mutex_);
  return {notices_.begin(), notices_.end()};
}

bool Client::request_chunk_hash(Vec3i chunk_pos) {
  return connection_.send(build_chunk_hash_request(chunk_pos), wire::Body::ChunkHashRequest);
}
void Client::capture_voxel_changes(std::size_t max_per_batch) {
  std::lock_guard lock(mutex_);
  voxel_change_cap_ = max_per_batch;
}

bool Client::ping(std::uint64_t nonce) { return connection_.send(build_ping(nonce), wire::Body::Ping); }
bool Client::send_raw(Frame bytes) { return connection_.send(std::move(bytes), wire::Body::NONE); }

ClientView Client::client_view() const {
  return ClientView{replica_,          counters_,    welcome_.has_value(), closed_,   disconnect_reason_,
                    edits_.outcomes(), hash_checks_, read_results_,        presence_, notices_,
                    admin_results_,     linked_,      sessions_,            unconfirmed_,
                    state_held_};
}

bool Client::wait_until(const std::function<bool(const ClientView&)>& pred, std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  return changed_.wait_for(lock, timeout, [&] { return pred(client_view()); });
}

Voxel Client::get(Vec3i voxel) const {
  std::lock_guard lock(mutex_);
  return replica_.get(voxel);
}

void Client::read_box(Vec3i min, Box& out) const {
  std::lock_guard lock(mutex_);
  replica_.read_box(min, out);
}

int Client::resolution_at(Vec3i voxel) const {
  std::lock_guard lock(mutex_);
  return replica_.resolution_at(voxel);
}

std::optional<RayHit> Client::raycast(Vec3f origin, Vec3f direction, float max_distance) const {
  std::lock_guard lock(mutex_);
  return replica_.raycast(origin, direction, max_distance);
}

std::optional<std::int32_t> Client::surface_height(std::int32_t x, std::int32_t z) const {
  std::lock_guard lock(mutex_);
  if (!welcome_) return std::nullopt;
  return replica_.surface_height(x, z, welcome_->bounds_min_y, welcome_->bounds_max_y);
}

std::optional<WelcomeMsg> Client::welcome() const {
  std::lock_guard lock(mutex_);
  return welcome_;
}

ClientCounters Client::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

bool Client::closed() const {
  std::lock_guard lock(mutex_);
  return closed_;
}

std::string Client::disconnect_reason() const {
  std::lock_guard lock(mutex_);
  return disconnect_reason_;
}

}  // namespace terrane
