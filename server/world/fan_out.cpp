#include "server/world/fan_out.h"

#include <algorithm>
#include <cassert>
#include <cmath>

#include "common/world/view.h"

namespace terrane {

FanOut::FanOut(const WorldOptions& options, ServerCounters& counters) : options_(options), counters_(counters) {}

void FanOut::join(ClientId id, std::shared_ptr<WorldClient> link, std::string name, bool presence_records) {
  Client c;
  c.link = std::move(link);
  c.name = std::move(name);
  c.presence_records = presence_records;
  if (clients_.emplace(id, std::move(c)).second && !turns_.empty()) turn_of(id).push_back(id);
}

void FanOut::leave(ClientId id) {
  if (clients_.erase(id) != 0 && !turns_.empty()) {
    auto& turn = turn_of(id);
    turn.erase(std::find(turn.begin(), turn.end(), id));
  }
  presence_.remove(id);
}

void FanOut::moved(ClientId id, Vec3f position, std::int32_t view_distance, std::int32_t full_res_radius) {
  auto it = clients_.find(id);
  if (it == clients_.end()) return;
  it->second.position = position;
  it->second.view_distance = view_distance;
  it->second.full_res_radius = full_res_radius;
  it->second.placed = true;
  presence_.place(id, position);
}

void FanOut::release(ClientId id, const std::vector<Vec3i>& chunks) {
  for (const Vec3i cp : chunks) interest_.release(cp, id);
  count_memory();
}

void FanOut::holds_full(ClientId id, const std::vector<Vec3i>& chunks) {
  auto client = clients_.find(id);
  if (client == clients_.end()) return;
  Client& c = client->second;
  bool news = false;
  for (const Vec3i cp : chunks) {
    if (!interest_.holds(cp, id)) continue;  // released since
    interest_.hold(cp, id, true);
    news = news || std::any_of(c.mip_news.begin(), c.mip_news.end(), [cp](const VersionPtr& v) { return v->pos() == cp; });
  }
  // A change of one of them gathered for later goes now, with the rest.
  if (news) hand_mip_news(c);
}

bool FanOut::answer(ClientId id, WorldAnswer answer) {
  auto it = clients_.find(id);
  if (it == clients_.end()) return false;
  it->second.link->answer(std::move(answer));
  return true;
}

bool FanOut::granted(ClientId id, std::vector<VersionPtr> versions) {
  auto it = clients_.find(id);
  if (it == clients_.end()) return false;
  it->second.link->granted(std::move(versions));
  return true;
}

bool FanOut::horizons(ClientId id, std::vector<HorizonPtr> images) {
  auto it = clients_.find(id);
  if (it == clients_.end()) return false;
  it->second.link->horizons(std::move(images));
  return true;
}

void FanOut::close_all(CloseReason why, const std::string& text) {
  for (auto& [id, c] : clients_) c.link->close(why, text);
}

bool FanOut::within_full_res(ClientId id, const Region& r) const {
  auto it = clients_.find(id);
  if (it == clients_.end()) return false;
  const Client& c = it->second;
  bool ok = c.placed;
  for_each_chunk_in(r, [&](Vec3i cp) { ok = ok && within(c.position, cp, c.full_res_radius); });
  return ok;
}

void FanOut::hand_mip_news(Client& c) {
  c.link->mips_changed(c.mip_news_tick, std::move(c.mip_news));
  c.mip_news.clear();
}

void FanOut::deliver_mip_news(std::chrono::steady_clock::time_point now) {
  while (!mip_news_due_.empty() && mip_news_due_.front().first <= now) {
    const ClientId id = mip_news_due_.front().second;
    mip_news_due_.pop_front();
    auto it = clients_.find(id);
    if (it == clients_.end() || it->second.mip_news.empty() || it->second.mip_due > now) continue;
    hand_mip_news(it->second);
  }
}

void FanOut::publish(std::uint64_t tick, const std::vector<VersionPtr>& versions,
                     std::chrono::steady_clock::time_point now) {
  std::unordered_map<ClientId, std::vector<VersionPtr>> news;
  std::uint64_t deliveries = 0;
  const bool gather = options_.mip_refresh_ms > 0;
  const auto due = now + std::chrono::milliseconds(options_.mip_refresh_ms);
  for (const VersionPtr& v : versions) {
    interest_.for_each_holder(v->pos(), [&](InterestIndex::Holder h) {
      ++deliveries;
      if (h.full() || !gather) {
        news[h.id()].push_back(v);
        return;
      }
      auto c = clients_.find(h.id());
      if (c == clients_.end()) return;
      if (c->second.mip_news.empty()) {
        c->second.mip_due = due;
        mip_news_due_.emplace_back(due, h.id());
      }
      c->second.mip_news.push_back(v);
      c->second.mip_news_tick = tick;
    });
  }
  counters_.deliveries.fetch_add(deliveries, std::memory_order_relaxed);
  for (auto& [id, changed] : news)
    if (auto it = clients_.find(id); it != clients_.end()) it->second.link->committed(tick, std::move(changed));
}

void FanOut::changed(std::uint64_t tick, const VersionPtr& v) {
  interest_.for_each_holder(v->pos(), [&](InterestIndex::Holder h) {
    if (auto holder = clients_.find(h.id()); holder != clients_.end()) holder->second.link->committed(tick, {v});
  });
}

void FanOut::send_presence(std::uint64_t tick) {
  // Each client every `every` ticks, at a phase of its own (its id): a
  // thousand nearest-neighbour queries and frames spread over the ticks
  // instead of lengthening one.
  const std::uint32_t hz = std::max<std::uint32_t>(1, options_.tick_hz);
  const std::uint64_t every = std::max<std::uint64_t>(1, hz / std::max<std::uint32_t>(1, options_.presence_hz));
  if (turns_.size() != every) {
    turns_.assign(every, {});
    for (const auto& [id, c] : clients_) turn_of(id).push_back(id);
  }
  // (id + tick) % every == 0: the clients of phase (every - tick % every) % every.
  for (const ClientId id : turns_[(every - tick % every) % every]) {
    const auto it = clients_.find(id);
    assert(it != clients_.end());  // turns_ holds the ids of clients_
    Client& c = it->second;
    if (!c.placed) continue;
    auto entries =
        presence_.nearest(id, c.position, static_cast<float>(c.view_distance), options_.presence_max_entries);
    if (c.presence_records) {
      send_presence_records(c, std::move(entries));
      continue;
    }
    // Only when something changed: idle crowds cost nothing.
    auto same = [](const PresenceEntryMsg& a, const PresenceEntryMsg& b) {
      return a.client_id == b.client_id && a.position.x == b.position.x && a.position.y == b.position.y &&
             a.position.z == b.position.z;
    };
    if (entries.size() == c.presence.size() && std::equal(entries.begin(), entries.end(), c.presence.begin(), same))
      continue;
    // Names are fixed per client: told once, with an entry new to the
    // list (the client keeps it while the entry stays), and not compared.
    for (auto& e : entries) {
      const bool listed = std::any_of(c.presence.begin(), c.presence.end(),
                                      [&](const PresenceEntryMsg& before) { return before.client_id == e.client_id; });
      if (listed) continue;
      if (auto other = clients_.find(e.client_id); other != clients_.end()) e.name = other->second.name;
    }
    c.link->answer(PresenceNearby{entries});
    c.presence = std::move(entries);
    counters_.presence_sent.fetch_add(1, std::memory_order_relaxed);
  }
}

void FanOut::send_presence_records(Client& c, std::vector<PresenceEntryMsg> entries) {
  const std::uint64_t turn = c.presence_turns++;
  std::vector<PresenceRecord> records;  // those that left first, then in list order
  std::vector<std::uint32_t> now;
  now.reserve(entries.size());
  for (const PresenceEntryMsg& e : entries) now.push_back(e.client_id);
  std::sort(now.begin(), now.end());
  for (const PresenceList::Entry& k : c.known.entries())
    if (!std::binary_search(now.begin(), now.end(), k.client_id))
      records.push_back({PresenceRecordKind::kLeft, k.client_id, {}, {}});
  for (const PresenceEntryMsg& e : entries) {
    const Vec3i at = presence_eighths(e.position);
    const PresenceList::Entry* before = c.known.find(e.client_id);
    if (before == nullptr) {
      PresenceRecord r{PresenceRecordKind::kEntered, e.client_id, at, {}};
      if (auto other = clients_.find(e.client_id); other != clients_.end()) r.name = other->second.name;
      records.push_back(std::move(r));
      continue;
    }
    // A move is told on the entry's turns, fewer the farther it is; one
    // not told now is told on a later turn (the list keeps the old place).
    const float dx = e.position.x - c.position.x, dy = e.position.y - c.position.y, dz = e.position.z - c.position.z;
    const std::uint64_t period = presence_move_period(std::sqrt(dx * dx + dy * dy + dz * dz));
    if (at != before->eighths && (turn + e.client_id) % period == 0)
      records.push_back({PresenceRecordKind::kMoved, e.client_id, at - before->eighths, {}});
  }
  if (records.empty()) return;  // only when something is told: idle crowds cost nothing
  // The list as the client makes it of these records. They fit it by
  // construction (left and moved are of entries in it, entered of others;
  // FanOutTest applies them as a client would), so its Status says nothing.
  (void)c.known.apply(records);
  c.link->answer(PresenceChanged{std::move(records)});
  counters_.presence_sent.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace terrane
