// HorizonQueue: the horizon images one client's plan asked the world for
// (a region's image at one level each), and their turn: they are sent
// nearest region first, in the order the plan asked for them, however the
// world's threads make them. An image that comes before its turn waits
// here; one of a region this plan did not ask for, or at another level,
// answers an earlier plan and is dropped. Streaming's first pass (the
// chunks' own records) waits while any image is still to come.
//
// Threading: the client's session strand (one replicator's).
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/voxel/vec3_map.h"
#include "common/world/horizon.h"

namespace terrane {

class HorizonQueue {
 public:
  // A new plan: what the last one asked for is forgotten.
  void clear();
  // Asks for region's image at level, after those asked before; false if
  // this plan asked for the region already (nothing changes).
  bool want(Vec3i region, int level);
  // Whether an image this plan asked for is still to come.
  bool waiting() const { return !wanted_.empty(); }
  // Images as the world made them: each kept until its turn; send is
  // called for each image whose turn came, in the plan's order.
  void arrive(std::vector<HorizonPtr> images, const std::function<void(const HorizonPtr&)>& send);

 private:
  Vec3iMap<std::uint8_t> wanted_;  // region -> level, until sent
  std::deque<Vec3i> order_;        // the same regions, in the plan's order
  Vec3iMap<HorizonPtr> early_;     // images that came before their turn
};

}  // namespace terrane
