// Builds the network voxel codec's token and context tables (see
// net_codec_tables.h); each is built once per process.
#include "common/codec/net_codec_tables.h"

namespace terrane::net_codec_detail {
namespace {

// Fills the kTokenTableSize entries of context prev with ranking code.
void build_token_table(int prev, const TypeCode& code, int n, TokenEntry* t) {
  const int ranks = context_ranks(prev);
  for (unsigned x = 0; x < kTokenTableSize; ++x) {
    for (int r = 0; r < ranks; ++r) {
      const CodeWord w = code_word(prev, r);
      if ((x & ((1u << w.length) - 1)) != w.bits) continue;
      const TokenType type = code.rank[static_cast<std::size_t>(r)];
      unsigned bits = w.length;
      unsigned length = type == kLit ? 1 : 0;
      if (type != kLit) {
        const unsigned rest = x >> w.length;
        const unsigned avail = kPeekBits - w.length;
        const unsigned order = length_order(type, n);
        if (rest != 0) {
          const auto lg = static_cast<unsigned>(std::countr_zero(rest));
          if (2 * lg + 1 + order <= avail) {
            const unsigned wv = (1u << lg) | ((rest >> (lg + 1)) & ((1u << lg) - 1));
            const unsigned low = (rest >> (2 * lg + 1)) & ((1u << order) - 1);
            length = (((wv - 1) << order) | low) + 1;
            bits = w.length + 2 * lg + 1 + order;
          }
        }
      }
      t[x] = TokenEntry::make(type, bits, length);
      break;
    }
  }
}

}  // namespace

const TokenTables* build_token_tables(int n) {
  auto* t = new TokenTables;
  for (int p = 0; p < 4; ++p) {
    for (int id = 0; id < context_rankings(p); ++id) {
      build_token_table(p, code_from_id(p, id), n, t->data() + token_table_id(p, id) * kTokenTableSize);
    }
  }
  return t;
}

ContextTables build_context_tables() {
  ContextTables t{};
  for (int p = 0; p < 4; ++p) {
    for (int id = 0; id < context_rankings(p); ++id) {
      const TypeCode code = code_from_id(p, id);
      unsigned lit_code_length = 0;
      for (int rank = 0; rank < context_ranks(p); ++rank) {
        if (code.rank[static_cast<std::size_t>(rank)] == kLit) lit_code_length = code_word(p, rank).length;
      }
      const unsigned table = token_table_id(p, id);
      t.info[table] = static_cast<std::uint8_t>(table | (lit_code_length << 5));
    }
    t.default_table[static_cast<std::size_t>(p)] =
        static_cast<std::uint8_t>(token_table_id(p, ranking_id(p, kDefaultTypeCodes[static_cast<std::size_t>(p)])));
  }
  return t;
}

}  // namespace terrane::net_codec_detail
