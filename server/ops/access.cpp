#include "server/ops/access.h"

#include <algorithm>
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

FileResult<std::unique_ptr<AccessControl>> AccessControl::open(std::unique_ptr<WorldStore> store, std::string shared_token,
                                                                std::unordered_map<std::string, PlayerToken> players,
                                                                std::string admin_token) {
  std::unique_ptr<AccessControl> a(new AccessControl());
  a->shared_token_ = std::move(shared_token);
  a->players_ = std::move(players);
  a->admin_token_ = std::move(admin_token);
  a->store_ = std::move(store);
  if (auto st = a->load(); !st) return st.error();
  return a;
}

FileStatus AccessControl::load() {
  auto entries = store_->access_entries();
  if (!entries) return entries.error();
  for (const auto& [key, value] : *entries) {
    if (key == "whitelist") {
      whitelist_on_ = value == "on";
    } else if (key.rfind("whitelist:", 0) == 0) {
      whitelist_.insert(key.substr(10));
    } else if (key.rfind("ban:name:", 0) == 0 || key.rfind("ban:addr:", 0) == 0) {
      Ban b;
      b.address = key[4] == 'a';
      b.target = key.substr(9);
      std::istringstream v(value);
      v >> b.until;
      std::getline(v >> std::ws, b.reason);
      bans_[{kind_of(b.target, b.address), b.target}] = b;
    }
  }
  return Ok{};
}

Admission AccessControl::admit(const std::string& name, const std::string& token, const std::string& address,
                               std::int64_t now) const {
  Admission a;
  const bool is_admin = !admin_token_.empty() && token == admin_token_;
  if (is_admin) {
    a.admin = true;
  } else if (!players_.empty()) {
    auto it = players_.find(name);
    if (it == players_.end() || it->second.token != token) {
      a.reason = "authentication failed";
      return a;
    }
    a.admin = it->second.admin;
  } else if (!shared_token_.empty() && token != shared_token_) {
    a.reason = "authentication failed";
    return a;
  } else if (shared_token_.empty() && !admin_token_.empty() && !token.empty()) {
    // An open server with an admin token: a wrong token is refused rather
    // than let in as a player (it was meant to be the admin's).
    a.reason = "authentication failed";
    return a;
  }
  std::lock_guard lock(m_);
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
