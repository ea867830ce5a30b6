// Authority: whether this server may write a box of the world now, asked
// by the tick before it applies an edit; and, in a world several servers
// share, what goes with that (claims, hand-overs, edits forwarded to a
// region's writer and from other servers, chunks another server changed).
// Runs on the world strand. WorldOwner picks the implementation once:
// LocalAuthority for a world this server alone writes (SQLite), where
// every region is writable, or SharedAuthority (shared_authority.h) for a
// PostgreSQL world with leases.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "common/voxel/vec3.h"
#include "protocol/messages.h"
#include "server/base/counters.h"
#include "server/storage/notices.h"
#include "server/storage/postgres_store.h"  // ClaimRule
#include "server/world/interest.h"
#include "server/world/residency.h"

namespace terrane {

// An edit another server forwarded here: its row in this server's inbox,
// the server that forwarded it (the answer goes there), and until when it
// may be applied (InboxEdit::current_until: its deadline has surely not
// passed by the database's clock; later it is refused, for its sender has
// given up on it or is about to).
struct Forwarded {
  std::int64_t inbox_id = 0;
  std::uint32_t from = 0;
  // Passed back to its sender, nothing claimed for it: the two servers
  // asked each other for their regions at once, and the sender, with the
  // lower id, wins (SharedAuthority, "Two servers asking each other").
  bool back = false;
  // This server's own client's edit, passed back to it: queued ahead of
  // the edits waiting, as its player's later edits wait for its answer.
  bool own = false;
  std::chrono::steady_clock::time_point current_until = std::chrono::steady_clock::time_point::max();
};

// What an authority needs of the edit queue (the tick implements it).
class EditQueue {
 public:
  virtual ~EditQueue() = default;
  // An edit forwarded here, its chunks reserved: applied like a client's
  // edit in its turn and answered in the tick's commit.
  virtual void queue_forwarded(EditRequestMsg edit, std::string player, Forwarded from) = 0;
  // Rejects client id's edit, with the true state of its box when at hand.
  virtual void reject(ClientId id, const EditRequestMsg& edit, RejectReason why, const std::string& reason) = 0;
};

class Authority : public LoadWatcher {
 public:
  enum class Writable : std::uint8_t { kYes, kWaiting, kNo };

  // On the strand as the world starts.
  virtual void start() = 0;
  // Whether this server may write every chunk of r now. kNo sets why (and
  // holder, when the holding server is known); kWaiting: a claim is under
  // way. rule: how a free region is claimed (a client's own edit, which
  // can be forwarded, leaves one to the server writing its neighbours).
  virtual Writable writable(const Region& r, std::string* why, std::optional<std::uint32_t>* holder,
                            ClaimRule rule) = 0;
  // Whether a claim of a region of r is under way (or its stale chunks
  // are still being read again).
  virtual bool claiming(const Region& r) const = 0;
  // Whether this server holds region's lease.
  virtual bool writes_region(Vec3i lease_region) const = 0;
  // Whether client id has an edit being forwarded, or forwarded and not
  // answered yet, whose box meets chunks of r: its next edit there waits
  // (a player's edits keep their order whatever server applies them).
  virtual bool forward_pending(ClientId id, const Region& r) const = 0;
  // Sends client id's edit of box (in regions server to holds) to that
  // server's inbox, handing over first the regions of box this server
  // holds (so one server can write the whole edit).
  virtual void forward(ClientId id, const EditRequestMsg& edit, const std::string& player, const Region& box,
                       std::uint32_t to) = 0;
  // Passes an edit forwarded here (of box) on to server to, handing over
  // the regions of box this server holds; to answers its sender.
  virtual void relay(Forwarded f, const Region& box, std::uint32_t to) = 0;
  // Whether an edit forwarded here by server from, which holds regions of
  // it now, goes back to it rather than being refused: from has the lower
  // id, so it wins when both want the regions (no edit goes back and forth).
  virtual bool passes_back_to(std::uint32_t from) const = 0;
  // Every tick: tells clients the answers to their forwarded edits.
  virtual void settle() = 0;

  // Other servers' notices (WorldOwner's methods of the same names).
  virtual void changed_elsewhere(std::vector<ChunkChange> changes) = 0;
  virtual void read_again_elsewhere(std::vector<Vec3i> regions) = 0;
  virtual void inbox_has_edits() = 0;
  virtual void answered(ForwardAnswer answer) = 0;
};

// A world this server alone writes: every box is writable now, nothing is
// forwarded, no other server's notices come.
class LocalAuthority final : public Authority {
 public:
  void start() override {}
  Writable writable(const Region&, std::string*, std::optional<std::uint32_t>*, ClaimRule) override {
    return Writable::kYes;
  }
  bool claiming(const Region&) const override { return false; }
  bool writes_region(Vec3i) const override { return false; }
  bool forward_pending(ClientId, const Region&) const override { return false; }
  void forward(ClientId, const EditRequestMsg&, const std::string&, const Region&, std::uint32_t) override {}
  void relay(Forwarded, const Region&, std::uint32_t) override {}
  bool passes_back_to(std::uint32_t) const override { return false; }
  void settle() override {}
  void changed_elsewhere(std::vector<ChunkChange>) override {}
  void read_again_elsewhere(std::vector<Vec3i>) override {}
  void inbox_has_edits() override {}
  void answered(ForwardAnswer) override {}
  // LoadWatcher: no chunk is ever stored newer than held.
  bool stale(Vec3i) const override { return false; }
  void landed(Vec3i) override {}
};

}  // namespace terrane
