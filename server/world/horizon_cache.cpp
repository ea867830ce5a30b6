#include "server/world/horizon_cache.h"

#include "common/world/coarse_image.h"
#include "server/base/log.h"

namespace terrane {

HorizonCache::HorizonCache(Strand& strand, Storage& storage, FanOut& clients)
    : strand_(strand), storage_(storage), clients_(clients) {}

void HorizonCache::want(ClientId id, const std::vector<HorizonWant>& wants) {
  if (!clients_.present(id)) return;
  std::vector<HorizonPtr> ready;
  const auto now = std::chrono::steady_clock::now();
  for (const HorizonWant& w : wants) {
    const auto k = static_cast<std::size_t>(w.level - kHorizonNearLevel);
    if (auto it = kept_[k].find(w.region);
        it != kept_[k].end() && (!it->second.changed || now - it->second.made < kRefresh)) {
      ready.push_back(it->second.image);
      continue;
    }
    auto [making, fresh] = making_[k].try_emplace(w.region);
    making->second.waiting.push_back(id);
    if (fresh)
      storage_.load_horizon(w.region, w.level, [this](LoadedHorizon h) {
        asio::post(strand_, [this, h = std::move(h)]() mutable { on_loaded(std::move(h)); });
      });
  }
  if (!ready.empty()) clients_.horizons(id, std::move(ready));
}

void HorizonCache::on_loaded(LoadedHorizon h) {
  const auto k = static_cast<std::size_t>(h.level - kHorizonNearLevel);
  auto node = making_[k].extract(h.region);
  const bool changed = !node.empty() && node.mapped().changed;
  HorizonPtr image = h.image;
  if (!image) {
    server_log().error("horizon image of region ({},{},{}): {}; its chunks are sent as usual", h.region.x, h.region.y,
                       h.region.z, h.error);
    image = std::make_shared<const HorizonImage>(HorizonImage{h.region, h.level, {}});
  } else {
    // Kept even when its region changed while it was being made (marked so):
    // in a busy region that happens often, and the refresh rule applies.
    if (kept_[k].size() >= kMaxImages) kept_[k].clear();
    kept_[k].insert_or_assign(h.region, Kept{image, std::chrono::steady_clock::now(), changed});
  }
  if (node.empty()) return;
  for (const ClientId id : node.mapped().waiting) clients_.horizons(id, {image});
}

void HorizonCache::changed(Vec3i cp) {
  const Vec3i region = coarse_region_of(cp);
  for (std::size_t k = 0; k < kHorizonLevels; ++k) {
    if (auto it = kept_[k].find(region); it != kept_[k].end()) it->second.changed = true;
    if (auto it = making_[k].find(region); it != making_[k].end()) it->second.changed = true;
  }
}

}  // namespace terrane
