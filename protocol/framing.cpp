#include "protocol/framing.h"

#include "protocol/terrane_generated.h"

namespace terrane {

std::span<std::uint8_t> thread_read_buffer() {
  thread_local std::vector<std::uint8_t> buf(kSocketReadBytes);
  return buf;
}

namespace {
// Messages are flat: Message -> Body table -> at most a vector of tables
// (Presence). Depth 8 and 4096 tables leave room and stop pathological nesting.
constexpr flatbuffers::uoffset_t kMaxDepth = 8;
constexpr flatbuffers::uoffset_t kMaxTables = 4096;
}  // namespace

void append_frame(std::span<const std::uint8_t> body, std::vector<std::uint8_t>& out) {
  const auto n = static_cast<std::uint32_t>(body.size());
  const std::uint8_t header[4] = {static_cast<std::uint8_t>(n), static_cast<std::uint8_t>(n >> 8),
                                  static_cast<std::uint8_t>(n >> 16), static_cast<std::uint8_t>(n >> 24)};
  out.insert(out.end(), header, header + 4);
  out.insert(out.end(), body.begin(), body.end());
}

Result<const wire::Message*> verify_message(std::span<const std::uint8_t> body) {
  if (body.size() < 8) return DecodeError{DecodeErrorCode::kTruncated, body.size(), "message shorter than a FlatBuffer"};
  flatbuffers::Verifier verifier(body.data(), body.size(), kMaxDepth, kMaxTables);
  if (!wire::VerifyMessageBuffer(verifier))
    return DecodeError{DecodeErrorCode::kInvalidValue, 0, "message failed FlatBuffers verification"};
  const wire::Message* msg = wire::GetMessage(body.data());
  if (msg->body_type() == wire::Body::NONE || msg->body() == nullptr)
    return DecodeError{DecodeErrorCode::kInvalidValue, 0, "message has no body"};
  return msg;
}

}  // namespace terrane
