// The storage room's options: the loader threads, the edit log's
// retention and the free space needed at the start. Plain data, filled by main.cpp (part of ServerOptions,
// server/server_options.h); the Server gives them to Storage::open and
// Storage::set_edit_log_retention.
#pragma once

#include <cstdint>

namespace terrane {

struct StorageOptions {
  // Loader threads: reading stored chunks and generating missing ones.
  int worker_threads = 2;
  // The edit log (who changed what, for terrane-admin log and rollback)
  // keeps entries this many days and this many MiB of voxels (0: no bound).
  std::uint32_t edit_log_days = 30;
  std::uint32_t edit_log_mb = 1024;
  // A world directory's file system must have this many MiB free at the
  // start, or the server refuses to start (a full disk would fail the
  // first tick that stores); 0: no check.
  std::uint64_t min_free_mb = 64;
};

}  // namespace terrane
