// The cluster room's options: a world in PostgreSQL shared with other
// servers (server/storage/STORE_POSTGRESQL.md). Plain data, filled by
// main.cpp (part of ServerOptions, server/server_options.h).
//
// In base/ rather than cluster/: besides the cluster room (ClusterNode),
// the world's SharedAuthority (this server's id, the lease) and
// replication's Redirector (the id, the lease, the margin) are given it,
// and replication may not include cluster/.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace terrane {

// The longest lease terrane-server takes (--lease-ms): a forwarded edit's
// sender waits max(2 s, a lease), so no inbox row is meant to live longer
// (ClusterStore::inbox takes one saying more as saying this).
inline constexpr std::chrono::milliseconds kMaxLease{10 * 60 * 1000};

struct ClusterOptions {
  // The world in PostgreSQL ("postgresql://HOST:PORT/DB", with the world
  // directory empty), shared with other servers. Created with
  // default_world_meta() when the database holds none.
  std::string store_url;
  std::uint32_t server_id = 0;          // this server in a PostgreSQL world (below 2^31)
  std::chrono::milliseconds lease{5000};  // a region lease's length; renewed every tenth of it
  // Where clients reach this server ("HOST:PORT"), told to the other
  // servers of a PostgreSQL world; empty: the bind address and the port
  // listened on (none when bound to every address).
  std::string advertise;
  // A client standing this many voxels or more inside a region another
  // server writes (from every face of the 256^3 region) is redirected there
  // (PROTOCOL.md, "Redirects"); 0 never. At most 128 (half a region).
  std::int32_t redirect_margin = 32;
};

}  // namespace terrane
