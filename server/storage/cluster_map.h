// ClusterMap: in a world shared by several servers, which server writes
// each region and where each server takes clients (STORE_POSTGRESQL.md,
// "Redirects"). A snapshot of the database's leases and server addresses,
// read by the lease keeper each renewal round (about once a second);
// immutable, shared by every session strand through a ClusterDirectory.
//
// Threading: a ClusterMap never changes once made. ClusterDirectory's
// publish() and current() may be called from any thread.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/voxel/vec3_map.h"

namespace terrane {

// Where a server of the world takes clients: terrane-server --advertise.
struct ServerAddress {
  std::uint32_t id = 0;
  std::string host;
  std::uint16_t port = 0;
  std::string text() const;  // "HOST:PORT" ("[v6]:PORT")
  friend bool operator==(const ServerAddress&, const ServerAddress&) = default;
};

// "HOST:PORT" (parse_host_port's, with a port above 0 and a host of at
// most 253 bytes without spaces or controls): the address, or nullopt with
// *error saying what is wrong with it.
std::optional<ServerAddress> parse_server_address(std::string_view text, std::string* error);

// A current lease: region (8 x 8 x 8 chunks), the server writing it and
// the lease's epoch (a new one each time the region changes hands).
struct RegionWriter {
  Vec3i region;
  std::uint32_t server = 0;
  std::uint64_t epoch = 0;
};

class ClusterMap {
 public:
  using Clock = std::chrono::steady_clock;
  // previous: the map this one follows, if any: a region whose lease
  // (writer and epoch) is unchanged keeps the time it was first seen.
  ClusterMap(const std::vector<RegionWriter>& writers, const std::vector<ServerAddress>& servers, Clock::time_point read_at,
             const ClusterMap* previous = nullptr);
  ClusterMap(const ClusterMap&) = delete;
  ClusterMap& operator=(const ClusterMap&) = delete;

  // The server writing region and its address; nullptr when no server holds
  // a current lease on it, or its holder advertises no address.
  const ServerAddress* writer_of(Vec3i region) const;
  // Since when the maps have seen region's current lease (its writer and
  // epoch); nullopt when nobody writes it. Regions handed back and forth
  // across a busy border are young.
  std::optional<Clock::time_point> written_since(Vec3i region) const;
  Clock::time_point read_at() const { return read_at_; }
  std::size_t regions() const { return writers_.size(); }

 private:
  struct Lease {
    std::uint32_t server = 0;
    std::uint64_t epoch = 0;
    Clock::time_point since;
  };
  Vec3iMap<Lease> writers_;
  std::unordered_map<std::uint32_t, ServerAddress> servers_;
  Clock::time_point read_at_;
};

class ClusterDirectory {
 public:
  void publish(std::shared_ptr<const ClusterMap> map) {
    std::lock_guard lock(m_);
    map_ = std::move(map);
  }
  // The latest snapshot (null before the first).
  std::shared_ptr<const ClusterMap> current() const {
    std::lock_guard lock(m_);
    return map_;
  }

 private:
  mutable std::mutex m_;
  std::shared_ptr<const ClusterMap> map_;
};

}  // namespace terrane
