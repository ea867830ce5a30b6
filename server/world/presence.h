// Presence: where the other clients are, for each client the nearest ones
// within its view distance, found through a grid of 128-voxel x/z cells so a
// round costs each client the cells its view covers, not every client.
// Thread-safety: none; the world strand owns it.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "common/voxel/vec3.h"
#include "protocol/messages.h"
#include "server/world/interest.h"

namespace terrane {

// Every how many of a client's presence turns an entry this far from it
// has its move told (PROTOCOL.md, "Presence records"): 1 within 64 voxels,
// 2 within 128, 4 within 256, 8 beyond.
inline std::uint64_t presence_move_period(float distance) {
  return distance < 64 ? 1 : distance < 128 ? 2 : distance < 256 ? 4 : 8;
}

class PresenceGrid {
 public:
  static constexpr std::int32_t kCell = 128;

  void place(ClientId id, Vec3f position);
  void remove(ClientId id);
  // The nearest clients other than id within radius of position, at most
  // max, nearest first (ties by id).
  std::vector<PresenceEntryMsg> nearest(ClientId id, Vec3f position, float radius, std::size_t max) const;

 private:
  struct Cell {
    std::int32_t x, z;
    friend bool operator==(const Cell&, const Cell&) = default;
  };
  struct CellHash {
    std::size_t operator()(const Cell& c) const noexcept {
      return std::hash<std::uint64_t>{}((static_cast<std::uint64_t>(static_cast<std::uint32_t>(c.x)) << 32) |
                                        static_cast<std::uint32_t>(c.z));
    }
  };
  static Cell cell_of(Vec3f p);

  // Each cell's clients with their positions (a query reads them there,
  // without a lookup each), and where each client is.
  struct Placed {
    ClientId id;
    Vec3f position;
  };
  std::unordered_map<Cell, std::vector<Placed>, CellHash> cells_;
  std::unordered_map<ClientId, Vec3f> where_;
};

}  // namespace terrane
