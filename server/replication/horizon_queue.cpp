#include "server/replication/horizon_queue.h"

namespace terrane {

void HorizonQueue::clear() {
  wanted_.clear();
  order_.clear();
  early_.clear();
}

bool HorizonQueue::want(Vec3i region, int level) {
  if (!wanted_.emplace(region, static_cast<std::uint8_t>(level)).second) return false;
  order_.push_back(region);
  return true;
}

void HorizonQueue::arrive(std::vector<HorizonPtr> images, const std::function<void(const HorizonPtr&)>& send) {
  for (HorizonPtr& image : images) {
    auto w = wanted_.find(image->region);
    if (w == wanted_.end() || w->second != image->level) continue;  // asked for by an earlier plan
    early_.insert_or_assign(image->region, std::move(image));
  }
  while (!order_.empty()) {
    auto ready = early_.find(order_.front());
    if (ready == early_.end()) break;
    const HorizonPtr image = std::move(ready->second);
    early_.erase(ready);
    order_.pop_front();
    wanted_.erase(image->region);
    send(image);
  }
}

}  // namespace terrane
