#include "server/storage/edit_log_upkeep.h"

#include "server/base/log.h"

namespace terrane {

std::optional<EditLogSize> EditLogFigure::get() const {
  if (!known_.load(std::memory_order_acquire)) return std::nullopt;
  return EditLogSize{entries_.load(std::memory_order_relaxed), bytes_.load(std::memory_order_relaxed)};
}

void EditLogFigure::set(std::optional<EditLogSize> size) {
  if (!size) {
    known_.store(false, std::memory_order_release);
    return;
  }
  entries_.store(size->entries, std::memory_order_relaxed);
  bytes_.store(size->bytes, std::memory_order_relaxed);
  known_.store(true, std::memory_order_release);
}

void EditLogFigure::add(std::int64_t entries, std::uint64_t bytes) {
  if (!known_.load(std::memory_order_relaxed)) return;
  entries_.fetch_add(entries, std::memory_order_relaxed);
  bytes_.fetch_add(bytes, std::memory_order_relaxed);
}

EditLogUpkeep::EditLogUpkeep(EditLogFigure& figure, std::atomic<std::uint64_t>& pruned)
    : figure_(figure), pruned_(pruned) {}

void EditLogUpkeep::set_retention(std::chrono::seconds max_age, std::uint64_t max_bytes) {
  max_age_s_.store(max_age.count(), std::memory_order_relaxed);
  max_bytes_.store(max_bytes, std::memory_order_relaxed);
}

void EditLogUpkeep::run(WorldStore& store, std::chrono::steady_clock::time_point now) {
  const std::int64_t max_age_s = max_age_s_.load(std::memory_order_relaxed);
  const std::uint64_t max_bytes = max_bytes_.load(std::memory_order_relaxed);
  bool count = !next_count_ || now >= *next_count_;
  if ((max_age_s > 0 || max_bytes > 0) && now >= next_prune_) {
    next_prune_ = now + kPeriod;
    const std::int64_t now_ms =
        std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
            .count();
    const std::int64_t before = max_age_s == 0 ? 0 : now_ms - max_age_s * 1000;
    if (auto n = store.prune_edit_log(before, max_bytes); !n) {
      server_log().warn("edit log: pruning failed: {}", n.error().message);
    } else {
      pruned_.fetch_add(static_cast<std::uint64_t>(*n), std::memory_order_relaxed);
      count = count || *n > 0;
    }
  }
  if (!count) return;
  next_count_ = now + kPeriod;
  auto size = store.edit_log_size();
  if (!size) {
    // Unknown rather than wrong: status and /metrics say so.
    server_log().warn("edit log: its size cannot be counted: {}", size.error().message);
    figure_.set(std::nullopt);
    return;
  }
  figure_.set(*size);
}

void EditLogUpkeep::logged(std::span<const EditLogEntry> log) {
  std::uint64_t bytes = 0;
  for (const EditLogEntry& e : log) bytes += e.before.size() + e.after.size();
  figure_.add(static_cast<std::int64_t>(log.size()), bytes);
}

}  // namespace terrane
