// Walker: a script's body in the world — where it stands and faces, and how
// it moves there: move_to within the server's move budget (Pacing), walk_to
// over the voxel surface, and the search and step check terrane.walk steps
// on the event loop (find_path, can_stand). It owns the facing (the
// script's: the server is not told) and shares the client and its Pacing
// with the Client that holds it. Python side: called with the GIL held;
// waits and searches release it.
#pragma once

#include <memory>
#include <vector>

#include "client/client.h"
#include "client/path.h"
#include "client/python/events.h"
#include "client/python/pacing.h"

namespace terrane::python {

class Walker {
 public:
  static constexpr float kEyeHeight = 1.6f;

  Walker(std::shared_ptr<Client> c, std::shared_ptr<Pacing> pacing) : c_(std::move(c)), pacing_(std::move(pacing)) {}

  Vec3f position() const;
  Vec3f eye() const { return position() + Vec3f{0, kEyeHeight, 0}; }
  Vec3f facing() const { return facing_; }
  // Faces point from the eye; returns the unit direction.
  Vec3f look_at(Vec3f point);

  // Moves at once, or once the server's move budget allows (raises
  // ValueError beyond ten seconds of it).
  void move_to(Vec3f position);
  // Walks to the place to stand nearest target at speed voxels a second,
  // each step checked again as the world changes; returns the places walked.
  std::vector<IVec3> walk_to(Vec3f target, double speed, double timeout, std::size_t max_nodes);
  // The way walk_to would take now, without moving; whether a walker can
  // stand at p now.
  std::vector<IVec3> find_path(Vec3f target, double timeout, std::size_t max_nodes);
  bool can_stand(Vec3i p) const;

 private:
  // A way from where the client stands to target (client/path.h), or
  // Unreachable / TimeoutError with the reason.
  std::vector<Vec3i> plan(Vec3f target, const PathOptions& o) const;

  std::shared_ptr<Client> c_;
  std::shared_ptr<Pacing> pacing_;  // the moves' budget (the Client paces edits with it)
  Vec3f facing_{0, 0, 1};
};

}  // namespace terrane::python
