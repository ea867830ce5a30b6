// OutFrame: a frame's segments in order are its bytes; shared spans are not
// copied (a segment points into its owner's buffer) and keep their owner
// alive as long as the frame; spans shorter than kMinSharedBytes are
// copied; prepended bytes go before everything; a frame of one Frame or of
// one shared Frame is one segment; the first segment is what a session
// reads the message type from.
#include "protocol/out_frame.h"

#include <gtest/gtest.h>

#include <memory>
#include <numeric>

namespace terrane {
namespace {

std::shared_ptr<const Frame> bytes(std::size_t n, std::uint8_t first) {
  auto b = std::make_shared<Frame>(n);
  std::iota(b->begin(), b->end(), first);
  return b;
}

std::vector<std::span<const std::uint8_t>> segments(const OutFrame& f) {
  std::vector<std::span<const std::uint8_t>> out;
  f.for_each_segment([&](std::span<const std::uint8_t> s) { out.push_back(s); });
  return out;
}

TEST(OutFrame, SegmentsInOrderAreTheFramesBytesAndSharedSpansAreNotCopied) {
  auto big = bytes(OutFrame::kMinSharedBytes + 100, 7);
  auto other = bytes(OutFrame::kMinSharedBytes, 200);
  const auto small = bytes(OutFrame::kMinSharedBytes - 1, 50);
  std::weak_ptr<const Frame> watch = big;
  OutFrame f;
  f.append(std::vector<std::uint8_t>{1, 2, 3});
  f.append_shared(*big, big);
  f.owned_tail().push_back(4);
  f.append_shared(*small, small);  // copied: owned bytes run on
  f.append_shared(*other, other);
  f.append_shared(std::span(*big).first(600), std::shared_ptr<const Frame>());  // no owner: copied
  f.prepend(std::vector<std::uint8_t>{9, 9});

  Frame expected{9, 9, 1, 2, 3};
  expected.insert(expected.end(), big->begin(), big->end());
  expected.push_back(4);
  expected.insert(expected.end(), small->begin(), small->end());
  expected.insert(expected.end(), other->begin(), other->end());
  expected.insert(expected.end(), big->begin(), big->begin() + 600);
  EXPECT_EQ(f.flatten(), expected);
  EXPECT_EQ(f.size(), expected.size());
  EXPECT_EQ(f.shared_bytes(), big->size() + other->size());

  const auto s = segments(f);
  ASSERT_EQ(s.size(), 6u);  // head, owned, big, owned (4 + small), other, owned (the copy)
  EXPECT_EQ(f.segment_count(), 6u);
  EXPECT_EQ(s[0].size(), 2u);
  EXPECT_EQ(s[1].size(), 3u);
  EXPECT_EQ(s[2].data(), big->data()) << "the shared span itself, not a copy";
  EXPECT_EQ(s[3].size(), 1 + small->size());
  EXPECT_EQ(s[4].data(), other->data());
  EXPECT_NE(s[5].data(), other->data());
  EXPECT_EQ(f.first_segment().data(), s[0].data());

  // The frame keeps what it shares alive; moved, it still does.
  big.reset();
  EXPECT_FALSE(watch.expired());
  OutFrame moved = std::move(f);
  EXPECT_EQ(moved.flatten(), expected);
  moved = OutFrame{};
  EXPECT_TRUE(watch.expired());
}

TEST(OutFrame, AWholeFrameIsOneSegment) {
  const Frame whole{4, 0, 0, 0, 1, 2, 3, 4};
  const OutFrame owned(whole);
  ASSERT_EQ(owned.segment_count(), 1u);
  EXPECT_EQ(owned.flatten(), whole);
  EXPECT_EQ(owned.shared_bytes(), 0u);

  const auto shared = std::make_shared<const Frame>(whole);
  const OutFrame a(shared), b(shared);  // one frame for two sessions
  ASSERT_EQ(a.segment_count(), 1u);
  EXPECT_EQ(a.first_segment().data(), shared->data());
  EXPECT_EQ(b.first_segment().data(), shared->data());
  EXPECT_EQ(a.flatten(), whole);
  EXPECT_EQ(a.size(), whole.size());
  EXPECT_EQ(a.shared_bytes(), whole.size());
}

TEST(OutFrame, TheFirstSegmentIsWhateverComesFirst) {
  OutFrame empty;
  EXPECT_TRUE(empty.empty());
  EXPECT_TRUE(empty.first_segment().empty());
  EXPECT_EQ(empty.segment_count(), 0u);

  auto big = bytes(OutFrame::kMinSharedBytes, 1);
  OutFrame shared_first;
  shared_first.append_shared(*big, big);
  shared_first.append(std::vector<std::uint8_t>{5});
  EXPECT_EQ(shared_first.first_segment().data(), big->data());

  OutFrame owned_first;
  owned_first.append(std::vector<std::uint8_t>{5, 6});
  owned_first.append_shared(*big, big);
  EXPECT_EQ(owned_first.first_segment().size(), 2u);
}

}  // namespace
}  // namespace terrane
