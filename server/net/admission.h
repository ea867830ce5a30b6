// Admission: the handshake's question, whether a client may join and with
// which role. The client session (server/net/client_session.h) asks an
// Admitter; the server's is ops/access.h's AccessControl (tokens, bans, the
// whitelist), which lives in a room above this one and so is reached only
// through this interface.
//
// Threading: admit() is called on session strands, many at once: an
// implementation must be safe to call from any thread.
#pragma once

#include <cstdint>
#include <string>

#include "server/base/counters.h"

namespace terrane {

struct Admission {
  bool ok = false;
  bool admin = false;
  CloseReason why = CloseReason::kAuthFailed;
  std::string reason;  // sent to a refused client
  // The name is proven the player's: the token is that player's own (a
  // tokens file), not a shared one or none. Its undo history then outlives
  // its sessions (server/world/parked_histories.h).
  bool identified = false;
};

class Admitter {
 public:
  virtual ~Admitter() = default;
  // name and token as the Hello gave them; address: the peer's IP
  // (canonical_address); now: Unix seconds (bans that ended are ignored).
  virtual Admission admit(const std::string& name, const std::string& token, const std::string& address,
                          std::int64_t now) const = 0;
};

}  // namespace terrane
