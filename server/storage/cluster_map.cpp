#include "server/storage/cluster_map.h"

#include <fmt/format.h>

#include "common/cli/cli.h"

namespace terrane {

std::optional<ServerAddress> parse_server_address(std::string_view text, std::string* error) {
  auto hp = parse_host_port(std::string(text));
  auto fail = [&](const std::string& why) -> std::optional<ServerAddress> {
    if (error) *error = why;
    return std::nullopt;
  };
  if (!hp) return fail(hp.error().message);
  const auto& [host, port] = *hp;
  if (port == 0) return fail(fmt::format("'{}': a server's port is never 0", text));
  if (host.size() > 253) return fail(fmt::format("'{}': the host is longer than 253 bytes", text));
  for (const char c : host)
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f)
      return fail(fmt::format("'{}': the host has a space or a control character", text));
  return ServerAddress{0, host, port};
}

std::string ServerAddress::text() const {
  if (host.find(':') != std::string::npos) return fmt::format("[{}]:{}", host, port);
  return fmt::format("{}:{}", host, port);
}

ClusterMap::ClusterMap(const std::vector<RegionWriter>& writers, const std::vector<ServerAddress>& servers,
                       Clock::time_point read_at, const ClusterMap* previous)
    : read_at_(read_at) {
  for (const RegionWriter& w : writers) {
    Lease l{w.server, w.epoch, read_at};
    if (previous != nullptr)
      if (auto p = previous->writers_.find(w.region);
          p != previous->writers_.end() && p->second.server == w.server && p->second.epoch == w.epoch)
        l.since = p->second.since;
    writers_[w.region] = l;
  }
  for (const ServerAddress& s : servers) servers_[s.id] = s;
}

const ServerAddress* ClusterMap::writer_of(Vec3i region) const {
  auto it = writers_.find(region);
  if (it == writers_.end()) return nullptr;
  auto s = servers_.find(it->second.server);
  return s == servers_.end() ? nullptr : &s->second;
}

std::optional<ClusterMap::Clock::time_point> ClusterMap::written_since(Vec3i region) const {
  auto it = writers_.find(region);
  if (it == writers_.end()) return std::nullopt;
  return it->second.since;
}

}  // namespace terrane
