// ChunkSlot: what one replicator knows of one chunk for its client, in one
// record: what the client has of it (a Holding of its own, or only its
// region's horizon image), the version of a chunk held Full (for chunk
// hashes), the request outstanding to the world, the version granted and
// not yet sent, the claim of a resuming client, and the newest change
// waiting for the next refresh of mips.
//
// ChunkSlots: the slots of one client, by chunk. Every change goes through
// change() or change_if(), which keep the counts the replicator's hot paths
// read (requests outstanding, those of the coarse pass, claims, pending
// refreshes of mips) and erase a slot once nothing is left in it.
//
// A slot is one entry of a map as large as the client's view (tens of
// thousands of chunks): it keeps what every chunk has (what the client has
// of it) inline and the rest, which few chunks have at a time, out of line.
//
// Thread-safety: none (a replicator's session strand).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <utility>

#include "common/voxel/vec3_map.h"
#include "protocol/holding.h"
#include "protocol/stream_batch.h"
#include "server/base/chunk_version.h"

namespace terrane {

// Why a chunk was asked of the world: the coarse pass (the whole view at
// its coarsest), a refinement of a chunk held coarser than the plan wants,
// or a resuming client's claim, checked against the chunk's revision.
// The record a chunk sent at level (0 full, 1..3 a mip) goes in.
inline StreamRecordKind record_kind(int level) {
  return level == 0 ? StreamRecordKind::kFull : record_kind_of(mip_form(level));
}

// The form a version sent at level (0 full, 1..3 a mip) gives its chunk.
inline HoldingForm form_sent(const ChunkVersion& v, int level) {
  if (v.empty()) return HoldingForm::kEmpty;
  if (v.estimate()) return HoldingForm::kEstimate;
  return level == 0 ? HoldingForm::kFull : mip_form(level);
}

enum class ChunkIntent : std::uint8_t { kCoarse, kRefine, kClaim };

struct ChunkRequest {
  ChunkIntent intent = ChunkIntent::kCoarse;
  int level = 0;  // the level to send (0 full, 1..3 mip)
  // The chunk left the view after it was asked for: its grant, still on
  // its way, is dropped and released (the world registers a holder when
  // it grants, which may come after the client's release).
  bool cancelled = false;

  friend bool operator==(const ChunkRequest&, const ChunkRequest&) = default;
};

class ChunkSlot {
 public:
  // --- what the client has of the chunk

  // A record of the chunk's own sent to the client (Full .. Estimate);
  // none for a chunk seen only through a horizon image.
  std::optional<Holding> held() const {
    if (!has_ || is_image()) return std::nullopt;
    return Holding{form_, revision_};
  }
  // Seen only through its region's horizon image (no record of its own).
  bool image() const { return has_ && is_image(); }
  // Held, seen through an image, or claimed: a horizon image leaves it be.
  bool known() const { return has_ || claim().has_value(); }

  // The client now holds h of the chunk (forgetting an image). v is the
  // version h was made from: kept while h is Full (and v not all Air) for
  // chunk hashes. Returns whether that version is new, the chunk not held
  // Full with one before.
  bool hold(Holding h, const VersionPtr& v);
  // Seen through its region's horizon image at level (4 or 5): only for a
  // chunk not held.
  void see_image(int level);
  // The version of a chunk held Full, or null.
  const VersionPtr& full() const { return more_ ? more_->full : null_version(); }

  // --- the world's side

  const std::optional<ChunkRequest>& request() const { return more_ ? more_->request : no_request(); }
  // Asks for the chunk; an outstanding request is kept. Returns whether r
  // was taken.
  bool ask(ChunkRequest r);
  std::optional<ChunkRequest> take_request();

  // Granted, not yet sent.
  const VersionPtr& ready() const { return more_ ? more_->ready : null_version(); }
  // A grant: kept unless one waits already (returns whether it was kept).
  bool set_ready(VersionPtr v);
  // A change of a chunk granted and not yet sent: the newer version is
  // sent. Returns whether one waits (and so took the change).
  bool refresh_ready(const VersionPtr& v);
  VersionPtr take_ready();

  // What a resuming client said it holds, until it is adopted or resent.
  const std::optional<Holding>& claim() const { return more_ ? more_->claim : no_claim(); }
  void set_claim(Holding h);
  std::optional<Holding> take_claim();

  // The newest change of a chunk held coarser than full resolution,
  // waiting for the next refresh of mips.
  const VersionPtr& mip_pending() const { return more_ ? more_->mip : null_version(); }
  // Keeps v unless a newer change waits already. Returns whether nothing
  // waited before.
  bool park_mip(VersionPtr v);
  VersionPtr take_mip();

  // --- leaving the view

  struct Left {
    std::optional<std::uint64_t> claim;  // a claim dropped: Released at its revision
    std::optional<std::uint64_t> had;    // what the client had (held, or an image's: 0): Released at it
    bool registered = false;             // the world counts the client among the chunk's holders
  };
  // The chunk leaves the view: its claim, what the client has of it and a
  // grant waiting to be sent (with its request) are dropped; a request
  // still on its way is cancelled (its grant is dropped when it comes). A
  // change waiting for the refresh of mips stays (the refresh finds nothing
  // held).
  Left leave();

  // Nothing left: the slot goes.
  bool empty() const { return !has_ && !more_; }

 private:
  // What few chunks have at a time.
  struct More {
    VersionPtr full, ready, mip;
    std::optional<ChunkRequest> request;
    std::optional<Holding> claim;
    bool empty() const { return !full && !ready && !mip && !request && !claim; }
  };
  static const VersionPtr& null_version();
  static const std::optional<ChunkRequest>& no_request();
  static const std::optional<Holding>& no_claim();
  bool is_image() const { return form_ == HoldingForm::kHorizon4 || form_ == HoldingForm::kHorizon5; }
  More& more();
  void trim();  // drops an empty More
  // Takes the version in field (ready or mip), trimming what is left.
  VersionPtr take(VersionPtr More::*field);

  std::uint64_t revision_ = 0;
  HoldingForm form_ = HoldingForm::kEmpty;
  bool has_ = false;
  std::unique_ptr<More> more_;
};

// One per chunk in view: what is inline costs every chunk of every client.
static_assert(sizeof(ChunkSlot) <= 24);

class ChunkSlots {
 public:
  const ChunkSlot* find(Vec3i cp) const {
    auto it = map_.find(cp);
    return it == map_.end() ? nullptr : &it->second;
  }
  // Whether the client holds a record of cp's own (ChunkSlot::held).
  bool holds(Vec3i cp) const {
    const ChunkSlot* s = find(cp);
    return s != nullptr && s->held();
  }
  // Whether it holds, claims or has an image of cp (ChunkSlot::known).
  bool known(Vec3i cp) const {
    const ChunkSlot* s = find(cp);
    return s != nullptr && s->known();
  }
  // f(ChunkSlot&) on cp's slot, made if there is none. f must not insert
  // into these slots (a rebuild would move the slot under it).
  template <class F>
  void change(Vec3i cp, F&& f) {
    settle(map_.try_emplace(cp).first, std::forward<F>(f));
  }
  // The same for a slot that is there: false (and f not called) if none.
  template <class F>
  bool change_if(Vec3i cp, F&& f) {
    auto it = map_.find(cp);
    if (it == map_.end()) return false;
    settle(it, std::forward<F>(f));
    return true;
  }

  // Outstanding requests (granted or not, cancelled or not).
  std::size_t requests() const { return counts_[kRequested]; }
  // Those of the coarse pass (coarse or claim: not refining).
  std::size_t coarse_pass_requests() const { return counts_[kCoarsePass]; }
  std::size_t claims() const { return counts_[kClaimed]; }
  // Chunks with a change waiting for the next refresh of mips.
  std::size_t mips_pending() const { return counts_[kMipPending]; }

  std::size_t size() const { return map_.size(); }
  auto begin() const { return map_.begin(); }
  auto end() const { return map_.end(); }
  void clear() {
    map_.clear();
    counts_ = {};
  }

 private:
  enum Count { kRequested, kCoarsePass, kClaimed, kMipPending, kCounts };
  using Tally = std::array<bool, kCounts>;
  static Tally tally(const ChunkSlot& s) {
    const auto& r = s.request();
    return {r.has_value(), r.has_value() && r->intent != ChunkIntent::kRefine, s.claim().has_value(),
            s.mip_pending() != nullptr};
  }
  template <class F>
  void settle(Vec3iMap<ChunkSlot>::iterator it, F&& f) {
    ChunkSlot& s = it->second;
    const Tally before = tally(s);
    std::forward<F>(f)(s);
    const Tally after = tally(s);
    for (std::size_t i = 0; i < kCounts; ++i) counts_[i] = counts_[i] + after[i] - before[i];
    if (s.empty()) map_.erase(it);
  }

  Vec3iMap<ChunkSlot> map_;
  std::array<std::size_t, kCounts> counts_{};
};

}  // namespace terrane
