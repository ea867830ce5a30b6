#include "protocol/presence_records.h"

#include <algorithm>
#include <cmath>

#include "common/codec/bit_io.h"

namespace terrane {

namespace {

// Positions on the wire are within kMaxWireCoordinate: in eighths, 2^27.
constexpr std::int64_t kMaxEighths = std::int64_t{kMaxWireCoordinate} * 8;

DecodeError cut_short(std::size_t at) { return {DecodeErrorCode::kTruncated, at, "presence records: cut short"}; }

std::int32_t eighths_of(float v) {
  if (!std::isfinite(v)) return 0;  // (positions are checked finite where they come in)
  const double e = std::round(static_cast<double>(v) * 8.0);  // halves away from zero
  return static_cast<std::int32_t>(std::clamp<double>(e, -static_cast<double>(kMaxEighths),
                                                      static_cast<double>(kMaxEighths)));
}

}  // namespace

Vec3i presence_eighths(Vec3f p) { return {eighths_of(p.x), eighths_of(p.y), eighths_of(p.z)}; }

Vec3f presence_position(Vec3i e) {
  return {static_cast<float>(e.x) / 8.0f, static_cast<float>(e.y) / 8.0f, static_cast<float>(e.z) / 8.0f};
}

void encode_presence_records(std::span<const PresenceRecord> records, std::vector<std::uint8_t>& out) {
  put_varint(records.size(), out);
  for (const PresenceRecord& r : records) {
    put_varint(std::uint64_t{r.client_id} * 4 + static_cast<std::uint64_t>(r.kind), out);
    if (r.kind == PresenceRecordKind::kLeft) continue;
    put_varint(zigzag(r.eighths.x), out);
    put_varint(zigzag(r.eighths.y), out);
    put_varint(zigzag(r.eighths.z), out);
    if (r.kind == PresenceRecordKind::kEntered) {
      const std::size_t n = std::min(r.name.size(), kMaxClientNameBytes);
      out.push_back(static_cast<std::uint8_t>(n));
      out.insert(out.end(), r.name.begin(), r.name.begin() + static_cast<std::ptrdiff_t>(n));
    }
  }
}

Result<std::vector<PresenceRecord>> decode_presence_records(std::span<const std::uint8_t> bytes) {
  std::size_t pos = 0;
  auto varint = [&](std::uint64_t& v) -> Status {
    const std::size_t at = pos;
    // Five bytes hold every value the format has (a head is under 2^34),
    // so no bits are dropped unseen.
    const VarintRead r = get_varint(bytes, pos, 5, v);
    if (r == VarintRead::kTruncated) return cut_short(at);
    if (r == VarintRead::kTooLong) return DecodeError{DecodeErrorCode::kInvalidValue, at, "presence records: varint longer than 5 bytes"};
    return Ok{};
  };
  std::uint64_t count = 0;
  if (auto s = varint(count); !s) return s.error();
  if (count > kMaxPresenceRecords)
    return DecodeError{DecodeErrorCode::kOverLimit, 0, "presence records: more than 192 records"};
  std::vector<PresenceRecord> out;
  out.reserve(static_cast<std::size_t>(count));
  for (std::uint64_t i = 0; i < count; ++i) {
    const std::size_t at = pos;
    std::uint64_t head = 0;
    if (auto s = varint(head); !s) return s.error();
    if ((head >> 2) > 0xFFFFFFFFu)
      return DecodeError{DecodeErrorCode::kInvalidValue, at, "presence records: client id over 32 bits"};
    if ((head & 3) == 3) return DecodeError{DecodeErrorCode::kInvalidValue, at, "presence records: unknown kind 3"};
    PresenceRecord r;
    r.kind = static_cast<PresenceRecordKind>(head & 3);
    r.client_id = static_cast<std::uint32_t>(head >> 2);
    for (const PresenceRecord& before : out)
      if (before.client_id == r.client_id)
        return DecodeError{DecodeErrorCode::kInvalidValue, at, "presence records: a client twice in one message"};
    if (r.kind != PresenceRecordKind::kLeft) {
      // An entering position is within range, a move at most the width of it.
      const std::int64_t limit = r.kind == PresenceRecordKind::kEntered ? kMaxEighths : 2 * kMaxEighths;
      std::int32_t* axis[3] = {&r.eighths.x, &r.eighths.y, &r.eighths.z};
      for (std::int32_t* a : axis) {
        const std::size_t v_at = pos;
        std::uint64_t z = 0;
        if (auto s = varint(z); !s) return s.error();
        if (z > 2 * static_cast<std::uint64_t>(limit))
          return DecodeError{DecodeErrorCode::kInvalidValue, v_at, "presence records: position out of range"};
        *a = static_cast<std::int32_t>(unzigzag(z));
      }
    }
    if (r.kind == PresenceRecordKind::kEntered) {
      if (pos >= bytes.size()) return cut_short(pos);
      const std::size_t n = bytes[pos++];
      if (n > kMaxClientNameBytes)
        return DecodeError{DecodeErrorCode::kOverLimit, pos - 1, "presence records: name longer than 64 bytes"};
      if (bytes.size() - pos < n) return cut_short(pos);
      r.name.assign(reinterpret_cast<const char*>(bytes.data() + pos), n);
      if (const std::size_t bad = control_character_at(r.name); bad != std::string_view::npos)
        return DecodeError{DecodeErrorCode::kInvalidValue, pos + bad, "presence records: name with a control character"};
      pos += n;
    }
    out.push_back(std::move(r));
  }
  if (pos != bytes.size())
    return DecodeError{DecodeErrorCode::kTrailingBytes, pos, "presence records: bytes after the last record"};
  return out;
}

Status PresenceList::apply(std::span<const PresenceRecord> records) {
  std::vector<Entry> next = entries_;
  auto find = [&](std::uint32_t id) {
    auto it = std::lower_bound(next.begin(), next.end(), id, [](const Entry& e, std::uint32_t k) { return e.client_id < k; });
    return it != next.end() && it->client_id == id ? it : next.end();
  };
  for (std::size_t i = 0; i < records.size(); ++i) {
    const PresenceRecord& r = records[i];
    auto it = find(r.client_id);
    switch (r.kind) {
      case PresenceRecordKind::kEntered: {
        if (it != next.end())
          return DecodeError{DecodeErrorCode::kInvalidValue, i, "presence records: an entry entering is listed already"};
        auto at = std::lower_bound(next.begin(), next.end(), r.client_id,
                                   [](const Entry& e, std::uint32_t k) { return e.client_id < k; });
        next.insert(at, Entry{r.client_id, r.eighths, r.name});
        break;
      }
      case PresenceRecordKind::kMoved: {
        if (it == next.end())
          return DecodeError{DecodeErrorCode::kInvalidValue, i, "presence records: an entry moved is not listed"};
        const std::int64_t x = std::int64_t{it->eighths.x} + r.eighths.x, y = std::int64_t{it->eighths.y} + r.eighths.y,
                           z = std::int64_t{it->eighths.z} + r.eighths.z;
        if (std::max({std::abs(x), std::abs(y), std::abs(z)}) > kMaxEighths)
          return DecodeError{DecodeErrorCode::kInvalidValue, i, "presence records: an entry moved out of range"};
        it->eighths = {static_cast<std::int32_t>(x), static_cast<std::int32_t>(y), static_cast<std::int32_t>(z)};
        break;
      }
      case PresenceRecordKind::kLeft:
        if (it == next.end())
          return DecodeError{DecodeErrorCode::kInvalidValue, i, "presence records: an entry leaving is not listed"};
        next.erase(it);
        break;
    }
  }
  if (next.size() > kMaxPresenceEntries)
    return DecodeError{DecodeErrorCode::kOverLimit, records.size(), "presence records: a list of more than 64 entries"};
  entries_ = std::move(next);
  return Ok{};
}

const PresenceList::Entry* PresenceList::find(std::uint32_t client_id) const {
  auto it = std::lower_bound(entries_.begin(), entries_.end(), client_id,
                             [](const Entry& e, std::uint32_t k) { return e.client_id < k; });
  return it != entries_.end() && it->client_id == client_id ? &*it : nullptr;
}

std::vector<PresenceEntryMsg> PresenceList::nearest_first(Vec3f from) const {
  std::vector<std::pair<double, const Entry*>> by;
  by.reserve(entries_.size());
  for (const Entry& e : entries_) {
    const Vec3f p = presence_position(e.eighths);
    const double dx = p.x - from.x, dy = p.y - from.y, dz = p.z - from.z;
    by.emplace_back(dx * dx + dy * dy + dz * dz, &e);
  }
  std::sort(by.begin(), by.end(), [](const auto& a, const auto& b) {
    return a.first < b.first || (a.first == b.first && a.second->client_id < b.second->client_id);
  });
  std::vector<PresenceEntryMsg> out;
  out.reserve(by.size());
  for (const auto& [d, e] : by) out.push_back({e->client_id, presence_position(e->eighths), e->name});
  return out;
}

}  // namespace terrane
