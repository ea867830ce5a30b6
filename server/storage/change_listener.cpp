#include "server/storage/change_listener.h"

#include <chrono>

#include "server/log.h"

namespace terrane {

std::string ChangeListener::name_of(std::uint32_t server) {
  return "terrane-server " + std::to_string(server) + " listener";
}

StoreResult<std::unique_ptr<ChangeListener>> ChangeListener::open(const std::string& url, std::uint32_t server,
                                                                  Handlers handlers) {
  auto conn = PostgresStore::open(url);
  if (!conn) return conn.error();
  if (auto n = (*conn)->set_name(name_of(server)); !n) return n.error();
  if (auto l = (*conn)->listen(); !l) return l.error();
  std::unique_ptr<ChangeListener> out(new ChangeListener(url, server, std::move(handlers), std::move(*conn)));
  out->thread_ = std::thread([p = out.get()] { p->run(); });
  return out;
}

ChangeListener::ChangeListener(std::string url, std::uint32_t server, Handlers handlers,
                               std::unique_ptr<PostgresStore> conn)
    : url_(std::move(url)), server_(server), server_text_(std::to_string(server)), on_(std::move(handlers)), conn_(std::move(conn)) {}

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
      auto again = PostgresStore::open(url_);
      if (again && (*again)->set_name(name_of(server_)) && (*again)->listen()) {
        conn_ = std::move(*again);
        server_log().info("notices from the other servers: listening again; reading again what may have been missed");
        on_.missed();
        // Answers whose notices went out meanwhile, after the chunks they
        // acknowledge were marked for reading again.
        if (auto answers = conn_->take_answers(server_); answers) {
          for (ForwardAnswer& a : *answers) on_.answer(std::move(a));
        } else {
          server_log().warn("notices from the other servers: {}; connecting again", answers.error().message);
          conn_.reset();
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
      conn_.reset();
      continue;
    }
    std::vector<std::int64_t> answered;
    for (const PostgresStore::Notice& n : *got) hand_on(n, answered);
    // Their rows are not needed once the notices came (a failure leaves
    // them to the ten-minute sweep).
    if (!answered.empty()) (void)conn_->forget_answers(answered);
  }
}

void ChangeListener::hand_on(const PostgresStore::Notice& n, std::vector<std::int64_t>& answered) {
  bool read = true;
  if (n.channel == kChangesChannel) {
    auto changes = parse_change_notice(n.payload);
    read = changes.has_value();
    if (changes) on_.changes(std::move(*changes));
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
