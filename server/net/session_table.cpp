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
