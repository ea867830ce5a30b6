// A forwarded edit's stored bytes (server/storage/forwarded_edit.h).
#include "server/storage/forwarded_edit.h"

#include "protocol/framing.h"

namespace terrane {

std::vector<std::uint8_t> encode_forwarded_edit(const EditRequestMsg& edit) {
  return build_edit_request(edit);
}

Result<EditRequestMsg> decode_forwarded_edit(std::span<const std::uint8_t> frame) {
  if (frame.size() < kFrameHeaderBytes || frame.size() > kDefaultMaxFrameBytes + kFrameHeaderBytes)
    return DecodeError{DecodeErrorCode::kTruncated, frame.size(), "forwarded edit frame length"};
  const std::size_t length = std::size_t{frame[0]} | std::size_t{frame[1]} << 8 | std::size_t{frame[2]} << 16 |
                             std::size_t{frame[3]} << 24;
  if (length != frame.size() - kFrameHeaderBytes)
    return DecodeError{DecodeErrorCode::kInvalidValue, 0, "forwarded edit frame length disagrees with the row's"};
  // A copy, so the body starts allocator-aligned as the verifier expects.
  const std::vector<std::uint8_t> body(frame.begin() + kFrameHeaderBytes, frame.end());
  auto msg = verify_message(body);
  if (!msg) return msg.error();
  if ((*msg)->body_type() != wire::Body::EditRequest)
    return DecodeError{DecodeErrorCode::kInvalidValue, 0, "forwarded frame is not an EditRequest"};
  return parse_edit_request(*(*msg)->body_as_EditRequest());
}

}  // namespace terrane
