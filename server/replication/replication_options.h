// The replication room's options: views and their caps, streaming's window,
// rate and yield, pushed hashes, claims, and the per-client limits the
// replicator checks. Plain data, filled by main.cpp (part of ServerOptions,
// server/server_options.h) and given to each Replicator (and the view
// caps to the Welcome).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>

#include "protocol/messages.h"

namespace terrane {

struct ReplicationOptions {
  // The largest view a server serves: a view's table of chunk offsets grows
  // with its cube (about 15 MB at 2,048, 120 MB at 4,096).
  static constexpr std::int32_t kViewDistanceLimit = 4096;
  std::int32_t max_view_distance = 2048;   // voxels; client requests are capped to this
  std::int32_t max_full_res_radius = 256;  // voxels
  std::int32_t default_view_distance = 2048;   // until the client sends ClientState
  std::int32_t default_full_res_radius = 128;
  std::size_t stream_window_bytes = 512 * 1024;
  // Streaming yields when work waits longer than this on the io threads or
  // the world strand (replication/stream_gate.h); 0: it never yields.
  std::chrono::milliseconds stream_yield{20};
  // Chunks a resuming client may claim (Holdings) in all.
  std::size_t max_claims_per_client = 65536;
  // Each client is sent the hash of one of its full-resolution chunks this
  // often (0 = only on request).
  std::uint32_t hash_push_ms = 1000;
  // A distant chunk never generated is first sent as an estimate of its
  // coarsest mip (World::estimate_coarse), then generated in the background
  // and corrected; false: generated whole before its mip is sent. (Storage
  // is told too: Storage::set_horizon_estimates.)
  bool horizon_estimates = true;
  // A new view's first pass: every region of it as one horizon image (2^3
  // or 1 voxel per chunk), before any chunk's own coarsest mip.
  bool horizon_images = true;
  // Regions beyond 1,024 voxels at one voxel per 2^3 chunks (level 6), and
  // 2^3 voxels per chunk only within 256, to a client that takes them
  // (Hello.features); false: every client as one that does not.
  bool outer_horizon = true;
  // A changed mip of level 1 or 2 is refreshed as a Mip patch (its changed
  // 4^3 sub-units) to a client that takes them (Hello.features), when the
  // patch is smaller than the mip; false: always the whole mip.
  bool mip_patches = true;
  // Presence goes as PresenceRecords to a client that takes them
  // (Hello.features); false: whole Presence lists to every client.
  bool presence_records = true;
  // Per-client limits (0 = unlimited where a rate). A move faster than
  // max_speed (plus kSpeedSlackVoxels, replication/move_limit.h)
  // disconnects the client; an edit over max_edit_voxels is rejected. (The
  // edit rate is the world's: WorldOptions::edits_per_second.)
  std::int64_t max_edit_voxels = kMaxEditVolume;
  double max_speed = 256;                    // voxels per second
  double outbound_bytes_per_second = 32 << 20;  // streaming; updates are never held back
};

}  // namespace terrane
