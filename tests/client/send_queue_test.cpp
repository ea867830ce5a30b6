#include "client/send_queue.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

Outbound frame_of(std::size_t n, wire::Body type, std::uint32_t edit_id = 0) {
  return Outbound{Frame(n, std::uint8_t{7}), type, edit_id};
}

TEST(SendQueue, ReservesUpToItsCapAndGivesBytesBack) {
  SendQueue q(100);
  EXPECT_TRUE(q.reserve(60));
  EXPECT_FALSE(q.reserve(41));
  EXPECT_EQ(q.bytes(), 60u);
  q.unreserve(60);
  EXPECT_TRUE(q.reserve(100));
}

TEST(SendQueue, WritesInOrderOneAtATime) {
  SendQueue q(1000);
  ASSERT_TRUE(q.reserve(10));
  q.push_back(frame_of(10, wire::Body::Ping));
  ASSERT_TRUE(q.reserve(20));
  q.push_back(frame_of(20, wire::Body::EditRequest, 5));
  const Outbound* first = q.start_write();
  ASSERT_NE(first, nullptr);
  EXPECT_EQ(first->type, wire::Body::Ping);
  EXPECT_EQ(q.start_write(), nullptr);  // one write at a time
  q.finish_write();
  EXPECT_EQ(q.bytes(), 20u);
  const Outbound* second = q.start_write();
  ASSERT_NE(second, nullptr);
  EXPECT_EQ(second->edit_id, 5u);
  q.finish_write();
  EXPECT_EQ(q.start_write(), nullptr);
  EXPECT_EQ(q.bytes(), 0u);
}

TEST(SendQueue, SessionFramesGoFirstAndReplaceQueuedPositions) {
  SendQueue q(1000);
  ASSERT_TRUE(q.reserve(8));
  q.push_back(frame_of(8, wire::Body::ClientState));
  ASSERT_TRUE(q.reserve(9));
  q.push_back(frame_of(9, wire::Body::EditRequest, 1));
  q.drop(wire::Body::ClientState);
  std::vector<Outbound> session;
  session.push_back(frame_of(3, wire::Body::Hello));
  session.push_back(frame_of(4, wire::Body::ClientState));
  q.push_front(std::move(session));
  EXPECT_EQ(q.bytes(), 3u + 4u + 9u);
  std::vector<wire::Body> order;
  while (const Outbound* o = q.start_write()) {
    order.push_back(o->type);
    q.finish_write();
  }
  EXPECT_EQ(order, (std::vector<wire::Body>{wire::Body::Hello, wire::Body::ClientState, wire::Body::EditRequest}));
  EXPECT_EQ(q.bytes(), 0u);
}

TEST(SendQueue, AFrameCutOffMidWriteIsNotSentAgain) {
  SendQueue q(1000);
  ASSERT_TRUE(q.reserve(5));
  q.push_back(frame_of(5, wire::Body::EditRequest, 9));
  ASSERT_TRUE(q.reserve(6));
  q.push_back(frame_of(6, wire::Body::Ping));
  ASSERT_NE(q.start_write(), nullptr);
  EXPECT_EQ(q.abandon_write(), 9u);
  EXPECT_FALSE(q.writing());
  EXPECT_EQ(q.size(), 2u);  // stays while the old write may read it
  const Outbound* next = q.start_write();
  ASSERT_NE(next, nullptr);
  EXPECT_EQ(next->type, wire::Body::Ping);
  EXPECT_EQ(q.bytes(), 6u);
  EXPECT_EQ(q.abandon_write(), 0u);  // a frame without an edit
}

TEST(SendQueue, ClearForgetsEverything) {
  SendQueue q(1000);
  ASSERT_TRUE(q.reserve(5));
  q.push_back(frame_of(5, wire::Body::Ping));
  ASSERT_NE(q.start_write(), nullptr);
  q.clear();
  EXPECT_FALSE(q.writing());
  EXPECT_EQ(q.size(), 0u);
  EXPECT_EQ(q.bytes(), 0u);
}

}  // namespace
}  // namespace terrane
