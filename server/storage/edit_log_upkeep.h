// EditLogUpkeep: the edit log's retention and its size as the server shows
// it (terrane-admin status, /metrics). Storage owns it and runs it on the
// writer thread with the writer's connection: about once a minute it
// prunes the log to the retention and counts the log again
// (WorldStore::edit_log_size: a scan for PostgreSQL, whose log every
// server of the world writes), and after each commit it adds what the
// commit logged. The figure is published in an EditLogFigure (atomics), so
// the admin thread and /metrics read it without touching the store.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <optional>
#include <span>

#include "common/world/world_store.h"

namespace terrane {

// The edit log's size as the storage writer last knew it; unknown until
// first counted, and again after a count failed. Written by one thread
// (the writer), read by any: a reader may see the entries a commit ahead
// of the bytes, never a torn value.
class EditLogFigure {
 public:
  std::optional<EditLogSize> get() const;
  void set(std::optional<EditLogSize> size);
  // A commit stored entries holding bytes of voxels (nothing while unknown).
  void add(std::int64_t entries, std::uint64_t bytes);

 private:
  std::atomic<bool> known_{false};
  std::atomic<std::int64_t> entries_{0};
  std::atomic<std::uint64_t> bytes_{0};
};

class EditLogUpkeep {
 public:
  // How often the log is pruned (while a retention is set) and counted.
  static constexpr std::chrono::minutes kPeriod{1};

  // figure: where the size is published; pruned: counts the entries the
  // prunes delete. Both outlive this.
  EditLogUpkeep(EditLogFigure& figure, std::atomic<std::uint64_t>& pruned);

  // Entries are kept max_age (0: for ever) and at most max_bytes of voxels
  // (0: no bound). Any thread; the next run() applies it.
  void set_retention(std::chrono::seconds max_age, std::uint64_t max_bytes);
  // Writer thread, on each of its wake-ups: prunes when a retention is set
  // and the last prune is kPeriod old (the first at once), at most a
  // bounded number of rows (WorldStore::prune_edit_log); then counts the
  // log when it is not known yet, after a prune, or kPeriod after the last
  // count. A failure is logged and tried again kPeriod later.
  void run(WorldStore& store, std::chrono::steady_clock::time_point now);
  // Writer thread: a commit stored log; the figure grows by it.
  void logged(std::span<const EditLogEntry> log);

 private:
  EditLogFigure& figure_;
  std::atomic<std::uint64_t>& pruned_;
  // Written by set_retention (any thread), read by run().
  std::atomic<std::int64_t> max_age_s_{0};
  std::atomic<std::uint64_t> max_bytes_{0};
  // The writer thread's.
  std::chrono::steady_clock::time_point next_prune_{};
  std::optional<std::chrono::steady_clock::time_point> next_count_;
};

}  // namespace terrane
