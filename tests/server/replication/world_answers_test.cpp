// The world's answers as frames: each frame is the bytes the world built
// itself before it answered in types (the wire unchanged), parses back to
// the answer, and goes in its class (acks and bare rejects as control,
// what shows the world's state as data).
#include "server/replication/world_answers.h"

#include <gtest/gtest.h>

#include <vector>

#include "protocol/framing.h"

namespace terrane {
namespace {

// frame's message, verified (null when it does not verify).
const wire::Message* message_of(const Frame& frame, std::vector<std::uint8_t>& body) {
  EXPECT_GE(frame.size(), kFrameHeaderBytes);
  if (frame.size() < kFrameHeaderBytes) return nullptr;
  body.assign(frame.begin() + kFrameHeaderBytes, frame.end());  // allocator-aligned, as the verifier expects
  auto m = verify_message(body);
  EXPECT_TRUE(m.ok());
  return m.ok() ? *m : nullptr;
}

std::vector<Voxel> voxels_of(const Region& box) {
  std::vector<Voxel> v(static_cast<std::size_t>(box.volume()));
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = make_voxel(static_cast<Material>(i % 7), 255);
  return v;
}

TEST(WorldAnswers, AnAckIsAnEditAckSentAsControl) {
  const WorldAnswer a = EditAcked{42, 1234567};
  const Frame f = answer_frame(a);
  EXPECT_EQ(f, build_edit_ack(42, 1234567));
  std::vector<std::uint8_t> body;
  const auto* m = message_of(f, body);
  ASSERT_NE(m, nullptr);
  ASSERT_EQ(m->body_type(), wire::Body::EditAck);
  EXPECT_EQ(m->body_as_EditAck()->edit_id(), 42u);
  EXPECT_EQ(m->body_as_EditAck()->tick(), 1234567u);
  EXPECT_EQ(answer_send_class(a), SendClass::kControl);
}

TEST(WorldAnswers, ARejectWithoutTheWorldsStateIsSentAsControl) {
  for (const bool unknown : {false, true}) {
    const WorldAnswer a = EditRejectMsg{7, "storage failure: edit not saved", {}, {}, unknown};
    const Frame f = answer_frame(a);
    EXPECT_EQ(f, build_edit_reject(7, "storage failure: edit not saved", unknown));
    std::vector<std::uint8_t> body;
    const auto* m = message_of(f, body);
    ASSERT_NE(m, nullptr);
    ASSERT_EQ(m->body_type(), wire::Body::EditReject);
    auto r = parse_edit_reject(*m->body_as_EditReject());
    ASSERT_TRUE(r.ok());
    EXPECT_EQ(r->edit_id, 7u);
    EXPECT_EQ(r->reason, "storage failure: edit not saved");
    EXPECT_TRUE(r->box.empty());
    EXPECT_EQ(r->outcome_unknown, unknown);
    EXPECT_EQ(answer_send_class(a), SendClass::kControl);
  }
}

TEST(WorldAnswers, ARejectWithTheWorldsStateIsSentAsDataAfterTheChangesBeforeIt) {
  const Region box{{4, 1, 4}, {7, 3, 6}};
  const auto voxels = voxels_of(box);
  const WorldAnswer a = EditRejectMsg{9, "not yours", box, voxels, false};
  const Frame f = answer_frame(a);
  EXPECT_EQ(f, build_edit_reject(9, "not yours", box, voxels, false));
  std::vector<std::uint8_t> body;
  const auto* m = message_of(f, body);
  ASSERT_NE(m, nullptr);
  auto r = parse_edit_reject(*m->body_as_EditReject());
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->box, box);
  EXPECT_EQ(r->voxels, voxels);
  EXPECT_EQ(answer_send_class(a), SendClass::kData);
}

TEST(WorldAnswers, AReadsResultAndAnErrorAreSentAsData) {
  const Region box{{0, 0, 0}, {3, 2, 4}};
  const auto voxels = voxels_of(box);
  const WorldAnswer ok = ReadBoxResultMsg{5, box, {}, voxels};
  EXPECT_EQ(answer_frame(ok), build_read_box_result(5, box, voxels));
  std::vector<std::uint8_t> body;
  const auto* m = message_of(answer_frame(ok), body);
  ASSERT_NE(m, nullptr);
  auto r = parse_read_box_result(*m->body_as_ReadBoxResult());
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->request_id, 5u);
  EXPECT_EQ(r->box, box);
  EXPECT_TRUE(r->error.empty());
  EXPECT_EQ(r->voxels, voxels);
  EXPECT_EQ(answer_send_class(ok), SendClass::kData);

  const WorldAnswer failed = ReadBoxResultMsg{6, box, "no such chunk", {}};
  EXPECT_EQ(answer_frame(failed), build_read_box_error(6, box, "no such chunk"));
  EXPECT_EQ(answer_send_class(failed), SendClass::kData);
}

TEST(WorldAnswers, AChunkHashIsSentAsData) {
  const ChunkHashMsg h{{3, -1, 8}, 17, 0x0123456789abcdefULL};
  const WorldAnswer a = h;
  EXPECT_EQ(answer_frame(a), build_chunk_hash(h));
  std::vector<std::uint8_t> body;
  const auto* m = message_of(answer_frame(a), body);
  ASSERT_NE(m, nullptr);
  auto r = parse_chunk_hash(*m->body_as_ChunkHash());
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->chunk_pos, h.chunk_pos);
  EXPECT_EQ(r->revision, 17u);
  EXPECT_EQ(r->hash, h.hash);
  EXPECT_EQ(answer_send_class(a), SendClass::kData);
}

TEST(WorldAnswers, PresenceIsSentAsData) {
  const std::vector<PresenceEntryMsg> entries{{2, Vec3f{20, 10, 0}}, {5, Vec3f{-3.5f, 64, 12}}};
  const WorldAnswer a = PresenceNearby{entries};
  EXPECT_EQ(answer_frame(a), build_presence(entries));
  std::vector<std::uint8_t> body;
  const auto* m = message_of(answer_frame(a), body);
  ASSERT_NE(m, nullptr);
  auto r = parse_presence(*m->body_as_Presence());
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->size(), 2u);
  EXPECT_EQ((*r)[1].client_id, 5u);
  EXPECT_EQ((*r)[1].position.x, -3.5f);
  EXPECT_EQ(answer_send_class(a), SendClass::kData);
}

}  // namespace
}  // namespace terrane
