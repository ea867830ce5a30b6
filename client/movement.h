// Movement: where a client is and what it asks to see: the ClientState
// (position, view distance, full-resolution radius) it last sent, its
// first one (the options', or the spawn's once the Welcome names it), and
// the frames that send them: at each move, and again first thing on every
// new connection (a reconnect or a Redirect).
// Thread: none of its own; the Client guards it with its mutex (application
// threads move, the io side opens sessions and reads the Welcome).
#pragma once

#include <optional>

#include "client/client_options.h"
#include "client/view_coverage.h"
#include "protocol/messages.h"

namespace terrane {

class Movement {
 public:
  explicit Movement(const ClientOptions& o)
      : first_(o.state), start_at_spawn_(o.start_at_spawn), stream_(o.stream), spawn_offset_(o.spawn_offset) {}

  // Before connecting: a client that does not start at the spawn starts
  // where the options say (one that does not stream sends no state).
  void start();
  // The client moved: the frame to send.
  Frame move(const ClientStateMsg& state);
  // The first Welcome: the frame placing the client at the spawn (plus the
  // offset), when it starts there and has not moved yet; nullopt otherwise.
  std::optional<Frame> welcomed(const WelcomeMsg& w);
  // A new connection's ClientState (nullopt before there is one).
  std::optional<Frame> session_frame() const;

  const std::optional<ClientStateMsg>& last() const { return last_; }
  // The view the server streams for the last state (nullopt before one).
  std::optional<StreamedView> view(const WelcomeMsg& w) const;

 private:
  ClientStateMsg first_;
  bool start_at_spawn_;
  bool stream_;
  Vec3f spawn_offset_;
  std::optional<ClientStateMsg> last_;
};

}  // namespace terrane
