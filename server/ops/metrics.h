// Metrics: the server's counters in Prometheus' text exposition format
// (version 0.0.4), for `terrane-server --metrics ADDR:PORT` (/metrics) and
// the health rule behind /health. Pure functions of counters read with
// relaxed loads: a scrape may see one counter a moment ahead of another,
// never a torn value.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

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
  // When the sample is taken (the lease renewal's age is counted to it).
  std::chrono::steady_clock::time_point now = std::chrono::steady_clock::now();
};

// Every metric, named terrane_* (process_* for the process), with HELP and
// TYPE lines; counters end in _total, durations are _seconds histograms.
std::string render_metrics(const MetricsSources& s);

// /health: healthy while the world ticks and its changes can be stored. A
// tick is overdue after max(1 s, 10 tick periods) without one. A shared
// PostgreSQL world (lease_renewal: its leases' renewal period; 0 for a
// world directory) is also unhealthy while a commit is tried again, while
// the last renewal round that reached the database is older than two
// renewal periods, while the connection listening for the other servers'
// notices is broken, and while the inbox cannot be read
// (ServerCounters::database).
struct Health {
  bool ok = false;
  std::string text;  // "ok", or what is wrong (one line)
};
Health check_health(const ServerCounters& c, bool storage_failed, std::uint32_t tick_hz,
                    std::chrono::steady_clock::time_point now,
                    std::chrono::milliseconds lease_renewal = std::chrono::milliseconds(0));

}  // namespace terrane
