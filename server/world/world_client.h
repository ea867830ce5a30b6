// What the world strand says to a connected client (WorldClient, made by
// its replicator) and answers it with (WorldAnswer), what streaming asks of
// it (ChunkWant, HorizonWant), and what a rollback comes to
// (RollbackResult).
// Plain interface and data; every WorldClient call is made on the world
// strand, and implementations post to the client's own strand.
#pragma once

#include <cstdint>
#include <string>
#include <variant>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/world/horizon.h"
#include "server/base/chunk_version.h"
#include "server/base/counters.h"
#include "protocol/messages.h"
#include "protocol/presence_records.h"
#include "server/world/interest.h"

namespace terrane {

// An edit applied: its tick is committed (the EditAck message).
struct EditAcked {
  std::uint32_t edit_id = 0;
  std::uint64_t tick = 0;
  friend bool operator==(const EditAcked&, const EditAcked&) = default;
};

// The placed clients nearest a client, sent when they changed (the
// Presence message).
struct PresenceNearby {
  std::vector<PresenceEntryMsg> entries;
};
// What changed in that list since the client was last told, for a client
// that takes PresenceRecords (the PresenceRecords message).
struct PresenceChanged {
  std::vector<PresenceRecord> records;
};

// What the world answers one client with: an edit applied (EditAcked) or
// refused (EditRejectMsg; with a box, the true state of what the edit would
// have touched, read after every change already told), a read of a box
// (ReadBoxResultMsg), a chunk's hash (ChunkHashMsg), presence. The world
// only says what; the client's replicator makes the frame and picks its
// send class (server/replication/world_answers.h).
using WorldAnswer =
    std::variant<EditAcked, EditRejectMsg, ReadBoxResultMsg, ChunkHashMsg, PresenceNearby, PresenceChanged>;

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
  // An answer to the client (WorldAnswer), in the order the world gives
  // them, after what the world told the client before.
  virtual void answer(WorldAnswer answer) = 0;
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
