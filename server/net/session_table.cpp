#include "server/net/session_table.h"

namespace terrane {

bool SessionTable::add(std::uint64_t id, const std::shared_ptr<ClientSession>& client) {
  std::lock_guard lock(m_);
  peers_[id] = Peer{client->session(), client};
  return peers_.size() <= max_clients_;
}

void SessionTable::remove(std::uint64_t id) {
  std::lock_guard lock(m_);
  peers_.erase(id);
}

std::size_t SessionTable::size() const {
  std::lock_guard lock(m_);
  return peers_.size();
}

void SessionTable::for_each_welcomed(
    const std::function<void(std::uint64_t id, Session& session, const ClientSession::Info& info)>& fn) const {
  std::lock_guard lock(m_);
  for (const auto& [id, peer] : peers_) {
    auto s = peer.session.lock();
    auto c = peer.client.lock();
    if (!s || !c) continue;
    const ClientSession::Info info = c->info();
    if (info.welcomed) fn(id, *s, info);
  }
}

SessionTable::Replacement SessionTable::replace_earlier_joins(std::uint64_t id, const std::string& name,
                                                              std::uint64_t join_order, CloseReason why,
                                                              const std::string& text) const {
  Replacement r;
  for_each_welcomed([&](std::uint64_t other, Session& s, const ClientSession::Info& info) {
    if (other == id || info.admin || info.name != name) return;
    if (info.join_order < join_order) {
      s.close(why, text);
      r.ended.push_back(other);
    } else {
      r.newer = other;
    }
  });
  return r;
}

std::vector<std::shared_ptr<Session>> SessionTable::live() const {
  std::vector<std::shared_ptr<Session>> out;
  std::lock_guard lock(m_);
  out.reserve(peers_.size());
  for (const auto& [id, peer] : peers_)
    if (auto s = peer.session.lock()) out.push_back(std::move(s));
  return out;
}

void SessionTable::close_all(CloseReason why, const std::string& text) {
  for (const auto& s : live()) s->close(why, text);
}

}  // namespace terrane
