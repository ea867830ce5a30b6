#include "client/edit_tracker.h"

#include <gtest/gtest.h>

#include <algorithm>

namespace terrane {
namespace {

std::vector<std::uint32_t> ids(const SettledEdits& s) {
  std::vector<std::uint32_t> out;
  for (const auto& [id, o] : s) {
    EXPECT_FALSE(o.accepted);
    EXPECT_EQ(o.reason, kEditOutcomeUnknown);
    out.push_back(id);
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(EditTracker, AnOutcomeIsUnknownOnlyWhereTheEditMayHaveBeenApplied) {
  EXPECT_FALSE(edit_outcome_unknown(EditOutcome{true, 7, {}, {}, {}}));
  EXPECT_FALSE(edit_outcome_unknown(EditOutcome{false, 0, "edit outside the world", {}, {}}));
  EXPECT_FALSE(edit_outcome_unknown(EditOutcome{false, 0, "storage failure: edit not saved", {}, {}}));
  // The server's word (EditReject.outcome_unknown), not its text.
  EXPECT_FALSE(edit_outcome_unknown(EditOutcome{false, 0, "a text saying outcome unknown", {}, {}, false}));
  EXPECT_TRUE(edit_outcome_unknown(
      EditOutcome{false, 0, "the world's database cannot be reached; outcome unknown", {}, {}, true}));
  EditTracker t;
  const std::uint32_t id = t.begin();
  t.written(id);
  (void)t.settle_unanswered();
  EXPECT_TRUE(edit_outcome_unknown(t.outcomes().at(id)));
}

TEST(EditTracker, IdsAreDistinctAndNeverZero) {
  EditTracker t;
  const std::uint32_t a = t.begin(), b = t.begin();
  EXPECT_NE(a, 0u);
  EXPECT_NE(a, b);
  EXPECT_EQ(t.unanswered(), 2u);
}

TEST(EditTracker, AnAnswerEndsTheEditWithItsOutcome) {
  EditTracker t;
  const std::uint32_t id = t.begin();
  t.written(id);
  EXPECT_TRUE(t.awaiting_written());
  t.answered(id, EditOutcome{true, 42, {}, {}, {}});
  EXPECT_FALSE(t.awaiting_written());
  EXPECT_EQ(t.unanswered(), 0u);
  ASSERT_EQ(t.outcomes().count(id), 1u);
  EXPECT_TRUE(t.outcomes().at(id).accepted);
  EXPECT_EQ(t.outcomes().at(id).tick, 42u);
  // The write's completion may run after the answer: nothing waits again.
  t.written(id);
  EXPECT_FALSE(t.awaiting_written());
  EXPECT_TRUE(t.settle_unanswered().empty());
}

TEST(EditTracker, AnAbandonedEditHasNoOutcome) {
  EditTracker t;
  const std::uint32_t id = t.begin();
  t.abandon(id);
  EXPECT_EQ(t.unanswered(), 0u);
  EXPECT_TRUE(t.settle_unanswered().empty());
  EXPECT_EQ(t.outcomes().count(id), 0u);
}

TEST(EditTracker, ARedirectSettlesOnlyWhatWasWrittenAndACloseTheRest) {
  EditTracker t;
  const std::uint32_t written = t.begin(), queued = t.begin(), answered = t.begin();
  t.written(written);
  t.written(answered);
  t.answered(answered, EditOutcome{false, 0, "no", {}, {}});
  EXPECT_EQ(ids(t.settle_written()), std::vector<std::uint32_t>{written});
  EXPECT_EQ(t.unanswered(), 1u);
  EXPECT_EQ(ids(t.settle_unanswered()), std::vector<std::uint32_t>{queued});
  EXPECT_EQ(t.unanswered(), 0u);
  EXPECT_EQ(t.outcomes().at(written).reason, kEditOutcomeUnknown);
  EXPECT_EQ(t.outcomes().at(queued).reason, kEditOutcomeUnknown);
  EXPECT_EQ(t.outcomes().at(answered).reason, "no");
}

}  // namespace
}  // namespace terrane
