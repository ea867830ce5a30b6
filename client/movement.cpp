#include "client/movement.h"

namespace terrane {

void Movement::start() {
  if (!start_at_spawn_ && stream_) last_ = first_;
}

Frame Movement::move(const ClientStateMsg& state) {
  last_ = state;
  return build_client_state(state);
}

std::optional<Frame> Movement::welcomed(const WelcomeMsg& w) {
  if (!start_at_spawn_ || !stream_ || last_) return std::nullopt;
  ClientStateMsg s = first_;
  s.position = {w.spawn.x + spawn_offset_.x, w.spawn.y + spawn_offset_.y, w.spawn.z + spawn_offset_.z};
  return move(s);
}

std::optional<Frame> Movement::session_frame() const {
  if (!last_) return std::nullopt;
  return build_client_state(*last_);
}

std::optional<StreamedView> Movement::view(const WelcomeMsg& w) const {
  if (!last_) return std::nullopt;
  return streamed_view(*last_, w);
}

}  // namespace terrane
