#include "server/cluster/cluster_store.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <libpq-fe.h>
#include <poll.h>

#include <algorithm>
#include <cerrno>
#include <limits>
#include <map>

#include "protocol/framing.h"
#include "protocol/messages.h"
#include "server/base/cluster_options.h"
#include "server/storage/postgres_store.h"

namespace terrane {

using pg::be32_at;
using pg::be64_at;
using pg::blob;
using pg::bytes_at;
using pg::Param;
using pg::position_at;
using pg::region_range;
using pg::region_text;
using pg::text;

namespace {

// A lease row whose values are not what the schema allows.
StoreError bad_row(const char* what, Vec3i region) {
  return StoreError{StoreError::Kind::kDecode,
                    fmt::format("postgresql: {}: region {} has a lease row out of range", what, region_text(region))};
}

// The database's clock in microseconds since 1970, as a statement's column.
constexpr const char* kClockMicros = "(extract(epoch FROM clock_timestamp()) * 1000000)::bigint";

// What an inbox row may say is left before its deadline at most: a sender
// waits max(2 s, a lease), and a lease is at most kMaxLease. A row saying
// more (written by hand, or by a broken server; its deadline 'infinity'
// even) is taken as saying this, so that its time stays in the steady
// clock's range.
constexpr std::int64_t kMaxInboxLeftUs = std::chrono::microseconds(kMaxLease).count();

}  // namespace

ClusterStore::ClusterStore(std::unique_ptr<PgConnection> c) : c_(std::move(c)) {}

ClusterStore::~ClusterStore() = default;

StoreResult<std::unique_ptr<ClusterStore>> ClusterStore::open(const std::string& url) {
  auto c = PgConnection::open(url);  // with the schema made or upgraded
  if (!c) return c.error();
  return std::unique_ptr<ClusterStore>(new ClusterStore(std::move(*c)));
}

StoreResult<RegionLease> ClusterStore::claim(Vec3i region, std::uint32_t owner, std::chrono::milliseconds lease,
                                               ClaimRule rule) {
  if (owner > kMaxServerId)
    return StoreError{StoreError::Kind::kQuery, fmt::format("server id {} is not below 2^31", owner)};
  if (rule == ClaimRule::kPreferNeighbours) {
    auto left = left_to_neighbour(region, owner);
    if (!left) return left.error();
    if (*left) return **left;
  }
  // Free, expired or the claimant's own: taken at the next epoch (a server
  // that claims again is a new incarnation: whatever its earlier self still
  // has in flight is fenced). Held by another: no row changes, and the
  // answer is empty. The lease counts from when the row is taken: the
  // update's own clock_timestamp(), read after any wait for the row's lock
  // (EXCLUDED's is read before it, and a claim that waited for a stalled
  // commit would get a lease already run out).
  auto r = c_->exec("claim region",
                    "INSERT INTO terrane_leases AS l (rx, ry, rz, owner, epoch, expires_at)"
                    " VALUES ($1, $2, $3, $4, 1, clock_timestamp() + $5::bigint * interval '1 millisecond')"
                    " ON CONFLICT (rx, ry, rz) DO UPDATE SET"
                    "  epoch = l.epoch + 1, owner = EXCLUDED.owner,"
                    "  expires_at = clock_timestamp() + $5::bigint * interval '1 millisecond'"
                    "  WHERE l.owner = EXCLUDED.owner OR l.expires_at <= clock_timestamp()"
                    " RETURNING epoch",
                    {text(region.x), text(region.y), text(region.z), text(owner), text(lease.count())});
  if (!r) return r.error();
  if (r->count() == 1) {
    const auto epoch = r->integer(0, 0);
    if (!epoch || *epoch < 1) return bad_row("claim region", region);
    return RegionLease{region, owner, static_cast<std::uint64_t>(*epoch)};
  }
  auto who = c_->exec("read region holder",
                      "SELECT owner, epoch, expires_at FROM terrane_leases WHERE rx = $1 AND ry = $2 AND rz = $3",
                      {text(region.x), text(region.y), text(region.z)});
  if (!who) return who.error();
  const std::string holder = who->count() == 1 ? fmt::format("server {} (epoch {}) until {}", who->get(0, 0),
                                                              who->get(0, 1), who->get(0, 2))
                                               : std::string("another server");
  StoreError owned{StoreError::Kind::kOwned, fmt::format("region {} is leased to {}", region_text(region), holder), {}};
  if (who->count() == 1)
    if (const auto id = who->integer(0, 0); id && *id >= 0 && *id <= std::numeric_limits<std::int32_t>::max())
      owned.holder = static_cast<std::uint32_t>(*id);
  return owned;
}

StoreResult<std::optional<StoreError>> ClusterStore::left_to_neighbour(Vec3i region, std::uint32_t owner) {
  // Per server with a current lease in the 3 x 3 x 3 regions around (a
  // range of the primary key): how many of the region's 26 neighbours it
  // writes, and whether it writes the region itself. A preference, read
  // apart from the claim: a claim racing it only makes a territory less
  // whole.
  auto r = c_->exec("read neighbouring leases",
                    "SELECT owner,"
                    " count(*) FILTER (WHERE NOT (rx = $1::int AND ry = $2::int AND rz = $3::int)),"
                    " count(*) FILTER (WHERE rx = $1::int AND ry = $2::int AND rz = $3::int)"
                    " FROM terrane_leases WHERE expires_at > clock_timestamp()"
                    "  AND rx BETWEEN $1::int - 1 AND $1::int + 1 AND ry BETWEEN $2::int - 1 AND $2::int + 1"
                    "  AND rz BETWEEN $3::int - 1 AND $3::int + 1"
                    " GROUP BY owner",
                    {text(region.x), text(region.y), text(region.z)});
  if (!r) return r.error();
  struct Writer {
    std::int64_t id = 0, near = 0, here = 0;
  };
  std::vector<Writer> writers;
  for (int i = 0; i < r->count(); ++i) {
    Writer w{r->integer(i, 0).value_or(-1), r->integer(i, 1).value_or(-1), r->integer(i, 2).value_or(-1)};
    if (w.id < 0 || w.id > kMaxServerId || w.near < 0 || w.here < 0)
      return StoreError{StoreError::Kind::kDecode, "postgresql: read neighbouring leases: a row is not a lease count"};
    writers.push_back(w);
  }
  for (const Writer& w : writers) {
    if (w.here > 0) return std::optional<StoreError>{};  // held: by another (the claim says whom) or by owner
    if (w.id == owner && w.near > 0) return std::optional<StoreError>{};  // next to this server's own
  }
  const Writer* best = nullptr;
  for (const Writer& w : writers)
    if (w.id != owner && w.near > 0 &&
        (best == nullptr || w.near > best->near || (w.near == best->near && w.id < best->id)))
      best = &w;
  if (best == nullptr) return std::optional<StoreError>{};
  return std::optional<StoreError>{StoreError{
      StoreError::Kind::kLeft,
      fmt::format("region {} is left to server {}, which writes {} of its neighbours (this server writes none)",
                  region_text(region), best->id, best->near),
      static_cast<std::uint32_t>(best->id)}};
}

void ClusterStore::set_call_timeout(std::chrono::milliseconds t) { c_->set_call_timeout(t); }

StoreResult<std::vector<RegionLease>> ClusterStore::renew(std::span<const RegionLease> leases,
                                                           std::chrono::milliseconds lease, DatabaseClock* clock) {
  std::vector<RegionLease> kept;
  if (leases.empty()) {
    if (clock == nullptr) return kept;
    auto r = c_->exec("read clock", (std::string("SELECT ") + kClockMicros).c_str());
    if (!r) return r.error();
    const auto at = r->count() == 1 ? r->integer(0, 0) : std::nullopt;
    if (!at) return StoreError{StoreError::Kind::kDecode, "postgresql: read clock: not a time"};
    *clock = DatabaseClock{*at, std::chrono::steady_clock::now()};
    return kept;
  }
  // One statement for every lease of one owner (a server holds thousands
  // of regions in a big world): arrays of the regions and their epochs.
  std::map<std::uint32_t, std::vector<const RegionLease*>> by_owner;
  for (const RegionLease& l : leases) by_owner[l.owner].push_back(&l);
  for (const auto& [owner, ls] : by_owner) {
    std::vector<std::int64_t> xs, ys, zs, epochs;
    for (const RegionLease* l : ls) {
      xs.push_back(l->region.x);
      ys.push_back(l->region.y);
      zs.push_back(l->region.z);
      epochs.push_back(static_cast<std::int64_t>(l->epoch));
    }
    auto array = [](const std::vector<std::int64_t>& v) { return Param{fmt::format("{{{}}}", fmt::join(v, ",")), false}; };
    // The rows are locked first, in the order a commit checks its leases
    // (save_fenced: y, z, x), so a renewal and a commit of the same server
    // never wait for each other in a cycle (a deadlock aborts one). One
    // more row, its lease columns NULL, carries the database's clock.
    static const std::string sql =
        std::string("WITH locked AS MATERIALIZED (SELECT l.rx, l.ry, l.rz FROM terrane_leases AS l"
                    "  JOIN unnest($1::integer[], $2::integer[], $3::integer[], $4::bigint[]) AS k(rx, ry, rz, epoch)"
                    "  ON l.rx = k.rx AND l.ry = k.ry AND l.rz = k.rz AND l.epoch = k.epoch"
                    "  WHERE l.owner = $5 AND l.expires_at > clock_timestamp()"
                    "  ORDER BY l.ry, l.rz, l.rx FOR UPDATE OF l),"
                    " renewed AS (UPDATE terrane_leases AS l"
                    "  SET expires_at = clock_timestamp() + $6::bigint * interval '1 millisecond'"
                    "  FROM locked WHERE l.rx = locked.rx AND l.ry = locked.ry AND l.rz = locked.rz AND l.owner = $5"
                    "  AND l.expires_at > clock_timestamp() RETURNING l.rx, l.ry, l.rz, l.epoch)"
                    " SELECT rx, ry, rz, epoch, NULL::bigint FROM renewed"
                    " UNION ALL SELECT NULL, NULL, NULL, NULL, ") +
        kClockMicros;
    auto r = c_->exec("renew leases", sql.c_str(),
                      {array(xs), array(ys), array(zs), array(epochs), text(owner), text(lease.count())});
    if (!r) return r.error();
    if (clock != nullptr)
      for (int row = 0; row < r->count(); ++row)
        if (const auto at = r->integer(row, 4)) *clock = DatabaseClock{*at, std::chrono::steady_clock::now()};
    for (int row = 0; row < r->count(); ++row) {
      const auto x = r->integer(row, 0), y = r->integer(row, 1), z = r->integer(row, 2), e = r->integer(row, 3);
      if (!x || !y || !z || !e) continue;
      const RegionLease got{{static_cast<int>(*x), static_cast<int>(*y), static_cast<int>(*z)}, owner,
                            static_cast<std::uint64_t>(*e)};
      for (const RegionLease* l : ls)
        if (*l == got) {
          kept.push_back(*l);
          break;
        }
    }
  }
  return kept;
}

StoreResult<Ok> ClusterStore::release(std::span<const RegionLease> leases) {
  for (const RegionLease& l : leases) {
    auto r = c_->exec("release lease",
                      "UPDATE terrane_leases SET expires_at = clock_timestamp()"
                      " WHERE rx = $1 AND ry = $2 AND rz = $3 AND owner = $4 AND epoch = $5",
                      {text(l.region.x), text(l.region.y), text(l.region.z), text(l.owner),
                       text(static_cast<std::int64_t>(l.epoch))});
    if (!r) return r.error();
  }
  return Ok{};
}

StoreResult<std::optional<RegionLease>> ClusterStore::holder(Vec3i region) {
  auto r = c_->exec("read region holder",
                    "SELECT owner, epoch FROM terrane_leases"
                    " WHERE rx = $1 AND ry = $2 AND rz = $3 AND expires_at > clock_timestamp()",
                    {text(region.x), text(region.y), text(region.z)});
  if (!r) return r.error();
  if (r->count() == 0) return std::optional<RegionLease>{};
  const auto owner = r->integer(0, 0), epoch = r->integer(0, 1);
  if (!owner || *owner < 0 || !epoch || *epoch < 1) return bad_row("read region holder", region);
  return std::optional<RegionLease>{
      RegionLease{region, static_cast<std::uint32_t>(*owner), static_cast<std::uint64_t>(*epoch)}};
}

StoreResult<std::vector<RegionSeq>> ClusterStore::region_seqs() {
  auto r = c_->exec("read region sequences", "SELECT rx, ry, rz, seq FROM terrane_leases WHERE seq > 0");
  if (!r) return r.error();
  std::vector<RegionSeq> out;
  for (int row = 0; row < r->count(); ++row) {
    const auto x = r->integer(row, 0), y = r->integer(row, 1), z = r->integer(row, 2), seq = r->integer(row, 3);
    if (!x || !y || !z || !seq || *seq < 0) continue;
    out.push_back(RegionSeq{{static_cast<int>(*x), static_cast<int>(*y), static_cast<int>(*z)},
                            static_cast<std::uint64_t>(*seq)});
  }
  return out;
}

StoreResult<Ok> ClusterStore::advertise(std::uint32_t id, const std::string& address) {
  if (id > kMaxServerId) return StoreError{StoreError::Kind::kQuery, fmt::format("server id {} is not below 2^31", id)};
  auto r = c_->exec("advertise server",
                    "INSERT INTO terrane_servers AS s (id, address, seen_at) VALUES ($1, $2, clock_timestamp())"
                    " ON CONFLICT (id) DO UPDATE SET address = EXCLUDED.address, seen_at = EXCLUDED.seen_at",
                    {text(id), Param{address, false}});
  if (!r) return r.error();
  return Ok{};
}

StoreResult<Ok> ClusterStore::withdraw(std::uint32_t id) {
  auto r = c_->exec("withdraw server", "DELETE FROM terrane_servers WHERE id = $1", {text(id)});
  if (!r) return r.error();
  return Ok{};
}

StoreResult<std::vector<std::uint32_t>> ClusterStore::running(std::chrono::milliseconds fresh) {
  auto r = c_->exec("read running servers",
                    "SELECT id FROM terrane_servers WHERE seen_at > clock_timestamp() - $1::bigint * interval '1 millisecond'",
                    {text(fresh.count())});
  if (!r) return r.error();
  std::vector<std::uint32_t> out;
  for (int row = 0; row < r->count(); ++row)
    if (const auto id = r->integer(row, 0); id && *id >= 0 && *id <= kMaxServerId) out.push_back(static_cast<std::uint32_t>(*id));
  return out;
}

StoreResult<ClusterStore::Cluster> ClusterStore::cluster(std::chrono::milliseconds fresh) {
  Cluster out;
  auto servers = c_->exec("read servers",
                          "SELECT id, address FROM terrane_servers WHERE address <> ''"
                          " AND seen_at > clock_timestamp() - $1::bigint * interval '1 millisecond'",
                          {text(fresh.count())});
  if (!servers) return servers.error();
  for (int row = 0; row < servers->count(); ++row) {
    const auto id = servers->integer(row, 0);
    // Another server's row: an address that does not parse is skipped (no
    // client is sent there), never trusted.
    auto a = parse_server_address(servers->get(row, 1), nullptr);
    if (!id || *id < 0 || *id > kMaxServerId || !a) continue;
    a->id = static_cast<std::uint32_t>(*id);
    out.servers.push_back(std::move(*a));
  }
  auto leases = c_->exec("read leases",
                         "SELECT rx, ry, rz, owner, epoch FROM terrane_leases WHERE expires_at > clock_timestamp()");
  if (!leases) return leases.error();
  for (int row = 0; row < leases->count(); ++row) {
    const auto x = leases->integer(row, 0), y = leases->integer(row, 1), z = leases->integer(row, 2),
               owner = leases->integer(row, 3), epoch = leases->integer(row, 4);
    if (!x || !y || !z || !owner || *owner < 0 || *owner > kMaxServerId || !epoch || *epoch < 1) continue;
    out.writers.push_back(RegionWriter{{static_cast<int>(*x), static_cast<int>(*y), static_cast<int>(*z)},
                                       static_cast<std::uint32_t>(*owner), static_cast<std::uint64_t>(*epoch)});
  }
  return out;
}

StoreResult<Ok> ClusterStore::set_name(const std::string& application_name) {
  auto r = c_->exec("name connection", "SELECT set_config('application_name', $1, false)",
                    {Param{application_name, false}});
  if (!r) return r.error();
  return Ok{};
}

StoreResult<Ok> ClusterStore::listen() {
  for (const char* sql : {"LISTEN terrane_changes", "LISTEN terrane_inbox", "LISTEN terrane_answers"}) {
    auto r = c_->exec("listen for notices", sql);
    if (!r) return r.error();
  }
  return Ok{};
}

StoreResult<std::vector<ClusterStore::Notice>> ClusterStore::wait_notices(std::chrono::milliseconds timeout) {
  std::vector<Notice> out;
  const auto take = [&] {
    while (PGnotify* n = PQnotifies(c_->raw())) {
      out.push_back(Notice{n->relname, n->extra});
      PQfreemem(n);
    }
  };
  take();
  if (!out.empty()) return out;
  const int fd = PQsocket(c_->raw());
  if (fd < 0 || PQstatus(c_->raw()) != CONNECTION_OK)
    return StoreError{StoreError::Kind::kConnection, "postgresql: listen for changes: the connection is gone"};
  pollfd p{fd, POLLIN, 0};
  const int ready = ::poll(&p, 1, static_cast<int>(timeout.count()));
  if (ready < 0 && errno != EINTR)
    return StoreError{StoreError::Kind::kConnection, "postgresql: listen for changes: poll failed"};
  if (ready > 0 && PQconsumeInput(c_->raw()) == 0) return c_->error("listen for changes", nullptr);
  take();
  return out;
}

StoreResult<std::vector<ForwardAnswer>> ClusterStore::take_answers(std::uint32_t from) {
  auto r = c_->exec("take answers",
                    "DELETE FROM terrane_answers WHERE from_server = $1 RETURNING id, accepted, tick, reason",
                    {text(from)});
  if (!r) return r.error();
  std::vector<ForwardAnswer> out;
  for (int row = 0; row < r->count(); ++row) {
    const auto id = r->integer(row, 0), tick = r->integer(row, 2);
    if (!id || *id < 1 || !tick || *tick < 0) continue;  // not a row this build wrote: left out
    out.push_back(
        ForwardAnswer{*id, from, r->get(row, 1) == "t", static_cast<std::uint64_t>(*tick), r->get(row, 3).substr(0, 256)});
  }
  return out;
}

StoreResult<Ok> ClusterStore::forget_answers(std::span<const std::int64_t> ids) {
  // Rows nobody took (a sender that stopped) go after ten minutes.
  auto r = c_->exec("forget answers",
                    "DELETE FROM terrane_answers WHERE id = ANY($1::bigint[])"
                    " OR answered_at < clock_timestamp() - interval '10 minutes'",
                    {Param{fmt::format("{{{}}}", fmt::join(ids, ",")), false}});
  if (!r) return r.error();
  return Ok{};
}

StoreResult<Ok> ClusterStore::answer(std::span<const ForwardAnswer> answers) {
  return c_->transaction<Ok>("commit answers", [&] { return answer_forwarded(*c_, answers); });
}

StoreResult<std::int64_t> ClusterStore::forward(std::uint32_t from, std::uint32_t to, const std::string& player,
                                                 std::span<const std::uint8_t> edit, std::int64_t expires_us) {
  return c_->transaction<std::int64_t>("commit forward", [&]() -> StoreResult<std::int64_t> {
    auto row = c_->exec("forward edit",
                        "INSERT INTO terrane_inbox (to_server, from_server, player, edit, created_at, expires_at)"
                        " VALUES ($1, $2, $3, $4, clock_timestamp(),"
                        "  timestamptz 'epoch' + $5::bigint * interval '1 microsecond') RETURNING id",
                        {text(to), text(from), Param{player, false}, blob(edit), text(expires_us)});
    if (!row) return row.error();
    const auto id = row->count() == 1 ? row->integer(0, 0) : std::nullopt;
    if (!id) return StoreError{StoreError::Kind::kDecode, "postgresql: forward edit: no row id"};
    auto n = c_->exec("notify inbox", "SELECT pg_notify($1, $2)",
                      {Param{kInboxChannel, false}, Param{std::to_string(to), false}});
    if (!n) return n.error();
    return *id;
  });
}

StoreResult<Ok> ClusterStore::relay(std::int64_t id, std::uint32_t from, std::uint32_t to) {
  return c_->transaction<Ok>("commit relay", [&]() -> StoreResult<Ok> {
    auto row = c_->exec("relay edit",
                        "UPDATE terrane_inbox SET to_server = $3, taken = false"
                        " WHERE id = $1 AND to_server = $2 AND taken RETURNING id",
                        {text(id), text(from), text(to)});
    if (!row) return row.error();
    if (row->count() != 1)
      return StoreError{StoreError::Kind::kFenced,
                        fmt::format("postgresql: relay edit: inbox row {} is no longer server {}'s", id, from)};
    auto n = c_->exec("notify inbox", "SELECT pg_notify($1, $2)",
                      {Param{kInboxChannel, false}, Param{std::to_string(to), false}});
    if (!n) return n.error();
    return Ok{};
  });
}

StoreResult<std::vector<InboxEdit>> ClusterStore::inbox(std::uint32_t to, std::int64_t after, std::size_t limit) {
  if (after == 0) {
    auto swept = c_->exec("sweep inbox",
                          "DELETE FROM terrane_inbox WHERE to_server = $1"
                          " AND expires_at < clock_timestamp() - interval '10 minutes'",
                          {text(to)});
    if (!swept) return swept.error();
  }
  // Sent now: the database reads its clock after this, so what it says is
  // left of a row's time is left from here at least.
  const auto asked = std::chrono::steady_clock::now();
  auto r = c_->exec("take inbox",
                    // Rows a sender is taking back (locked) are skipped:
                    // they go. A row's player and edit are read only up to
                    // what a client may send (longer: empty, so refused).
                    "UPDATE terrane_inbox SET taken = true WHERE id IN ("
                    "  SELECT id FROM terrane_inbox WHERE to_server = $1 AND id > $2 AND NOT taken"
                    "   AND expires_at > clock_timestamp() ORDER BY id LIMIT $3 FOR UPDATE SKIP LOCKED)"
                    " AND to_server = $1 AND NOT taken AND expires_at > clock_timestamp()"
                    " RETURNING id, from_server,"
                    " CASE WHEN octet_length(player) <= $4 THEN player ELSE '' END,"
                    " CASE WHEN octet_length(edit) <= $5 THEN edit ELSE ''::bytea END,"
                    // What is left of its time, at most kMaxInboxLeftUs
                    // (an infinite deadline would not subtract).
                    " (extract(epoch FROM LEAST(expires_at, clock_timestamp() + $6::bigint * interval '1 microsecond')"
                    "  - clock_timestamp()) * 1000000)::bigint",
                    {text(to), text(after), text(static_cast<std::int64_t>(limit)),
                     text(static_cast<std::int64_t>(kMaxClientNameBytes)),
                     text(static_cast<std::int64_t>(kDefaultMaxFrameBytes + kFrameHeaderBytes)), text(kMaxInboxLeftUs)},
                    /*binary_result=*/true);
  if (!r) return r.error();
  std::vector<InboxEdit> out;
  for (int i = 0; i < r->count(); ++i) {
    const auto id = be64_at(r->res, i, 0);
    const auto from = be32_at(r->res, i, 1);
    const auto left_us = be64_at(r->res, i, 4);
    if (!id || !from || *from < 0 || !left_us)
      return StoreError{StoreError::Kind::kDecode, "postgresql: take inbox: a row does not read"};
    InboxEdit e;
    e.id = *id;
    e.from = static_cast<std::uint32_t>(*from);
    const auto name = bytes_at(r->res, i, 2), edit = bytes_at(r->res, i, 3);
    e.player.assign(name.begin(), name.end());
    e.edit.assign(edit.begin(), edit.end());
    e.current_until = asked + std::chrono::microseconds(std::clamp<std::int64_t>(*left_us, 0, kMaxInboxLeftUs));
    out.push_back(std::move(e));
  }
  // RETURNING keeps no order.
  std::sort(out.begin(), out.end(), [](const InboxEdit& a, const InboxEdit& b) { return a.id < b.id; });
  return out;
}

StoreResult<bool> ClusterStore::take_back(std::int64_t id) {
  auto r = c_->exec("take back forwarded edit", "DELETE FROM terrane_inbox WHERE id = $1 AND NOT taken RETURNING id",
                    {text(id)});
  if (!r) return r.error();
  return r->count() == 1;
}

StoreResult<std::vector<std::pair<Vec3i, std::uint64_t>>> ClusterStore::stored_revisions(Vec3i region) {
  auto r = c_->exec("read revisions",
                    "SELECT x, y, z, revision FROM terrane_chunks"
                    " WHERE x BETWEEN $1 AND $2 AND y BETWEEN $3 AND $4 AND z BETWEEN $5 AND $6",
                    region_range(region), /*binary_result=*/true);
  if (!r) return r.error();
  std::vector<std::pair<Vec3i, std::uint64_t>> out;
  for (int i = 0; i < r->count(); ++i) {
    const auto pos = position_at(r->res, i);
    const auto revision = be64_at(r->res, i, 3);
    if (!pos || !revision || *revision < 0)
      return StoreError{StoreError::Kind::kDecode, "postgresql: read revisions: a row does not read"};
    out.emplace_back(*pos, static_cast<std::uint64_t>(*revision));
  }
  return out;
}

}  // namespace terrane
