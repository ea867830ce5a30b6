// The world's answers as frames (server/replication/world_answers.h).
#include "server/replication/world_answers.h"

#include <type_traits>
#include <variant>

namespace terrane {

Frame answer_frame(const WorldAnswer& answer) {
  return std::visit(
      [](const auto& a) -> Frame {
        using T = std::decay_t<decltype(a)>;
        if constexpr (std::is_same_v<T, EditAcked>) {
          return build_edit_ack(a.edit_id, a.tick);
        } else if constexpr (std::is_same_v<T, EditRejectMsg>) {
          if (a.box.empty()) return build_edit_reject(a.edit_id, a.reason, a.outcome_unknown);
          return build_edit_reject(a.edit_id, a.reason, a.box, a.voxels, a.outcome_unknown);
        } else if constexpr (std::is_same_v<T, ReadBoxResultMsg>) {
          if (!a.error.empty()) return build_read_box_error(a.request_id, a.box, a.error);
          return build_read_box_result(a.request_id, a.box, a.voxels);
        } else if constexpr (std::is_same_v<T, ChunkHashMsg>) {
          return build_chunk_hash(a);
        } else if constexpr (std::is_same_v<T, PresenceNearby>) {
          return build_presence(a.entries);
        } else {
          static_assert(std::is_same_v<T, PresenceChanged>);
          std::vector<std::uint8_t> records;
          encode_presence_records(a.records, records);
          return build_presence_records(records);
        }
      },
      answer);
}

SendClass answer_send_class(const WorldAnswer& answer) {
  if (std::holds_alternative<EditAcked>(answer)) return SendClass::kControl;
  if (const auto* reject = std::get_if<EditRejectMsg>(&answer))
    return reject->box.empty() ? SendClass::kControl : SendClass::kData;
  return SendClass::kData;
}

}  // namespace terrane
