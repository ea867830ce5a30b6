// StreamOut: records go out in order, one frame per full batch or flush,
// nothing before the session can send; a changed mip goes in as a Mip patch
// only when the version knows what changed since the revision held and the
// patch is the smaller.
#include "server/replication/stream_out.h"

#include <gtest/gtest.h>

#include <vector>

#include "protocol/messages.h"

namespace terrane {
namespace {

// The records of the frames sent, in order.
std::vector<StreamRecord> records_of(const std::vector<Frame>& frames) {
  std::vector<StreamRecord> out;
  for (const Frame& f : frames) {
    auto m = verify_message(std::span<const std::uint8_t>(f).subspan(kFrameHeaderBytes));
    EXPECT_TRUE(m.ok());
    auto r = parse_stream_batch(*(*m)->body_as_StreamBatch());
    EXPECT_TRUE(r.ok());
    StreamDecodeScratch s;
    EXPECT_TRUE(decode_stream_batch(*r, s, [&](const StreamRecord& rec) -> Status {
                  StreamRecord copy = rec;
                  copy.voxels = nullptr;
                  copy.payload = {};
                  out.push_back(copy);
                  return Ok{};
                }).ok());
  }
  return out;
}

struct Sent {
  bool attached = false;
  std::vector<Frame> frames;
  StreamOut out{[this] { return attached; }, [this](OutFrame f) { frames.push_back(f.flatten()); }};
};

TEST(StreamOut, RecordsWaitForTheSessionThenGoOutInOrderAndAFullBatchGoesAtOnce) {
  Sent s;
  s.out.record(StreamRecordKind::kEmpty, {1, 0, 0}, 3);
  s.out.flush();
  EXPECT_TRUE(s.frames.empty()) << "no session yet: the batch waits";
  EXPECT_GT(s.out.pending_bytes(), 0u);
  s.attached = true;
  s.out.record(StreamRecordKind::kReleased, {2, 0, 0}, 4);
  s.out.flush();
  ASSERT_EQ(s.frames.size(), 1u);
  const auto recs = records_of(s.frames);
  ASSERT_EQ(recs.size(), 2u);
  EXPECT_EQ(recs[0].chunk_pos, (Vec3i{1, 0, 0}));
  EXPECT_EQ(recs[1].kind, StreamRecordKind::kReleased);
  EXPECT_EQ(s.out.pending_bytes(), 0u);
  // kMaxStreamRecords records make a frame without a flush.
  for (std::size_t i = 0; i < kMaxStreamRecords; ++i)
    s.out.record(StreamRecordKind::kEmpty, {static_cast<int>(i), 1, 0}, 1);
  EXPECT_EQ(s.frames.size(), 2u);
  EXPECT_EQ(s.out.pending_bytes(), 0u);
}

TEST(StreamOut, AChangedMipGoesAsAPatchOnlyWhenTheVersionKnowsWhatChangedAndItIsSmaller) {
  Chunk c;
  c.modify(Region{{0, 0, 0}, {32, 12, 32}}, [](Vec3i p, Voxel) {
    return make_voxel(static_cast<Material>(1 + (p.x * 7 + p.z * 3 + p.y) % 9), static_cast<std::uint8_t>(90 + p.x));
  });
  const auto v0 = std::make_shared<const ChunkVersion>(Vec3i{0, 0, 0}, 4, std::make_shared<const Chunk>(c.clone()));
  auto next = std::make_unique<Chunk>(c.clone());
  next->set({1, 2, 1}, make_voxel(materials::kSnow, 255));
  UnitBits changed;
  changed.set(0);
  const auto v1 = ChunkVersion::after(*v0, std::move(next), changed);
  Sent s;
  s.attached = true;
  EXPECT_FALSE(s.out.mip_patch({0, 0, 0}, 1, 4, *v0)) << "a loaded version cannot tell what changed";
  EXPECT_FALSE(s.out.mip_patch({0, 0, 0}, 1, 2, *v1)) << "older than its history";
  EXPECT_TRUE(s.out.mip_patch({0, 0, 0}, 1, 4, *v1));
  s.out.flush();
  const auto recs = records_of(s.frames);
  ASSERT_EQ(recs.size(), 1u);
  EXPECT_EQ(recs[0].kind, StreamRecordKind::kMipPatch);
  EXPECT_EQ(recs[0].revision, 5u);
  EXPECT_EQ(recs[0].patch_mask, 1u) << "unit 0 of level 0 lies in sub-unit 0 of level 1";
}

}  // namespace
}  // namespace terrane
