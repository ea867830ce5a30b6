#include "client/bots/server_watch.h"

#include <httplib.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <sstream>
#include <vector>

namespace terrane::bots {

namespace {

// A scrape larger than this is refused (a few KiB is usual).
constexpr std::size_t kMaxScrapeBytes = 16u << 20;

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double value_of(const Scrape& s, const std::string& series) {
  auto it = s.find(series);
  return it == s.end() ? 0 : it->second;
}

std::uint64_t growth(const Scrape& first, const Scrape& last, const std::string& series) {
  const double d = value_of(last, series) - value_of(first, series);
  return d > 0 ? static_cast<std::uint64_t>(std::llround(d)) : 0;
}

// Sum of a family's growth over every label set (name{...}).
std::uint64_t family_growth(const Scrape& first, const Scrape& last, const std::string& name) {
  std::uint64_t n = 0;
  const std::string prefix = name + "{";
  for (auto it = last.lower_bound(prefix); it != last.end() && it->first.rfind(prefix, 0) == 0; ++it)
    n += growth(first, last, it->first);
  return n;
}

}  // namespace

Scrape parse_exposition(const std::string& text) {
  Scrape out;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    // The series ends at the space after the closing brace (label values
    // may hold spaces) or at the first space.
    std::size_t end = line.find('{');
    end = end == std::string::npos ? line.find(' ') : line.find("} ", end);
    if (end == std::string::npos) continue;
    if (line[end] == '}') ++end;
    const std::string series = line.substr(0, end);
    std::istringstream v(line.substr(end));
    std::string token;
    v >> token;
    try {
      std::size_t used = 0;
      const double d = token == "+Inf" ? std::numeric_limits<double>::infinity() : std::stod(token, &used);
      if (token != "+Inf" && used != token.size()) continue;
      out[series] = d;
    } catch (const std::exception&) {
      continue;
    }
  }
  return out;
}

std::optional<double> histogram_quantile_ms(const Scrape& first, const Scrape& last, const std::string& name,
                                            double q) {
  // Buckets as (bound, cumulative growth), in the order of their bounds.
  std::vector<std::pair<double, double>> buckets;
  const std::string prefix = name + "_bucket{le=\"";
  for (auto it = last.lower_bound(prefix); it != last.end() && it->first.rfind(prefix, 0) == 0; ++it) {
    const std::string& key = it->first;  // the server's text: checked, never trusted
    if (key.size() < prefix.size() + 2 || key.compare(key.size() - 2, 2, "\"}") != 0) continue;
    const std::string le = key.substr(prefix.size(), key.size() - prefix.size() - 2);
    double bound = std::numeric_limits<double>::infinity();
    if (le != "+Inf") {
      char* end = nullptr;
      bound = std::strtod(le.c_str(), &end);
      if (le.empty() || end != le.c_str() + le.size()) continue;
    }
    buckets.emplace_back(bound, it->second - value_of(first, key));
  }
  std::sort(buckets.begin(), buckets.end());
  if (buckets.empty() || buckets.back().second <= 0) return std::nullopt;
  const double want = q * buckets.back().second;
  for (const auto& [bound, n] : buckets)
    if (n >= want) return bound * 1000;
  return std::numeric_limits<double>::infinity();
}

std::optional<double> histogram_mean_ms(const Scrape& first, const Scrape& last, const std::string& name) {
  const double n = value_of(last, name + "_count") - value_of(first, name + "_count");
  if (n <= 0) return std::nullopt;
  return 1000 * (value_of(last, name + "_sum") - value_of(first, name + "_sum")) / n;
}

namespace {
// The server's CPU seconds between two scrapes (never negative: a counter
// that went back is a restarted server, not negative time).
double cpu_seconds(const Scrape& first, const Scrape& last) {
  return std::max(0.0, value_of(last, "process_cpu_seconds_total") - value_of(first, "process_cpu_seconds_total"));
}
}  // namespace

ServerInterval server_interval(const Scrape& first, double first_at_s, const Scrape& last, double last_at_s) {
  ServerInterval i;
  if (const double wall = last_at_s - first_at_s; wall > 0) i.cpu_share = cpu_seconds(first, last) / wall;
  i.edits_applied = growth(first, last, "terrane_edits_applied_total");
  i.tick_ms_mean = histogram_mean_ms(first, last, "terrane_tick_duration_seconds");
  i.commit_ms_mean = histogram_mean_ms(first, last, "terrane_commit_duration_seconds");
  i.edit_ack_ms_mean = histogram_mean_ms(first, last, "terrane_edit_ack_duration_seconds");
  i.edit_ack_p99_ms = histogram_quantile_ms(first, last, "terrane_edit_ack_duration_seconds", 0.99);
  i.tick_ms_max = histogram_quantile_ms(first, last, "terrane_tick_duration_seconds", 1.0);
  i.commit_ms_max = histogram_quantile_ms(first, last, "terrane_commit_duration_seconds", 1.0);
  i.fanout_ms_max = histogram_quantile_ms(first, last, "terrane_fanout_duration_seconds", 1.0);
  i.ticks_late = growth(first, last, "terrane_ticks_late_total");
  i.tick_p99_ms = histogram_quantile_ms(first, last, "terrane_tick_duration_seconds", 0.99);
  // A gauge as a whole number of bytes: what the exposition holds is input
  // (a negative or non-finite value counts as none).
  const auto gauge = [&](const char* name) -> std::optional<std::uint64_t> {
    const auto it = last.find(name);
    if (it == last.end() || !(it->second >= 0 && it->second < 1e19)) return std::nullopt;
    return static_cast<std::uint64_t>(it->second);
  };
  i.rss_bytes = gauge("process_resident_memory_bytes");
  i.send_queue_bytes = gauge("terrane_send_queue_bytes");
  return i;
}

ServerWatch::ServerWatch(std::string host, std::uint16_t port) : host_(std::move(host)), port_(port) {}

ServerWatch::~ServerWatch() { stop(); }

bool ServerWatch::scrape(std::string* error) {
  httplib::Client http(host_, port_);
  http.set_connection_timeout(2, 0);
  http.set_read_timeout(5, 0);
  auto res = http.Get("/metrics");
  std::string why;
  if (!res)
    why = "GET http://" + host_ + ":" + std::to_string(port_) + "/metrics: " + httplib::to_string(res.error());
  else if (res->status != 200)
    why = "GET http://" + host_ + ":" + std::to_string(port_) + "/metrics: status " + std::to_string(res->status);
  else if (res->body.size() > kMaxScrapeBytes)
    why = "GET http://" + host_ + ":" + std::to_string(port_) + "/metrics: more than 16 MiB";
  std::lock_guard lock(m_);
  if (!why.empty()) {
    ++errors_;
    if (first_error_.empty()) first_error_ = why;
    if (error != nullptr) *error = why;
    return false;
  }
  Scrape s = parse_exposition(res->body);
  rss_peak_ = std::max(rss_peak_, static_cast<std::uint64_t>(value_of(s, "process_resident_memory_bytes")));
  const double at = now_s();
  if (scrapes_++ == 0) {
    first_ = mark_ = s;
    first_at_s_ = mark_at_s_ = at;
  }
  last_ = std::move(s);
  last_at_s_ = at;
  return true;
}

bool ServerWatch::start(std::string* error) {
  if (!scrape(error)) return false;
  thread_ = std::thread([this] { loop(); });
  return true;
}

void ServerWatch::loop() {
  std::unique_lock lock(m_);
  while (!stopping_) {
    if (cv_.wait_for(lock, std::chrono::seconds(1), [this] { return stopping_; })) break;
    lock.unlock();
    scrape(nullptr);
    lock.lock();
  }
}

void ServerWatch::stop() {
  {
    std::lock_guard lock(m_);
    if (stopping_ || !thread_.joinable()) return;
    stopping_ = true;
  }
  cv_.notify_all();
  thread_.join();
  scrape(nullptr);
}

void ServerWatch::mark_joined() {
  {
    std::lock_guard lock(m_);
    if (joined_ || stopping_) return;
  }
  if (!scrape(nullptr)) return;
  std::lock_guard lock(m_);
  if (!joined_) {
    joined_ = last_;
    joined_at_s_ = last_at_s_;
  }
}

JoinCost join_cost(const Scrape& first, double first_at_s, const Scrape& joined, double joined_at_s) {
  JoinCost c;
  c.wall_s = std::max(0.0, joined_at_s - first_at_s);
  c.cpu_s = cpu_seconds(first, joined);
  c.records = family_growth(first, joined, "terrane_streamed_chunks_total") +
              growth(first, joined, "terrane_horizon_images_sent_total");
  c.stream_bytes = growth(first, joined, "terrane_sent_bytes_total{type=\"StreamBatch\"}");
  return c;
}

ServerFigures ServerWatch::figures() const {
  std::lock_guard lock(m_);
  ServerFigures f;
  f.scrapes = scrapes_;
  f.scrape_errors = errors_;
  f.first_error = first_error_;
  if (scrapes_ == 0) return f;
  if (joined_) f.joins = join_cost(first_, first_at_s_, *joined_, joined_at_s_);
  f.wall_s = last_at_s_ - first_at_s_;
  f.cpu_s = cpu_seconds(first_, last_);
  f.rss_peak = rss_peak_;
  f.edits_applied = growth(first_, last_, "terrane_edits_applied_total");
  f.edits_rejected = family_growth(first_, last_, "terrane_edits_rejected_total");
  f.ticks = growth(first_, last_, "terrane_ticks_total");
  f.ticks_late = growth(first_, last_, "terrane_ticks_late_total");
  f.disconnects = family_growth(first_, last_, "terrane_disconnects_total");
  f.tick_p99_ms = histogram_quantile_ms(first_, last_, "terrane_tick_duration_seconds", 0.99);
  f.commit_p99_ms = histogram_quantile_ms(first_, last_, "terrane_commit_duration_seconds", 0.99);
  f.fanout_p99_ms = histogram_quantile_ms(first_, last_, "terrane_fanout_duration_seconds", 0.99);
  f.edit_ack_p99_ms = histogram_quantile_ms(first_, last_, "terrane_edit_ack_duration_seconds", 0.99);
  f.edit_ack_mean_ms = histogram_mean_ms(first_, last_, "terrane_edit_ack_duration_seconds");
  f.stream_gate_closings = growth(first_, last_, "terrane_stream_gate_closed_total");
  f.stream_gate_closed_s = std::max(0.0, value_of(last_, "terrane_stream_gate_closed_seconds_total") -
                                             value_of(first_, "terrane_stream_gate_closed_seconds_total"));
  const std::string frames = "terrane_sent_frames_total{type=\"";
  for (auto it = last_.lower_bound(frames); it != last_.end() && it->first.rfind(frames, 0) == 0; ++it) {
    if (it->first.size() < frames.size() + 2 || f.sent_by_type.size() >= 64) continue;
    const std::string type = it->first.substr(frames.size(), it->first.size() - frames.size() - 2);
    const std::uint64_t n = growth(first_, last_, it->first);
    if (n == 0) continue;
    f.sent_by_type[type] = {n, growth(first_, last_, "terrane_sent_bytes_total{type=\"" + type + "\"}")};
  }
  return f;
}

std::optional<ServerInterval> ServerWatch::next_interval() {
  std::lock_guard lock(m_);
  if (scrapes_ == 0 || last_at_s_ <= mark_at_s_) return std::nullopt;
  ServerInterval i = server_interval(mark_, mark_at_s_, last_, last_at_s_);
  mark_ = last_;
  mark_at_s_ = last_at_s_;
  return i;
}

}  // namespace terrane::bots
