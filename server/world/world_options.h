// The world room's options: the tick, the chunks kept loaded, edits and
// their undo history, presence and the mip news. Plain data, filled by
// main.cpp (part of ServerOptions, server/server_options.h) and given to
// the WorldOwner, which hands it to its owners; replicators read the
// edit rate and the mips' refresh period through WorldOwner::options().
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>

namespace terrane {

struct WorldOptions {
  // An edit waits for the next tick, up to one period: at 60 Hz a sixth of
  // the 100 ms an edit may take to reach every holder, at 30 Hz a third.
  // (World 1,000 on 2 cores, median of 3: fan-out p50 47.5 -> 24.2 ms,
  // p99 175.8 -> 140.0 ms from 30 to 60 Hz, the server's CPU unchanged.)
  std::uint32_t tick_hz = 60;
  std::size_t max_edits_queued_per_client = 64;
  // A player's edits per second (0 = unlimited): a client's flood beyond
  // the burst (edits_per_second * 2) disconnects it (its replicator
  // counts), and edits forwarded from other servers are held to it too.
  double edits_per_second = 20;
  // Presence: how often (0 = never) and how many of the nearest clients.
  std::uint32_t presence_hz = 2;
  std::size_t presence_max_entries = 32;
  // Chunks a client holds as mips are refreshed at most this often, with
  // their newest version (0: at the tick that changed them).
  std::uint32_t mip_refresh_ms = 500;
  // Chunks kept loaded beyond those someone holds at full resolution or is
  // editing (about once a second the least recently used of the rest go;
  // they come back from the store).
  std::size_t resident_chunks = 32768;
  // Undo and redo history kept per client, in bytes (oldest steps go first).
  std::size_t history_bytes_per_client = 4u << 20;
  // The histories kept for identified players between their sessions, in
  // bytes over all of them (the longest parked go first).
  std::size_t parked_history_bytes = 64u << 20;
  // Called (on the world strand) when the server cannot go on, e.g. the
  // store refused a tick's changes; the owner of the Server should stop it.
  std::function<void()> on_fatal;
};

}  // namespace terrane
