#include "server/cluster/change_listener.h"

#include <chrono>

#include "server/base/log.h"

namespace terrane {

std::string ChangeListener::name_of(std::uint32_t server) {
  return "terrane-server " + std::to_string(server) + " listener";
}

StoreResult<std::unique_ptr<ChangeListener>> ChangeListener::open(const std::string& url, std::uint32_t server,
                                                                  Handlers handlers, DatabaseCounters* counters) {
  auto conn = ClusterStore::open(url);
  if (!conn) return conn.error();
  if (auto n = (*conn)->set_name(name_of(server)); !n) return n.error();
  if (auto l = (*conn)->listen(); !l) return l.error();
  std::unique_ptr<ChangeListener> out(
      new ChangeListener(url, server, std::move(handlers), std::move(*conn), counters));
  // Subscribed first: every write after this read is in a notice.
  if (auto seqs = out->read_seqs(); !seqs) return seqs.error();
  out->thread_ = std::thread([p = out.get()] { p->run(); });
  return out;
}

ChangeListener::ChangeListener(std::string url, std::uint32_t server, Handlers handlers,
                               std::unique_ptr<ClusterStore> conn, DatabaseCounters* counters)
    : url_(std::move(url)),
      server_(server),
      server_text_(std::to_string(server)),
      on_(std::move(handlers)),
      counters_(counters),
      conn_(std::move(conn)) {}

void ChangeListener::lose_connection() {
  conn_.reset();
  if (counters_ != nullptr) counters_->listener_down.store(1, std::memory_order_relaxed);
}

ChangeListener::~ChangeListener() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void ChangeListener::run() {
  const auto stopping = [&] {
    std::lock_guard lock(mutex_);
    return stopping_;
  };
  while (!stopping()) {
    if (!conn_) {
      // Connected again and subscribed before anything is read again, so
      // nothing committed after the read can be missed.
      auto again = ClusterStore::open(url_);
      if (again && (*again)->set_name(name_of(server_)) && (*again)->listen()) {
        conn_ = std::move(*again);
        auto moved = read_seqs();
        if (!moved) {
          server_log().warn("notices from the other servers: {}; connecting again", moved.error().message);
          lose_connection();
          continue;
        }
        server_log().info("notices from the other servers: listening again; {} regions written meanwhile are read again",
                          moved->size());
        on_.missed(std::move(*moved));
        // Answers whose notices went out meanwhile, after the chunks they
        // acknowledge were marked for reading again.
        if (auto answers = conn_->take_answers(server_); answers) {
          for (ForwardAnswer& a : *answers) on_.answer(std::move(a));
          if (counters_ != nullptr) counters_->listener_down.store(0, std::memory_order_relaxed);
        } else {
          server_log().warn("notices from the other servers: {}; connecting again", answers.error().message);
          lose_connection();
        }
        continue;
      }
      std::unique_lock lock(mutex_);
      wake_.wait_for(lock, std::chrono::seconds(1), [&] { return stopping_; });
      continue;
    }
    // Short waits, so a stop is noticed soon.
    auto got = conn_->wait_notices(std::chrono::milliseconds(200));
    if (!got) {
      server_log().warn("notices from the other servers: {}; connecting again", got.error().message);
      lose_connection();
      continue;
    }
    std::vector<std::int64_t> answered;
    for (const ClusterStore::Notice& n : *got) hand_on(n, answered);
    // Their rows are not needed once the notices came (a failure leaves
    // them to the ten-minute sweep).
    if (!answered.empty()) (void)conn_->forget_answers(answered);
  }
}

StoreResult<std::vector<Vec3i>> ChangeListener::read_seqs() {
  auto now = conn_->region_seqs();
  if (!now) return now.error();
  std::vector<Vec3i> moved;
  for (const RegionSeq& r : *now) {
    std::uint64_t& known = seqs_[{r.region.x, r.region.y, r.region.z}];
    if (r.seq > known) {
      moved.push_back(r.region);
      known = r.seq;
    }
  }
  return moved;
}

void ChangeListener::hand_on(const ClusterStore::Notice& n, std::vector<std::int64_t>& answered) {
  bool read = true;
  if (n.channel == kChangesChannel) {
    auto notice = parse_change_notice(n.payload);
    read = notice.has_value();
    if (notice) {
      std::vector<Vec3i> skipped;
      for (const RegionSeq& r : notice->regions) {
        std::uint64_t& known = seqs_[{r.region.x, r.region.y, r.region.z}];
        if (r.seq > known + 1) skipped.push_back(r.region);
        known = std::max(known, r.seq);
      }
      if (notice->units_unread != 0)
        server_log().warn("notices from the other servers: the units of {} chunks do not read; reading them again",
                          notice->units_unread);
      if (!notice->chunks.empty()) on_.changes(std::move(notice->chunks));
      if (!skipped.empty()) {
        server_log().warn("notices from the other servers: {} regions skipped a write; reading them again",
                          skipped.size());
        on_.missed(std::move(skipped));
      }
    }
  } else if (n.channel == kInboxChannel) {
    if (n.payload == server_text_) on_.inbox();
  } else if (n.channel == kAnswersChannel) {
    auto a = parse_answer_notice(n.payload);
    read = a.has_value();
    if (a && a->from == server_) {
      answered.push_back(a->id);
      on_.answer(std::move(*a));
    }
  }
  if (!read)
    server_log().warn("notices from the other servers: a {} notice that does not read ({} bytes), ignored", n.channel,
                      n.payload.size());
}

}  // namespace terrane
