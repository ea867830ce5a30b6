#include "server/replication/stream_gate.h"

#include <algorithm>
#include <future>

namespace terrane {

// A probe: a timer on one context (on a strand of its own: the io context
// has several threads), re-armed each period; its lateness is how long its
// completion waited behind the context's other work.
struct StreamGate::Prober {
  Prober(asio::io_context& ctx, Probe p) : strand(asio::make_strand(ctx)), timer(strand), which(p) {}
  asio::strand<asio::io_context::executor_type> strand;
  asio::steady_timer timer;
  Probe which;
  bool stopped = false;  // on the strand
};

namespace {
// Probes per threshold: a queue is seen late at most a fraction of the
// threshold after it became so.
constexpr int kProbesPerThreshold = 4;
}  // namespace

StreamGate::StreamGate(std::chrono::milliseconds threshold) : threshold_(threshold) {}
StreamGate::~StreamGate() = default;

void StreamGate::observe(Probe p, std::chrono::nanoseconds late) {
  if (threshold_.count() <= 0) return;
  const auto i = static_cast<std::size_t>(p);
  std::lock_guard lock(m_);
  if (late > threshold_)
    late_[i] = true;
  else if (late * 2 <= threshold_)
    late_[i] = false;
  update();
}

void StreamGate::hold_closed(bool held) {
  std::lock_guard lock(m_);
  held_ = held;
  held_flag_.store(held, std::memory_order_relaxed);
  update();
}

void StreamGate::update() {
  const bool open = !held_ && std::none_of(late_.begin(), late_.end(), [](bool late) { return late; });
  if (open == open_.load(std::memory_order_relaxed)) return;
  const auto now = std::chrono::steady_clock::now();
  if (!open) {
    closed_at_ = now;
    closed_count_.fetch_add(1, std::memory_order_relaxed);
  } else {
    closed_for_ += now - closed_at_;
  }
  open_.store(open, std::memory_order_relaxed);
}

double StreamGate::closed_seconds() const {
  std::lock_guard lock(m_);
  auto d = closed_for_;
  if (!open_.load(std::memory_order_relaxed)) d += std::chrono::steady_clock::now() - closed_at_;
  return std::chrono::duration<double>(d).count();
}

void StreamGate::start(asio::io_context& io, asio::io_context& world) {
  if (threshold_.count() <= 0) return;
  probers_[0] = std::make_unique<Prober>(io, Probe::kIo);
  probers_[1] = std::make_unique<Prober>(world, Probe::kWorld);
  for (auto& p : probers_) {
    p->timer.expires_after(threshold_ / kProbesPerThreshold);
    arm(*p);
  }
}

void StreamGate::arm(Prober& p) {
  p.timer.async_wait([this, &p](const asio::error_code& ec) {
    if (ec || p.stopped) return;
    const auto expiry = p.timer.expiry();
    observe(p.which, std::chrono::steady_clock::now() - expiry);
    p.timer.expires_at(std::max(expiry + threshold_ / kProbesPerThreshold, std::chrono::steady_clock::now()));
    arm(p);
  });
}

void StreamGate::stop() {
  for (auto& p : probers_) {
    if (!p) continue;
    Prober* raw = p.get();
    // On the probe's strand: its handler never runs beside this one and
    // sees stopped (or operation_aborted) after it; the second round runs
    // after the cancelled wait's handler, so none is left once it has.
    for (int round = 0; round < 2; ++round) {
      std::promise<void> done;
      asio::post(raw->strand, [raw, &done] {
        raw->stopped = true;
        raw->timer.cancel();
        done.set_value();
      });
      done.get_future().wait();
    }
  }
}

}  // namespace terrane
