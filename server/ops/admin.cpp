#include "server/ops/admin.h"

#include <chrono>
#include <cstdio>
#include <ctime>
#include <future>
#include <sstream>

#include "common/cli/cli.h"
#include "common/cli/json.h"
#include "common/world/sqlite_store.h"
#include "server/base/log.h"

namespace terrane {

const char* const kAdminHelp =
    "status                          the server at a glance\n"
    "players                         who is connected: name, address, position, bytes in/out\n"
    "kick NAME [REASON...]           end NAME's session (they may join again)\n"
    "ban NAME|ADDRESS|NETWORK [--for DURATION] [REASON...]\n"
    "                                refuse NAME, ADDRESS or every address of NETWORK (10.0.0.0/8)\n"
    "                                at the handshake (DURATION: 90s, 15m, 2h, 7d; default: until\n"
    "                                unbanned) and end their sessions\n"
    "unban NAME|ADDRESS|NETWORK      lift a ban\n"
    "bans                            the bans in force\n"
    "whitelist on|off|add NAME|remove NAME|list\n"
    "                                while on, only listed players may join (admins always may)\n"
    "say TEXT...                     a message to every client\n"
    "log [--player NAME] [--box X0,Y0,Z0,X1,Y1,Z1] [--since DURATION] [--limit N]\n"
    "                                who changed what, newest first (default limit 50)\n"
    "rollback --player NAME [--since DURATION] [--box X0,Y0,Z0,X1,Y1,Z1]\n"
    "                                undo NAME's edits, newest first, leaving voxels others\n"
    "                                changed since as they are; one edit, itself logged\n"
    "save                            wait until every edit applied so far is stored\n"
    "backup PATH                     a consistent copy of the world, made while it runs, in the\n"
    "                                new directory PATH (on the server's machine)\n"
    "shutdown [--in SECONDS] [--restart] [--reason TEXT...]\n"
    "                                warn every client (again 10 min, 5 min, 2 min, 60 s, 30 s,\n"
    "                                10 s and 5 s before), then stop (saving); --restart tells\n"
    "                                them the server comes back, so they reconnect by themselves\n"
    "shutdown --cancel (or cancel-shutdown)\n"
    "                                cancel a pending shutdown and tell every client\n"
    "help                            this text\n";

namespace {


std::string num(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

// Bytes as MiB with two decimals (the unit of --edit-log-mb).
std::string mib(std::uint64_t bytes) {
  char b[64];
  std::snprintf(b, sizeof b, "%.2f", static_cast<double>(bytes) / (1 << 20));
  return b;
}

std::string join(const std::vector<std::string>& v, std::size_t from) {
  std::string out;
  for (std::size_t i = from; i < v.size(); ++i) out += (i > from ? " " : "") + v[i];
  return out;
}

std::int64_t unix_now() {
  return std::chrono::duration_cast<std::chrono::seconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}

bool is_address(const std::string& s) {
  asio::error_code ec;
  (void)asio::ip::make_address(s, ec);
  return !ec;
}

// What a ban names, as stored: an address or a network (canonical; address
// set), else a player's name.
std::string ban_target(const std::string& text, bool& address) {
  if (auto network = canonical_network(text)) {
    address = true;
    return *network;
  }
  address = is_address(text);
  return address ? canonical_address(text) : text;
}

std::string utc(std::int64_t ms) {
  const std::time_t t = static_cast<std::time_t>(ms / 1000);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%d %H:%M:%S", &tm);
  return b;
}

std::string region_text(const Region& r) {
  return std::to_string(r.min.x) + "," + std::to_string(r.min.y) + "," + std::to_string(r.min.z) + " .. " +
         std::to_string(r.max.x) + "," + std::to_string(r.max.y) + "," + std::to_string(r.max.z);
}

// The options of log and rollback; "" or the error.
struct LogOptions {
  EditLogQuery query;
};
std::string parse_log_options(const std::vector<std::string>& a, LogOptions* o) {
  for (std::size_t i = 0; i < a.size(); ++i) {
    const bool has_value = i + 1 < a.size();
    if (a[i] == "--player" && has_value) {
      o->query.player = a[++i];
    } else if (a[i] == "--since" && has_value) {
      const auto d = parse_duration_s(a[++i]);
      if (!d) return "--since '" + a[i] + "': not a duration (90s, 15m, 2h, 7d)";
      o->query.since_ms = (unix_now() - *d) * 1000;
    } else if (a[i] == "--box" && has_value) {
      std::int32_t c[6];
      if (!parse_int_list<std::int32_t>(a[++i], c, 6)) return "--box '" + a[i] + "': not X0,Y0,Z0,X1,Y1,Z1";
      const Region r{{std::min(c[0], c[3]), std::min(c[1], c[4]), std::min(c[2], c[5])},
                     {std::max(c[0], c[3]), std::max(c[1], c[4]), std::max(c[2], c[5])}};
      if (r.empty()) return "--box '" + a[i] + "': an empty box";
      o->query.box = r;
    } else if (a[i] == "--limit" && has_value) {
      const std::string& v = a[++i];
      if (v.empty() || v.size() > 5 || v.find_first_not_of("0123456789") != std::string::npos || std::stoul(v) == 0 ||
          std::stoul(v) > 10000)
        return "--limit '" + v + "': a number from 1 to 10000";
      o->query.limit = std::stoul(v);
    } else {
      return "unexpected '" + a[i] + "'";
    }
  }
  return "";
}

AdminResultMsg ok(std::string text, std::string json) { return {0, true, std::move(text), std::move(json)}; }
AdminResultMsg fail(std::string text) { return {0, false, text, "{\"error\": " + json_string(text) + "}"}; }

}  // namespace

std::optional<std::int64_t> parse_duration_s(const std::string& text) {
  if (text.empty()) return std::nullopt;
  std::int64_t unit = 1;
  std::string digits = text;
  switch (text.back()) {
    case 's': unit = 1; digits.pop_back(); break;
    case 'm': unit = 60; digits.pop_back(); break;
    case 'h': unit = 3600; digits.pop_back(); break;
    case 'd': unit = 86400; digits.pop_back(); break;
    default: break;
  }
  if (digits.empty() || digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos)
    return std::nullopt;
  const std::int64_t n = std::stoll(digits) * unit;
  if (n <= 0) return std::nullopt;
  return n;
}

Admin::Admin(const WorldStore& store, std::string world_dir, AccessControl& access, AdminHooks hooks)
    : store_(store),
      world_dir_(std::move(world_dir)),
      access_(access),
      hooks_(std::move(hooks)),
      work_(asio::make_work_guard(io_)) {
  thread_ = std::thread([this] { io_.run(); });
}

Admin::~Admin() {
  stopping_ = true;  // a command waiting on the world gives up
  work_.reset();
  io_.stop();
  if (thread_.joinable()) thread_.join();
}

template <class Future>
bool Admin::wait_for(Future& f, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (f.wait_for(std::chrono::milliseconds(100)) != std::future_status::ready) {
    if (stopping_ || std::chrono::steady_clock::now() > deadline) return false;
  }
  return true;
}

void Admin::handle(const std::string& who, AdminRequestMsg req, Reply reply) {
  asio::post(io_, [this, who, req = std::move(req), reply = std::move(reply)] {
    AdminResultMsg r;
    try {
      r = run(who, req);
    } catch (const std::exception& e) {  // e.g. a promise broken by a stopping world
      r = fail(req.command + ": " + e.what());
    }
    r.request_id = req.request_id;
    server_log().info("admin {}: {} {} -> {}", who, req.command, join(req.args, 0),
                      r.ok ? "ok" : "refused: " + r.text);
    reply(std::move(r));
  });
}

AdminResultMsg Admin::run(const std::string& who, const AdminRequestMsg& req) {
  const std::string& cmd = req.command;
  const std::vector<std::string>& a = req.args;
  if (cmd == "help") return ok(kAdminHelp, "{\"help\": " + json_string(kAdminHelp) + "}");

  if (cmd == "status") {
    const ServerStatus s = hooks_.status();
    std::ostringstream t;
    t << "terrane-server " << s.version << " on " << s.address << "\n"
      << "world " << s.world_dir << " (epoch " << s.epoch << ")" << (s.border.empty() ? "" : ", " + s.border) << ", up "
      << static_cast<long long>(s.uptime_s) << " s\n"
      << (s.shutdown_in_s ? "shutdown pending: stopping in " + std::to_string(*s.shutdown_in_s) + " s\n" : "")
      << s.clients << " players, " << s.admin_sessions << " admin sessions; " << s.ticks << " ticks at " << s.tick_hz << " Hz (mean " << num(s.tick_mean_ms)
      << " ms); edits " << s.edits_applied << " applied, " << s.edits_rejected << " rejected; " << s.chunks_resident
      << " chunks resident; storage " << (s.storage_failed ? "FAILED" : "ok") << "; edit log "
      << (s.edit_log ? std::to_string(s.edit_log->entries) + " entries, " + mib(s.edit_log->bytes) + " MiB"
                     : std::string("size unknown"))
      << "; whitelist " << (access_.whitelist_on() ? "on" : "off") << "\n";
    std::ostringstream j;
    j << "{\"version\": " << json_string(s.version) << ", \"address\": " << json_string(s.address)
      << ", \"border\": " << json_string(s.border) << ", \"shutdown_in_s\": "
      << (s.shutdown_in_s ? std::to_string(*s.shutdown_in_s) : std::string("null"))
      << ", \"world\": " << json_string(s.world_dir) << ", \"epoch\": " << s.epoch << ", \"uptime_s\": " << num(s.uptime_s)
      << ", \"clients\": " << s.clients << ", \"admin_sessions\": " << s.admin_sessions << ", \"ticks\": " << s.ticks << ", \"tick_hz\": " << s.tick_hz
      << ", \"tick_mean_ms\": " << num(s.tick_mean_ms) << ", \"edits_applied\": " << s.edits_applied
      << ", \"edits_rejected\": " << s.edits_rejected << ", \"chunks_resident\": " << s.chunks_resident
      << ", \"storage_failed\": " << (s.storage_failed ? "true" : "false") << ", \"edit_log_entries\": "
      << (s.edit_log ? std::to_string(s.edit_log->entries) : std::string("null")) << ", \"edit_log_bytes\": "
      << (s.edit_log ? std::to_string(s.edit_log->bytes) : std::string("null"))
      << ", \"whitelist\": " << (access_.whitelist_on() ? "true" : "false") << "}";
    return ok(t.str(), j.str());
  }

  if (cmd == "players") {
    const auto players = hooks_.players();
    std::ostringstream t, j;
    char line[512];
    std::snprintf(line, sizeof line, "%-20s %-16s %-26s %8s %8s %12s %12s\n", "name", "address", "position", "online",
                  "ping", "bytes in", "bytes out");
    t << line;
    j << "{\"players\": [";
    for (std::size_t i = 0; i < players.size(); ++i) {
      const PlayerInfo& p = players[i];
      char pos[96];
      std::snprintf(pos, sizeof pos, "%.0f,%.0f,%.0f", p.position.x, p.position.y, p.position.z);
      char ping[32];
      if (p.ping_ms < 0)
        std::snprintf(ping, sizeof ping, "-");
      else
        std::snprintf(ping, sizeof ping, "%.1fms", p.ping_ms);
      std::snprintf(line, sizeof line, "%-20s %-16s %-26s %7.0fs %8s %12llu %12llu%s\n", p.name.c_str(),
                    p.address.c_str(), pos, p.connected_s, ping, static_cast<unsigned long long>(p.bytes_in),
                    static_cast<unsigned long long>(p.bytes_out), p.admin ? "  (admin)" : "");
      t << line;
      j << (i ? ", " : "") << "{\"id\": " << p.id << ", \"name\": " << json_string(p.name)
        << ", \"address\": " << json_string(p.address) << ", \"position\": [" << num(p.position.x) << ", "
        << num(p.position.y) << ", " << num(p.position.z) << "], \"admin\": " << (p.admin ? "true" : "false")
        << ", \"connected_s\": " << num(p.connected_s)
        << ", \"ping_ms\": " << (p.ping_ms < 0 ? std::string("null") : num(p.ping_ms)) << ", \"bytes_in\": " << p.bytes_in
        << ", \"bytes_out\": " << p.bytes_out << "}";
    }
    j << "]}";
    t << players.size() << " connected\n";
    return ok(t.str(), j.str());
  }

  if (cmd == "kick") {
    if (a.empty()) return fail("usage: kick NAME [REASON...]");
    const std::string reason = a.size() > 1 ? join(a, 1) : "no reason given";
    const int n = hooks_.close_matching([&](const PlayerInfo& p) { return p.name == a[0]; }, CloseReason::kKicked,
                                        "kicked by an operator: " + reason);
    if (n == 0) return fail("no player named '" + a[0] + "' is connected");
    return ok("kicked " + a[0] + " (" + std::to_string(n) + " session" + (n == 1 ? "" : "s") + ")\n",
              "{\"kicked\": " + std::to_string(n) + "}");
  }

  if (cmd == "ban") {
    if (a.empty()) return fail("usage: ban NAME|ADDRESS|NETWORK [--for DURATION] [REASON...]");
    if (const auto slash = a[0].find('/');
        slash != std::string::npos && is_address(a[0].substr(0, slash)) && !canonical_network(a[0]))
      return fail("ban '" + a[0] + "': not a network (ADDRESS/PREFIX, a prefix of at most 32 bits for IPv4, 128 for IPv6)");
    Ban b;
    b.target = ban_target(a[0], b.address);
    std::size_t rest = 1;
    if (a.size() > 2 && a[1] == "--for") {
      const auto d = parse_duration_s(a[2]);
      if (!d) return fail("ban --for '" + a[2] + "': not a duration (90s, 15m, 2h, 7d)");
      b.until = unix_now() + *d;
      rest = 3;
    } else if (a.size() == 2 && a[1] == "--for") {
      return fail("ban --for: missing DURATION");
    }
    b.reason = join(a, rest);
    if (auto st = access_.ban(b); !st) return fail("ban: " + st.error().message);
    const int n = hooks_.close_matching(
        [&](const PlayerInfo& p) {
          if (p.admin) return false;
          if (!b.address) return p.name == b.target;
          return p.address == b.target || address_in_network(p.address, b.target);
        },
        CloseReason::kBanned, "banned" + (b.reason.empty() ? std::string() : ": " + b.reason));
    const std::string how = b.until == 0 ? "until unbanned" : "for " + std::to_string(b.until - unix_now()) + " s";
    const char* what = !b.address ? "" : b.target.find('/') != std::string::npos ? "network " : "address ";
    return ok("banned " + std::string(what) + b.target + " " + how + " (" + std::to_string(n) +
                  " session" + (n == 1 ? "" : "s") + " ended)\n",
              "{\"banned\": " + json_string(b.target) + ", \"address\": " + (b.address ? "true" : "false") +
                  ", \"until\": " + std::to_string(b.until) + ", \"sessions_ended\": " + std::to_string(n) + "}");
  }

  if (cmd == "unban") {
    if (a.size() != 1) return fail("usage: unban NAME|ADDRESS|NETWORK");
    bool address = false;
    auto r = access_.unban(ban_target(a[0], address));
    if (!r) return fail("unban: " + r.error().message);
    if (!*r) return fail("'" + a[0] + "' is not banned");
    return ok("unbanned " + a[0] + "\n", "{\"unbanned\": " + json_string(a[0]) + "}");
  }

  if (cmd == "bans") {
    const auto bans = access_.bans(unix_now());
    std::ostringstream t, j;
    j << "{\"bans\": [";
    for (std::size_t i = 0; i < bans.size(); ++i) {
      const Ban& b = bans[i];
      t << (b.address ? "address " : "name    ") << b.target << "  "
        << (b.until == 0 ? std::string("until unbanned") : std::to_string(b.until - unix_now()) + " s left")
        << (b.reason.empty() ? "" : "  " + b.reason) << "\n";
      j << (i ? ", " : "") << "{\"target\": " << json_string(b.target) << ", \"address\": " << (b.address ? "true" : "false")
        << ", \"until\": " << b.until << ", \"reason\": " << json_string(b.reason) << "}";
    }
    j << "]}";
    t << bans.size() << " bans\n";
    return ok(t.str(), j.str());
  }

  if (cmd == "whitelist") {
    const std::string sub = a.empty() ? "list" : a[0];
    if (sub == "on" || sub == "off") {
      if (auto st = access_.set_whitelist(sub == "on"); !st) return fail("whitelist: " + st.error().message);
      return ok("whitelist " + sub + "\n", std::string("{\"whitelist\": ") + (sub == "on" ? "true" : "false") + "}");
    }
    if (sub == "add" && a.size() == 2) {
      if (a[1].empty() || a[1].size() > kMaxClientNameBytes) return fail("whitelist add: a name is 1 to 64 bytes");
      if (auto st = access_.whitelist_add(a[1]); !st) return fail("whitelist: " + st.error().message);
      return ok("added " + a[1] + " to the whitelist\n", "{\"added\": " + json_string(a[1]) + "}");
    }
    if (sub == "remove" && a.size() == 2) {
      auto r = access_.whitelist_remove(a[1]);
      if (!r) return fail("whitelist: " + r.error().message);
      if (!*r) return fail("'" + a[1] + "' is not on the whitelist");
      return ok("removed " + a[1] + " from the whitelist\n", "{\"removed\": " + json_string(a[1]) + "}");
    }
    if (sub == "list" && a.size() <= 1) {
      const auto names = access_.whitelist();
      std::ostringstream t, j;
      t << "whitelist " << (access_.whitelist_on() ? "on" : "off") << ", " << names.size() << " names\n";
      j << "{\"on\": " << (access_.whitelist_on() ? "true" : "false") << ", \"names\": [";
      bool first = true;
      for (const auto& n : names) {
        t << "  " << n << "\n";
        j << (first ? "" : ", ") << json_string(n);
        first = false;
      }
      j << "]}";
      return ok(t.str(), j.str());
    }
    return fail("usage: whitelist on|off|add NAME|remove NAME|list");
  }

  if (cmd == "say") {
    if (a.empty()) return fail("usage: say TEXT...");
    ServerNoticeMsg n;
    n.kind = wire::NoticeKind::Say;
    n.text = join(a, 0);
    if (n.text.size() > kMaxNoticeBytes) return fail("say: text longer than 1024 bytes");
    hooks_.notify_all(n);
    return ok("said to every client\n", "{\"said\": " + json_string(n.text) + "}");
  }

  if (cmd == "log") {
    LogOptions o;
    o.query.limit = 50;
    if (auto e = parse_log_options(a, &o); !e.empty())
      return fail("log: " + e + " (usage: log [--player NAME] [--box X0,Y0,Z0,X1,Y1,Z1] [--since DURATION] [--limit N])");
    auto store = store_.reopen();
    if (!store) return fail("log: " + store.error().message);
    auto entries = (*store)->edit_log(o.query);
    if (!entries) return fail("log: " + entries.error().message);
    std::ostringstream t, j;
    j << "{\"edits\": [";
    for (std::size_t i = 0; i < entries->size(); ++i) {
      const EditLogEntry& e = (*entries)[i];
      t << utc(e.time_ms) << "  " << e.player << "  " << region_text(e.box) << "  (tick " << e.tick << ")\n";
      j << (i ? ", " : "") << "{\"id\": " << e.id << ", \"time_ms\": " << e.time_ms << ", \"tick\": " << e.tick
        << ", \"player\": " << json_string(e.player) << ", \"box\": [" << e.box.min.x << ", " << e.box.min.y << ", "
        << e.box.min.z << ", " << e.box.max.x << ", " << e.box.max.y << ", " << e.box.max.z << "]}";
    }
    j << "]}";
    t << entries->size() << " edits" << (entries->size() == o.query.limit ? " (the limit: --limit N for more)" : "")
      << "\n";
    return ok(t.str(), j.str());
  }

  if (cmd == "rollback") {
    LogOptions o;
    for (const std::string& arg : a)
      if (arg == "--limit") return fail("rollback: takes no --limit (narrow it with --since or --box)");
    o.query.limit = kMaxRollbackEdits + 1;
    if (auto e = parse_log_options(a, &o); !e.empty() || o.query.player.empty())
      return fail("rollback: " + (e.empty() ? std::string("--player NAME is required") : e) +
                  " (usage: rollback --player NAME [--since DURATION] [--box X0,Y0,Z0,X1,Y1,Z1])");
    auto store = store_.reopen();
    if (!store) return fail("rollback: " + store.error().message);
    // First the boxes alone: the work is bounded before any voxels are read.
    auto boxes = (*store)->edit_log(o.query);
    if (!boxes) return fail("rollback: " + boxes.error().message);
    if (boxes->empty()) return fail("rollback: no edits by '" + o.query.player + "' match");
    if (boxes->size() > kMaxRollbackEdits)
      return fail("rollback: more than " + std::to_string(kMaxRollbackEdits) +
                  " edits match; narrow it with --since or --box");
    std::int64_t volume = 0;
    for (const EditLogEntry& e : *boxes) volume += e.box.volume();
    if (volume > kMaxRollbackVoxels)
      return fail("rollback: the matching edits cover " + std::to_string(volume) + " voxels, more than " +
                  std::to_string(kMaxRollbackVoxels) + " at once; narrow it with --since or --box");
    o.query.with_voxels = true;
    auto entries = (*store)->edit_log(o.query);
    if (!entries) return fail("rollback: " + entries.error().message);
    if (entries->empty()) return fail("rollback: no edits by '" + o.query.player + "' match");
    const std::size_t n = entries->size();
    auto done = std::make_shared<std::promise<std::tuple<bool, std::string, std::uint64_t, std::uint64_t>>>();
    auto f = done->get_future();
    hooks_.rollback(who, std::move(*entries), o.query.box,
                    [done](bool good, std::string error, std::uint64_t tick, std::uint64_t voxels) {
                      done->set_value({good, std::move(error), tick, voxels});
                    });
    if (!wait_for(f, std::chrono::seconds(300)))
      return fail(stopping_ ? "rollback: the server is stopping (it may not have been applied)"
                            : "rollback: still not applied after 300 s (it applies once its chunks are loaded)");
    const auto [good, error, tick, voxels] = f.get();
    if (!good) return fail("rollback: " + error);
    return ok("rolled back " + std::to_string(n) + " edits by " + o.query.player + ": " + std::to_string(voxels) +
                  " voxels restored at tick " + std::to_string(tick) + " (logged as " + who + "'s edit)\n",
              "{\"edits\": " + std::to_string(n) + ", \"voxels_restored\": " + std::to_string(voxels) +
                  ", \"tick\": " + std::to_string(tick) + "}");
  }

  if (cmd == "save") {
    if (!a.empty()) return fail("usage: save");
    auto done = std::make_shared<std::promise<std::pair<std::uint64_t, bool>>>();
    auto f = done->get_future();
    hooks_.flush([done](std::uint64_t tick, bool stored) { done->set_value({tick, stored}); });
    if (!wait_for(f, std::chrono::seconds(60)))
      return fail(stopping_ ? "save: the server is stopping" : "save: the store did not confirm within 60 s");
    const auto [tick, stored] = f.get();
    if (!stored) return fail("save: the store has failed; edits since the failure were not saved");
    return ok("saved: every edit applied up to tick " + std::to_string(tick) + " is stored\n",
              "{\"saved_through_tick\": " + std::to_string(tick) + "}");
  }

  if (cmd == "backup") {
    if (a.size() != 1) return fail("usage: backup PATH");
    if (world_dir_.empty())
      return fail("backup: the world is in PostgreSQL (" + store_.where() +
                  "): back it up with PostgreSQL's own tools (pg_dump, or a base backup)");
    auto store = SqliteStore::open(world_dir_);
    if (!store) return fail("backup: " + store.error().message);
    const auto t0 = std::chrono::steady_clock::now();
    if (auto st = (*store)->backup_to(a[0], [](int, int) {}); !st) return fail("backup: " + st.error().message);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return ok("backed up the world to " + a[0] + " in " + num(s) + " s\n",
              "{\"backup\": " + json_string(a[0]) + ", \"seconds\": " + num(s) + "}");
  }

  if (cmd == "cancel-shutdown" || (cmd == "shutdown" && a.size() == 1 && a[0] == "--cancel")) {
    if (cmd == "cancel-shutdown" && !a.empty()) return fail("usage: cancel-shutdown");
    if (!hooks_.cancel_shutdown || !hooks_.cancel_shutdown()) return fail("no shutdown is pending");
    return ok("the scheduled shutdown is cancelled\n", "{\"cancelled\": true}");
  }

  if (cmd == "shutdown") {
    std::uint32_t seconds = 0;
    bool restart = false;
    std::string reason;
    for (std::size_t i = 0; i < a.size(); ++i) {
      if (a[i] == "--in" && i + 1 < a.size()) {
        const auto d = a[i + 1] == "0" ? std::optional<std::int64_t>(0) : parse_duration_s(a[i + 1]);
        if (!d || *d > 86400) return fail("shutdown --in '" + a[i + 1] + "': not a duration up to a day");
        seconds = static_cast<std::uint32_t>(*d);
        ++i;
      } else if (a[i] == "--restart") {
        restart = true;
      } else if (a[i] == "--reason" && i + 1 < a.size()) {
        reason = join(a, i + 1);
        break;
      } else {
        return fail("usage: shutdown [--in SECONDS] [--restart] [--reason TEXT...]");
      }
    }
    hooks_.shutdown(seconds, restart, reason);
    return ok("stopping in " + std::to_string(seconds) + " s" + (restart ? ", clients told to reconnect" : "") + "\n",
              "{\"seconds\": " + std::to_string(seconds) + ", \"restart\": " + (restart ? "true" : "false") + "}");
  }

  (void)who;
  return fail("unknown command '" + cmd + "' (try help)");
}

}  // namespace terrane
