// Per-client undo and redo over real sockets: exact restoration, the
// concurrent-edit rule (only voxels still as this client left them are
// restored), empty history and the history's byte bound.
#include <gtest/gtest.h>

#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using testing_support::msg;
using testing_support::RawPeer;
using testing_support::ServerTest;

class UndoTest : public ServerTest {
 protected:
  static constexpr Vec3f kHome{1002.0f, 12.0f, 1002.0f};
  static inline const Region kBox{{1000, 8, 1000}, {1004, 12, 1004}};

  std::unique_ptr<RawPeer> editor(const std::string& name) {
    auto p = join(name);
    EXPECT_TRUE(hold_full(*p, kHome, chunk_of(kBox.min)));
    return p;
  }
  // Sends an edit; true if acknowledged, false if rejected (*reason set).
  bool edit(RawPeer& p, EditRequestMsg e, std::string* reason = nullptr) {
    e.edit_id = ++next_id_;
    EXPECT_TRUE(p.send(build_edit_request(e)));
    while (auto f = p.next()) {
      const wire::Message& m = msg(*f);
      if (m.body_type() == wire::Body::EditAck && m.body_as_EditAck()->edit_id() == e.edit_id) return true;
      if (m.body_type() == wire::Body::EditReject && m.body_as_EditReject()->edit_id() == e.edit_id) {
        if (reason != nullptr) *reason = parse_edit_reject(*m.body_as_EditReject())->reason;
        return false;
      }
    }
    ADD_FAILURE() << "connection lost";
    return false;
  }
  static EditRequestMsg fill(const Region& box, Material m) {
    EditRequestMsg e;
    e.kind = EditKind::kFillBox;
    e.box = box;
    e.material = m;
    e.occupancy = 255;
    return e;
  }
  static EditRequestMsg kind(EditKind k) {
    EditRequestMsg e;
    e.kind = k;
    return e;
  }
  std::vector<Voxel> voxels(const Region& r) {
    std::vector<Voxel> out;
    server_->inspect([&](const WorldView& c) {
      for (int y = r.min.y; y < r.max.y; ++y)
        for (int z = r.min.z; z < r.max.z; ++z)
          for (int x = r.min.x; x < r.max.x; ++x) out.push_back(c.get({x, y, z}));
    });
    return out;
  }
  std::uint32_t next_id_ = 0;
};

TEST_F(UndoTest, UndoRestoresAndRedoReapplies) {
  start();
  auto a = editor("a");
  const auto original = voxels(kBox);
  ASSERT_TRUE(edit(*a, fill(kBox, materials::kBrick)));
  const auto bricked = voxels(kBox);
  ASSERT_NE(bricked, original);
  ASSERT_TRUE(edit(*a, kind(EditKind::kUndo)));
  EXPECT_EQ(voxels(kBox), original);
  ASSERT_TRUE(edit(*a, kind(EditKind::kRedo)));
  EXPECT_EQ(voxels(kBox), bricked);
  ASSERT_TRUE(edit(*a, kind(EditKind::kUndo)));
  EXPECT_EQ(voxels(kBox), original);
  std::string why;
  EXPECT_FALSE(edit(*a, kind(EditKind::kUndo), &why));
  EXPECT_EQ(why, "nothing to undo");
  // A new edit after an undo forgets what could be redone.
  ASSERT_TRUE(edit(*a, fill(kBox, materials::kSand)));
  EXPECT_FALSE(edit(*a, kind(EditKind::kRedo), &why));
  EXPECT_EQ(why, "nothing to redo");
}

TEST_F(UndoTest, UndoKeepsAnotherClientsLaterChanges) {
  start();
  auto a = editor("a");
  auto b = editor("b");
  const auto original = voxels(kBox);
  ASSERT_TRUE(edit(*a, fill(kBox, materials::kBrick)));
  // b changes one column of a's box afterwards.
  const Region column{{1001, 8, 1001}, {1002, 12, 1002}};
  ASSERT_TRUE(edit(*b, fill(column, materials::kSnow)));
  ASSERT_TRUE(edit(*a, kind(EditKind::kUndo)));
  const auto after = voxels(kBox);
  std::size_t i = 0;
  for (int y = kBox.min.y; y < kBox.max.y; ++y)
    for (int z = kBox.min.z; z < kBox.max.z; ++z)
      for (int x = kBox.min.x; x < kBox.max.x; ++x, ++i) {
        if (column.contains({x, y, z}))
          EXPECT_EQ(after[i], solid(materials::kSnow)) << x << "," << y << "," << z;  // b's change stands
        else
          EXPECT_EQ(after[i], original[i]) << x << "," << y << "," << z;  // a's change undone
      }
  // Undo history is per client: b's undo removes only b's snow, bringing
  // back what was there when b edited (a's brick).
  ASSERT_TRUE(edit(*b, kind(EditKind::kUndo)));
  const auto column_now = voxels(column);
  for (const Voxel v : column_now) EXPECT_EQ(v, solid(materials::kBrick));
}

TEST_F(UndoTest, HistoryIsBoundedInBytes) {
  ServerOptions o;
  o.world.history_bytes_per_client = 2000;  // a handful of small steps
  // 80 edits, each sent once the last is acknowledged: at 60 ticks a
  // second that is faster than the default rate limit's burst allows.
  o.world.edits_per_second = 1000;
  start(o);
  auto a = editor("a");
  int acked = 0;
  for (int i = 0; i < 40; ++i) {
    const Region cell{{1000 + i % 4, 8 + (i / 4) % 4, 1000}, {1001 + i % 4, 9 + (i / 4) % 4, 1004}};
    acked += edit(*a, fill(cell, static_cast<Material>(1 + i % 6))) ? 1 : 0;
  }
  ASSERT_EQ(acked, 40);
  int undone = 0;
  while (edit(*a, kind(EditKind::kUndo))) ++undone;
  EXPECT_GT(undone, 0);
  EXPECT_LT(undone, 40);  // the oldest steps were forgotten
}

}  // namespace
}  // namespace terrane
