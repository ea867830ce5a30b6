// A forwarded edit's stored bytes: the EditRequest frame its client sent
// (the inbox rows' format, unchanged), decoded back to the same edit; a
// row that is not such a frame (any truncated prefix, another message) is
// an error, never a crash.
#include "server/storage/forwarded_edit.h"

#include <gtest/gtest.h>

#include <vector>

#include "protocol/framing.h"

namespace terrane {
namespace {

EditRequestMsg write_box() {
  EditRequestMsg e;
  e.edit_id = 31;
  e.kind = EditKind::kWriteBox;
  e.box = Region{{10, 2, -4}, {13, 4, -2}};
  e.voxels.resize(static_cast<std::size_t>(e.box.volume()));
  for (std::size_t i = 0; i < e.voxels.size(); ++i)
    e.voxels[i] = make_voxel(static_cast<Material>(1 + i % 5), static_cast<std::uint8_t>(40 * (i % 6)));
  return e;
}

EditRequestMsg dig() {
  EditRequestMsg e;
  e.edit_id = 32;
  e.kind = EditKind::kDig;
  e.center = Vec3f{100.5f, 20, -7.25f};
  e.radius = 3.5f;
  e.material = materials::kAir;
  return e;
}

TEST(ForwardedEdit, IsTheEditRequestFrameItsClientSent) {
  for (const EditRequestMsg& e : {write_box(), dig()}) EXPECT_EQ(encode_forwarded_edit(e), build_edit_request(e));
}

TEST(ForwardedEdit, DecodesToTheSameEdit) {
  for (const EditRequestMsg& e : {write_box(), dig()}) {
    auto back = decode_forwarded_edit(encode_forwarded_edit(e));
    ASSERT_TRUE(back.ok()) << back.error().detail;
    EXPECT_EQ(back->edit_id, e.edit_id);
    EXPECT_EQ(back->kind, e.kind);
    EXPECT_EQ(back->box, e.box);
    EXPECT_EQ(back->voxels, e.voxels);
    EXPECT_EQ(back->center.x, e.center.x);
    EXPECT_EQ(back->radius, e.radius);
    EXPECT_EQ(back->material, e.material);
  }
}

TEST(ForwardedEdit, EveryTruncatedPrefixIsAnError) {
  const auto bytes = encode_forwarded_edit(write_box());
  for (std::size_t n = 0; n < bytes.size(); ++n)
    EXPECT_FALSE(decode_forwarded_edit(std::span<const std::uint8_t>(bytes.data(), n)).ok()) << n << " bytes";
}

TEST(ForwardedEdit, AHeaderThatDisagreesWithTheRowIsAnError) {
  auto bytes = encode_forwarded_edit(write_box());
  ASSERT_TRUE(decode_forwarded_edit(bytes).ok());
  auto longer = bytes;
  longer.push_back(0);  // a byte after the message
  EXPECT_FALSE(decode_forwarded_edit(longer).ok());
  auto lying = bytes;
  lying[0] = static_cast<std::uint8_t>(lying[0] - 1);  // the header says one byte less
  lying.back() = 0;
  EXPECT_FALSE(decode_forwarded_edit(lying).ok());
}

TEST(ForwardedEdit, AnotherMessageIsAnError) {
  EXPECT_FALSE(decode_forwarded_edit(build_edit_ack(1, 2)).ok());
  EXPECT_FALSE(decode_forwarded_edit(std::vector<std::uint8_t>{1, 1}).ok());
}

}  // namespace
}  // namespace terrane
