#include "protocol/framing.h"

#include <gtest/gtest.h>

#include <random>

#include "protocol/terrane_generated.h"

namespace terrane {
namespace {

std::vector<std::uint8_t> ping_body(std::uint64_t nonce) {
  flatbuffers::FlatBufferBuilder fbb;
  auto ping = wire::CreatePing(fbb, nonce);
  fbb.Finish(wire::CreateMessage(fbb, wire::Body::Ping, ping.Union()));
  return {fbb.GetBufferPointer(), fbb.GetBufferPointer() + fbb.GetSize()};
}

TEST(Framing, FramesSurviveAnySplitOfTheStream) {
  std::vector<std::uint8_t> stream;
  for (std::uint64_t i = 0; i < 20; ++i) append_frame(ping_body(i * 7919), stream);
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    FrameReader reader;
    std::vector<std::uint64_t> nonces;
    std::size_t at = 0;
    while (at < stream.size()) {
      const std::size_t n = std::min<std::size_t>(stream.size() - at, std::uniform_int_distribution<std::size_t>(1, 40)(rng));
      ASSERT_TRUE(reader.feed(std::span(stream.data() + at, n), [&](std::span<const std::uint8_t> body) {
                      auto msg = verify_message(body);
                      ASSERT_TRUE(msg.ok());
                      ASSERT_EQ((*msg)->body_type(), wire::Body::Ping);
                      nonces.push_back((*msg)->body_as_Ping()->nonce());
                    }).ok());
      at += n;
    }
    ASSERT_EQ(nonces.size(), 20u);
    for (std::uint64_t i = 0; i < 20; ++i) EXPECT_EQ(nonces[i], i * 7919);
    EXPECT_EQ(reader.buffered(), 0u);
  }
}

TEST(Framing, OversizedLengthIsRejectedBeforeBuffering) {
  FrameReader reader(1024);
  const std::uint8_t header[4] = {0x01, 0x04, 0x00, 0x00};  // 1025
  auto s = reader.feed(header, [](std::span<const std::uint8_t>) { FAIL(); });
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, DecodeErrorCode::kOverLimit);
  EXPECT_LE(reader.buffered(), kFrameHeaderBytes);
}

TEST(Framing, EmptyFrameIsRejected) {
  FrameReader reader;
  const std::uint8_t header[4] = {0, 0, 0, 0};
  EXPECT_FALSE(reader.feed(header, [](std::span<const std::uint8_t>) {}).ok());
}

TEST(VerifyMessage, RejectsGarbageAndEveryTruncation) {
  const std::vector<std::uint8_t> body = ping_body(42);
  ASSERT_TRUE(verify_message(body).ok());
  for (std::size_t n = 0; n < body.size(); ++n)
    EXPECT_FALSE(verify_message(std::span(body.data(), n)).ok()) << "prefix " << n;
  std::mt19937 rng(9);
  std::vector<std::uint8_t> garbage(64);
  int accepted = 0;
  for (int i = 0; i < 2000; ++i) {
    for (auto& b : garbage) b = static_cast<std::uint8_t>(rng());
    accepted += verify_message(garbage).ok();
  }
  EXPECT_LT(accepted, 20);  // random bytes are almost never a valid Message
}

TEST(VerifyMessage, RejectsMessageWithoutBody) {
  flatbuffers::FlatBufferBuilder fbb;
  fbb.Finish(wire::CreateMessage(fbb));
  EXPECT_FALSE(verify_message(std::span(fbb.GetBufferPointer(), fbb.GetSize())).ok());
}

}  // namespace
}  // namespace terrane
