// HorizonCache: the horizon images made for clients (Storage::load_horizon),
// kept until a chunk of their region changes (and kRefresh has passed),
// and the images being made with the clients waiting for each. Runs on the
// world strand; Storage's callbacks are posted back to it.
#pragma once

#include <asio.hpp>
#include <chrono>
#include <cstddef>
#include <unordered_map>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/world/horizon.h"
#include "server/storage/storage.h"
#include "server/world/fan_out.h"
#include "server/world/world_client.h"

namespace terrane {

class HorizonCache {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;
  // Images kept at most (a few kilobytes each); beyond, all are dropped
  // and made again when wanted.
  static constexpr std::size_t kMaxImages = 4096;
  // A kept image whose region changed is served until it is this old, then
  // made again when next wanted: images are approximate, and remaking one
  // after every tick that edits its region would cost a busy world a
  // region's read per joining client.
  static constexpr std::chrono::seconds kRefresh{10};

  HorizonCache(Strand& strand, Storage& storage, FanOut& clients);

  // Images of these regions at these levels (nearest first) for id: those
  // kept go at once (FanOut::horizons), the others as each is made.
  void want(ClientId id, const std::vector<HorizonWant>& wants);
  // A chunk of chunk_pos's region changed: its images are made again when
  // next wanted after kRefresh.
  void changed(Vec3i chunk_pos);

 private:
  struct Kept {
    HorizonPtr image;
    std::chrono::steady_clock::time_point made;
    bool changed = false;  // a chunk of the region changed since
  };
  struct Making {
    std::vector<ClientId> waiting;
    bool changed = false;  // kept as changed once made
  };
  void on_loaded(LoadedHorizon h);

  Strand& strand_;
  Storage& storage_;
  FanOut& clients_;
  // Each indexed by level - kHorizonNearLevel.
  std::unordered_map<Vec3i, Kept, Vec3iHash> kept_[kHorizonLevels];
  std::unordered_map<Vec3i, Making, Vec3iHash> making_[kHorizonLevels];
};

}  // namespace terrane
