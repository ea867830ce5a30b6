// SharedAuthority: which regions this server may write in a world several
// servers share (PostgreSQL), and what goes with that. Owns the regions'
// leases as this server's edits know them (claimed as edits need them,
// handed over with edits forwarded across a border), the chunks held
// older than stored (another server wrote them: read again), the edits
// this server forwarded and is waiting to hear of (each with a deadline
// its owner takes it by, or it is taken back: STORE_POSTGRESQL.md,
// "Forwarded edits"), this server's inbox of edits forwarded to it (with
// each player's forwarded rate), and answers that came early. Runs on the world strand; Storage's callbacks are
// posted back to it.
#pragma once

#include <asio.hpp>
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "common/world/world.h"
#include "server/base/cluster_options.h"
#include "server/base/rate_limit.h"
#include "server/storage/storage.h"
#include "server/world/authority.h"
#include "server/world/fan_out.h"
#include "server/world/residency.h"
#include "server/world/world_clock.h"
#include "server/world/world_options.h"

namespace terrane {

class SharedAuthority final : public Authority {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;
  // Players whose forwarded rate is kept at most (then the idle ones are
  // forgotten).
  static constexpr std::size_t kMaxForwardedRates = 4096;

  // options: the edit rate (forwarded edits are held to it); cluster: this
  // server's id and the lease's length.
  SharedAuthority(Strand& strand, World& world, Storage& storage, const WorldOptions& options,
                  const ClusterOptions& cluster, ServerCounters& counters, const WorldClock& clock,
                  Residency& residency, FanOut& clients, EditQueue& queue);

  // Takes the edits forwarded while this server was away.
  void start() override { take_inbox(); }
  Writable writable(const Region& r, std::string* why, std::optional<std::uint32_t>* holder,
                    ClaimRule rule) override;
  bool claiming(const Region& r) const override;
  bool writes_region(Vec3i lease_region) const override;
  bool forward_pending(ClientId id, const Region& r) const override;
  void forward(ClientId id, const EditRequestMsg& edit, const std::string& player, const Region& box,
               std::uint32_t to) override;
  void relay(Forwarded f, const Region& box, std::uint32_t to) override;
  bool passes_back_to(std::uint32_t from) const override { return from < server_id_; }
  void settle() override {
    if (!forwarded_.empty() || !unsure_.empty()) settle_forwarded();
  }
  void changed_elsewhere(std::vector<ChunkChange> changes) override;
  void read_again_elsewhere(std::vector<Vec3i> regions) override;
  void inbox_has_edits() override { take_inbox(); }
  void answered(ForwardAnswer answer) override;
  // LoadWatcher
  bool stale(Vec3i chunk_pos) const override { return stale_.count(chunk_pos) != 0; }
  // After a load of chunk_pos landed: a stale chunk is done once held at
  // its stored revision (or no longer held), else read again.
  void landed(Vec3i chunk_pos) override;

 private:
  // A region as far as this server's edits know it: claiming; held, with
  // stale chunks of it still being read again; held; held by another
  // server; or not known, the database out of reach (both asked again
  // after a second; edits wait in the second case); being handed over.
  struct RegionLeaseState {
    enum : std::uint8_t { kClaiming, kRefreshing, kHeld, kRefused, kUnreachable, kHandingOver } state = kClaiming;
    bool left = false;  // kRefused: free, left to holder by ClaimRule::kPreferNeighbours
    // kHandingOver: an edit from the server it goes to wants it, and this
    // server wins it (a lower id): asked again once released.
    bool wanted_back = false;
    std::string why;
    std::optional<std::uint32_t> holder;
    std::chrono::steady_clock::time_point ask_again{};
  };
  // An edit of box being forwarded to server to, its inbox row not known yet.
  struct Forwarding {
    Region box;
    std::uint32_t to;
  };
  // An edit this server forwarded to a region's owner, waiting for its
  // answer; then for the edit's chunks to be read again here, before the
  // client is told. Its wait runs out at deadline (the row's deadline has
  // then passed by the database's clock too): the row is taken back if
  // nobody took it (the edit was not applied); taken, its owner's answer is
  // waited for another answer_wait() before its outcome is called unknown.
  //
  //   kWaiting --deadline--> kTakingBack --deleted--> refused: not applied
  //      |                        |------taken-----> kTaken --answer_wait--> outcome unknown
  //      +--answer (any state)--> told                |-----database out of reach---> outcome unknown
  struct Outgoing {
    enum : std::uint8_t { kWaiting, kTakingBack, kTaken } state = kWaiting;
    ClientId id;
    EditRequestMsg edit;
    Region box;
    std::uint32_t to;
    std::chrono::steady_clock::time_point deadline;
    std::optional<ForwardAnswer> answer;
  };
  // A forward whose commit's answer was lost: its row may be there (its id
  // is not known), and may be taken until its deadline. Its player's next
  // edits there wait (forward_pending) until its outcome is called unknown,
  // once no owner can apply it any more.
  struct Unsure {
    ClientId id;
    EditRequestMsg edit;
    Region box;
    std::chrono::steady_clock::time_point tell_at;
  };

  void on_claimed(Vec3i region, Storage::Claimed claimed);
  // Whether held is older than revision (an estimate is older than anything stored).
  static bool older_than(const ChunkVersion& held, std::uint64_t revision);
  bool stale_in(Vec3i region) const;
  // cp is stored at revision, newer than held here (another server wrote
  // it): read again until held at least at revision.
  void read_again(Vec3i cp, std::uint64_t revision, Storage::Priority priority);
  // The version after prev (held with its voxels at c.revision - 1) that
  // c's units make, or null when they do not decode as units of its chunk.
  VersionPtr apply_units(const ChunkVersion& prev, const ChunkChange& c);
  // Marks the regions of box this server holds as being handed over to
  // server to (edits there wait), and lists them; handed_over settles them
  // once the release is done (ok) or failed.
  std::vector<Vec3i> hand_over(const Region& box, std::uint32_t to);
  void handed_over(const std::vector<Vec3i>& regions, bool ok);
  // Whether an edit of box that server from forwarded here shares a region
  // with an edit this server forwarded to from and has not settled yet:
  // the two servers asked each other for regions at once.
  bool asked_each_other(std::uint32_t from, const Region& box) const;
  void take_inbox();
  void read_inbox_page(std::int64_t after);
  // One forwarded edit of player within its rate (forwarded_rate_).
  bool take_forwarded_rate(const std::string& player);
  // How long a forwarded edit waits for its owner to take it (its deadline).
  std::chrono::milliseconds forward_wait() const;
  // How long, after that, the answer of an owner that took it is waited for.
  std::chrono::milliseconds answer_wait() const { return lease_; }
  // Tells clients the answers to their forwarded edits once the edits'
  // chunks are current here; takes back those not taken by their
  // deadline; gives up on those taken and unanswered for too long.
  void settle_forwarded();
  void taken_back(std::int64_t row, StoreResult<bool> deleted);
  // A forward that failed: its player is told in Terrane's words (the
  // database's own go to the log).
  void forward_failed(ClientId id, const EditRequestMsg& edit, const Region& box, std::uint32_t to,
                      std::chrono::steady_clock::time_point deadline, const StoreError& e);

  Strand& strand_;
  World& world_;
  Storage& storage_;
  const WorldOptions& options_;
  const std::uint32_t server_id_;
  const std::chrono::milliseconds lease_;
  ServerCounters& counters_;
  const WorldClock& clock_;
  Residency& residency_;
  FanOut& clients_;
  EditQueue& queue_;
  std::unordered_map<Vec3i, RegionLeaseState, Vec3iHash> leases_;
  // Chunks held older than stored (another server wrote them): chunk ->
  // the revision stored.
  std::unordered_map<Vec3i, std::uint64_t, Vec3iHash> stale_;
  // Forwarded edits: this server's clients' (inbox row -> edit; being
  // sent; sent with their outcome unsure), and the inbox of this server
  // (a read under way; another notice came during it).
  std::unordered_map<std::int64_t, Outgoing> forwarded_;
  std::unordered_multimap<ClientId, Forwarding> forwarding_;  // sent, row not known yet
  std::vector<Unsure> unsure_;
  // Forwarded edits per player, whatever server they came through, at the
  // rate a session may keep up: a player cannot pass it by editing here
  // through several servers at once.
  std::unordered_map<std::string, TokenBucket> forwarded_rate_;
  bool inbox_reading_ = false, inbox_again_ = false;
  // Answers that came before their forward's own callback.
  std::unordered_map<std::int64_t, std::pair<ForwardAnswer, std::chrono::steady_clock::time_point>> early_answers_;
  std::vector<UnitUpdate> units_scratch_;  // apply_units'
  // The database's own words of failures, for the log (players are told in
  // Terrane's): at most one line a second.
  RateLimitedLog database_log_{1};
};

}  // namespace terrane
