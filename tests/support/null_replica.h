// A client's replication that does nothing: for tests of a session's
// surroundings (the session table, operations) where what a client holds
// does not matter.
#pragma once

#include <string>

#include "server/net/client_session.h"

namespace terrane::testing_support {

class NullReplica final : public ClientReplica {
 public:
  void join(const std::string&, bool, std::uint32_t) override {}
  bool move(const ClientStateMsg&) override { return true; }
  void edit(EditRequestMsg) override {}
  void read_box(const ReadBoxMsg&) override {}
  void holdings(const HoldingsMsg&) override {}
  void hash_request(Vec3i) override {}
  void drained() override {}
  void closed() override {}
};

}  // namespace terrane::testing_support
