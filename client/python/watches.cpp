#include "client/python/watches.h"

#include <utility>

#include "client/python/gil.h"

namespace terrane::python {

// The continuations by token (touched only under the GIL).
struct Watches::Ids::Pending {
  std::unordered_map<std::uint64_t, Continuation> by_token;
  std::uint64_t next_token = 1;

  // Takes token's continuation out and runs it, if it is still there.
  void run(std::uint64_t token) {
    auto it = by_token.find(token);
    if (it == by_token.end()) return;
    Continuation then = std::move(it->second);
    by_token.erase(it);
    then();
  }
};

Watches::Watches(std::shared_ptr<DispatcherSlot> slot)
    : ids_(std::make_shared<Ids>()), pending_(std::make_shared<Ids::Pending>()) {
  ids_->slot_ = std::move(slot);
  ids_->pending_ = pending_;
}

void Watches::on_edit(Client& c, std::uint32_t id, Continuation then) {
  watch(Kind::kEdit, id, false, std::move(then));
  // Answered before the watch was in place: run it here, unless the io
  // side already took it.
  bool now = false;
  without_gil([&] {
    c.wait_until([&](const ClientView& v) { return now = v.closed || v.edits.count(id) != 0; },
                 std::chrono::milliseconds(0));
  });
  if (now) watch(Kind::kEdit, id, true, nullptr);
}

void Watches::on_read(Client& c, std::uint32_t id, Continuation then) {
  watch(Kind::kRead, id, false, std::move(then));
  bool now = false;
  without_gil([&] {
    c.wait_until([&](const ClientView& v) { return now = v.closed || v.read_results.count(id) != 0; },
                 std::chrono::milliseconds(0));
  });
  if (now) watch(Kind::kRead, id, true, nullptr);
}

std::uint64_t Watches::keep(Continuation then) {
  // The callbacks thread must exist before the io side posts to it.
  ids_->slot_->get();
  const std::uint64_t token = pending_->next_token++;
  pending_->by_token.emplace(token, std::move(then));
  return token;
}

void Watches::on_event(Continuation then) {
  const std::uint64_t token = keep(std::move(then));
  std::lock_guard lock(ids_->mutex_);
  ids_->events_.push_back(token);
}

void Watches::watch(Kind kind, std::uint32_t id, bool answered_now, Continuation then) {
  auto& ids = kind == Kind::kEdit ? ids_->edits_ : ids_->reads_;
  if (!answered_now) {
    const std::uint64_t token = keep(std::move(then));
    std::lock_guard lock(ids_->mutex_);
    ids[id] = token;
    return;
  }
  std::uint64_t token = 0;
  {
    std::lock_guard lock(ids_->mutex_);
    auto it = ids.find(id);
    if (it == ids.end()) return;  // the io side took it: posted
    token = it->second;
    ids.erase(it);
  }
  pending_->run(token);
}

void Watches::Ids::edit_answered(std::uint32_t id) {
  std::vector<std::uint64_t> tokens;
  {
    std::lock_guard lock(mutex_);
    if (auto it = edits_.find(id); it != edits_.end()) {
      tokens.push_back(it->second);
      edits_.erase(it);
    }
  }
  post(tokens);
}

void Watches::Ids::read_answered(std::uint32_t id) {
  std::vector<std::uint64_t> tokens;
  {
    std::lock_guard lock(mutex_);
    if (auto it = reads_.find(id); it != reads_.end()) {
      tokens.push_back(it->second);
      reads_.erase(it);
    }
  }
  post(tokens);
}

void Watches::Ids::connection_lost() {
  std::vector<std::uint64_t> tokens;
  {
    std::lock_guard lock(mutex_);
    for (const auto& [id, token] : reads_) tokens.push_back(token);
    reads_.clear();
  }
  post(tokens);
}

void Watches::Ids::closed() {
  std::vector<std::uint64_t> tokens;
  {
    std::lock_guard lock(mutex_);
    for (const auto& [id, token] : edits_) tokens.push_back(token);
    for (const auto& [id, token] : reads_) tokens.push_back(token);
    tokens.insert(tokens.end(), events_.begin(), events_.end());
    edits_.clear();
    reads_.clear();
    events_.clear();
  }
  post(tokens);
}

void Watches::Ids::event_queued() {
  std::vector<std::uint64_t> tokens;
  {
    std::lock_guard lock(mutex_);
    tokens.swap(events_);
  }
  post(tokens);
}

void Watches::Ids::post(const std::vector<std::uint64_t>& tokens) {
  if (tokens.empty()) return;
  auto d = slot_->peek();
  if (!d) return;
  // One job each (a continuation that raises does not keep the next from
  // running); must: never dropped (an await would never return).
  for (std::uint64_t t : tokens)
    d->post(
        [pending = pending_, t] {
          if (auto p = pending.lock()) p->run(t);
        },
        true);
}

}  // namespace terrane::python
