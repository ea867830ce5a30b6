// What the world strand says to a connected client (WorldClient, made by
// its replicator), what streaming asks of it (ChunkWant, HorizonWant), and
// what a rollback comes to (RollbackResult).
// Plain interface and data; every WorldClient call is made on the world
// strand, and implementations post to the client's own strand.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/world/horizon.h"
#include "server/base/chunk_version.h"
#include "server/base/counters.h"
#include "server/net/session.h"  // SharedFrame, SendClass: the world still builds frames
#include "server/world/interest.h"

namespace terrane {

// What the world needs of a connected client. Each call is made on the
// world strand; implementations post to the client's own strand.
class WorldClient {
 public:
  virtual ~WorldClient() = default;
  // Versions of chunks the client asked for (in want), nearest asked first.
  virtual void granted(std::vector<VersionPtr> versions) = 0;
  // Horizon images the client asked for (want_horizon), in the order they
  // were made. An image with no unit could not be made (its region's
  // coarse image is unreadable): the chunks come as usual.
  virtual void horizons(std::vector<HorizonPtr> images) = 0;
  // A committed tick's new versions of chunks the client holds at full
  // resolution (with mip_refresh_ms 0: of every chunk it holds).
  virtual void committed(std::uint64_t tick, std::vector<VersionPtr> changed) = 0;
  // New versions of chunks the client holds coarser than full resolution,
  // gathered for mip_refresh_ms since the first of them (oldest first; a
  // chunk may come more than once), the newest committed at tick: to be
  // refreshed now.
  virtual void mips_changed(std::uint64_t tick, std::vector<VersionPtr> changed) = 0;
  // Frames the world answers with (acks, rejects, read results, presence).
  virtual void send(SharedFrame frame, SendClass cls) = 0;
  virtual void close(CloseReason why, const std::string& text) = 0;
};

// A rollback's outcome (WorldOwner::rollback).
struct RollbackResult {
  bool ok = false;
  std::string error;
  std::uint64_t tick = 0;
  std::uint64_t voxels_restored = 0;
};

struct HorizonWant {
  Vec3i region;
  int level = kHorizonFarLevel;
};

struct ChunkWant {
  Vec3i chunk_pos;
  bool full = false;  // the client will hold it at full resolution
  int level = 0;      // the level it will be sent at: 0 full, 1..3 a mip (3: served from coarse images)
  bool exact = false; // never an estimate (ChunkVersion::estimate), even at level 3
};

}  // namespace terrane
