// Per-client undo and redo on the world strand: each step is a box and its
// voxels before and after (byte RLE, as the storage article keeps undo
// data), bounded in bytes per client (the oldest steps go first, undo
// before redo).
//
// Undo restores only voxels still as the client left them: where another
// client has since changed a voxel, its change stands (PROTOCOL.md, "Undo
// and redo"). Redo is the undo of an undo.
// Thread-safety: none; the world strand owns every History.
#pragma once

#include <cstdint>
#include <deque>
#include <string>
#include <vector>

#include "common/voxel/grid.h"
#include "server/world/edits.h"

namespace terrane {

struct HistoryEntry {
  Region box;
  std::vector<std::uint8_t> before, after;
  std::size_t bytes() const { return before.size() + after.size() + sizeof(HistoryEntry); }
};

// Byte RLE of the box's voxels in grid.
std::vector<std::uint8_t> snapshot(const Grid& grid, const Region& box);

class History {
 public:
  explicit History(std::size_t max_bytes) : max_bytes_(max_bytes) {}

  // A new edit: its step goes on the undo list and the redo list is dropped
  // (a new edit forks the history).
  void record(HistoryEntry e);
  // The box the next undo (or redo) would restore, if any.
  const HistoryEntry* top(bool redo) const;
  // Applies the top undo (or redo) step to grid; false with *why when there
  // is none. The step moves to the other list.
  bool apply(Grid& grid, bool redo, ChangedUnits& changed, std::string* why);
  // Drops the top step without applying it.
  void drop(bool redo);

  std::size_t bytes() const { return bytes_; }
  std::size_t steps(bool redo) const { return (redo ? redo_ : undo_).size(); }

 private:
  void push(std::deque<HistoryEntry>& to, HistoryEntry e);

  std::size_t max_bytes_;
  std::size_t bytes_ = 0;
  std::deque<HistoryEntry> undo_, redo_;
};

}  // namespace terrane
