#include "client/edit_tracker.h"

#include <algorithm>

namespace terrane {

std::uint32_t EditTracker::begin() {
  const std::uint32_t id = next_id_++;
  if (next_id_ == 0) next_id_ = 1;
  unanswered_[id] = false;
  return id;
}

void EditTracker::written(std::uint32_t id) {
  // Its answer may have been read before the write's completion ran.
  if (auto it = unanswered_.find(id); it != unanswered_.end()) it->second = true;
}

void EditTracker::answered(std::uint32_t id, EditOutcome o) {
  unanswered_.erase(id);
  outcomes_[id] = std::move(o);
}

bool EditTracker::awaiting_written() const {
  return std::any_of(unanswered_.begin(), unanswered_.end(), [](const auto& e) { return e.second; });
}

SettledEdits EditTracker::settle_unanswered() { return settle(false); }
SettledEdits EditTracker::settle_written() { return settle(true); }

SettledEdits EditTracker::settle(bool written_only) {
  SettledEdits unknown;
  for (auto it = unanswered_.begin(); it != unanswered_.end();) {
    if (written_only && !it->second) {
      ++it;
      continue;
    }
    EditOutcome o{false, 0, kEditOutcomeUnknown, {}, {}, true};
    outcomes_[it->first] = o;
    unknown.emplace_back(it->first, std::move(o));
    it = unanswered_.erase(it);
  }
  return unknown;
}

}  // namespace terrane
