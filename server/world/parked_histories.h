// ParkedHistories: the undo histories of identified players who left, kept
// by player name so the same player's next session takes its history
// back (PROTOCOL.md, "Undo and redo"). Only a player the server can prove
// is the same one (a token of the tokens file: one player's own token) is
// parked; with an open server or one shared token a name proves nothing,
// and the history stays per connection. Bounded in bytes over all players:
// the longest parked go first. Kept in memory only (a restart forgets).
// Thread-safety: none; Tick owns it on the world strand.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "server/world/history.h"

namespace terrane {

class ParkedHistories {
 public:
  explicit ParkedHistories(std::size_t max_bytes) : max_bytes_(max_bytes) {}

  // Keeps player's history (replacing one parked before); an empty history
  // is not kept. Histories parked longest go until the total is within the
  // bound.
  void park(const std::string& player, History history);
  // player's parked history, no longer parked; nullopt if none.
  std::optional<History> take(const std::string& player);

  std::size_t bytes() const { return bytes_; }
  std::size_t count() const { return by_player_.size(); }

 private:
  struct Parked {
    History history;
    std::uint64_t order;  // when parked: the lowest goes first
  };

  std::size_t max_bytes_;
  std::size_t bytes_ = 0;
  std::uint64_t next_order_ = 0;
  std::map<std::string, Parked> by_player_;
};

}  // namespace terrane
