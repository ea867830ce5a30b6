// ServerOptions: every option of a server, one struct per room that reads
// it (server/README.md, "Options"). main.cpp fills it from the command
// line; Server::create takes it whole and hands each room its own part, so
// a room's header sees only its own settings (and those of another room
// it is given explicitly).
#pragma once

#include <string>

#include "common/world/world_bounds.h"
#include "server/base/cluster_options.h"
#include "server/net/net_options.h"
#include "server/ops/ops_options.h"
#include "server/replication/replication_options.h"
#include "server/replication/update_faults.h"
#include "server/storage/storage_options.h"
#include "server/world/world_options.h"

namespace terrane {

struct ServerOptions {
  std::string world_dir;                // created with default_world_meta() when missing
  bool create_world = true;             // false: a missing world_dir is an error (--no-create)
  // A world border to set (persisted in the world): nothing is generated,
  // streamed or editable beyond it. border_set with !bounded_xz removes one.
  bool border_set = false;
  WorldBounds border;
  // Niceness by thread role (server/base/thread_role.h): the loaders below the
  // rest.
  bool thread_priorities = true;
  NetOptions net;
  WorldOptions world;
  ReplicationOptions replication;
  StorageOptions storage;
  // A PostgreSQL world instead of world_dir: cluster.store_url.
  ClusterOptions cluster;
  OpsOptions ops;
  UpdateFaultOptions faults;
};

}  // namespace terrane
