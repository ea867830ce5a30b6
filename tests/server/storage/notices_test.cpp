// The notices' payloads on their own (no database): what a commit tells
// the other servers and the answers to forwarded edits, written and read
// back, and payloads that are not ours refused.
#include "server/storage/notices.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace terrane {
namespace {

TEST(ChangeNoticeTest, ChunksAndRegionSequencesRoundTripAndBadPayloadsAreRefused) {
  std::vector<ChunkWrite> chunks;
  for (int i = 0; i < 600; ++i) chunks.push_back(ChunkWrite{{i, -i, 1 << 20}, static_cast<std::uint64_t>(i) * 977, {}});
  const std::vector<RegionSeq> regions{{{0, 0, 0}, 1}, {{-3, 2, 1 << 17}, 123456789}};
  const auto notices = change_notices(chunks, regions);
  ASSERT_GT(notices.size(), 1u);  // split under the size cap
  std::vector<ChunkChange> got_chunks;
  std::vector<RegionSeq> got_regions;
  for (const std::string& n : notices) {
    EXPECT_LE(n.size(), kMaxChangeNoticeBytes);
    auto p = parse_change_notice(n);
    ASSERT_TRUE(p) << n.substr(0, 80);
    got_chunks.insert(got_chunks.end(), p->chunks.begin(), p->chunks.end());
    got_regions.insert(got_regions.end(), p->regions.begin(), p->regions.end());
  }
  EXPECT_EQ(got_regions, regions);
  ASSERT_EQ(got_chunks.size(), chunks.size());
  for (std::size_t i = 0; i < chunks.size(); ++i)
    EXPECT_EQ(got_chunks[i], (ChunkChange{chunks[i].pos, chunks[i].revision}));
  for (const char* bad : {"1,2,3", "1,2,3,-4", "r,1,2,3", "x,1,2,3,4", "1,2,99999999999,4", "r,1,2,3,-1"})
    EXPECT_FALSE(parse_change_notice(bad)) << bad;
}

TEST(ChangeNoticeTest, AChunksChangedUnitsTravelWithItsRevisionUnlessTooLarge) {
  // Bytes of every value, so each base64 tail (none, one and two '=') is met.
  std::vector<ChunkWrite> chunks;
  for (int n = 1; n <= 300; ++n) {
    ChunkWrite w{{n, 2, -3}, static_cast<std::uint64_t>(n), {}};
    w.tick = 1000u + static_cast<std::uint64_t>(n);
    for (int i = 0; i < n; ++i) w.units.push_back(static_cast<std::uint8_t>(i * 37 + n));
    chunks.push_back(std::move(w));
  }
  chunks.push_back(ChunkWrite{{0, 0, 0}, 7, {}});  // units not known
  ChunkWrite large{{1, 1, 1}, 9, {}};
  large.units.assign(kMaxNoticeUnitsBytes / 4 * 3 + 1, 0xAB);  // base64 over the cap: left out
  chunks.push_back(large);
  std::vector<ChunkChange> got;
  for (const std::string& n : change_notices(chunks)) {
    EXPECT_LE(n.size(), kMaxChangeNoticeBytes);
    auto p = parse_change_notice(n);
    ASSERT_TRUE(p) << n.substr(0, 80);
    got.insert(got.end(), p->chunks.begin(), p->chunks.end());
  }
  ASSERT_EQ(got.size(), chunks.size());
  for (std::size_t i = 0; i + 1 < chunks.size(); ++i)
    EXPECT_EQ(got[i], (ChunkChange{chunks[i].pos, chunks[i].revision, chunks[i].units,
                                   chunks[i].units.empty() ? 0 : chunks[i].tick}))
        << i;
  EXPECT_EQ(got.back(), (ChunkChange{large.pos, large.revision, {}}));
  auto ok = parse_change_notice("1,2,3,4,50,QUJD 5,6,7,8,50,QUI= 9,10,11,12,51,QQ==");
  ASSERT_TRUE(ok);
  ASSERT_EQ(ok->chunks.size(), 3u);
  EXPECT_EQ(ok->chunks[0].units, (std::vector<std::uint8_t>{'A', 'B', 'C'}));
  EXPECT_EQ(ok->chunks[1].units, (std::vector<std::uint8_t>{'A', 'B'}));
  EXPECT_EQ(ok->chunks[2].units, (std::vector<std::uint8_t>{'A'}));
  EXPECT_EQ(ok->chunks[2].tick, 51u);
  EXPECT_EQ(ok->units_unread, 0u);
  // Units that are not padded base64 (or run over the cap) cost the chunk
  // its units only: it is read again, and the rest of the notice stands.
  const std::string at_cap(kMaxNoticeUnitsBytes, 'A'), over_cap(kMaxNoticeUnitsBytes + 4, 'A');
  for (const std::string& units : {std::string("QUJD="), std::string("QU=D"), std::string("Q==="), std::string("QQ==QUJD"),
                                   std::string("QUJD,QUJD"), std::string(""), std::string("QU*D"), std::string("5"), over_cap}) {
    auto p = parse_change_notice("r,0,0,0,7 1,2,3,4,50," + units + " 5,6,7,8,50,QUJD");
    ASSERT_TRUE(p) << units;
    ASSERT_EQ(p->chunks.size(), 2u) << units;
    EXPECT_EQ(p->chunks[0], (ChunkChange{{1, 2, 3}, 4, {}, 50})) << units;
    EXPECT_EQ(p->chunks[1].units.size(), 3u) << units;
    EXPECT_EQ(p->units_unread, 1u) << units;
    EXPECT_EQ(p->regions.size(), 1u) << units;
  }
  auto cap = parse_change_notice("1,2,3,4,50," + at_cap);
  ASSERT_TRUE(cap);
  EXPECT_EQ(cap->chunks[0].units.size(), kMaxNoticeUnitsBytes / 4 * 3);
  // A region's sequence takes no units, and a tick is a number.
  for (const char* bad : {"r,1,2,3,4,50,QUJD", "1,2,3,4,x,QUJD", "1,2,3,4,-1,QUJD", "1,2,3,4,QUJD", "1,2,3,4,5"})
    EXPECT_FALSE(parse_change_notice(bad)) << bad;
}

TEST(AnswerNoticeTest, AnswersRoundTripAndBadPayloadsAreRefused) {
  for (const ForwardAnswer& a : {ForwardAnswer{42, 3, true, 1234, ""},
                                 ForwardAnswer{1, 0, false, 0, "region (1,0,2) is leased to server 3"}}) {
    auto back = parse_answer_notice(answer_notice(a));
    ASSERT_TRUE(back) << answer_notice(a);
    EXPECT_EQ(*back, a);
  }
  // The reason is cut at 256 bytes.
  auto cut = parse_answer_notice(answer_notice(ForwardAnswer{7, 1, false, 0, std::string(300, 'x')}));
  ASSERT_TRUE(cut);
  EXPECT_EQ(cut->reason, std::string(256, 'x'));
  for (const char* bad : {"", "1 2 3", "1 0 1 5 ok", "-1 2 1 5", "1 2 2 5", "1 2 1 -5", "x 2 1 5", "1 2 1 5x"})
    EXPECT_FALSE(parse_answer_notice(bad)) << bad;
}

}  // namespace
}  // namespace terrane
