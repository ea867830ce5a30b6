// UpdateFaults: the test seam of the replicators' UpdateBatches. A server
// started with --test-drop-updates N or --test-corrupt-updates N
// (UpdateFaultOptions, below: the bots' tests, whose runs must then fail
// and name the region) gives every replicator one BudgetedUpdateFaults;
// otherwise replicators get none, and a replicator's only trace of the
// seam is one call before it joins a batch.
//
// Threading: tamper() is called on every session strand at once
// (BudgetedUpdateFaults's budgets are atomics, shared by the server's
// replicators).
#pragma once

#include <atomic>
#include <vector>

#include "common/codec/update_batch.h"
#include "server/base/counters.h"

namespace terrane {

// The seam's options (ServerOptions::faults), test-only: silently skip
// sending drop_updates UpdateBatch frames (the client's revision still
// advances on the server's books), then send corrupt_updates of them with
// one voxel wrong.
struct UpdateFaultOptions {
  int drop_updates = 0;
  int corrupt_updates = 0;
};

class UpdateFaults {
 public:
  virtual ~UpdateFaults() = default;
  // Before an UpdateBatch is joined from pieces (in chunk order): false
  // drops the batch. A piece may be replaced by one kept in scratch, which
  // the caller keeps alive until the batch is joined.
  virtual bool tamper(std::vector<const UpdatePiece*>& pieces, UpdatePiece& scratch) = 0;
};

// Drops the next drop batches, then corrupts the next corrupt ones (one
// voxel of the first unit of the first chunk made wrong: Air becomes Rock,
// anything else Air), counting each (updates_dropped_by_fault,
// updates_corrupted_by_fault); then lets every batch through.
class BudgetedUpdateFaults final : public UpdateFaults {
 public:
  BudgetedUpdateFaults(int drop, int corrupt, ServerCounters& counters);
  bool tamper(std::vector<const UpdatePiece*>& pieces, UpdatePiece& scratch) override;

 private:
  // Takes one from budget if any is left.
  static bool take(std::atomic<int>& budget);

  std::atomic<int> drop_;
  std::atomic<int> corrupt_;
  ServerCounters& counters_;
};

}  // namespace terrane
