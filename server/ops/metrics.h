// Metrics: the server's counters in Prometheus' text exposition format
// (version 0.0.4), for `terrane-server --metrics ADDR:PORT` (/metrics) and
// the health rule behind /health. Pure functions of counters read with
// relaxed loads: a scrape may see one counter a moment ahead of another,
// never a torn value.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

#include "common/world/world_bounds.h"
#include "server/base/counters.h"
#include "server/storage/storage.h"
#include "server/base/chunk_version.h"

namespace terrane {

// What the process itself costs (Linux /proc/self; zeros elsewhere).
struct ProcessStats {
  double cpu_seconds = 0;
  std::uint64_t resident_bytes = 0;
  std::uint64_t virtual_bytes = 0;
  std::uint64_t open_fds = 0;
  double start_time_seconds = 0;  // since the Unix epoch
};
ProcessStats read_process_stats();

struct MetricsSources {
  const ServerCounters& server;
  const StorageCounters& storage;
  const EncodeCounters& encode;
  bool storage_failed = false;
  ProcessStats process;
  // Streaming yielding to live traffic (replication/stream_gate.h).
  std::uint64_t stream_gate_closings = 0;
  double stream_gate_closed_seconds = 0;
  // Free bytes on the world directory's file system (none: a PostgreSQL
  // world, or not readable).
  std::optional<std::uint64_t> disk_free_bytes = std::nullopt;
  // The world's bounds as they are now (its border: the horizontal limits,
  // while bounded_xz); default: no border.
  WorldBounds bounds = {};
  // This process's SQLite memory (sqlite_memory_used()): a world
  // directory's page caches and statements (the loaders', the writer's and
  // the world's connections); a PostgreSQL world's servers have none.
  std::int64_t store_memory_bytes = 0;
  // When the sample is taken (the lease renewal's age is counted to it).
  std::chrono::steady_clock::time_point now = std::chrono::steady_clock::now();
};

// Every metric, named terrane_* (process_* for the process), with HELP and
// TYPE lines; counters end in _total, durations are _seconds histograms.
std::string render_metrics(const MetricsSources& s);

// /health: the server's state, for orchestrators (Docker, Kubernetes,
// Agones) to act on:
//   starting  not ticking yet (503)
//   ready     ticking and storing (200)
//   draining  a shutdown is pending or under way (503): take it out of
//             rotation, send no new players (Operations::health())
//   failing   its changes cannot be stored, or it stopped ticking (503)
// check_health() gives starting, ready or failing. Failing: a tick is
// overdue after max(1 s, 10 tick periods) without one. A shared
// PostgreSQL world (lease_renewal: its leases' renewal period; 0 for a
// world directory) is also failing while a commit is tried again, while
// the last renewal round that reached the database is older than two
// renewal periods, while the connection listening for the other servers'
// notices is broken, and while the inbox cannot be read
// (ServerCounters::database).
enum class HealthState { kStarting, kReady, kDraining, kFailing };
inline constexpr HealthState kHealthStates[] = {HealthState::kStarting, HealthState::kReady, HealthState::kDraining,
                                                HealthState::kFailing};
const char* health_state_name(HealthState s);  // "starting", "ready", "draining", "failing"

struct Health {
  HealthState state = HealthState::kFailing;
  std::string text;  // "ok", or why not ready (one line)
  bool ok() const { return state == HealthState::kReady; }
};
Health check_health(const ServerCounters& c, bool storage_failed, std::uint32_t tick_hz,
                    std::chrono::steady_clock::time_point now,
                    std::chrono::milliseconds lease_renewal = std::chrono::milliseconds(0));

// The state as a gauge: terrane_health_state{state="..."}, 1 for the
// current state and 0 for the others (appended to /metrics by Operations).
std::string render_health_gauge(const Health& h);

}  // namespace terrane
