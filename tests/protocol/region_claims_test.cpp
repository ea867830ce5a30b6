#include "protocol/region_claims.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>
#include <tuple>

#include "common/codec/bit_io.h"
#include "common/world/coarse_image.h"
#include "protocol/framing.h"

namespace terrane {
namespace {

// Claims in the order decode_region_claims gives them back: regions by
// (y, z, x), chunks by their index in the region.
std::vector<HeldChunkMsg> canonical(std::vector<HeldChunkMsg> v) {
  const auto key = [](const HeldChunkMsg& c) {
    const Vec3i r = coarse_region_of(c.chunk_pos);
    return std::tuple(r.y, r.z, r.x, coarse_index(c.chunk_pos));
  };
  std::sort(v.begin(), v.end(), [&](const auto& a, const auto& b) { return key(a) < key(b); });
  return v;
}

bool same(const std::vector<HeldChunkMsg>& a, const std::vector<HeldChunkMsg>& b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](const auto& x, const auto& y) {
           return x.chunk_pos == y.chunk_pos && x.holding == y.holding;
         });
}

// A view's worth of claims: a column of regions, mostly one form and
// revision per layer, a few chunks edited, some not held.
std::vector<HeldChunkMsg> view_claims() {
  std::vector<HeldChunkMsg> v;
  for (int x = -20; x < 20; ++x)
    for (int z = -20; z < 20; ++z)
      for (int y = -4; y < 8; ++y) {
        if ((x * 7 + z * 3) % 11 == 0 && y == 2) continue;  // not held
        HoldingForm f = y > 2 ? HoldingForm::kEmpty : (std::abs(x) < 3 && std::abs(z) < 3 ? HoldingForm::kFull : HoldingForm::kMip3);
        std::uint64_t rev = f == HoldingForm::kEmpty ? 0 : 1;
        if (x == 5 && z == -7) rev = 900000000000ull;  // edited often
        v.push_back({{x, y, z}, {f, rev}});
      }
  return v;
}

TEST(RegionClaims, RoundTripOfAView) {
  const auto claims = view_claims();
  std::vector<std::uint8_t> bytes;
  encode_region_claims(claims, bytes);
  std::vector<HeldChunkMsg> back;
  ASSERT_TRUE(decode_region_claims(bytes, back, claims.size()).ok());
  EXPECT_TRUE(same(back, canonical(claims)));
  // Runs of alike claims: under a byte a claim here, where a HeldChunk
  // takes 32.
  EXPECT_LT(bytes.size(), claims.size()) << bytes.size() << " bytes for " << claims.size() << " claims";
}

TEST(RegionClaims, RandomClaimsRoundTrip) {
  std::mt19937 rng(7);
  for (int round = 0; round < 200; ++round) {
    std::vector<HeldChunkMsg> claims;
    std::set<std::tuple<int, int, int>> used;
    const int n = static_cast<int>(rng() % 700);
    for (int i = 0; i < n; ++i) {
      const int span = round % 2 == 0 ? 20 : (1 << 19) - 1;
      const Vec3i cp{static_cast<int>(rng() % (2 * span + 1)) - span, static_cast<int>(rng() % 40) - 20,
                     static_cast<int>(rng() % (2 * span + 1)) - span};
      if (!used.insert({cp.x, cp.y, cp.z}).second) continue;
      const auto form = static_cast<HoldingForm>(rng() % 5);
      const std::uint64_t rev = rng() % 3 == 0 ? 0 : (std::uint64_t{rng()} << 32 | rng()) >> (rng() % 64);
      claims.push_back({cp, {form, rev}});
    }
    std::vector<std::uint8_t> bytes;
    encode_region_claims(claims, bytes);
    std::vector<HeldChunkMsg> back;
    const auto st = decode_region_claims(bytes, back, kMaxHoldingsPerMessage);
    if (claims.empty()) {
      EXPECT_TRUE(bytes.empty());
      continue;
    }
    ASSERT_TRUE(st.ok()) << st.error().detail << " at " << st.error().offset;
    ASSERT_TRUE(same(back, canonical(claims))) << "round " << round;
  }
}

// Every truncation is an error, at or before the end; never a crash.
TEST(RegionClaims, EveryTruncationIsAnError) {
  const auto claims = view_claims();
  std::vector<std::uint8_t> bytes;
  encode_region_claims(claims, bytes);
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    std::vector<HeldChunkMsg> back;
    const auto st = decode_region_claims(std::span<const std::uint8_t>(bytes).first(n), back, claims.size());
    ASSERT_FALSE(st.ok()) << n;
    EXPECT_LE(st.error().offset, n);
  }
}

std::vector<std::uint8_t> region_bytes(std::initializer_list<std::uint64_t> values) {
  std::vector<std::uint8_t> out;
  for (const std::uint64_t v : values) put_varint(v, out);
  return out;
}

TEST(RegionClaims, MalformedClaimsAreRefusedWithTheirOffset) {
  struct Case {
    std::vector<std::uint8_t> bytes;
    std::size_t offset;
    const char* what;
  };
  // One region at (0, 0, 0): regions 1, dx dy dz, runs, then runs of
  // (length, form[, revision]).
  std::vector<Case> cases = {
      {region_bytes({0}), 0, "no region"},
      {region_bytes({1, 0, 0, 0, 0}), 4, "run count"},
      {region_bytes({1, 0, 0, 0, 513}), 4, "run count"},
      {region_bytes({1, 0, 0, 0, 1, 0, 15}), 5, "run of 0"},
      {region_bytes({1, 0, 0, 0, 1, 513, 15}), 5, "past"},
      {region_bytes({1, 0, 0, 0, 1, 511, 15}), 8, "end before"},
      {region_bytes({1, 0, 0, 0, 2, 511, 15, 2, 15}), 8, "past"},
      {region_bytes({1, 0, 0, 0, 1, 512, 5, 0}), 7, "form"},
      {region_bytes({1, 0, 0, 0, 1, 512, 7, 0}), 7, "form"},
      {region_bytes({1, 0, 0, 0, 1, 512, 15, 0}), 8, "trailing"},
      {region_bytes({1, zigzag(1 << 16), 0, 0, 1, 512, 0, 1}), 7, "out of range"},
      {region_bytes({1, zigzag(std::int64_t{1} << 18), 0, 0, 1, 512, 0, 1}), 1, "region out of range"},
  };
  // A revision over 64 bits.
  {
    auto b = region_bytes({1, 0, 0, 0, 1, 512, 0});
    for (int i = 0; i < 9; ++i) b.push_back(0xFF);
    b.push_back(0x02);
    cases.push_back({b, 8, "too long"});
  }
  for (const Case& c : cases) {
    std::vector<HeldChunkMsg> back;
    const auto st = decode_region_claims(c.bytes, back, kMaxHoldingsPerMessage);
    ASSERT_FALSE(st.ok()) << c.what;
    EXPECT_EQ(st.error().offset, c.offset) << c.what << ": " << st.error().detail;
    EXPECT_NE(std::string(st.error().detail).find(c.what), std::string::npos) << st.error().detail;
  }
  // More claims than allowed, counting those already out.
  std::vector<HeldChunkMsg> back(10);
  const auto st = decode_region_claims(region_bytes({1, 0, 0, 0, 1, 512, 0, 1}), back, 500);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, DecodeErrorCode::kOverLimit);
}

// Many claims go in whole regions, at most 16384 to a message, and come
// back through the frames as they went.
TEST(RegionClaims, HoldingsFramesCarryEveryClaim) {
  std::vector<HeldChunkMsg> claims;
  for (int x = 0; x < 64; ++x)
    for (int z = 0; z < 64; ++z)
      for (int y = 0; y < 12; ++y) claims.push_back({{x, y, z}, {HoldingForm::kMip3, std::uint64_t(x % 3)}});
  const auto frames = build_region_holdings(claims, 0xfeedull);
  ASSERT_GE(frames.size(), 3u);  // 49,152 claims
  std::vector<HeldChunkMsg> back;
  for (const Frame& f : frames) {
    auto m = verify_message(std::span<const std::uint8_t>(f).subspan(kFrameHeaderBytes));
    ASSERT_TRUE(m.ok());
    ASSERT_EQ((*m)->body_type(), wire::Body::Holdings);
    EXPECT_EQ((*m)->body_as_Holdings()->world_id(), 0xfeedull);
    auto got = parse_holdings(*(*m)->body_as_Holdings());
    ASSERT_TRUE(got.ok()) << got.error().detail;
    EXPECT_LE(got->size(), kMaxHoldingsPerMessage);
    back.insert(back.end(), got->begin(), got->end());
  }
  EXPECT_TRUE(same(back, canonical(claims)));
  EXPECT_TRUE(build_region_holdings({}, 1).empty());
}

}  // namespace
}  // namespace terrane
