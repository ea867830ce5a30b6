#include "server/ops/metrics.h"

#include <dirent.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <utility>
#include <vector>

#include "protocol/messages.h"

namespace terrane {

namespace {

// Writes one metric family at a time: HELP and TYPE, then its samples.
class Exposition {
 public:
  void family(const char* name, const char* type, const char* help) {
    out_ << "# HELP " << name << ' ' << help << "\n# TYPE " << name << ' ' << type << '\n';
  }
  template <class T>
  void sample(const std::string& name, T value, const std::string& labels = {}) {
    out_ << name;
    if (!labels.empty()) out_ << '{' << labels << '}';
    out_ << ' ' << value << '\n';
  }
  template <class T>
  void counter(const char* name, const char* help, T value) {
    family(name, "counter", help);
    sample(name, value);
  }
  template <class T>
  void gauge(const char* name, const char* help, T value) {
    family(name, "gauge", help);
    sample(name, value);
  }
  void histogram(const char* name, const char* help, const DurationHistogram& h) {
    family(name, "histogram", help);
    std::uint64_t cumulative = 0;
    for (std::size_t i = 0; i < DurationHistogram::kBuckets; ++i) {
      cumulative += h.bucket(i);
      std::ostringstream le;
      if (i < DurationHistogram::kBounds.size())
        le << DurationHistogram::kBounds[i];
      else
        le << "+Inf";
      sample(std::string(name) + "_bucket", cumulative, "le=\"" + le.str() + "\"");
    }
    // _count is the +Inf bucket, read once above: the two always agree.
    sample(std::string(name) + "_sum", h.sum_seconds());
    sample(std::string(name) + "_count", cumulative);
  }
  std::string str() const { return out_.str(); }

 private:
  std::ostringstream out_;
};

std::uint64_t load(const std::atomic<std::uint64_t>& a) { return a.load(std::memory_order_relaxed); }

}  // namespace

ProcessStats read_process_stats() {
  ProcessStats p;
  const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  const auto page = static_cast<std::uint64_t>(sysconf(_SC_PAGESIZE));
  if (std::ifstream stat("/proc/self/stat"); stat) {
    std::string line;
    std::getline(stat, line);
    // Fields after the command name (which may hold spaces) start at ')'.
    const auto close = line.rfind(')');
    if (close != std::string::npos && tick > 0) {
      std::istringstream rest(line.substr(close + 2));
      std::string f;
      // rest[0] is field 3 (state); utime, stime are fields 14, 15;
      // starttime is field 22 (clock ticks after boot).
      std::vector<std::string> fields;
      while (rest >> f) fields.push_back(f);
      if (fields.size() > 19) {
        p.cpu_seconds = (std::stod(fields[11]) + std::stod(fields[12])) / tick;
        double boot = 0;
        if (std::ifstream st("/proc/stat"); st) {
          std::string key;
          while (st >> key)
            if (key == "btime") {
              st >> boot;
              break;
            }
        }
        p.start_time_seconds = boot + std::stod(fields[19]) / tick;
      }
    }
  }
  if (std::ifstream statm("/proc/self/statm"); statm) {
    std::uint64_t size = 0, resident = 0;
    statm >> size >> resident;
    p.virtual_bytes = size * page;
    p.resident_bytes = resident * page;
  }
  if (DIR* d = opendir("/proc/self/fd")) {
    while (const dirent* e = readdir(d))
      if (e->d_name[0] != '.') ++p.open_fds;
    closedir(d);
    if (p.open_fds > 0) --p.open_fds;  // the directory stream itself
  }
  return p;
}

std::string render_metrics(const MetricsSources& s) {
  const ServerCounters& c = s.server;
  Exposition m;

  m.gauge("terrane_clients", "Players connected and past the handshake (operators' sessions: terrane_admin_sessions).",
          load(c.clients));
  m.gauge("terrane_admin_sessions", "Operators' sessions (terrane-admin) connected and past the handshake.",
          load(c.admin_sessions));
  m.counter("terrane_sessions_accepted_total", "TCP connections accepted.", load(c.sessions_accepted));
  m.counter("terrane_joins_total", "Handshakes accepted (Welcome sent).", load(c.joins));
  m.family("terrane_disconnects_total", "counter", "Sessions ended, by reason.");
  for (std::size_t r = 0; r < static_cast<std::size_t>(CloseReason::kCount); ++r)
    m.sample("terrane_disconnects_total", load(c.net.disconnects[r]),
             std::string("reason=\"") + close_reason_label(static_cast<CloseReason>(r)) + "\"");
  m.counter("terrane_auth_failures_total", "Handshakes refused for a missing or wrong token.", load(c.auth_failures));
  m.counter("terrane_limit_violations_total", "Clients dropped for exceeding a per-client limit.",
            load(c.limit_violations));

  m.counter("terrane_ticks_total", "World ticks run.", load(c.ticks));
  m.counter("terrane_ticks_late_total", "Ticks that started more than a period late (the schedule restarted).",
            load(c.ticks_late));
  m.histogram("terrane_tick_duration_seconds", "Time the world strand spent in each tick (applying edits, "
                                               "publishing versions, presence, unloading).",
              c.tick_duration);
  m.gauge("terrane_tick_lag_seconds", "How late the last tick started after its scheduled time.",
          static_cast<double>(c.tick_lag_ns.load(std::memory_order_relaxed)) * 1e-9);
  m.histogram("terrane_fanout_duration_seconds",
              "Time the world strand spent handing each committed tick's changes to their holders.",
              c.fanout_duration);
  m.histogram("terrane_edit_ack_duration_seconds",
              "Time from a client's edit reaching the world to its acknowledgement being queued: the wait for "
              "the next tick, the tick, the commit and the fan-out.",
              c.edit_ack_duration);
  m.counter("terrane_deliveries_total", "Changed chunks handed to a holder (one per chunk and holder).",
            load(c.deliveries));

  m.counter("terrane_edits_applied_total", "Edits applied (each acknowledged once stored).", load(c.edits_applied));
  m.family("terrane_edits_rejected_total", "counter", "Edits refused, by reason.");
  for (std::size_t r = 0; r < static_cast<std::size_t>(RejectReason::kCount); ++r)
    m.sample("terrane_edits_rejected_total", load(c.edits_rejected_by[r]),
             std::string("reason=\"") + reject_reason_label(static_cast<RejectReason>(r)) + "\"");

  const StorageCounters& st = s.storage;
  m.histogram("terrane_commit_duration_seconds", "Wall time of each store transaction (one or more ticks).",
              st.commit_duration);
  m.histogram("terrane_coarse_catch_up_duration_seconds",
              "Wall time of each transaction writing coarse images after their chunks' commit.",
              st.coarse_catch_up_duration);
  m.gauge("terrane_coarse_regions_pending", "Regions whose coarse image is behind its chunks (loads read past it).",
          load(st.coarse_regions_pending));
  m.counter("terrane_commits_total", "Store transactions committed.", load(st.commits));
  m.counter("terrane_ticks_committed_total", "Ticks carried by those transactions.", load(st.ticks_committed));
  m.counter("terrane_chunks_written_total", "Chunks written to the store.", load(st.chunks_written));
  m.gauge("terrane_storage_failed", "1 once a tick's changes could not be stored (the server stops serving).",
          s.storage_failed ? 1 : 0);
  if (const std::optional<EditLogSize> log = st.edit_log.get()) {
    m.gauge("terrane_edit_log_entries", "Entries in the edit log (terrane-admin log, rollback), as last counted.",
            log->entries);
    m.gauge("terrane_edit_log_bytes",
            "Bytes of voxels before and after in the edit log's entries (bounded by --edit-log-mb).", log->bytes);
  }
  if (s.disk_free_bytes)
    m.gauge("terrane_disk_free_bytes",
            "Bytes still free on the file system of the world directory (the server stops when a commit fails).",
            *s.disk_free_bytes);
  const DatabaseCounters& db = c.database;
  m.gauge("terrane_storage_retrying",
          "Commits being tried again now because the database went away (a shared PostgreSQL world).",
          load(db.commits_retrying));
  m.counter("terrane_storage_retries_total", "Commit attempts that failed for want of the database and were tried again.",
            load(db.commit_retries));
  const std::int64_t renewed = db.lease_renewed_at_ns.load(std::memory_order_relaxed);
  m.gauge("terrane_lease_renewal_age_seconds",
          "Seconds since the last lease renewal round that reached the database started (0 for a world directory).",
          renewed == 0 ? 0.0 : static_cast<double>(std::max<std::int64_t>(0, steady_ns(s.now) - renewed)) * 1e-9);
  m.gauge("terrane_database_listener_down",
          "1 while the connection hearing the other servers' notices is broken (a shared PostgreSQL world).",
          load(db.listener_down));
  m.gauge("terrane_inbox_read_failing", "1 while the last read of the inbox of forwarded edits failed.",
          load(db.inbox_failing));

  // The border (terrane-server --border): its edges only while there is one.
  const WorldBounds& b = s.bounds;
  m.gauge("terrane_world_bounded", "1 while the world has a horizontal border (terrane-server --border), else 0.",
          b.bounded_xz ? 1 : 0);
  if (b.bounded_xz) {
    m.family("terrane_world_border_voxels", "gauge",
             "The world border's edges in voxels: x from min_x to max_x, z from min_z to max_z, each max excluded "
             "(present only while the world has a border).");
    const std::pair<const char*, std::int32_t> edges[] = {
        {"min_x", b.min_x}, {"max_x", b.max_x}, {"min_z", b.min_z}, {"max_z", b.max_z}};
    for (const auto& [edge, at] : edges)
      m.sample("terrane_world_border_voxels", at, std::string("edge=\"") + edge + "\"");
  }

  m.gauge("terrane_chunks_resident", "Chunks loaded in memory now.", load(c.chunks_loaded));
  m.counter("terrane_chunks_loaded_total", "Chunks read from the store.", load(st.loaded_from_store));
  m.counter("terrane_chunks_generated_total", "Chunks made by the world's generator.", load(st.generated));
  m.counter("terrane_coarse_images_read_total",
            "Coarse images read from the store (each serves the 4^3 mips of a 256^3 region's chunks).",
            load(st.coarse_images_read));
  m.counter("terrane_chunks_unloaded_total", "Chunks dropped from memory (they come back from the store).",
            load(c.chunks_unloaded));
  m.counter("terrane_chunks_quarantined_total", "Stored chunks that failed to decode and were set aside.",
            load(st.quarantined));
  const std::uint64_t asked = load(s.encode.asked), made = load(s.encode.made);
  m.counter("terrane_encode_cache_hits_total", "Chunk encodings served from a version's own copy.",
            asked > made ? asked - made : 0);
  m.counter("terrane_encode_cache_misses_total", "Chunk encodings made (once per version and level).", made);

  m.family("terrane_streamed_chunks_total", "counter", "Chunks streamed to clients, by what was sent.");
  m.sample("terrane_streamed_chunks_total", load(c.chunks_sent), "kind=\"full\"");
  m.sample("terrane_streamed_chunks_total", load(c.mips_sent), "kind=\"mip\"");
  m.sample("terrane_streamed_chunks_total", load(c.empties_sent), "kind=\"empty\"");
  m.sample("terrane_streamed_chunks_total", load(c.estimates_sent), "kind=\"estimate\"");
  m.counter("terrane_horizon_images_sent_total", "Regions sent to clients as one horizon image (a new view's first pass).",
            load(c.horizons_sent));
  m.counter("terrane_horizon_images_made_total", "Horizon images made (each shared by every client until its region changes).",
            load(st.horizons_made));
  m.counter("terrane_coarse_estimated_total", "Never-generated chunks whose coarsest mip was estimated.",
            load(st.coarse_estimated));
  m.counter("terrane_estimates_replaced_total", "Estimated chunks since generated for real.",
            load(c.estimates_replaced));
  m.counter("terrane_estimates_corrected_total",
            "Of those, the chunks whose exact coarsest mip differed from the estimate (holders were sent it).",
            load(c.estimates_corrected));
  m.counter("terrane_chunks_changed_elsewhere_total",
            "Chunks held here that another server of a shared world stored newer: read again from the database, "
            "or forgotten when no client here holds them.",
            load(c.chunks_changed_elsewhere));
  m.counter("terrane_chunks_forgotten_elsewhere_total",
            "Of those, the chunks no client here held: forgotten, read from the database when next wanted.",
            load(c.chunks_forgotten_elsewhere));
  m.counter("terrane_chunks_updated_elsewhere_total",
            "Of those, the chunks brought up to date from the units in the other server's notice, not read again "
            "(their holders are sent the units).",
            load(c.chunks_updated_elsewhere));
  m.counter("terrane_edits_forwarded_total", "Edits in regions another server holds, sent to its inbox.",
            load(c.edits_forwarded));
  m.counter("terrane_forwarded_edits_received_total", "Edits other servers forwarded to this one.",
            load(c.forwarded_edits_received));
  m.counter("terrane_redirects_sent_total",
            "Clients told to go on at the server writing the region they stand in.", load(c.redirects_sent));
  m.counter("terrane_redirects_received_total", "Clients that arrived with a Redirect's token.",
            load(c.redirects_received));
  m.counter("terrane_regions_handed_over_total",
            "Regions released to another server with an edit across their border that it writes.",
            load(c.regions_handed_over));
  m.counter("terrane_chunks_resumed_total", "Chunks a resuming client still held, current, and not resent.",
            load(c.chunks_resumed));
  m.counter("terrane_mip_refreshes_total", "Mips sent again because their bytes changed.", load(c.mip_refreshes));
  m.counter("terrane_mip_patches_total", "Of the mips sent again, those sent as a patch of their changed 4^3 sub-units.",
            load(c.mip_patches));
  m.counter("terrane_update_batches_total", "UpdateBatch frames sent.", load(c.update_batches_sent));
  m.counter("terrane_update_units_total", "4x4x4 update units sent in them.", load(c.update_units_sent));
  m.counter("terrane_presence_sent_total", "Presence frames sent.", load(c.presence_sent));
  m.counter("terrane_hashes_pushed_total", "Chunk hashes pushed to clients unasked.", load(c.hashes_pushed));
  m.counter("terrane_chunks_asked_total", "Chunks the replicators asked the world for (streaming; each view's churn).",
            load(c.chunks_asked));
  m.counter("terrane_stream_yields_total",
            "Times a client's streaming paused because the server was behind (--stream-yield-ms).",
            load(c.stream_yields));
  m.counter("terrane_mip_refresh_yields_total",
            "Times a client's refreshes of mips waited because the server was behind (--stream-yield-ms).",
            load(c.mip_refresh_yields));
  m.counter("terrane_stream_gate_closed_total", "Times streaming was paused server-wide (work waited too long).",
            s.stream_gate_closings);
  m.counter("terrane_stream_gate_closed_seconds_total", "Time streaming was paused server-wide.",
            s.stream_gate_closed_seconds);

  m.gauge("terrane_send_queue_bytes", "Bytes queued for sending, every session together.",
          std::max<std::int64_t>(0, c.net.queued_bytes.load(std::memory_order_relaxed)));
  m.family("terrane_memory_bytes", "gauge",
           "The server's memory by part, estimated by each part's owner from its sizes and counts (the parts "
           "that grow with the clients; send_queues: terrane_send_queue_bytes; store: this process's SQLite memory, "
           "its worlds' page caches and statements).");
  for (std::size_t p = 0; p < static_cast<std::size_t>(MemoryPart::kCount); ++p)
    m.sample("terrane_memory_bytes", std::max<std::int64_t>(0, c.memory.load(static_cast<MemoryPart>(p))),
             std::string("part=\"") + memory_part_label(static_cast<MemoryPart>(p)) + "\"");
  m.sample("terrane_memory_bytes", std::max<std::int64_t>(0, c.net.queued_bytes.load(std::memory_order_relaxed)),
           "part=\"send_queues\"");
  m.sample("terrane_memory_bytes", std::max<std::int64_t>(0, s.store_memory_bytes), "part=\"store\"");
  struct Traffic {
    const char* name;
    const char* help;
    const std::array<std::atomic<std::uint64_t>, NetCounters::kTypes>& values;
  };
  const Traffic traffic[] = {
      {"terrane_sent_bytes_total", "Bytes sent (frame headers included), by message type.", c.net.sent_bytes},
      {"terrane_sent_frames_total", "Frames sent, by message type.", c.net.sent_frames},
      {"terrane_received_bytes_total", "Bytes received (frame headers included), by message type.",
       c.net.received_bytes},
      {"terrane_received_frames_total", "Frames received, by message type.", c.net.received_frames},
  };
  m.counter("terrane_socket_writes_total",
            "Gathered writes to clients' sockets: each takes every frame queued for its session (up to a bound), "
            "so terrane_sent_frames_total over this is the frames a write carries.",
            load(c.net.writes));
  for (const Traffic& t : traffic) {
    m.family(t.name, "counter", t.help);
    for (std::size_t i = 1; i <= static_cast<std::size_t>(wire::Body::MAX) && i < NetCounters::kTypes; ++i)
      m.sample(t.name, load(t.values[i]),
               std::string("type=\"") + wire::EnumNameBody(static_cast<wire::Body>(i)) + "\"");
  }

  const ProcessStats& p = s.process;
  m.counter("process_cpu_seconds_total", "User and system CPU time spent, in seconds.", p.cpu_seconds);
  m.gauge("process_resident_memory_bytes", "Resident memory size, in bytes.", p.resident_bytes);
  m.gauge("process_virtual_memory_bytes", "Virtual memory size, in bytes.", p.virtual_bytes);
  m.gauge("process_open_fds", "Open file descriptors.", p.open_fds);
  m.gauge("process_start_time_seconds", "Start time of the process since the Unix epoch, in seconds.",
          static_cast<std::uint64_t>(p.start_time_seconds));
  m.family("terrane_build_info", "gauge", "Always 1; the labels say which build and protocol this is.");
  m.sample("terrane_build_info", 1,
           "version=\"" TERRANE_VERSION_STRING "\",protocol=\"" + std::to_string(kProtocolVersion) + "\"");
  return m.str();
}

Health check_health(const ServerCounters& c, bool storage_failed, std::uint32_t tick_hz,
                    std::chrono::steady_clock::time_point now, std::chrono::milliseconds lease_renewal) {
  using std::chrono::milliseconds;
  const auto ms_text = [](std::chrono::nanoseconds d) {
    return std::to_string(std::chrono::duration_cast<milliseconds>(d).count()) + " ms";
  };
  constexpr HealthState kFailing = HealthState::kFailing;
  if (storage_failed) return {kFailing, "storage failed: the world's changes can no longer be saved"};
  const DatabaseCounters& db = c.database;
  if (load(db.commits_retrying) > 0)
    return {kFailing, "storage retrying: a commit waits for the database (" + std::to_string(load(db.commit_retries)) +
                       " failed attempts tried again so far)"};
  const std::int64_t last = c.last_tick_at_ns.load(std::memory_order_relaxed);
  const auto period = std::chrono::nanoseconds(1'000'000'000LL / std::max<std::uint32_t>(1, tick_hz));
  const auto limit = std::max<std::chrono::nanoseconds>(std::chrono::seconds(1), period * 10);
  if (last == 0) return {HealthState::kStarting, "not ticking yet"};
  const auto since = std::chrono::nanoseconds(steady_ns(now) - last);
  if (since > limit) return {kFailing, "no tick for " + ms_text(since)};
  if (lease_renewal.count() > 0) {
    const std::int64_t renewed = db.lease_renewed_at_ns.load(std::memory_order_relaxed);
    const auto age = std::chrono::nanoseconds(steady_ns(now) - renewed);
    // Two periods: one round may be slow; none for two means the database
    // is out of reach (a lease lasts ten: LeaseTimes::of).
    if (renewed != 0 && age > 2 * lease_renewal)
      return {kFailing, "database out of reach: leases not renewed for " + ms_text(age)};
  }
  if (load(db.listener_down) != 0)
    return {kFailing, "database connection broken: the other servers' notices are not heard"};
  if (load(db.inbox_failing) != 0) return {kFailing, "database: the inbox of forwarded edits cannot be read"};
  return {HealthState::kReady, "ok"};
}

const char* health_state_name(HealthState s) {
  switch (s) {
    case HealthState::kStarting: return "starting";
    case HealthState::kReady: return "ready";
    case HealthState::kDraining: return "draining";
    case HealthState::kFailing: return "failing";
  }
  return "failing";
}

std::string render_health_gauge(const Health& h) {
  std::string out =
      "# HELP terrane_health_state The state /health answers: 1 for the current one (starting, ready, draining, "
      "failing), 0 for the others.\n# TYPE terrane_health_state gauge\n";
  for (const HealthState s : kHealthStates)
    out += std::string("terrane_health_state{state=\"") + health_state_name(s) + "\"} " + (s == h.state ? "1" : "0") +
           "\n";
  return out;
}

}  // namespace terrane
