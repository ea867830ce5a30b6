#include "server/replication/update_faults.h"

#include <array>
#include <cstddef>


namespace terrane {

BudgetedUpdateFaults::BudgetedUpdateFaults(int drop, int corrupt, ServerCounters& counters)
    : drop_(drop), corrupt_(corrupt), counters_(counters) {}

bool BudgetedUpdateFaults::take(std::atomic<int>& budget) {
  return budget.load(std::memory_order_relaxed) > 0 && budget.fetch_sub(1, std::memory_order_relaxed) > 0;
}

bool BudgetedUpdateFaults::tamper(std::vector<const UpdatePiece*>& pieces, UpdatePiece& scratch) {
  if (pieces.empty()) return true;
  if (take(drop_)) {
    counters_.updates_dropped_by_fault.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  if (!take(corrupt_)) return true;
  // One voxel of the first unit made wrong.
  counters_.updates_corrupted_by_fault.fetch_add(1, std::memory_order_relaxed);
  scratch = *pieces.front();
  std::array<Voxel, kUpdateUnitVoxels> unit{};
  if (auto n = net_codec_decode_prefix(kUpdateUnitSize, scratch.rest, unit); n) {
    Voxel& v0 = unit[0];
    v0 = v0.material == kAir ? solid(materials::kRock) : Voxel{};
    std::vector<std::uint8_t> rest;
    net_codec_encode(kUpdateUnitSize, unit, rest);
    rest.insert(rest.end(), scratch.rest.begin() + static_cast<std::ptrdiff_t>(*n), scratch.rest.end());
    scratch.rest = std::move(rest);
  }
  pieces.front() = &scratch;
  return true;
}

}  // namespace terrane
