// Fuzz target: one frame body as either peer receives it — verifier, then
// every message parser, then the voxel payload decoders — on arbitrary
// bytes. Seeds: tests/fuzz/corpus/message/ (one valid body per message type).
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "common/codec/net_codec.h"
#include "common/codec/update_batch.h"
#include "protocol/messages.h"
#include "protocol/presence_records.h"
#include "protocol/stream_batch.h"

namespace {

using namespace terrane;

void decode_payloads(const wire::Message& m) {
  switch (m.body_type()) {
    case wire::Body::UpdateBatch:
      if (auto b = parse_update_batch(*m.body_as_UpdateBatch())) {
        std::vector<UnitUpdate> units(64);
        (void)net_codec_decode_update_batch(b->data, units);
      }
      break;
    case wire::Body::StreamBatch:
      if (auto r = parse_stream_batch(*m.body_as_StreamBatch())) {
        StreamDecodeScratch scratch;
        (void)decode_stream_batch(*r, scratch, [](const StreamRecord&) -> Status { return Ok{}; });
      }
      break;
    case wire::Body::PresenceRecords:
      if (auto r = decode_presence_records(parse_presence_records(*m.body_as_PresenceRecords()))) {
        PresenceList list;
        (void)list.apply(*r);
      }
      break;
    default:
      break;
  }
}

void parse_any(const wire::Message& m) {
  switch (m.body_type()) {
    case wire::Body::Hello: (void)parse_hello(*m.body_as_Hello()); break;
    case wire::Body::Welcome: (void)parse_welcome(*m.body_as_Welcome()); break;
    case wire::Body::Disconnect: (void)parse_disconnect(*m.body_as_Disconnect()); break;
    case wire::Body::ClientState: (void)parse_client_state(*m.body_as_ClientState()); break;
    case wire::Body::Holdings: (void)parse_holdings(*m.body_as_Holdings()); break;
    case wire::Body::EditRequest: (void)parse_edit_request(*m.body_as_EditRequest()); break;
    case wire::Body::ReadBox: (void)parse_read_box(*m.body_as_ReadBox()); break;
    case wire::Body::ReadBoxResult: (void)parse_read_box_result(*m.body_as_ReadBoxResult()); break;
    case wire::Body::EditReject: (void)parse_edit_reject(*m.body_as_EditReject()); break;
    case wire::Body::ChunkHash: (void)parse_chunk_hash(*m.body_as_ChunkHash()); break;
    case wire::Body::ChunkHashRequest: (void)parse_chunk_hash_request(*m.body_as_ChunkHashRequest()); break;
    case wire::Body::Presence: (void)parse_presence(*m.body_as_Presence()); break;
    case wire::Body::AdminRequest: (void)parse_admin_request(*m.body_as_AdminRequest()); break;
    case wire::Body::AdminResult: (void)parse_admin_result(*m.body_as_AdminResult()); break;
    case wire::Body::ServerNotice: (void)parse_server_notice(*m.body_as_ServerNotice()); break;
    case wire::Body::Redirect: (void)parse_redirect(*m.body_as_Redirect()); break;
    default: decode_payloads(m); break;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // Copy into an allocator-aligned buffer, as FrameReader hands bodies out.
  const std::vector<std::uint8_t> body(data, data + size);
  auto msg = verify_message(body);
  if (msg.ok()) parse_any(**msg);
  return 0;
}
