#include "server/world/parked_histories.h"

#include <algorithm>
#include <utility>

namespace terrane {

void ParkedHistories::park(const std::string& player, History history) {
  take(player);  // the older one goes
  if (history.steps(false) == 0 && history.steps(true) == 0) return;
  bytes_ += history.bytes();
  by_player_.insert_or_assign(player, Parked{std::move(history), next_order_++});
  // Over the bound: the longest parked go (a few hundred players at most
  // are parked within it; a scan per eviction is cheap at that size).
  while (bytes_ > max_bytes_ && !by_player_.empty()) {
    const auto oldest = std::min_element(by_player_.begin(), by_player_.end(), [](const auto& a, const auto& b) {
      return a.second.order < b.second.order;
    });
    bytes_ -= oldest->second.history.bytes();
    by_player_.erase(oldest);
  }
}

std::optional<History> ParkedHistories::take(const std::string& player) {
  auto it = by_player_.find(player);
  if (it == by_player_.end()) return std::nullopt;
  bytes_ -= it->second.history.bytes();
  History h = std::move(it->second.history);
  by_player_.erase(it);
  return h;
}

}  // namespace terrane
