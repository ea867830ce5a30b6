#include "protocol/stream_batch.h"

#include <algorithm>
#include <bit>

#include "common/codec/bit_io.h"
#include "common/codec/net_codec.h"
#include "common/world/horizon.h"

namespace terrane {

namespace {

class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> b) : b_(b) {}
  bool done() const { return pos_ == b_.size(); }
  std::size_t pos() const { return pos_; }
  std::span<const std::uint8_t> rest() const { return b_.subspan(pos_); }
  void skip(std::size_t n) { pos_ += n; }
  Result<std::uint8_t> byte() {
    if (pos_ >= b_.size()) return DecodeError{DecodeErrorCode::kTruncated, pos_, "stream batch: record cut short"};
    return b_[pos_++];
  }
  Result<std::uint64_t> varint() {
    std::uint64_t v = 0;
    const VarintRead r = get_varint(b_, pos_, 10, v);
    if (r == VarintRead::kTruncated) return DecodeError{DecodeErrorCode::kTruncated, pos_, "stream batch: record cut short"};
    if (r == VarintRead::kTooLong) {
      return DecodeError{DecodeErrorCode::kInvalidValue, pos_, "stream batch: varint longer than 64 bits"};
    }
    return v;
  }

 private:
  std::span<const std::uint8_t> b_;
  std::size_t pos_ = 0;
};

}  // namespace

void put_stream_record_head(StreamRecordKind kind, Vec3i chunk_pos, std::uint64_t revision, Vec3i& prev,
                            std::vector<std::uint8_t>& out) {
  out.push_back(static_cast<std::uint8_t>(kind));
  put_varint(zigzag(std::int64_t{chunk_pos.x} - prev.x), out);
  put_varint(zigzag(std::int64_t{chunk_pos.y} - prev.y), out);
  put_varint(zigzag(std::int64_t{chunk_pos.z} - prev.z), out);
  put_varint(revision, out);
  prev = chunk_pos;
}

void StreamBatchWriter::put_head(StreamRecordKind kind, Vec3i cp, std::uint64_t revision) {
  put_stream_record_head(kind, cp, revision, prev_, bytes_.owned_tail());
  ++records_;
}

void StreamBatchWriter::put_horizon_head(Vec3i region, int level, const HorizonMask* mask) {
  put_head(StreamRecordKind::kHorizon, region * kHorizonRegionChunks, 0);
  const std::uint8_t head[2] = {static_cast<std::uint8_t>(level), static_cast<std::uint8_t>(mask != nullptr ? 1 : 0)};
  bytes_.append(head);
  if (mask != nullptr) bytes_.append(*mask);
}

void StreamBatchWriter::add_mip_patch(Vec3i cp, std::uint64_t revision, int level, std::uint64_t mask,
                                      std::span<const std::uint8_t> units) {
  put_head(StreamRecordKind::kMipPatch, cp, revision);
  std::uint8_t head[9] = {static_cast<std::uint8_t>(level)};
  const int mask_bytes = patch_mask_bytes(level);
  for (int i = 0; i < mask_bytes; ++i) head[1 + i] = static_cast<std::uint8_t>(mask >> (8 * i));
  bytes_.append(std::span<const std::uint8_t>(head, static_cast<std::size_t>(1 + mask_bytes)));
  bytes_.append(units);
}

OutFrame StreamBatchWriter::finish() {
  OutFrame f = gather_stream_batch(std::move(bytes_));
  bytes_ = OutFrame{};
  prev_ = {0, 0, 0};
  records_ = 0;
  return f;
}

const Box& record_voxels(const StreamRecord& r, StreamDecodeScratch& s) {
  if (r.voxels != nullptr) return *r.voxels;
  if (r.kind == StreamRecordKind::kFull) {
    std::span<const std::uint8_t> rest = r.payload;
    for (int i = 0; i < 8; ++i) {
      auto n = net_codec_decode_prefix(16, rest, s.unit.voxels());
      if (!n) break;  // (never: the payload decoded before)
      rest = rest.subspan(*n);
      const Vec3i off = Vec3i{i & 1, (i >> 1) & 1, (i >> 2) & 1} * 16;
      for (int uy = 0; uy < 16; ++uy)
        for (int uz = 0; uz < 16; ++uz)
          std::copy_n(s.unit.read_row(uy, uz), 16, s.chunk.write_row(off.y + uy, off.z + uz) + off.x);
    }
    return s.chunk;
  }
  const int n = kChunkSize >> r.level;
  s.mip.resize({n, n, n});
  (void)net_codec_decode(n, r.payload, s.mip.voxels());
  return s.mip;
}

Status decode_stream_batch(std::span<const std::uint8_t> records, StreamDecodeScratch& s,
                           const std::function<Status(const StreamRecord&)>& fn, const KnownPayloadFn& known) {
  Reader r(records);
  Vec3i prev{0, 0, 0};
  std::size_t count = 0;
  while (!r.done()) {
    const std::size_t record_start = r.pos();
    if (++count > kMaxStreamRecords)
      return DecodeError{DecodeErrorCode::kOverLimit, r.pos(), "stream batch: more than 4096 records"};
    auto kind = r.byte();
    if (!kind) return kind.error();
    if (!known_record_kind(*kind))
      return DecodeError{DecodeErrorCode::kInvalidValue, r.pos() - 1, "stream batch: unknown record kind"};
    // A delta is bounded before it is added: the previous position is within
    // +-lim, so any delta beyond 2*lim lands out of range (and an unchecked
    // one could overflow the sum).
    constexpr std::int64_t lim = kMaxWireCoordinate / kChunkSize;
    std::int64_t c[3];
    for (auto& v : c) {
      auto d = r.varint();
      if (!d) return d.error();
      v = unzigzag(*d);
      if (v > 2 * lim || v < -2 * lim)
        return DecodeError{DecodeErrorCode::kInvalidValue, r.pos(), "stream batch: chunk position out of range"};
    }
    const std::int64_t x = prev.x + c[0], y = prev.y + c[1], z = prev.z + c[2];
    if (std::max({std::abs(x), std::abs(y), std::abs(z)}) > lim)
      return DecodeError{DecodeErrorCode::kInvalidValue, r.pos(), "stream batch: chunk position out of range"};
    auto rev = r.varint();
    if (!rev) return rev.error();
    StreamRecord rec;
    rec.kind = static_cast<StreamRecordKind>(*kind);
    rec.chunk_pos = {static_cast<std::int32_t>(x), static_cast<std::int32_t>(y), static_cast<std::int32_t>(z)};
    rec.revision = *rev;
    if (known && carries_units(rec.kind)) {
      KnownPayload k = known(rec.kind, r.rest());
      if (k.made && k.bytes > 0 && k.bytes <= r.rest().size()) {
        rec.level = payload_level(rec.kind);
        rec.payload = r.rest().first(k.bytes);
        rec.known = std::move(k.made);
        r.skip(k.bytes);
        rec.bytes = r.pos() - record_start;
        if (auto st = fn(rec); !st) return st;
        prev = rec.chunk_pos;
        continue;
      }
    }
    switch (rec.kind) {
      case StreamRecordKind::kFull: {
        const std::span<const std::uint8_t> start = r.rest();
        for (int i = 0; i < 8; ++i) {
          auto n = net_codec_decode_prefix(16, r.rest(), s.unit.voxels());
          if (!n) return DecodeError{n.error().code, r.pos() + n.error().offset, n.error().detail};
          r.skip(*n);
          const Vec3i off = Vec3i{i & 1, (i >> 1) & 1, (i >> 2) & 1} * 16;
          for (int uy = 0; uy < 16; ++uy)
            for (int uz = 0; uz < 16; ++uz)
              std::copy_n(s.unit.read_row(uy, uz), 16, s.chunk.write_row(off.y + uy, off.z + uz) + off.x);
        }
        rec.voxels = &s.chunk;
        rec.payload = start.first(start.size() - r.rest().size());
        break;
      }
      case StreamRecordKind::kMip1:
      case StreamRecordKind::kMip2:
      case StreamRecordKind::kMip3:
      case StreamRecordKind::kEstimate: {
        rec.level = payload_level(rec.kind);
        const int n = kChunkSize >> rec.level;
        s.mip.resize({n, n, n});
        auto used = net_codec_decode_prefix(n, r.rest(), s.mip.voxels());
        if (!used) return DecodeError{used.error().code, r.pos() + used.error().offset, used.error().detail};
        rec.payload = r.rest().first(*used);
        r.skip(*used);
        rec.voxels = &s.mip;
        break;
      }
      case StreamRecordKind::kEmpty:
      case StreamRecordKind::kReleased:
        break;
      case StreamRecordKind::kMipPatch: {
        auto level = r.byte();
        if (!level) return level.error();
        if (*level != 1 && *level != 2)
          return DecodeError{DecodeErrorCode::kInvalidValue, r.pos() - 1, "stream batch: mip patch level not 1 or 2"};
        const int mask_bytes = patch_mask_bytes(*level);
        std::uint64_t mask = 0;
        for (int i = 0; i < mask_bytes; ++i) {
          auto b = r.byte();
          if (!b) return b.error();
          mask |= std::uint64_t{*b} << (8 * i);
        }
        if (mask == 0) return DecodeError{DecodeErrorCode::kInvalidValue, r.pos() - 1, "stream batch: mip patch with no sub-unit"};
        const int n = kChunkSize >> *level;
        s.mip.resize({n, n, n});
        const std::size_t units_start = r.pos();
        for (std::uint64_t rest = mask; rest != 0; rest &= rest - 1) {
          const int i = std::countr_zero(rest);
          auto used = net_codec_decode_prefix(4, r.rest(), s.patch_unit.voxels());
          if (!used) return DecodeError{used.error().code, r.pos() + used.error().offset, used.error().detail};
          r.skip(*used);
          const Vec3i o = patch_subunit_origin(*level, i);
          for (int uy = 0; uy < 4; ++uy)
            for (int uz = 0; uz < 4; ++uz)
              std::copy_n(s.patch_unit.read_row(uy, uz), 4, s.mip.write_row(o.y + uy, o.z + uz) + o.x);
        }
        rec.level = *level;
        rec.patch_mask = mask;
        rec.voxels = &s.mip;
        rec.payload = records.subspan(units_start, r.pos() - units_start);
        break;
      }
      case StreamRecordKind::kHorizon: {
        // One record for the region: its image ((256 >> level)^3 voxels) and mask.
        const Vec3i first = rec.chunk_pos;
        if (floor_mod(first, kHorizonRegionChunks) != Vec3i{0, 0, 0} ||
            std::max({first.x, first.y, first.z}) + kHorizonRegionChunks - 1 > lim)
          return DecodeError{DecodeErrorCode::kInvalidValue, r.pos(), "stream batch: horizon region not aligned to 8 chunks"};
        auto level = r.byte();
        if (!level) return level.error();
        if (!is_horizon_level(*level))
          return DecodeError{DecodeErrorCode::kInvalidValue, r.pos() - 1, "stream batch: horizon level not 4, 5 or 6"};
        auto masked = r.byte();
        if (!masked) return masked.error();
        if (*masked > 1)
          return DecodeError{DecodeErrorCode::kInvalidValue, r.pos() - 1, "stream batch: horizon mask flag not 0 or 1"};
        HorizonMask mask;
        mask.fill(0xFF);
        if (*masked == 1) {
          if (r.rest().size() < mask.size())
            return DecodeError{DecodeErrorCode::kTruncated, r.pos(), "stream batch: record cut short"};
          std::copy_n(r.rest().begin(), mask.size(), mask.begin());
          r.skip(mask.size());
        }
        const int side = horizon_side(*level);
        s.horizon.resize({side, side, side});
        auto used = net_codec_decode_prefix(side, r.rest(), s.horizon.voxels());
        if (!used) return DecodeError{used.error().code, r.pos() + used.error().offset, used.error().detail};
        r.skip(*used);
        s.mask = mask;
        rec.level = *level;
        rec.voxels = &s.horizon;
        rec.mask = &s.mask;
        break;
      }
    }
    rec.bytes = r.pos() - record_start;
    if (auto st = fn(rec); !st) return st;
    prev = rec.chunk_pos;
  }
  return Ok{};
}

}  // namespace terrane
