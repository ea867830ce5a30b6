#include "server/replication/chunk_slot.h"

#include <utility>

namespace terrane {

// The allocator's header (glibc: 8 bytes, rounded to 16) beside the bytes.
const std::size_t ChunkSlot::kMoreBytes = sizeof(ChunkSlot::More) + 16;

const VersionPtr& ChunkSlot::null_version() {
  static const VersionPtr none;
  return none;
}

const std::optional<ChunkRequest>& ChunkSlot::no_request() {
  static const std::optional<ChunkRequest> none;
  return none;
}

const std::optional<Holding>& ChunkSlot::no_claim() {
  static const std::optional<Holding> none;
  return none;
}

ChunkSlot::More& ChunkSlot::more() {
  if (!more_) more_ = std::make_unique<More>();
  return *more_;
}

void ChunkSlot::trim() {
  if (more_ && more_->empty()) more_.reset();
}

bool ChunkSlot::hold(Holding h, const VersionPtr& v) {
  set(h.form, h.revision);
  if (h.form == HoldingForm::kFull && v && !v->empty()) {
    const bool fresh = !more().full;
    more_->full = v;
    return fresh;
  }
  if (more_) {
    more_->full.reset();
    trim();
  }
  return false;
}

void ChunkSlot::see_image(int level) {
  set(horizon_form(level), 0);
}

bool ChunkSlot::ask(ChunkRequest r) {
  if (request()) return false;
  more().request = r;
  return true;
}

std::optional<ChunkRequest> ChunkSlot::take_request() {
  if (!more_) return std::nullopt;
  std::optional<ChunkRequest> r = std::exchange(more_->request, std::nullopt);
  trim();
  return r;
}

bool ChunkSlot::set_ready(VersionPtr v) {
  if (ready()) return false;
  more().ready = std::move(v);
  return true;
}

bool ChunkSlot::refresh_ready(const VersionPtr& v) {
  if (!ready()) return false;
  if (more_->ready->revision() < v->revision()) more_->ready = v;
  return true;
}

VersionPtr ChunkSlot::take(VersionPtr More::*field) {
  if (!more_) return nullptr;
  VersionPtr v = std::exchange((*more_).*field, nullptr);
  trim();
  return v;
}

VersionPtr ChunkSlot::take_ready() { return take(&More::ready); }

void ChunkSlot::set_claim(Holding h) { more().claim = h; }

std::optional<Holding> ChunkSlot::take_claim() {
  if (!more_) return std::nullopt;
  std::optional<Holding> c = std::exchange(more_->claim, std::nullopt);
  trim();
  return c;
}

bool ChunkSlot::park_mip(VersionPtr v) {
  const VersionPtr& waiting = mip_pending();
  if (waiting && waiting->revision() >= v->revision()) return false;
  const bool fresh = !waiting;
  more().mip = std::move(v);
  return fresh;
}

VersionPtr ChunkSlot::take_mip() { return take(&More::mip); }

ChunkSlot::Left ChunkSlot::leave() {
  Left left;
  if (more_ && more_->claim) {
    left.claim = more_->claim->revision;
    more_->claim.reset();
  }
  if (has()) {
    left.had = revision();  // 0 for an image
    left.registered = !is_image();
    bits_ = 0;
    if (more_) more_->full.reset();
  }
  if (more_ && more_->ready) {
    // Granted (so registered) and not sent: dropped with its request.
    more_->ready.reset();
    more_->request.reset();
    left.registered = true;
  } else if (more_ && more_->request) {
    // Its grant is on its way: it comes to nothing.
    more_->request->cancelled = true;
  }
  trim();
  return left;
}

}  // namespace terrane
