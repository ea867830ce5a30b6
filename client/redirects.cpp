#include "client/redirects.h"

#include <utility>

namespace terrane {

bool Redirects::offer(RedirectMsg r, Clock::time_point now) {
  // One at a time; a client that does not follow stays (and is closed by
  // the server after its grace).
  if (!follow_ || pending_) return false;
  if (target_of(r) == unreachable_ && now < unreachable_until_) return false;  // failed a moment ago: stay
  pending_ = std::move(r);
  return true;
}

RedirectMsg Redirects::follow() {
  RedirectMsg to = std::move(*pending_);
  pending_.reset();
  token_ = to.token;
  return to;
}

void Redirects::unreachable(const std::string& target, Clock::time_point now) {
  unreachable_ = target;
  unreachable_until_ = now + kUnreachableFor;
  token_.clear();
}

std::string Redirects::take_token() { return std::exchange(token_, std::string()); }

}  // namespace terrane
