// EditTracker: a client's edits and their futures: the ids it gives, the
// edits that wait for an answer (and whether their request reached this
// server's socket), and each answered edit's outcome.
//
// An edit ends in exactly one outcome: the server's EditAck or EditReject,
// or, when the connection that carried it goes before the answer
// (a reconnect, a Redirect followed, the final close), kEditOutcomeUnknown:
// it may or may not have been applied.
// Thread: none of its own; the Client guards it with its mutex (the io side
// records answers and writes, application threads start edits).
#pragma once

#include <cstdint>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/voxel/voxel.h"

namespace terrane {

inline constexpr const char* kEditOutcomeUnknown = "connection lost before the answer; outcome unknown";

struct EditOutcome {
  bool accepted = false;
  std::uint64_t tick = 0;
  std::string reason;  // rejections
  // Rejections decided against the world also carry its true state over the
  // edit's box (empty box otherwise), for clients that predicted the edit.
  Region state_box;
  std::vector<Voxel> state;
  // A rejection whose edit may have been applied: the connection went before
  // the answer (reason kEditOutcomeUnknown), or the server could not learn
  // it (EditReject.outcome_unknown: a commit or a forward to another server
  // of a shared world whose answer was lost).
  bool unknown = false;
};

// Whether a refusal leaves the edit's fate open (EditOutcome::unknown).
// Such an edit may or may not have been applied; any other refusal was not
// applied.
inline bool edit_outcome_unknown(const EditOutcome& o) { return !o.accepted && o.unknown; }

// Edits given an outcome at once, for on_edit_result.
using SettledEdits = std::vector<std::pair<std::uint32_t, EditOutcome>>;

class EditTracker {
 public:
  // A new edit: its id (never 0), unanswered from now on.
  std::uint32_t begin();
  // Its request could not be queued: forgotten (no outcome).
  void abandon(std::uint32_t id) { unanswered_.erase(id); }
  // Its request reached the socket (an edit already answered stays so).
  void written(std::uint32_t id);
  // The server's answer.
  void answered(std::uint32_t id, EditOutcome o);

  // An edit written and not answered.
  bool awaiting_written() const;
  std::size_t unanswered() const { return unanswered_.size(); }
  // Every unanswered edit (the connection and its queue went) gets the
  // outcome unknown.
  SettledEdits settle_unanswered();
  // Only those written (a Redirect: the rest go to the next server).
  SettledEdits settle_written();
  // Answered or settled edits by id.
  const std::unordered_map<std::uint32_t, EditOutcome>& outcomes() const { return outcomes_; }

 private:
  SettledEdits settle(bool written_only);

  std::uint32_t next_id_ = 1;
  std::unordered_map<std::uint32_t, bool> unanswered_;  // id -> its request was written
  std::unordered_map<std::uint32_t, EditOutcome> outcomes_;
};

}  // namespace terrane
