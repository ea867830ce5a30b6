#include "client/bots/stats.h"

#include <algorithm>
#include <cmath>
#include <unordered_set>

namespace terrane::bots {

namespace {
// Fan-out samples kept for the live progress line.
constexpr std::size_t kRecentSamples = 20000;
}  // namespace

LatencySummary summarize(const LatencyHistogram& h) {
  LatencySummary r;
  r.count = h.count();
  r.p50 = h.percentile(0.50);
  r.p95 = h.percentile(0.95);
  r.p99 = h.percentile(0.99);
  r.max = h.max_ms();
  r.histogram = h;
  return r;
}

LatencySummary summarize(std::vector<float> s) {
  LatencySummary r;
  r.count = s.size();
  if (s.empty()) return r;
  std::sort(s.begin(), s.end());
  auto rank = [&](double p) {
    const auto i = static_cast<std::size_t>(std::ceil(p * static_cast<double>(s.size())));
    return static_cast<double>(s[std::min(s.size(), std::max<std::size_t>(i, 1)) - 1]);
  };
  r.p50 = rank(0.50);
  r.p95 = rank(0.95);
  r.p99 = rank(0.99);
  r.max = static_cast<double>(s.back());
  return r;
}

double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

std::string reason_class(std::string_view reason) {
  if (const std::size_t until = reason.find(" until "); until != std::string_view::npos) reason = reason.substr(0, until);
  std::string out;
  out.reserve(reason.size());
  for (std::size_t i = 0; i < reason.size(); ++i) {
    const bool digit = reason[i] >= '0' && reason[i] <= '9';
    if (!digit)
      out += reason[i];
    else if (i == 0 || reason[i - 1] < '0' || reason[i - 1] > '9')
      out += 'N';
  }
  return out;
}

namespace {
// How long after an edit a change of its chunks at a bot of another server
// still counts as the edit's (fan-out is measured below this).
constexpr auto kArrivalWindow = std::chrono::seconds(3);
}  // namespace

FanoutTracker::FanoutTracker(Clock::time_point run_start, Clock::time_point measure_from, int servers)
    : run_start_(run_start), measure_from_(measure_from), servers_(std::max(1, servers)) {}

void add_per_second(std::vector<LatencyHistogram>& by_second, Clock::time_point run_start, Clock::time_point t,
                    double ms) {
  const std::size_t s =
      t <= run_start ? 0 : static_cast<std::size_t>(std::chrono::duration_cast<std::chrono::seconds>(t - run_start).count());
  if (by_second.size() <= s) by_second.resize(s + 1);
  by_second[s].record(ms);
}

std::uint32_t FanoutTracker::send_edit(int bot, const Region& bounds, double edited_voxels,
                                       const std::function<std::uint32_t()>& send) {
  std::lock_guard lock(mutex_);
  Edit e;
  e.bot = bot;
  e.voxels = edited_voxels;
  for_each_chunk_in(bounds, [&](Vec3i cp) {
    e.chunks.push_back(cp);
    if (servers_ == 1) return;
    auto h = held_full_.find(cp);
    e.held_by.push_back(h != held_full_.end() ? std::vector<int>(h->second.begin(), h->second.end()) : std::vector<int>{});
  });
  e.sent = Clock::now();
  const std::uint32_t id = send();
  if (id == 0) return 0;
  ++totals_.edits_sent;
  in_flight_[key(bot, id)] = std::move(e);
  return id;
}

void FanoutTracker::edit_result(int bot, std::uint32_t edit_id, const EditOutcome& o, Clock::time_point t) {
  std::lock_guard lock(mutex_);
  auto it = in_flight_.find(key(bot, edit_id));
  if (it == in_flight_.end()) return;
  Edit e = std::move(it->second);
  in_flight_.erase(it);
  if (!o.accepted) {
    ++totals_.edits_rejected;
    ++totals_.reject_reasons[reason_class(o.reason)];
    return;
  }
  ++totals_.edits_acked;
  e.acked = t;
  if (e.sent >= measure_from_) {
    const double ms = ms_between(e.sent, t);
    ack_ms_.record(ms);
    add_per_second(ack_by_second_, run_start_, e.sent, ms);
  }
  auto [tick, fresh] = ticks_.try_emplace(tick_key(bot, o.tick));
  if (fresh) tick->second.first_seen = t;
  tick->second.edits.push_back(std::move(e));
}

void FanoutTracker::update_received(int bot, std::uint64_t tick, const std::vector<ChunkRevisionMsg>& revisions,
                                    Clock::time_point t) {
  std::lock_guard lock(mutex_);
  auto [it, fresh] = ticks_.try_emplace(tick_key(bot, tick));
  if (fresh) it->second.first_seen = t;
  for (const auto& r : revisions) {
    it->second.updates.push_back(Update{bot, r.chunk_pos, t, r.revision});
    // Several servers: an edit forwarded to its region's server reaches
    // that server's bots as an update of that server's tick.
    if (servers_ > 1) arrivals_[r.chunk_pos].push_back(Arrival{bot, t, r.revision});
  }
}

void FanoutTracker::chunk_arrived(int bot, Vec3i chunk, Clock::time_point t) {
  if (servers_ == 1) return;
  std::lock_guard lock(mutex_);
  arrived_locked(bot, chunk, t);
}

void FanoutTracker::arrived_locked(int bot, Vec3i chunk, Clock::time_point t) {
  if (!held_full_[chunk].insert(bot).second) arrivals_[chunk].push_back(Arrival{bot, t, 0});
}

void FanoutTracker::bot_on_server(int bot, std::uint32_t server_id) {
  std::lock_guard lock(mutex_);
  server_of_bot_[bot] = server_id;
}

void FanoutTracker::chunk_released(int bot, Vec3i chunk) {
  if (servers_ == 1) return;
  std::lock_guard lock(mutex_);
  released_locked(bot, chunk);
}

void FanoutTracker::released_locked(int bot, Vec3i chunk) {
  if (auto it = held_full_.find(chunk); it != held_full_.end()) {
    it->second.erase(bot);
    if (it->second.empty()) held_full_.erase(it);
  }
}

void FanoutTracker::holdings_changed(int bot, std::span<const HoldingChange> changes, Clock::time_point t) {
  if (servers_ == 1) return;
  std::lock_guard lock(mutex_);
  for (const HoldingChange& c : changes) {
    if (c.now && c.now->full_resolution())
      arrived_locked(bot, c.chunk_pos, t);
    else
      released_locked(bot, c.chunk_pos);
  }
}

std::vector<std::pair<std::size_t, std::uint64_t>> FanoutTracker::changed_by(const Edit& e, const Tick& tk) const {
  std::vector<std::pair<std::size_t, std::uint64_t>> out;
  bool editor_held = false;
  for (std::size_t i = 0; i < e.chunks.size(); ++i) {
    const Vec3i cp = e.chunks[i];
    const auto& held = e.held_by[i];
    editor_held = editor_held || std::find(held.begin(), held.end(), e.bot) != held.end();
    std::uint64_t revision = 0;
    bool changed = false;
    for (const Update& u : tk.updates)
      if (u.chunk == cp) {
        changed = true;
        revision = std::max(revision, u.revision);
      }
    if (!changed)
      if (auto a = arrivals_.find(cp); a != arrivals_.end())
        changed = std::any_of(a->second.begin(), a->second.end(), [&](const Arrival& arrival) {
          return arrival.bot == e.bot && arrival.t >= e.sent && arrival.t <= e.acked;
        });
    if (changed) out.emplace_back(i, revision);
  }
  if (out.empty() && !editor_held)
    for (std::size_t i = 0; i < e.chunks.size(); ++i) out.emplace_back(i, 0);
  return out;
}

void FanoutTracker::settle(Clock::time_point now, Clock::duration horizon) {
  std::lock_guard lock(mutex_);
  std::unordered_map<int, Clock::time_point> last;  // receiver -> last batch for one edit
  for (auto it = ticks_.begin(); it != ticks_.end();) {
    Tick& tk = it->second;
    if (horizon.count() != 0 && tk.first_seen + horizon > now) {
      ++it;
      continue;
    }
    for (const Edit& e : tk.edits) {
      last.clear();
      for (const Update& u : tk.updates) {
        if (u.bot == e.bot) continue;
        if (std::find(e.chunks.begin(), e.chunks.end(), u.chunk) == e.chunks.end()) continue;
        auto [l, fresh] = last.try_emplace(u.bot, u.t);
        if (!fresh && u.t > l->second) l->second = u.t;
      }
      // Receivers on other servers: the first change of any of the chunks
      // the edit changed that they receive after it was sent, within the
      // window (one commit's chunks arrive together). The chunks changed:
      // those of its box in its tick's updates, or (an edit forwarded to
      // another server) arriving again at the editor before its ack (which
      // waits for them); its whole box if the editor held none of it (a
      // chunk the box reaches but the edit left alone changes next by
      // another edit, seconds later). Measured: receivers that held the
      // chunk when the edit was sent, by an update at the edit's revision
      // or later (an earlier one is another edit's) or the chunk whole.
      std::unordered_map<int, Clock::time_point> other;
      if (servers_ > 1)
        for (const auto& [i, revision] : changed_by(e, tk)) {
          auto a = arrivals_.find(e.chunks[i]);
          if (a == arrivals_.end()) continue;
          const auto& held = e.held_by[i];
          for (const Arrival& arrival : a->second) {
            const Clock::time_point t = arrival.t;
            if (server_of(arrival.bot) == server_of(e.bot) || t < e.sent || t > e.sent + kArrivalWindow) continue;
            if (revision != 0 && arrival.revision != 0 && arrival.revision < revision) continue;
            if (std::find(held.begin(), held.end(), arrival.bot) == held.end()) continue;
            auto [o, fresh] = other.try_emplace(arrival.bot, t);
            if (!fresh && t < o->second) o->second = t;
          }
        }
      if (e.sent < measure_from_) continue;
      for (const auto& [bot, t] : other) fanout_other_ms_.record(ms_between(e.sent, t));
      totals_.receiver_pairs += other.size();
      ++totals_.edits_measured;
      totals_.receiver_pairs += last.size();
      totals_.edited_voxel_receivers += e.voxels * static_cast<double>(last.size());
      for (const auto& [bot, t] : last) {
        const double ms = ms_between(e.sent, t);
        fanout_ms_.record(ms);
        add_per_second(fanout_by_second_, run_start_, e.sent, ms);
        recent_.push_back(static_cast<float>(ms));
      }
    }
    it = ticks_.erase(it);
  }
  if (recent_.size() > kRecentSamples) recent_.erase(recent_.begin(), recent_.end() - kRecentSamples / 2);
  // Arrivals are kept a few horizons, for edits settled later.
  if (servers_ > 1 && horizon.count() != 0)
    for (auto a = arrivals_.begin(); a != arrivals_.end();) {
      auto& v = a->second;
      v.erase(std::remove_if(v.begin(), v.end(), [&](const Arrival& p) { return p.t + 4 * horizon < now; }), v.end());
      a = v.empty() ? arrivals_.erase(a) : std::next(a);
    }
}

FanoutTracker::Totals FanoutTracker::totals() const {
  std::lock_guard lock(mutex_);
  return totals_;
}
LatencyHistogram FanoutTracker::ack_ms() const {
  std::lock_guard lock(mutex_);
  return ack_ms_;
}
LatencyHistogram FanoutTracker::fanout_ms() const {
  std::lock_guard lock(mutex_);
  return fanout_ms_;
}
LatencyHistogram FanoutTracker::fanout_other_server_ms() const {
  std::lock_guard lock(mutex_);
  return fanout_other_ms_;
}
std::vector<LatencyHistogram> FanoutTracker::fanout_by_second() const {
  std::lock_guard lock(mutex_);
  return fanout_by_second_;
}
std::vector<LatencyHistogram> FanoutTracker::ack_by_second() const {
  std::lock_guard lock(mutex_);
  return ack_by_second_;
}
double FanoutTracker::recent_fanout_p99() const {
  std::lock_guard lock(mutex_);
  return summarize(recent_).p99;
}

void MismatchLog::add(const Mismatch& m) {
  std::lock_guard lock(mutex_);
  list_.push_back(m);
}
std::vector<Mismatch> MismatchLog::all() const {
  std::lock_guard lock(mutex_);
  return list_;
}
std::size_t MismatchLog::count() const {
  std::lock_guard lock(mutex_);
  return list_.size();
}

void LatencyLog::add(Clock::time_point t, double ms) {
  std::lock_guard lock(mutex_);
  if (t >= measure_from_) all_.record(ms);
  add_per_second(by_second_, run_start_, t, ms);
}

LatencyHistogram LatencyLog::all() const {
  std::lock_guard lock(mutex_);
  return all_;
}

std::vector<LatencyHistogram> LatencyLog::by_second() const {
  std::lock_guard lock(mutex_);
  return by_second_;
}

}  // namespace terrane::bots
