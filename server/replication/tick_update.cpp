#include "server/replication/tick_update.h"

#include <algorithm>
#include <tuple>

#include "common/codec/update_batch.h"
#include "protocol/messages.h"

namespace terrane {

std::optional<OutFrame> TickUpdate::finish(std::uint64_t tick, UpdateFaults* faults, std::size_t& units, bool codec1) {
  // Chunk order, so the joined batch is what one encoder would write.
  std::sort(versions_.begin(), versions_.end(), [](const VersionPtr& a, const VersionPtr& b) {
    const Vec3i u = a->pos(), w = b->pos();
    return std::tie(u.y, u.z, u.x) < std::tie(w.y, w.z, w.x);
  });
  std::vector<const UpdatePiece*> pieces;
  std::vector<ChunkRevisionMsg> revisions;
  std::vector<UpdatePiece> version1;  // codec1: each version's piece made again
  if (codec1) version1.reserve(versions_.size());
  for (const VersionPtr& v : versions_) {
    if (codec1) {
      version1.push_back(v->make_update_piece(kNetCodecVersion1));
      pieces.push_back(&version1.back());
    } else {
      pieces.push_back(&v->update_piece());
    }
    revisions.push_back(ChunkRevisionMsg{v->pos(), v->revision()});
  }
  UpdatePiece tampered;  // outlives pieces, which may point at it
  if (faults != nullptr && !faults->tamper(pieces, tampered)) return std::nullopt;
  // A piece still its version's is shared; one the faults made is copied.
  OutFrame data;
  net_codec_join_update_pieces(pieces, data.owned_tail(), [&](std::size_t i, std::span<const std::uint8_t> rest) {
    if (!codec1 && i < versions_.size() && pieces[i] == &versions_[i]->update_piece()) {
      data.append_shared(rest, versions_[i]);
    } else {
      data.append(rest);
    }
  });
  units = 0;
  for (const UpdatePiece* p : pieces) units += p->count;
  return gather_update_batch(tick, std::move(data), revisions);
}

}  // namespace terrane
