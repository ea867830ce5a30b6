#include "server/base/counters.h"

namespace terrane {

const char* memory_part_label(MemoryPart p) {
  switch (p) {
    case MemoryPart::kChunkSlots: return "chunk_slots";
    case MemoryPart::kInterest: return "interest";
    case MemoryPart::kResidency: return "residency";
    case MemoryPart::kCount: break;
  }
  return "unknown";
}

const char* close_reason_label(CloseReason r) {
  switch (r) {
    case CloseReason::kPeerClosed: return "peer_closed";
    case CloseReason::kClientBye: return "client_bye";
    case CloseReason::kSocketError: return "socket_error";
    case CloseReason::kHandshakeTimeout: return "handshake_timeout";
    case CloseReason::kIdleTimeout: return "idle_timeout";
    case CloseReason::kFrameTimeout: return "frame_timeout";
    case CloseReason::kTooSlow: return "too_slow";
    case CloseReason::kTooFarBehind: return "too_far_behind";
    case CloseReason::kInboundRate: return "inbound_rate";
    case CloseReason::kProtocolError: return "protocol_error";
    case CloseReason::kVersionMismatch: return "version_mismatch";
    case CloseReason::kAuthFailed: return "auth_failed";
    case CloseReason::kMovingTooFast: return "moving_too_fast";
    case CloseReason::kEditRate: return "edit_rate";
    case CloseReason::kRequestRate: return "request_rate";
    case CloseReason::kServerFull: return "server_full";
    case CloseReason::kShutdown: return "shutdown";
    case CloseReason::kStorageFailure: return "storage_failure";
    case CloseReason::kKicked: return "kicked";
    case CloseReason::kBanned: return "banned";
    case CloseReason::kNotWhitelisted: return "not_whitelisted";
    case CloseReason::kReplaced: return "replaced";
    case CloseReason::kCount: break;
  }
  return "unknown";
}

const char* reject_reason_label(RejectReason r) {
  switch (r) {
    case RejectReason::kInvalid: return "invalid";
    case RejectReason::kUnknownMaterial: return "unknown_material";
    case RejectReason::kTooLarge: return "too_large";
    case RejectReason::kOutsideWorld: return "outside_world";
    case RejectReason::kOutsideFullRes: return "outside_full_resolution";
    case RejectReason::kQueueFull: return "queue_full";
    case RejectReason::kHistory: return "history";
    case RejectReason::kShutdown: return "shutdown";
    case RejectReason::kStorageFailure: return "storage_failure";
    case RejectReason::kNotOwner: return "not_owner";
    case RejectReason::kOutcomeUnknown: return "outcome_unknown";
    case RejectReason::kCount: break;
  }
  return "unknown";
}

}  // namespace terrane
