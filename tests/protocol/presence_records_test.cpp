#include "protocol/presence_records.h"

#include <gtest/gtest.h>

#include <random>

#include "common/codec/bit_io.h"
#include "protocol/framing.h"

namespace terrane {
namespace {

std::vector<std::uint8_t> bytes_of(const std::vector<PresenceRecord>& records) {
  std::vector<std::uint8_t> out;
  encode_presence_records(records, out);
  return out;
}

std::vector<PresenceRecord> some_records() {
  return {{PresenceRecordKind::kEntered, 7, {8 * 100 + 4, 8 * 40, -8 * 3000}, "builder"},
          {PresenceRecordKind::kMoved, 3, {-5, 0, 17}, {}},
          {PresenceRecordKind::kLeft, 70000, {}, {}},
          {PresenceRecordKind::kEntered, 0xFFFFFFFFu, {0, 0, 0}, ""}};
}

TEST(PresenceRecords, RoundTripThroughAFrame) {
  const auto records = some_records();
  const Frame f = build_presence_records(bytes_of(records));
  auto m = verify_message(std::span<const std::uint8_t>(f).subspan(kFrameHeaderBytes));
  ASSERT_TRUE(m.ok());
  ASSERT_EQ((*m)->body_type(), wire::Body::PresenceRecords);
  auto back = decode_presence_records(parse_presence_records(*(*m)->body_as_PresenceRecords()));
  ASSERT_TRUE(back.ok()) << back.error().detail;
  EXPECT_EQ(*back, records);
}

// A moving entry costs its id and three small changes: a few bytes, where
// a Presence entry is a table of about 30.
TEST(PresenceRecords, AMoveIsAFewBytes) {
  EXPECT_EQ(bytes_of({{PresenceRecordKind::kMoved, 1000, {4, 0, -3}, {}}}).size(), 1u + 2u + 3u);
  EXPECT_EQ(bytes_of({}).size(), 1u);
}

TEST(PresenceRecords, EveryTruncationIsAnError) {
  const auto bytes = bytes_of(some_records());
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    auto r = decode_presence_records(std::span(bytes).first(n));
    ASSERT_FALSE(r.ok()) << n;
    EXPECT_EQ(r.error().code, DecodeErrorCode::kTruncated) << n;
  }
  auto extra = bytes;
  extra.push_back(0);
  auto r = decode_presence_records(extra);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, DecodeErrorCode::kTrailingBytes);
  EXPECT_EQ(r.error().offset, bytes.size());
}

TEST(PresenceRecords, MalformedRecordsAreRefusedWithWhatAndWhere) {
  auto refused = [](std::vector<std::uint8_t> b, DecodeErrorCode code, std::size_t offset) {
    auto r = decode_presence_records(b);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, code) << r.error().detail;
    EXPECT_EQ(r.error().offset, offset) << r.error().detail;
  };
  refused({1, 4 * 5 + 3}, DecodeErrorCode::kInvalidValue, 1);                  // kind 3
  refused({2, 4 * 5 + 2, 4 * 5 + 2}, DecodeErrorCode::kInvalidValue, 2);       // a client twice
  refused({1, 4 * 5 + 1, 0, 0, 0, 65}, DecodeErrorCode::kOverLimit, 5);        // a name of 65 bytes
  refused({1, 4 * 5 + 1, 0, 0, 0, 2, 'a', 0x7f}, DecodeErrorCode::kInvalidValue, 7);  // a control character
  refused({0xC1, 0x01}, DecodeErrorCode::kOverLimit, 0);                       // 193 records
  // A client id over 32 bits.
  std::vector<std::uint8_t> big;
  put_varint((std::uint64_t{1} << 32) * 4 + 2, big);
  big.insert(big.begin(), 1);
  refused(big, DecodeErrorCode::kInvalidValue, 1);
  // A position beyond the wire's range (2^24 voxels: 2^27 eighths).
  std::vector<std::uint8_t> far{1, 4 * 5 + 1};
  put_varint(zigzag((std::int64_t{1} << 27) + 1), far);
  far.insert(far.end(), {0, 0, 0});
  refused(far, DecodeErrorCode::kInvalidValue, 2);
  // A varint of more than 5 bytes (its bits above the 35th would be lost).
  std::vector<std::uint8_t> endless(7, 0x80);
  endless[0] = 1;
  endless[6] = 0x02;
  refused(endless, DecodeErrorCode::kInvalidValue, 1);
}

TEST(PresenceRecords, PositionsAreEighthsRoundedHalfAwayFromZero) {
  EXPECT_EQ(presence_eighths({1.0f, -1.0f, 0.0f}), (Vec3i{8, -8, 0}));
  EXPECT_EQ(presence_eighths({0.0625f, -0.0625f, 0.06f}), (Vec3i{1, -1, 0}));
  EXPECT_EQ(presence_position({4, -12, 1}), (Vec3f{0.5f, -1.5f, 0.125f}));
  const float lim = static_cast<float>(kMaxWireCoordinate);
  EXPECT_EQ(presence_eighths({lim, -lim, 1e30f}), (Vec3i{8 * kMaxWireCoordinate, -8 * kMaxWireCoordinate, 8 * kMaxWireCoordinate}));
}

TEST(PresenceList, AppliesEnteredMovedAndLeft) {
  PresenceList list;
  ASSERT_TRUE(list.apply(std::vector<PresenceRecord>{{PresenceRecordKind::kEntered, 9, {80, 0, 0}, "far"},
                                                     {PresenceRecordKind::kEntered, 4, {16, 8, 0}, "near"}})
                  .ok());
  ASSERT_TRUE(list.apply(std::vector<PresenceRecord>{{PresenceRecordKind::kMoved, 4, {8, 0, -8}, {}}}).ok());
  const auto near_first = list.nearest_first({0, 0, 0});
  ASSERT_EQ(near_first.size(), 2u);
  EXPECT_EQ(near_first[0].client_id, 4u);
  EXPECT_EQ(near_first[0].position, (Vec3f{3, 1, -1}));
  EXPECT_EQ(near_first[0].name, "near");
  EXPECT_EQ(near_first[1].name, "far");
  // Seen from elsewhere, the order follows.
  EXPECT_EQ(list.nearest_first({10, 0, 0})[0].client_id, 9u);
  ASSERT_TRUE(list.apply(std::vector<PresenceRecord>{{PresenceRecordKind::kLeft, 9, {}, {}}}).ok());
  ASSERT_EQ(list.entries().size(), 1u);
  EXPECT_EQ(list.entries()[0].client_id, 4u);
}

// Records that do not fit the list are refused whole: the list is as it was.
TEST(PresenceList, RecordsThatDoNotFitTheListAreRefusedWhole) {
  PresenceList list;
  ASSERT_TRUE(list.apply(std::vector<PresenceRecord>{{PresenceRecordKind::kEntered, 1, {0, 0, 0}, "a"}}).ok());
  auto refused = [&](std::vector<PresenceRecord> records, std::size_t index) {
    auto s = list.apply(records);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().offset, index) << s.error().detail;
    ASSERT_EQ(list.entries().size(), 1u);
    EXPECT_EQ(list.entries()[0].eighths, (Vec3i{0, 0, 0}));
  };
  refused({{PresenceRecordKind::kMoved, 1, {1, 1, 1}, {}}, {PresenceRecordKind::kMoved, 2, {1, 0, 0}, {}}}, 1);
  refused({{PresenceRecordKind::kLeft, 3, {}, {}}}, 0);
  refused({{PresenceRecordKind::kEntered, 1, {0, 0, 0}, "again"}}, 0);
  refused({{PresenceRecordKind::kMoved, 1, {8 * kMaxWireCoordinate + 1, 0, 0}, {}}}, 0);
  std::vector<PresenceRecord> crowd;
  for (std::uint32_t id = 10; id < 10 + kMaxPresenceEntries; ++id)
    crowd.push_back({PresenceRecordKind::kEntered, id, {0, 0, 0}, {}});
  auto s = list.apply(crowd);  // 65 entries
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, DecodeErrorCode::kOverLimit);
  EXPECT_EQ(list.entries().size(), 1u);
}

// Any bytes: an error or records, never a crash (the fuzz target goes on).
TEST(PresenceRecords, RandomBytesDecodeOrFailCleanly) {
  std::mt19937 rng(5);
  PresenceList list;
  for (int i = 0; i < 20000; ++i) {
    std::vector<std::uint8_t> b(rng() % 24);
    for (auto& x : b) x = static_cast<std::uint8_t>(rng() % 4 == 0 ? rng() : rng() % 12);
    if (auto r = decode_presence_records(b)) {
      EXPECT_LE(r->size(), kMaxPresenceRecords);
      (void)list.apply(*r);
      EXPECT_LE(list.entries().size(), kMaxPresenceEntries);
    }
  }
}

}  // namespace
}  // namespace terrane
