// FanOut: the clients as the world knows them — each one's link, name,
// position and view, the presence it was last sent, and the changes of chunks it
// holds coarser than full resolution gathered for it (mip news, handed
// over when due) — with the interest index (who holds what) and the
// presence grid. It tells holders of new versions (publish), answers
// clients (answer) and tells them of presence. Runs on the world strand;
// no locks.
//
// Holders at full resolution hear of every tick at once
// (WorldClient::committed); the others' news is gathered and handed over
// every mip_refresh_ms (deliver_mip_news, WorldClient::mips_changed): told
// of every tick, a thousand clients each holding some of the world's edits
// afar cost a thousand posts a tick, for refreshes their replicators hold
// back anyway.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "common/voxel/chunk.h"
#include "server/base/counters.h"
#include "server/world/interest.h"
#include "server/world/presence.h"
#include "server/world/world_client.h"
#include "server/world/world_options.h"

namespace terrane {

class FanOut {
 public:
  FanOut(const WorldOptions& options, ServerCounters& counters);

  // name: its Hello's, told to the others with its presence.
  // presence_records: it is told its presence as PresenceRecords (what
  // changed, a far entry's moves less often) instead of whole lists.
  void join(ClientId id, std::shared_ptr<WorldClient> link, std::string name = {}, bool presence_records = false);
  // After this nothing more reaches id (the replicator released what it
  // held just before).
  void leave(ClientId id);
  void moved(ClientId id, Vec3f position, std::int32_t view_distance, std::int32_t full_res_radius);
  bool present(ClientId id) const { return clients_.count(id) != 0; }

  // The chunks id no longer holds.
  void release(ClientId id, const std::vector<Vec3i>& chunks);
  // id now holds these chunks (those it still holds) at full resolution:
  // news of them gathered for later goes at once, with the rest.
  void holds_full(ClientId id, const std::vector<Vec3i>& chunks);
  // Registers id as a holder of chunk_pos (a grant): every later change
  // reaches it.
  void hold(Vec3i chunk_pos, ClientId id, bool full) {
    interest_.hold(chunk_pos, id, full);
    count_memory();
  }
  bool watched(Vec3i chunk_pos) const { return interest_.watched(chunk_pos); }
  bool held_full(Vec3i chunk_pos) const { return interest_.held_full(chunk_pos); }

  // To one client, if it is still here (false when it left).
  bool answer(ClientId id, WorldAnswer answer);
  bool granted(ClientId id, std::vector<VersionPtr> versions);
  bool horizons(ClientId id, std::vector<HorizonPtr> images);
  void close_all(CloseReason why, const std::string& text);

  // Whether every chunk of r lies in id's full-resolution region where it
  // is now (false before its first move, or once it left).
  bool within_full_res(ClientId id, const Region& r) const;

  // Tells the holders of committed versions: those at full resolution at
  // once, the others gathered for deliver_mip_news (due mip_refresh_ms
  // after their first). With mip_refresh_ms 0 all hear at once.
  void publish(std::uint64_t tick, const std::vector<VersionPtr>& versions, std::chrono::steady_clock::time_point now);
  // Every holder of v's chunk at once (a loaded chunk that differs from
  // what they were granted).
  void changed(std::uint64_t tick, const VersionPtr& v);
  // Hands each client whose mip news is due its news; every tick.
  void deliver_mip_news(std::chrono::steady_clock::time_point now);
  // Presence to the placed clients whose turn it is at tick (each every
  // tick_hz / presence_hz ticks, at a phase of its own), when it changed.
  void send_presence(std::uint64_t tick);

 private:
  struct Client {
    std::shared_ptr<WorldClient> link;
    std::string name;
    Vec3f position;
    std::int32_t view_distance = 0, full_res_radius = 0;
    bool placed = false;
    std::vector<PresenceEntryMsg> presence;  // last sent (whole lists)
    bool presence_records = false;
    // PresenceRecords: the list as the client made it of the records sent
    // (the server applies them too), and its turns.
    PresenceList known;
    std::uint64_t presence_turns = 0;
    std::vector<VersionPtr> mip_news;        // oldest first
    std::uint64_t mip_news_tick = 0;         // the newest news' tick
    std::chrono::steady_clock::time_point mip_due;
  };
  // The interest index's memory, to its part of the server's (MemoryPart).
  void count_memory() {
    counters_.memory[MemoryPart::kInterest].store(static_cast<std::int64_t>(interest_.memory_bytes()),
                                                  std::memory_order_relaxed);
  }
  // c's presence turn as PresenceRecords: what changed since it was told.
  void send_presence_records(Client& c, std::vector<PresenceEntryMsg> entries);
  // Hands c its mip news now, whenever it was due.
  static void hand_mip_news(Client& c);

  const WorldOptions& options_;
  ServerCounters& counters_;
  std::unordered_map<ClientId, Client> clients_;
  // The clients by presence phase (id % turns_.size(), the ticks between a
  // client's turns): a tick visits only the clients whose turn it is, not
  // every client's entry. Remade when the period changes.
  std::vector<std::vector<ClientId>> turns_;
  std::vector<ClientId>& turn_of(ClientId id) { return turns_[id % turns_.size()]; }
  // Clients with mip news, by when it is due, earliest first (one period
  // for all: a queue). An entry is stale when its client's news went out
  // sooner (holds_full) or it left: skipped.
  std::deque<std::pair<std::chrono::steady_clock::time_point, ClientId>> mip_news_due_;
  InterestIndex interest_;
  PresenceGrid presence_;
};

}  // namespace terrane
