// AccessControl: who may join and who is an admin. Tokens (the shared
// token, per-player tokens with a role, the admin token) come from the
// options; bans (by name, address or network, for a while or for ever) and the
// whitelist are the operators' (terrane-admin) and live in the world's
// store (table "access", common/world/WORLD_FORMAT.md), so they survive restarts.
//
// Both are reloaded on SIGHUP (reload(): the tokens file read again, the
// bans and whitelist from the store, which another process may have
// changed).
//
// Threading: every method may be called from any thread (one mutex; the
// store is its own SQLite connection, written only by admin commands).
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "common/world/world_store.h"
#include "server/base/counters.h"
#include "server/net/admission.h"
#include "server/net/limits.h"

namespace terrane {

struct Ban {
  std::string target;   // a name, an address or a network ("10.0.0.0/8"; canonical_network)
  bool address = false;
  std::int64_t until = 0;  // Unix seconds; 0 = never ends
  std::string reason;
};

class AccessControl final : public Admitter {
 public:
  static FileResult<std::unique_ptr<AccessControl>> open(std::unique_ptr<WorldStore> store, std::string shared_token,
                                                          std::unordered_map<std::string, PlayerToken> players,
                                                          std::string admin_token);

  // now: Unix seconds (bans that ended are ignored).
  Admission admit(const std::string& name, const std::string& token, const std::string& address,
                  std::int64_t now) const override;
  bool open_to_all() const;

  // Takes players (a tokens file read again) unless nullopt, and reads the
  // bans and the whitelist again from the store. Returns what changed, a
  // line per kind (empty: nothing did); on a store error nothing changes.
  FileResult<std::vector<std::string>> reload(std::optional<std::unordered_map<std::string, PlayerToken>> players);

  FileStatus ban(const Ban& b);
  // True if something was banned under target (a name, an address or a network).
  FileResult<bool> unban(const std::string& target);
  std::vector<Ban> bans(std::int64_t now) const;

  FileStatus set_whitelist(bool on);
  FileStatus whitelist_add(const std::string& name);
  FileResult<bool> whitelist_remove(const std::string& name);
  bool whitelist_on() const;
  std::set<std::string> whitelist() const;

 private:
  AccessControl() = default;
  // The bans and the whitelist as the store has them.
  struct Lists;
  FileResult<Lists> read_lists();
  // How admit() finds a ban: a name's and an address's by their key, a
  // network's by walking the networks only (bans_ keeps them together).
  enum class BanKind : std::uint8_t { kAddress, kNetwork, kName };
  static BanKind kind_of(const std::string& target, bool address);

  std::string shared_token_, admin_token_;
  // m_ guards the players and the lists (admit() reads them on io
  // threads); store_m_ the store's connection, so a write waiting on
  // SQLite never holds up admit().
  std::unordered_map<std::string, PlayerToken> players_;
  mutable std::mutex m_;
  std::mutex store_m_;
  std::unique_ptr<WorldStore> store_;
  std::map<std::pair<BanKind, std::string>, Ban> bans_;  // by kind_of and target
  std::set<std::string> whitelist_;
  bool whitelist_on_ = false;
};

}  // namespace terrane
