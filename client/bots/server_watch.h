// ServerWatch: the server's own figures for a bots run, from its metrics
// endpoint (terrane-server --metrics; terrane-bots --server-metrics). A
// thread scrapes /metrics once a second from start() to stop(); figures()
// turns the first and last scrape into the run's deltas (CPU, edits, ticks,
// bytes by message type) and every scrape into the peak RSS.
// Thread-safety: start/stop/figures from the run's thread only.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

namespace terrane::bots {

// One scrape: each sample's series (name and labels exactly as exposed)
// and its value. Malformed lines are skipped; comments ignored.
using Scrape = std::map<std::string, double>;
Scrape parse_exposition(const std::string& text);

// The p-quantile's bucket bound, in ms, of a histogram's growth between
// two scrapes ("le" bounds); +inf when it lies beyond the last bound, and
// nullopt without observations.
std::optional<double> histogram_quantile_ms(const Scrape& first, const Scrape& last, const std::string& name, double q);
// The mean, in ms, of a histogram's observations between two scrapes
// (_sum and _count); nullopt without observations.
std::optional<double> histogram_mean_ms(const Scrape& first, const Scrape& last, const std::string& name);

// The server between two scrapes: the timeline's second-by-second view of
// it, so a slow second can be told to be the server's or the bots'.
struct ServerInterval {
  double cpu_share = 0;  // of one core
  std::uint64_t edits_applied = 0;
  std::optional<double> tick_ms_mean, commit_ms_mean, edit_ack_ms_mean;
  std::optional<double> edit_ack_p99_ms;  // bucket bound (histogram_quantile_ms)
  // The longest tick, store transaction and fan-out of the interval, as the
  // bound of the highest bucket reached: with about 30 of each a second a
  // p99 would say no more, and one slow commit holds every edit behind it.
  std::optional<double> tick_ms_max, commit_ms_max, fanout_ms_max;
  std::uint64_t ticks_late = 0;  // started more than a period late
  std::optional<double> tick_p99_ms;  // bucket bound (histogram_quantile_ms)
  // Gauges at the interval's end (nullopt when the server does not expose
  // them): resident memory and the bytes queued for sending, every session
  // together (terrane_send_queue_bytes).
  std::optional<std::uint64_t> rss_bytes, send_queue_bytes;
};
ServerInterval server_interval(const Scrape& first, double first_at_s, const Scrape& last, double last_at_s);

// The server from the first scrape to the one taken once every bot had
// joined at full resolution (ServerWatch::mark_joined): what the joins cost
// it. Records: chunk records streamed (full, mip, empty, estimate) and
// region horizon images.
struct JoinCost {
  double wall_s = 0, cpu_s = 0;
  std::uint64_t records = 0, stream_bytes = 0;
};

struct ServerFigures {
  double wall_s = 0;             // between the first and last scrape
  double cpu_s = 0;              // process_cpu_seconds_total growth
  std::uint64_t rss_peak = 0;    // largest process_resident_memory_bytes seen
  std::uint64_t edits_applied = 0, edits_rejected = 0;
  std::uint64_t ticks = 0, ticks_late = 0, disconnects = 0;
  std::optional<double> tick_p99_ms, commit_p99_ms, fanout_p99_ms;
  // An edit inside the server (terrane_edit_ack_duration_seconds): from its
  // session handing it to the world to its ack being queued.
  std::optional<double> edit_ack_mean_ms, edit_ack_p99_ms;
  // Streaming paused because the server was behind (its stream gate).
  std::uint64_t stream_gate_closings = 0;
  double stream_gate_closed_s = 0;
  std::map<std::string, std::pair<std::uint64_t, std::uint64_t>> sent_by_type;  // frames, bytes
  std::optional<JoinCost> joins;  // once mark_joined() was called
  int scrapes = 0, scrape_errors = 0;
  std::string first_error;
};

JoinCost join_cost(const Scrape& first, double first_at_s, const Scrape& joined, double joined_at_s);

class ServerWatch {
 public:
  ServerWatch(std::string host, std::uint16_t port);
  ~ServerWatch();
  ServerWatch(const ServerWatch&) = delete;
  ServerWatch& operator=(const ServerWatch&) = delete;

  // Scrapes once now (false with *error when the endpoint does not answer),
  // then every second on a thread of its own.
  bool start(std::string* error);
  // Scrapes a last time and stops the thread.
  void stop();
  // Scrapes now and keeps it as the end of the joins (JoinCost); the first
  // call counts.
  void mark_joined();
  ServerFigures figures() const;
  // The server from the scrape the previous call ended at (the first
  // scrape, at the first call) to the newest; nullopt when no scrape came
  // since. Called once a second, it trails the caller's second by up to one.
  std::optional<ServerInterval> next_interval();

 private:
  bool scrape(std::string* error);
  void loop();

  std::string host_;
  std::uint16_t port_;
  std::thread thread_;
  mutable std::mutex m_;
  std::condition_variable cv_;
  bool stopping_ = false;
  // mark_: where the next interval starts (the first scrape, then the
  // newest at each next_interval()).
  Scrape first_, last_, mark_;
  std::optional<Scrape> joined_;
  double joined_at_s_ = 0;
  double first_at_s_ = 0, last_at_s_ = 0, mark_at_s_ = 0;
  std::uint64_t rss_peak_ = 0;
  int scrapes_ = 0, errors_ = 0;
  std::string first_error_;
};

}  // namespace terrane::bots
