#include "protocol/region_claims.h"

#include <algorithm>
#include <cstdlib>
#include <tuple>

#include "common/codec/bit_io.h"
#include "common/world/coarse_image.h"

namespace terrane {

static_assert(kCoarseRegionChunks == 8 && kRegionClaimSlots == 512);

namespace {

DecodeError bad(std::size_t at, const char* what) { return DecodeError{DecodeErrorCode::kInvalidValue, at, what}; }

}  // namespace

void encode_region_claims(std::span<const HeldChunkMsg> claims, std::vector<std::uint8_t>& out) {
  struct Keyed {
    Vec3i region;
    int index;
    Holding holding;
  };
  std::vector<Keyed> keyed;
  keyed.reserve(claims.size());
  for (const HeldChunkMsg& c : claims)
    keyed.push_back({coarse_region_of(c.chunk_pos), coarse_index(c.chunk_pos), c.holding});
  const auto key = [](const Keyed& k) { return std::tuple(k.region.y, k.region.z, k.region.x, k.index); };
  std::sort(keyed.begin(), keyed.end(), [&](const Keyed& a, const Keyed& b) { return key(a) < key(b); });

  std::size_t regions = 0;
  for (std::size_t i = 0; i < keyed.size(); ++i)
    if (i == 0 || !(keyed[i].region == keyed[i - 1].region)) ++regions;
  if (regions == 0) return;
  put_varint(regions, out);

  Vec3i prev{0, 0, 0};
  std::vector<std::uint8_t> runs;
  for (std::size_t i = 0; i < keyed.size();) {
    const Vec3i region = keyed[i].region;
    std::size_t end = i;
    while (end < keyed.size() && keyed[end].region == region) ++end;
    put_varint(zigzag(region.x - prev.x), out);
    put_varint(zigzag(region.y - prev.y), out);
    put_varint(zigzag(region.z - prev.z), out);
    prev = region;
    // The region's runs: a gap (chunks not claimed) or chunks claimed alike.
    runs.clear();
    std::size_t count = 0;
    int next = 0;  // the first chunk index not yet in a run
    auto run = [&](std::size_t length, std::uint8_t form, std::uint64_t revision) {
      put_varint(length, runs);
      runs.push_back(form);
      if (form != kRegionClaimNone) put_varint(revision, runs);
      ++count;
    };
    for (std::size_t j = i; j < end;) {
      if (keyed[j].index > next) run(static_cast<std::size_t>(keyed[j].index - next), kRegionClaimNone, 0);
      std::size_t k = j + 1;
      while (k < end && keyed[k].index == keyed[k - 1].index + 1 && keyed[k].holding == keyed[j].holding) ++k;
      run(k - j, static_cast<std::uint8_t>(keyed[j].holding.form), keyed[j].holding.revision);
      next = keyed[k - 1].index + 1;
      j = k;
    }
    if (next < static_cast<int>(kRegionClaimSlots))
      run(kRegionClaimSlots - static_cast<std::size_t>(next), kRegionClaimNone, 0);
    put_varint(count, out);
    out.insert(out.end(), runs.begin(), runs.end());
    i = end;
  }
}

Status decode_region_claims(std::span<const std::uint8_t> bytes, std::vector<HeldChunkMsg>& out,
                            std::size_t max_claims) {
  std::size_t pos = 0;
  auto varint = [&](std::uint64_t& v, std::size_t max_bytes) -> Status {
    const std::size_t at = pos;
    const VarintRead r = get_varint(bytes, pos, max_bytes, v);
    if (r == VarintRead::kTruncated) return DecodeError{DecodeErrorCode::kTruncated, at, "region claims: truncated"};
    // Ten bytes hold 70 bits: the tenth may carry only the 64th.
    if (r == VarintRead::kTooLong || (max_bytes == 10 && pos - at == 10 && bytes[pos - 1] > 1))
      return bad(at, "region claims: varint too long");
    return Ok{};
  };
  std::uint64_t regions = 0;
  if (auto s = varint(regions, 5); !s) return s.error();
  if (regions == 0) return bad(0, "region claims: no region");
  Vec3i prev{0, 0, 0};
  for (std::uint64_t r = 0; r < regions; ++r) {
    std::int64_t d[3];
    const std::size_t region_at = pos;
    for (std::int64_t& c : d) {
      std::uint64_t z = 0;
      if (auto s = varint(z, 5); !s) return s.error();
      c = unzigzag(z);
    }
    // A region's coordinates are chunk coordinates / 8: a region beyond
    // ±2^17 holds no chunk in the wire's range (±2^19); those within are
    // checked chunk by chunk.
    const std::int64_t x = prev.x + d[0], y = prev.y + d[1], z = prev.z + d[2];
    constexpr std::int64_t kLimit = std::int64_t{1} << 17;
    if (std::max({std::abs(x), std::abs(y), std::abs(z)}) > kLimit) return bad(region_at, "region claims: region out of range");
    const Vec3i region{static_cast<std::int32_t>(x), static_cast<std::int32_t>(y), static_cast<std::int32_t>(z)};
    prev = region;
    std::uint64_t runs = 0;
    const std::size_t runs_at = pos;
    if (auto s = varint(runs, 5); !s) return s.error();
    if (runs == 0 || runs > kRegionClaimSlots) return bad(runs_at, "region claims: run count not 1..512");
    std::size_t index = 0;
    for (std::uint64_t k = 0; k < runs; ++k) {
      std::uint64_t length = 0;
      const std::size_t length_at = pos;
      if (auto s = varint(length, 5); !s) return s.error();
      if (length == 0 || length > kRegionClaimSlots - index)
        return bad(length_at, "region claims: a run of 0 chunks or past the region's 512th");
      if (pos >= bytes.size()) return DecodeError{DecodeErrorCode::kTruncated, pos, "region claims: truncated"};
      const std::size_t form_at = pos;
      const std::uint8_t form = bytes[pos++];
      if (form == kRegionClaimNone) {
        index += static_cast<std::size_t>(length);
        continue;
      }
      if (form >= kHoldingForms || !claimable(static_cast<HoldingForm>(form)))
        return bad(form_at, "region claims: form not 0..4 (Full, Mip 1..3, Empty) or 15 (none)");
      std::uint64_t revision = 0;
      if (auto s = varint(revision, 10); !s) return s.error();
      if (out.size() + length > max_claims)
        return DecodeError{DecodeErrorCode::kOverLimit, length_at, "region claims: more claims than a Holdings may carry"};
      const Vec3i base = region * kCoarseRegionChunks;
      for (std::uint64_t n = 0; n < length; ++n, ++index) {
        const int i = static_cast<int>(index);
        const Vec3i cp = base + Vec3i{i % 8, i / 64, (i / 8) % 8};
        if (!wire_chunk_ok(cp)) return bad(length_at, "region claims: chunk position out of range");
        out.push_back(HeldChunkMsg{cp, Holding{static_cast<HoldingForm>(form), revision}});
      }
    }
    if (index != kRegionClaimSlots) return bad(pos, "region claims: runs end before the region's 512th chunk");
  }
  if (pos != bytes.size()) return bad(pos, "region claims: trailing bytes");
  return Ok{};
}

}  // namespace terrane
