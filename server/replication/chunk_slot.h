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
// There is a slot for every chunk of the client's view (tens of thousands
// of chunks): it keeps what every chunk has (what the client has of it)
// inline and the rest, which few chunks have at a time, out of line. The
// slots are kept in blocks of 4^3 chunks (ChunkSlots), and counted in the
// server's memory by part (MemoryPart::kChunkSlots).
//
// Thread-safety: none (a replicator's session strand).
#pragma once

#include <array>
#include <cassert>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "common/voxel/vec3_map.h"
#include "common/world/coarse_image.h"
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
    if (!has() || is_image()) return std::nullopt;
    return Holding{form(), revision()};
  }
  // Seen only through its region's horizon image (no record of its own).
  bool image() const { return has() && is_image(); }
  // Held, seen through an image, or claimed: a horizon image leaves it be.
  bool known() const { return has() || claim().has_value(); }

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
  bool empty() const { return !has() && !more_; }
  // Something kept out of line (a version, a request or a claim).
  bool has_more() const { return more_ != nullptr; }
  // What that costs: its bytes and the allocator's header.
  static const std::size_t kMoreBytes;

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
  bool is_image() const { return form() == HoldingForm::kHorizon4 || form() == HoldingForm::kHorizon5; }
  // What the client has, in one word: the revision above bit 8, whether
  // it has anything in bit 7, the form below (revisions are the world's
  // own, counted per chunk from 0: far below 2^56).
  static constexpr int kRevisionShift = 8;
  static constexpr std::uint64_t kHasBit = 1u << 7, kFormMask = kHasBit - 1;
  bool has() const { return (bits_ & kHasBit) != 0; }
  HoldingForm form() const { return static_cast<HoldingForm>(bits_ & kFormMask); }
  std::uint64_t revision() const { return bits_ >> kRevisionShift; }
  void set(HoldingForm form, std::uint64_t revision) {
    assert(revision >> (64 - kRevisionShift) == 0);
    bits_ = revision << kRevisionShift | kHasBit | static_cast<std::uint64_t>(form);
  }
  More& more();
  void trim();  // drops an empty More
  // Takes the version in field (ready or mip), trimming what is left.
  VersionPtr take(VersionPtr More::*field);

  std::uint64_t bits_ = 0;  // nothing: has() false
  std::unique_ptr<More> more_;
};

// One per chunk in view: what is inline costs every chunk of every client.
static_assert(sizeof(ChunkSlot) <= 16);

class ChunkSlots {
  // Chunks are kept in blocks of kSide^3 = 64: per block a word of bits
  // (which of its chunks have a slot) and their slots side by side in
  // chunk order. A slot costs its own 16 bytes and a block's key, word and
  // vector (about 50 bytes) are shared by the block's slots, where a flat
  // map of slots cost each a key and a table's slack (about 65 bytes a
  // chunk in all). A lookup is a block lookup and a count of bits; making
  // or erasing a slot moves the slots after it in its block (at most 63).
  static constexpr int kSide = 4;
  struct Block {
    std::uint64_t has = 0;
    std::vector<ChunkSlot> slots;  // one per set bit, in bit order

    bool test(int i) const { return (has >> i & 1) != 0; }
    // Slots before bit i.
    std::size_t rank(int i) const {
      return static_cast<std::size_t>(std::popcount(has & ((std::uint64_t{1} << i) - 1)));
    }
  };
  using Blocks = Vec3iMap<Block>;
  static Vec3i block_of(Vec3i cp) { return floor_div(cp, kSide); }
  static int bit_of(Vec3i cp) {
    const Vec3i l = floor_mod(cp, kSide);
    return (l.y * kSide + l.z) * kSide + l.x;
  }
  // The k-th (0..7) of a region's 2^3 blocks.
  static Vec3i region_block(Vec3i region, int k) {
    static_assert(kCoarseRegionChunks == 2 * kSide);
    return region * 2 + Vec3i{k & 1, k >> 2, (k >> 1) & 1};
  }
  static Vec3i chunk_at(Vec3i block, int bit) {
    return Vec3i{block.x * kSide + bit % kSide, block.y * kSide + bit / (kSide * kSide),
                 block.z * kSide + bit / kSide % kSide};
  }

 public:
  // bytes: where this client's share of the server's memory is counted
  // (memory_bytes(), kept up to date as it changes; null: nowhere). Its
  // share is taken back when the slots go.
  explicit ChunkSlots(std::atomic<std::int64_t>* bytes = nullptr) : share_(bytes) {}
  ChunkSlots(const ChunkSlots&) = delete;
  ChunkSlots& operator=(const ChunkSlots&) = delete;
  ~ChunkSlots() { report(0); }

  const ChunkSlot* find(Vec3i cp) const {
    auto it = blocks_.find(block_of(cp));
    if (it == blocks_.end()) return nullptr;
    const Block& b = it->second;
    const int i = bit_of(cp);
    return b.test(i) ? &b.slots[b.rank(i)] : nullptr;
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
  // Whether a chunk of region (8^3 chunks: 2^3 blocks) may have a slot
  // (false: none has).
  bool any_in_region(Vec3i region) const {
    for (int k = 0; k < 8; ++k)
      if (blocks_.find(region_block(region, k)) != blocks_.end()) return true;
    return false;
  }
  // Region's chunks in mask (chunk i = (y * 8 + z) * 8 + x of the region,
  // as in a Horizon record) that are not known(): each seen through the
  // region's image at level (ChunkSlot::see_image); the known ones are
  // taken out of mask. Returns the chunks seen so. A block with no slots
  // yet is made whole at once: a view's first images mark every chunk of
  // it (157,000 at view 2,048).
  std::size_t see_images(Vec3i region, HorizonMask& mask, int level) {
    std::size_t seen = 0;
    for (int k = 0; k < 8; ++k) {
      const Vec3i block = region_block(region, k);
      std::uint64_t bits = 0;
      for (int i = 0; i < kSide * kSide * kSide; ++i)
        if (horizon_mask_has(mask, coarse_index(chunk_at(block, i)))) bits |= std::uint64_t{1} << i;
      if (bits == 0) continue;
      if (auto [it, fresh] = blocks_.try_emplace(block); fresh) {
        Block& b = it->second;
        const auto n = static_cast<std::size_t>(std::popcount(bits));
        b.has = bits;
        b.slots.resize(n);
        for (ChunkSlot& slot : b.slots) {
          slot.see_image(level);
          assert(tally(slot) == Tally{});  // no count changes
        }
        slot_bytes_ += b.slots.capacity() * sizeof(ChunkSlot);
        size_ += n;
        seen += n;
        continue;
      }
      for (std::uint64_t rest = bits; rest != 0; rest &= rest - 1) {
        const Vec3i cp = chunk_at(block, std::countr_zero(rest));
        if (known(cp)) {
          horizon_mask_clear(mask, coarse_index(cp));
          continue;
        }
        change(cp, [&](ChunkSlot& s) { s.see_image(level); });
        ++seen;
      }
    }
    report(memory_bytes());
    return seen;
  }
  // f(ChunkSlot&) on cp's slot, made if there is none. f must not change
  // these slots otherwise (making a slot may move the others of its block).
  template <class F>
  void change(Vec3i cp, F&& f) {
    Block& b = blocks_[block_of(cp)];
    const int i = bit_of(cp);
    const std::size_t at = b.rank(i);
    if (!b.test(i)) {
      const std::size_t cap = b.slots.capacity();
      // Grown by a quarter, not doubled: a block's slots stay within an
      // eighth or so of their own bytes.
      if (b.slots.size() == cap) b.slots.reserve(cap + cap / 4 + 2);
      b.slots.emplace(b.slots.begin() + static_cast<std::ptrdiff_t>(at));
      b.has |= std::uint64_t{1} << i;
      slot_bytes_ += (b.slots.capacity() - cap) * sizeof(ChunkSlot);
      ++size_;
    }
    settle(block_of(cp), b, i, at, std::forward<F>(f));
  }
  // The same for a slot that is there: false (and f not called) if none.
  template <class F>
  bool change_if(Vec3i cp, F&& f) {
    auto it = blocks_.find(block_of(cp));
    const int i = bit_of(cp);
    if (it == blocks_.end() || !it->second.test(i)) return false;
    settle(it->first, it->second, i, it->second.rank(i), std::forward<F>(f));
    return true;
  }

  // Outstanding requests (granted or not, cancelled or not).
  std::size_t requests() const { return counts_[kRequested]; }
  // Those of the coarse pass (coarse or claim: not refining).
  std::size_t coarse_pass_requests() const { return counts_[kCoarsePass]; }
  std::size_t claims() const { return counts_[kClaimed]; }
  // Chunks with a change waiting for the next refresh of mips.
  std::size_t mips_pending() const { return counts_[kMipPending]; }

  std::size_t size() const { return size_; }
  // The slots' memory: the table of blocks, the slots and what few slots
  // have out of line (ChunkSlot::kMoreBytes each).
  std::size_t memory_bytes() const {
    return blocks_.table_bytes() + slot_bytes_ + counts_[kWithMore] * ChunkSlot::kMoreBytes;
  }

  // Every slot, block by block (chunk order within each), as
  // (chunk, slot) pairs; invalid after a change.
  class const_iterator {
   public:
    using value_type = std::pair<Vec3i, const ChunkSlot&>;
    const_iterator(Blocks::const_iterator it, Blocks::const_iterator end) : it_(it), end_(end) { enter(); }
    value_type operator*() const {
      return {chunk_at(it_->first, std::countr_zero(rest_)), it_->second.slots[k_]};
    }
    const_iterator& operator++() {
      rest_ &= rest_ - 1;
      ++k_;
      if (rest_ == 0) {
        ++it_;
        enter();
      }
      return *this;
    }
    friend bool operator==(const const_iterator& a, const const_iterator& b) {
      return a.it_ == b.it_ && a.rest_ == b.rest_;
    }

   private:
    void enter() {
      k_ = 0;
      rest_ = it_ == end_ ? 0 : it_->second.has;  // a block in the table has a slot
    }
    Blocks::const_iterator it_, end_;
    std::uint64_t rest_ = 0;  // the block's bits not yet visited
    std::size_t k_ = 0;       // the slot of the lowest of them
  };
  const_iterator begin() const { return const_iterator(blocks_.begin(), blocks_.end()); }
  const_iterator end() const { return const_iterator(blocks_.end(), blocks_.end()); }

  // Every slot goes, and the table's memory with them.
  void clear() {
    Blocks().swap(blocks_);
    counts_ = {};
    size_ = 0;
    slot_bytes_ = 0;
    report(memory_bytes());
  }

 private:
  enum Count { kRequested, kCoarsePass, kClaimed, kMipPending, kWithMore, kCounts };
  using Tally = std::array<bool, kCounts>;
  static Tally tally(const ChunkSlot& s) {
    const auto& r = s.request();
    return {r.has_value(), r.has_value() && r->intent != ChunkIntent::kRefine, s.claim().has_value(),
            s.mip_pending() != nullptr, s.has_more()};
  }
  // f on the slot at bit i (position at) of block b (key block); the slot
  // goes if f leaves it empty, and the block with its last slot.
  template <class F>
  void settle(Vec3i block, Block& b, int i, std::size_t at, F&& f) {
    ChunkSlot& s = b.slots[at];
    const Tally before = tally(s);
    std::forward<F>(f)(s);
    const Tally after = tally(s);
    for (std::size_t c = 0; c < kCounts; ++c) counts_[c] = counts_[c] + after[c] - before[c];
    if (s.empty()) {
      b.slots.erase(b.slots.begin() + static_cast<std::ptrdiff_t>(at));
      b.has &= ~(std::uint64_t{1} << i);
      --size_;
      if (b.has == 0) {
        slot_bytes_ -= b.slots.capacity() * sizeof(ChunkSlot);
        blocks_.erase(block);
      }
    }
    report(memory_bytes());
  }
  // Moves the share counted in share_ to bytes.
  void report(std::size_t bytes) {
    if (share_ == nullptr || bytes == reported_) return;
    share_->fetch_add(static_cast<std::int64_t>(bytes) - static_cast<std::int64_t>(reported_),
                      std::memory_order_relaxed);
    reported_ = bytes;
  }

  Blocks blocks_;
  std::size_t size_ = 0;
  std::size_t slot_bytes_ = 0;  // the blocks' vectors' capacity
  std::array<std::size_t, kCounts> counts_{};
  std::atomic<std::int64_t>* const share_;
  std::size_t reported_ = 0;
};

}  // namespace terrane
