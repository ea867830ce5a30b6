#include "server/ops/access.h"

#include <algorithm>
#include <map>
#include <sstream>

namespace terrane {

namespace {

std::string ban_key(const std::string& target, bool address) {
  return std::string(address ? "ban:addr:" : "ban:name:") + target;
}

}  // namespace

AccessControl::BanKind AccessControl::kind_of(const std::string& target, bool address) {
  if (!address) return BanKind::kName;
  return target.find('/') == std::string::npos ? BanKind::kAddress : BanKind::kNetwork;
}

struct AccessControl::Lists {
  std::map<std::pair<BanKind, std::string>, Ban> bans;
  std::set<std::string> whitelist;
  bool whitelist_on = false;
};

FileResult<std::unique_ptr<AccessControl>> AccessControl::open(std::unique_ptr<WorldStore> store, std::string shared_token,
                                                                std::unordered_map<std::string, PlayerToken> players,
                                                                std::string admin_token) {
  std::unique_ptr<AccessControl> a(new AccessControl());
  a->shared_token_ = std::move(shared_token);
  a->players_ = std::move(players);
  a->admin_token_ = std::move(admin_token);
  a->store_ = std::move(store);
  auto lists = a->read_lists();
  if (!lists) return lists.error();
  a->bans_ = std::move(lists->bans);
  a->whitelist_ = std::move(lists->whitelist);
  a->whitelist_on_ = lists->whitelist_on;
  return a;
}

FileResult<AccessControl::Lists> AccessControl::read_lists() {
  std::lock_guard store_lock(store_m_);
  auto entries = store_->access_entries();
  if (!entries) return entries.error();
  Lists l;
  for (const auto& [key, value] : *entries) {
    if (key == "whitelist") {
      l.whitelist_on = value == "on";
    } else if (key.rfind("whitelist:", 0) == 0) {
      l.whitelist.insert(key.substr(10));
    } else if (key.rfind("ban:name:", 0) == 0 || key.rfind("ban:addr:", 0) == 0) {
      Ban b;
      b.address = key[4] == 'a';
      b.target = key.substr(9);
      std::istringstream v(value);
      v >> b.until;
      std::getline(v >> std::ws, b.reason);
      l.bans[{kind_of(b.target, b.address), b.target}] = b;
    }
  }
  return l;
}

namespace {

// "what: +a +b -c ~d" for the keys added, removed and changed, or "".
template <class Map, class Same>
std::string changes(const std::string& what, const Map& before, const Map& after, Same same,
                    std::string (*name)(const typename Map::key_type&)) {
  std::string added, removed, changed;
  for (const auto& [k, v] : after) {
    const auto it = before.find(k);
    if (it == before.end())
      added += " +" + name(k);
    else if (!same(it->second, v))
      changed += " ~" + name(k);
  }
  for (const auto& [k, v] : before)
    if (after.find(k) == after.end()) removed += " -" + name(k);
  if (added.empty() && removed.empty() && changed.empty()) return "";
  return what + ":" + added + removed + changed;
}

}  // namespace

FileResult<std::vector<std::string>> AccessControl::reload(
    std::optional<std::unordered_map<std::string, PlayerToken>> players) {
  auto lists = read_lists();
  if (!lists) return lists.error();
  std::vector<std::string> out;
  auto keep = [&](std::string line) {
    if (!line.empty()) out.push_back(std::move(line));
  };
  std::lock_guard lock(m_);
  if (players) {
    // In name order, for a stable line.
    const std::map<std::string, PlayerToken> was(players_.begin(), players_.end()), now(players->begin(), players->end());
    keep(changes(
        "tokens", was, now,
        [](const PlayerToken& a, const PlayerToken& b) { return a.token == b.token && a.admin == b.admin; },
        +[](const std::string& k) { return k; }));
    players_ = std::move(*players);
  }
  keep(changes(
      "bans", bans_, lists->bans,
      [](const Ban& a, const Ban& b) { return a.until == b.until && a.reason == b.reason; },
      +[](const std::pair<BanKind, std::string>& k) { return k.second; }));
  std::map<std::string, bool> was_listed, now_listed;
  for (const auto& n : whitelist_) was_listed[n] = true;
  for (const auto& n : lists->whitelist) now_listed[n] = true;
  keep(changes(
      "whitelist", was_listed, now_listed, [](bool, bool) { return true; }, +[](const std::string& k) { return k; }));
  if (whitelist_on_ != lists->whitelist_on) keep(std::string("whitelist turned ") + (lists->whitelist_on ? "on" : "off"));
  bans_ = std::move(lists->bans);
  whitelist_ = std::move(lists->whitelist);
  whitelist_on_ = lists->whitelist_on;
  return out;
}

bool AccessControl::open_to_all() const {
  std::lock_guard lock(m_);
  return shared_token_.empty() && players_.empty();
}

Admission AccessControl::admit(const std::string& name, const std::string& token, const std::string& address,
                               std::int64_t now) const {
  Admission a;
  const bool is_admin = !admin_token_.empty() && token == admin_token_;
  std::lock_guard lock(m_);
  if (is_admin) {
    a.admin = true;
  } else if (!players_.empty()) {
    auto it = players_.find(name);
    if (it == players_.end() || it->second.token != token) {
      a.reason = "authentication failed";
      return a;
    }
    a.admin = it->second.admin;
    a.identified = true;
  } else if (!shared_token_.empty() && token != shared_token_) {
    a.reason = "authentication failed";
    return a;
  } else if (shared_token_.empty() && !admin_token_.empty() && !token.empty()) {
    // An open server with an admin token: a wrong token is refused rather
    // than let in as a player (it was meant to be the admin's).
    a.reason = "authentication failed";
    return a;
  }
  if (!a.admin) {
    const auto in_force = [&](const Ban& b) { return b.until == 0 || b.until > now; };
    const Ban* found = nullptr;
    for (const auto& key : {std::pair{BanKind::kName, name}, std::pair{BanKind::kAddress, address}}) {
      auto it = bans_.find(key);
      if (it != bans_.end() && in_force(it->second)) {
        found = &it->second;
        break;
      }
    }
    // Network bans ("10.0.0.0/8"), the only ones walked: few.
    for (auto it = bans_.lower_bound({BanKind::kNetwork, ""});
         found == nullptr && it != bans_.end() && it->first.first == BanKind::kNetwork; ++it)
      if (in_force(it->second) && address_in_network(address, it->second.target)) found = &it->second;
    if (found != nullptr) {
      a.why = CloseReason::kBanned;
      a.reason = "banned";
      if (found->until != 0) a.reason += " for " + std::to_string(found->until - now) + " s more";
      if (!found->reason.empty()) a.reason += ": " + found->reason;
      return a;
    }
    if (whitelist_on_ && whitelist_.count(name) == 0) {
      a.why = CloseReason::kNotWhitelisted;
      a.reason = "not on the whitelist: the server admits listed players only (ask an operator)";
      return a;
    }
  }
  a.ok = true;
  return a;
}

FileStatus AccessControl::ban(const Ban& b) {
  std::lock_guard store_lock(store_m_);
  const std::string key = ban_key(b.target, b.address);
  if (auto st = store_->put_access(key, std::to_string(b.until) + " " + b.reason); !st) return st;
  std::lock_guard lock(m_);
  bans_[{kind_of(b.target, b.address), b.target}] = b;
  return Ok{};
}

FileResult<bool> AccessControl::unban(const std::string& target) {
  std::lock_guard store_lock(store_m_);
  bool any = false;
  for (const bool address : {false, true}) {
    const std::pair key{kind_of(target, address), target};
    {
      std::lock_guard lock(m_);
      if (bans_.count(key) == 0) continue;
    }
    if (auto st = store_->erase_access(ban_key(target, address)); !st) return st.error();
    std::lock_guard lock(m_);
    bans_.erase(key);
    any = true;
  }
  return any;
}

std::vector<Ban> AccessControl::bans(std::int64_t now) const {
  std::lock_guard lock(m_);
  std::vector<Ban> out;
  for (const auto& [key, b] : bans_)
    if (b.until == 0 || b.until > now) out.push_back(b);
  // In the store keys' order: addresses and networks by their text, then names.
  std::sort(out.begin(), out.end(), [](const Ban& a, const Ban& b) {
    return std::pair{!a.address, a.target} < std::pair{!b.address, b.target};
  });
  return out;
}

FileStatus AccessControl::set_whitelist(bool on) {
  std::lock_guard store_lock(store_m_);
  if (auto st = store_->put_access("whitelist", on ? "on" : "off"); !st) return st;
  std::lock_guard lock(m_);
  whitelist_on_ = on;
  return Ok{};
}

FileStatus AccessControl::whitelist_add(const std::string& name) {
  std::lock_guard store_lock(store_m_);
  if (auto st = store_->put_access("whitelist:" + name, ""); !st) return st;
  std::lock_guard lock(m_);
  whitelist_.insert(name);
  return Ok{};
}

FileResult<bool> AccessControl::whitelist_remove(const std::string& name) {
  std::lock_guard store_lock(store_m_);
  {
    std::lock_guard lock(m_);
    if (whitelist_.count(name) == 0) return false;
  }
  if (auto st = store_->erase_access("whitelist:" + name); !st) return st.error();
  std::lock_guard lock(m_);
  whitelist_.erase(name);
  return true;
}

bool AccessControl::whitelist_on() const {
  std::lock_guard lock(m_);
  return whitelist_on_;
}

std::set<std::string> AccessControl::whitelist() const {
  std::lock_guard lock(m_);
  return whitelist_;
}

}  // namespace terrane
