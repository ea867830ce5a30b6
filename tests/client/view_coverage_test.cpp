#include "client/view_coverage.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "common/world/view.h"

namespace terrane {
namespace {

StreamRecord bare(StreamRecordKind kind, Vec3i cp) { return StreamRecord{kind, cp, 1, 0, nullptr, nullptr, {}}; }

StreamRecord coarse(StreamRecordKind kind, Vec3i cp, int level, Box& box) {
  const int n = kChunkSize >> level;
  box.resize({n, n, n});
  box.fill(solid(materials::kRock));
  return StreamRecord{kind, cp, 1, level, &box, nullptr, {}};
}

// Centred on chunk (1, 1, 1), view 32: its 27 neighbours (offsets -1..1);
// full-resolution radius 16: the centre and its 6 faces, the rest mip 1.
const StreamedView kView{{48, 48, 48}, 32, 16};
const WorldBounds kEverywhere{-1024, 1024, false, 0, 0, 0, 0};

TEST(ViewCoverage, CountsWhatIsHeldOfEachChunkInViewAndWhetherItIsAtItsLevel) {
  Replica r;
  Box full({kChunkSize, kChunkSize, kChunkSize});
  full.fill(solid(materials::kRock));
  r.apply_stream_record(StreamRecord{StreamRecordKind::kFull, {1, 1, 1}, 1, 0, &full, nullptr, {}});
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, {2, 1, 1}));
  Box a, b, c, d;
  r.apply_stream_record(coarse(StreamRecordKind::kMip1, {0, 1, 1}, 1, a));  // wants full resolution
  r.apply_stream_record(coarse(StreamRecordKind::kMip1, {2, 2, 1}, 1, b));  // wants mip 1
  r.apply_stream_record(coarse(StreamRecordKind::kMip2, {1, 2, 2}, 2, c));
  r.apply_stream_record(coarse(StreamRecordKind::kEstimate, {2, 2, 2}, 3, d));
  Box image({16, 16, 16});
  image.fill(solid(materials::kSand));
  HorizonMask mask{};
  mask[0] = 0b1;  // chunk (0, 0, 0)
  std::vector<Vec3i> covered;
  r.apply_horizon(StreamRecord{StreamRecordKind::kHorizon, {0, 0, 0}, 0, kHorizonNearLevel, &image, &mask, {}}, covered);
  ASSERT_EQ(covered, (std::vector<Vec3i>{Vec3i{0, 0, 0}}));
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, {9, 9, 9}));  // out of view

  const ViewCoverage v = coverage(r, kView, kEverywhere);
  EXPECT_EQ(v.in_view, 27u);
  EXPECT_EQ(v.full, 1u);
  EXPECT_EQ(v.empty, 1u);
  EXPECT_EQ(v.mip1, 2u);
  EXPECT_EQ(v.mip2, 1u);
  EXPECT_EQ(v.mip3, 0u);
  EXPECT_EQ(v.estimate, 1u);
  EXPECT_EQ(v.horizon, 1u);
  EXPECT_EQ(v.not_held, 20u);
  EXPECT_EQ(v.held(), 7u);
  EXPECT_EQ(v.settled, 3u);  // Full, Empty and the mip 1 that wants mip 1
  EXPECT_EQ(v.want_full, 7u);
  EXPECT_EQ(v.held_full, 2u);
  EXPECT_FALSE(v.full_region_held());
  EXPECT_FALSE(v.complete);
}

TEST(ViewCoverage, CompleteOnceEveryChunkIsAtItsDistancesLevel) {
  Replica r;
  const Vec3i center = view_chunk(kView.position);
  std::vector<Box> boxes(27);
  std::size_t i = 0;
  for (const Vec3i cp : chunks_in_view(kView.position, kView.view_distance, kEverywhere)) {
    const int level = offset_level(cp - center, kView.full_res_radius);
    if (level == 0)
      r.apply_stream_record(bare(StreamRecordKind::kEmpty, cp));
    else
      r.apply_stream_record(coarse(record_kind_of(mip_form(level)), cp, level, boxes[i++]));
  }
  ViewCoverage v = coverage(r, kView, kEverywhere);
  EXPECT_TRUE(v.complete);
  EXPECT_TRUE(v.full_region_held());
  EXPECT_EQ(v.settled, 27u);
  EXPECT_EQ(v.empty, 7u);
  EXPECT_EQ(v.mip1, 20u);
  // Released: not held, and the view is no longer complete.
  r.apply_stream_record(bare(StreamRecordKind::kReleased, center));
  v = coverage(r, kView, kEverywhere);
  EXPECT_FALSE(v.complete);
  EXPECT_EQ(v.not_held, 1u);
  EXPECT_EQ(v.held_full, 6u);
}

TEST(ViewCoverage, ChunksBeyondTheWorldsBoundsAreNotInView) {
  Replica r;
  const WorldBounds above_zero{kChunkSize, 1024, false, 0, 0, 0, 0};  // chunk row y = 0 lies below
  const ViewCoverage v = coverage(r, kView, above_zero);
  EXPECT_EQ(v.in_view, 18u);
  EXPECT_EQ(v.not_held, 18u);
  EXPECT_FALSE(v.complete);
  EXPECT_TRUE(coverage(r, StreamedView{{48, 48, 48}, 32, 16}, WorldBounds{5000, 6000, false, 0, 0, 0, 0}).complete)
      << "nothing in view: nothing missing";
}

TEST(ViewCoverage, TheChunksInViewAreTheViewRulesAndTheirLevelsToo) {
  Replica r;
  const WorldBounds bounds{-64, 100, true, -200, 150, -90, 300};
  for (const StreamedView v : {StreamedView{{-70.5f, 3, 12}, 200, 60}, StreamedView{{100, -40, 5}, 96, 96},
                               StreamedView{{0, 0, 0}, 1, 1}}) {
    const auto chunks = chunks_in_view(v.position, v.view_distance, bounds);
    const ViewCoverage c = coverage(r, v, bounds);
    EXPECT_EQ(c.in_view, chunks.size());
    EXPECT_EQ(c.not_held, chunks.size());
    std::size_t full = 0;
    for (const Vec3i cp : chunks) full += desired_level(v.position, cp, v.full_res_radius) == 0 ? 1 : 0;
    EXPECT_EQ(c.want_full, full);
  }
}

TEST(ViewCoverage, TheStreamedViewTakesDefaultsAndCaps) {
  WelcomeMsg w;
  w.max_view_distance = 300;
  w.max_full_res_radius = 100;
  w.default_view_distance = 200;
  w.default_full_res_radius = 50;
  StreamedView v = streamed_view(ClientStateMsg{{1, 2, 3}, 0, 0}, w);
  EXPECT_EQ(v.view_distance, 200);
  EXPECT_EQ(v.full_res_radius, 50);
  EXPECT_EQ(v.position, (Vec3f{1, 2, 3}));
  v = streamed_view(ClientStateMsg{{0, 0, 0}, 999, 999}, w);
  EXPECT_EQ(v.view_distance, 300);
  EXPECT_EQ(v.full_res_radius, 100);
  v = streamed_view(ClientStateMsg{{0, 0, 0}, 30, 0}, w);
  EXPECT_EQ(v.full_res_radius, 30);
}

void expect_same(const ViewCoverage& a, const ViewCoverage& b, int step) {
  EXPECT_EQ(a.in_view, b.in_view) << "step " << step;
  EXPECT_EQ(a.full, b.full) << "step " << step;
  EXPECT_EQ(a.empty, b.empty) << "step " << step;
  EXPECT_EQ(a.mip1, b.mip1) << "step " << step;
  EXPECT_EQ(a.mip2, b.mip2) << "step " << step;
  EXPECT_EQ(a.mip3, b.mip3) << "step " << step;
  EXPECT_EQ(a.estimate, b.estimate) << "step " << step;
  EXPECT_EQ(a.horizon, b.horizon) << "step " << step;
  EXPECT_EQ(a.not_held, b.not_held) << "step " << step;
  EXPECT_EQ(a.settled, b.settled) << "step " << step;
  EXPECT_EQ(a.want_full, b.want_full) << "step " << step;
  EXPECT_EQ(a.held_full, b.held_full) << "step " << step;
  EXPECT_EQ(a.complete, b.complete) << "step " << step;
}

TEST(ViewCoverageCounter, AgreesWithAPassOverTheViewAfterEveryHoldingChange) {
  // A view cut by the world's bounds on every side, and chunks streamed,
  // refined, coarsened and released at random, some outside the view and
  // some told twice.
  const WorldBounds bounds{-40, 70, true, -100, 90, -75, 120};
  const StreamedView view{{10.5f, 5, -3}, 96, 40};
  Replica r;
  Box full({kChunkSize, kChunkSize, kChunkSize});
  full.fill(solid(materials::kRock));
  std::vector<Box> boxes(400);
  // Two chunks held before the count starts.
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, {0, 0, 0}));
  r.apply_stream_record(coarse(StreamRecordKind::kMip2, {1, 0, 0}, 2, boxes[0]));
  ViewCoverageCounter counter(view, bounds, r);
  expect_same(counter.coverage(), coverage(r, view, bounds), -1);
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> axis(-5, 5), kind(0, 6);
  for (int step = 0; step < 400; ++step) {
    const Vec3i cp{axis(rng), axis(rng), axis(rng)};
    switch (kind(rng)) {
      case 0: r.apply_stream_record(StreamRecord{StreamRecordKind::kFull, cp, 1, 0, &full, nullptr, {}}); break;
      case 1: r.apply_stream_record(bare(StreamRecordKind::kEmpty, cp)); break;
      case 2: r.apply_stream_record(coarse(StreamRecordKind::kMip1, cp, 1, boxes[step])); break;
      case 3: r.apply_stream_record(coarse(StreamRecordKind::kMip2, cp, 2, boxes[step])); break;
      case 4: r.apply_stream_record(coarse(StreamRecordKind::kMip3, cp, 3, boxes[step])); break;
      case 5: r.apply_stream_record(coarse(StreamRecordKind::kEstimate, cp, 3, boxes[step])); break;
      default: r.apply_stream_record(bare(StreamRecordKind::kReleased, cp)); break;
    }
    counter.update(cp, r.holding(cp));
    if (step % 3 == 0) counter.update(cp, r.holding(cp));  // told twice: no change
    expect_same(counter.coverage(), coverage(r, view, bounds), step);
  }
  EXPECT_GT(counter.coverage().in_view, 0u);
  EXPECT_LT(counter.coverage().not_held, counter.coverage().in_view);
}

}  // namespace
}  // namespace terrane
