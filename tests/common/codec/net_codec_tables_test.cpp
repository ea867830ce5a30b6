// The network voxel codec's code tables (common/codec/net_codec_tables.h)
// against the rules of common/codec/NET_CODEC.md: rankings and their ids,
// the type code words, the token lookup tables, the context bytes and
// truncated binary codes.
#include "common/codec/net_codec_tables.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

namespace terrane::net_codec_detail {
namespace {

constexpr int kSizes[] = {4, 8, 16};

const TokenEntry* tables_for(int n) {
  switch (n) {
    case 4: return token_tables<4>();
    case 8: return token_tables<8>();
    default: return token_tables<16>();
  }
}

// The types a context may rank, ascending: all four after Lit, else the
// three other than the context's own type.
std::vector<int> allowed_types(int prev) {
  std::vector<int> types;
  for (int s = 0; s < 4; ++s) {
    if (prev == kLit || s != prev) types.push_back(s);
  }
  return types;
}

// The Exp-Golomb code of a length as NET_CODEC.md reads it (z zeros, a one,
// z bits of r, m bits of t), as an LSB-first value and its bit count.
struct Code {
  std::uint32_t value;
  unsigned bits;
};
Code exp_golomb(std::uint32_t length, unsigned m) {
  const std::uint32_t v = length - 1;
  const std::uint32_t w = (v >> m) + 1;
  unsigned z = 0;
  while ((w >> (z + 1)) != 0) ++z;
  const std::uint32_t r = w - (1u << z);
  const std::uint32_t t = v & ((1u << m) - 1);
  return {(1u << z) | (r << (z + 1)) | (t << (2 * z + 1)), 2 * z + 1 + m};
}

TEST(NetCodecTables, EveryRankingIdMapsBackToItsRanking) {
  for (int prev = 0; prev < 4; ++prev) {
    for (int id = 0; id < context_rankings(prev); ++id) {
      const TypeCode code = code_from_id(prev, id);
      EXPECT_EQ(ranking_id(prev, code), id) << "prev=" << prev;
      // The ranks hold each allowed type once.
      std::vector<int> ranked;
      for (int r = 0; r < context_ranks(prev); ++r) ranked.push_back(code.rank[static_cast<std::size_t>(r)]);
      std::sort(ranked.begin(), ranked.end());
      EXPECT_EQ(ranked, allowed_types(prev)) << "prev=" << prev << " id=" << id;
    }
  }
}

TEST(NetCodecTables, DefaultRankingsAreTheSpecsAndSendable) {
  const TypeCode expected[4] = {{{kRun, kCopyZ, kLit, kCopyY}},
                                {{kCopyZ, kLit, kCopyY, kLit}},
                                {{kLit, kRun, kCopyY, kLit}},
                                {{kCopyZ, kLit, kRun, kLit}}};
  for (int prev = 0; prev < 4; ++prev) {
    const TypeCode& d = kDefaultTypeCodes[static_cast<std::size_t>(prev)];
    const TypeCode again = code_from_id(prev, ranking_id(prev, d));
    for (int r = 0; r < context_ranks(prev); ++r) {
      EXPECT_EQ(d.rank[static_cast<std::size_t>(r)], expected[prev].rank[static_cast<std::size_t>(r)]);
      EXPECT_EQ(again.rank[static_cast<std::size_t>(r)], d.rank[static_cast<std::size_t>(r)]);
    }
  }
}

TEST(NetCodecTables, TypeCodeWordsFormACompletePrefixCode) {
  for (int prev = 0; prev < 4; ++prev) {
    const int ranks = context_ranks(prev);
    double kraft = 0;
    for (int a = 0; a < ranks; ++a) {
      const CodeWord wa = code_word(prev, a);
      ASSERT_GE(wa.length, 1);
      ASSERT_LT(wa.bits, 1u << wa.length);
      kraft += 1.0 / (1u << wa.length);
      for (int b = 0; b < ranks; ++b) {
        if (a == b) continue;
        const CodeWord wb = code_word(prev, b);
        // Read LSB-first, a is a prefix of b when b's first a.length bits are a's.
        const bool prefix = wa.length <= wb.length && (wb.bits & ((1u << wa.length) - 1)) == wa.bits;
        EXPECT_FALSE(prefix) << "prev=" << prev << " rank " << a << " prefixes rank " << b;
      }
    }
    EXPECT_EQ(kraft, 1.0) << "prev=" << prev;
    // Shorter codes for better ranks.
    for (int r = 1; r < ranks; ++r) EXPECT_LE(code_word(prev, r - 1).length, code_word(prev, r).length);
  }
}

TEST(NetCodecTables, TokenTableIdsCoverTheTwentyOneTablesOnce) {
  std::vector<int> seen(kTokenTableCount, 0);
  for (int prev = 0; prev < 4; ++prev) {
    for (int id = 0; id < context_rankings(prev); ++id) {
      const unsigned t = token_table_id(prev, id);
      ASSERT_LT(t, static_cast<unsigned>(kTokenTableCount));
      ++seen[t];
    }
  }
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), kTokenTableCount);
}

// Every code word followed by every length the window holds (and some it
// does not) finds its type, and its length and bit count when they fit.
TEST(NetCodecTables, EveryTokenTableEntryDecodesItsTypeCodeAndLength) {
  for (int n : kSizes) {
    const TokenEntry* tables = tables_for(n);
    for (int prev = 0; prev < 4; ++prev) {
      for (int id = 0; id < context_rankings(prev); ++id) {
        const TypeCode code = code_from_id(prev, id);
        const TokenEntry* table = tables + token_table_id(prev, id) * kTokenTableSize;
        for (int r = 0; r < context_ranks(prev); ++r) {
          const CodeWord w = code_word(prev, r);
          const TokenType type = code.rank[static_cast<std::size_t>(r)];
          if (type == kLit) {
            // Whatever follows, the entry is a literal of one voxel.
            for (std::uint32_t rest = 0; rest < (kTokenTableSize >> w.length); ++rest) {
              const TokenEntry e = table[w.bits | (rest << w.length)];
              ASSERT_EQ(e.type(), kLit);
              ASSERT_EQ(e.bits(), w.length);
              ASSERT_EQ(e.length(), 1u);
            }
            continue;
          }
          for (std::uint32_t length = 1; length <= 200; ++length) {
            const Code eg = exp_golomb(length, length_order(type, n));
            const unsigned total = w.length + eg.bits;
            const std::uint32_t window = (w.bits | (eg.value << w.length)) & (kTokenTableSize - 1);
            const TokenEntry e = table[window];
            ASSERT_EQ(e.type(), type) << "n=" << n << " prev=" << prev << " id=" << id << " length=" << length;
            if (total <= kPeekBits) {
              ASSERT_EQ(e.length(), length);
              ASSERT_EQ(e.bits(), total);
            } else {
              // Too long for the window: the decoder reads it after the type code.
              ASSERT_EQ(e.length(), 0u) << "length=" << length;
              ASSERT_EQ(e.bits(), w.length);
            }
          }
        }
      }
    }
  }
}

TEST(NetCodecTables, TokenTablesAreBuiltOncePerUnitSize) {
  EXPECT_EQ(token_tables<4>(), token_tables<4>());
  EXPECT_NE(token_tables<4>(), token_tables<8>());
  EXPECT_NE(token_tables<8>(), token_tables<16>());
  EXPECT_EQ(&context_tables(), &context_tables());
}

TEST(NetCodecTables, ContextBytesNameTheirTableAndTheLengthOfLitsCode) {
  const ContextTables& c = context_tables();
  for (int prev = 0; prev < 4; ++prev) {
    for (int id = 0; id < context_rankings(prev); ++id) {
      const unsigned t = token_table_id(prev, id);
      const TypeCode code = code_from_id(prev, id);
      unsigned lit_length = 0;
      for (int r = 0; r < context_ranks(prev); ++r) {
        if (code.rank[static_cast<std::size_t>(r)] == kLit) lit_length = code_word(prev, r).length;
      }
      EXPECT_NE(lit_length, 0u);  // Lit may follow every type
      EXPECT_EQ(c.info[t] & 31u, t);
      EXPECT_EQ(static_cast<unsigned>(c.info[t] >> 5), lit_length);
    }
    EXPECT_EQ(c.default_table[static_cast<std::size_t>(prev)],
              token_table_id(prev, ranking_id(prev, kDefaultTypeCodes[static_cast<std::size_t>(prev)])));
  }
}

TEST(NetCodecTables, LengthOrdersAreTheSpecs) {
  EXPECT_EQ(length_order(kRun, 4), 0u);
  EXPECT_EQ(length_order(kRun, 16), 0u);
  EXPECT_EQ(length_order(kCopyZ, 4), 1u);
  EXPECT_EQ(length_order(kCopyZ, 8), 2u);
  EXPECT_EQ(length_order(kCopyZ, 16), 2u);
  EXPECT_EQ(length_order(kCopyY, 4), 2u);
  EXPECT_EQ(length_order(kCopyY, 16), 2u);
}

// Every value of every count 1..64 reads back, the codes are b - 1 or b
// bits, and together they fill the code space (a complete prefix code).
TEST(NetCodecTables, TruncatedBinaryRoundTripsAndIsComplete) {
  for (unsigned count = 1; count <= 64; ++count) {
    const TruncatedBinary code(count);
    std::vector<std::uint8_t> buf(count * 8 + 16, 0);
    BitWriter w(buf.data());
    std::vector<std::size_t> lengths;
    for (std::uint32_t v = 0; v < count; ++v) {
      const std::size_t before = w.bit_count();
      code.put(w, v);
      lengths.push_back(w.bit_count() - before);
    }
    const std::size_t size = w.finish();
    BitReader r(buf.data(), buf.data() + size);
    double kraft = 0;
    for (std::uint32_t v = 0; v < count; ++v) {
      r.refill();
      ASSERT_EQ(code.get(r), v) << "count=" << count;
      const std::size_t l = lengths[v];
      EXPECT_TRUE(l == code.bits || (code.bits > 0 && l == code.bits - 1)) << "count=" << count;
      kraft += 1.0 / static_cast<double>(std::size_t{1} << l);
    }
    EXPECT_FALSE(r.overran());
    EXPECT_EQ(kraft, 1.0) << "count=" << count;
  }
}

TEST(NetCodecTables, PackedIndexBitsIsCeilLog2) {
  EXPECT_EQ(packed_index_bits(1), 0u);
  EXPECT_EQ(packed_index_bits(2), 1u);
  EXPECT_EQ(packed_index_bits(3), 2u);
  EXPECT_EQ(packed_index_bits(4), 2u);
  EXPECT_EQ(packed_index_bits(5), 3u);
  EXPECT_EQ(packed_index_bits(33), 6u);
  EXPECT_EQ(packed_index_bits(64), 6u);
}

}  // namespace
}  // namespace terrane::net_codec_detail
