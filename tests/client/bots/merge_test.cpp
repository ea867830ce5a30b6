// terrane-bots merge (client/bots/merge.h): a report read back from its
// JSON is the report; the parts of one sample set, each written as JSON and
// read back, merge into the report of the whole (counts exactly, latency
// histograms bucket for bucket, percentiles within the histograms'
// precision of the exact ones); parts that are not the shards of one
// scenario are refused. A real sharded run is tested in
// tests/client/bots_test.cpp.
#include "client/bots/merge.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "client/bots/report.h"

namespace terrane::bots {
namespace {

BotsOptions scenario(int shard, int shards) {
  BotsOptions o;
  o.port = 7777;
  o.servers = {{"127.0.0.1", 7777}};
  o.bots = 12;
  o.duration_s = 20;
  o.behavior = Behavior::kMixed;
  o.seed = 3;
  o.shard_index = shard;
  o.shard_count = shards;
  Threshold t;
  EXPECT_EQ(parse_threshold("fanout_p99<80", &t), "");
  o.thresholds.push_back(t);
  return o;
}

double exact(std::vector<double> v, double p) {
  for (double& x : v) x = std::round(x * 1000) / 1000;
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size())));
  return v[std::clamp<std::size_t>(rank, 1, v.size()) - 1];
}

// One run's figures, bot by bot: bot i's samples and counts go to the
// whole report and to part i mod 3.
struct Split {
  BotsReport whole;
  std::vector<BotsReport> parts;
  std::vector<double> fanout;  // every fan-out sample
};

Split make_split() {
  constexpr int kShards = 3;
  Split s;
  s.whole.options = scenario(0, 1);
  for (int p = 0; p < kShards; ++p) {
    s.parts.emplace_back();
    s.parts.back().options = scenario(p, kShards);
  }
  std::mt19937_64 rng(17);
  std::lognormal_distribution<double> latency(std::log(30.0), 0.8);
  LatencyHistogram whole_fanout, whole_join, whole_second[2];
  LatencyHistogram part_fanout[kShards], part_join[kShards], part_second[kShards][2];
  for (int bot = 0; bot < 12; ++bot) {
    const int p = bot % kShards;
    BotsReport& part = s.parts[static_cast<std::size_t>(p)];
    for (BotsReport* r : {&s.whole, &part}) {
      ++r->bots;
      r->bytes_received += 1000 + static_cast<std::uint64_t>(bot) * 37;
      r->edits_sent += 10;
      r->edits_acked += 9;
      r->edits_rejected += 1;
      ++r->reject_reasons["region (N,N,N) is leased"];
      r->replica_regions_checked += 6;
      ++r->bots_per_server[1];
      r->by_message_type[2].frames_in += 5;
      r->by_message_type[2].bytes_in += 500;
      r->duration_s = 21.5;
    }
    const double join = latency(rng) * 10;
    whole_join.record(join);
    part_join[p].record(join);
    for (int e = 0; e < 200; ++e) {
      const double v = latency(rng);
      s.fanout.push_back(v);
      whole_fanout.record(v);
      part_fanout[p].record(v);
      whole_second[e % 2].record(v);
      part_second[p][e % 2].record(v);
    }
  }
  s.whole.edit_fanout_ms = summarize(whole_fanout);
  s.whole.join_full_ms = summarize(whole_join);
  s.whole.timeline.resize(2);
  for (int t = 0; t < 2; ++t) {
    s.whole.timeline[static_cast<std::size_t>(t)].t_s = t + 1;
    s.whole.timeline[static_cast<std::size_t>(t)].bots_connected = 12;
    s.whole.timeline[static_cast<std::size_t>(t)].fanout_ms = summarize(whole_second[t]);
  }
  for (int p = 0; p < kShards; ++p) {
    BotsReport& part = s.parts[static_cast<std::size_t>(p)];
    part.edit_fanout_ms = summarize(part_fanout[p]);
    part.join_full_ms = summarize(part_join[p]);
    part.timeline.resize(2);
    for (int t = 0; t < 2; ++t) {
      part.timeline[static_cast<std::size_t>(t)].t_s = t + 1;
      part.timeline[static_cast<std::size_t>(t)].bots_connected = 4;
      part.timeline[static_cast<std::size_t>(t)].fanout_ms = summarize(part_second[p][t]);
    }
    part.thresholds = evaluate_thresholds(part.options.thresholds, part.threshold_values());  // as run_bots does
  }
  return s;
}

TEST(BotsMerge, AReportReadBackFromItsJsonIsTheReport) {
  Split s = make_split();
  BotsReport& r = s.parts[1];
  r.mismatches.push_back(Mismatch{4, {1, -2, 3}, 5, 6, "voxels differ", true});
  r.disconnects.emplace_back(7, "timed out");
  r.unexpected_disconnects = 1;
  r.server = ServerFigures{};
  r.server->cpu_s = 2.5;
  r.server->tick_p99_ms = std::numeric_limits<double>::infinity();
  r.server->sent_by_type["UpdateBatch"] = {10, 2000};
  r.timeline[0].server = ServerInterval{};
  r.timeline[0].server->tick_ms_mean = 3.5;
  r.timeline[0].server->tick_p99_ms = 2.5;
  r.timeline[0].server->rss_bytes = 31457280;
  r.timeline[0].server->send_queue_bytes = 4096;
  r.timeline[1].joins = 3;
  r.timeline[1].bytes_in_by_type[static_cast<std::size_t>(wire::Body::UpdateBatch)] = 1234;
  r.thresholds = evaluate_thresholds(r.options.thresholds, r.threshold_values());
  const std::string json = report_json(r);
  BotsReport back;
  ASSERT_EQ(report_from_json(json, &back), "");
  EXPECT_EQ(report_json(back), json);
  EXPECT_EQ(back.edit_fanout_ms.histogram, r.edit_fanout_ms.histogram);
  EXPECT_EQ(back.options.shard_index, 1);
  EXPECT_EQ(back.options.shard_count, 3);
  ASSERT_EQ(back.options.thresholds.size(), 1u);
  EXPECT_EQ(back.options.thresholds[0].expression, "fanout_p99<80");
  EXPECT_EQ(back.timeline[1].joins, 3);
  EXPECT_EQ(back.timeline[1].bytes_in_by_type[static_cast<std::size_t>(wire::Body::UpdateBatch)], 1234u);
  ASSERT_TRUE(back.timeline[0].server && back.timeline[0].server->rss_bytes);
  EXPECT_EQ(*back.timeline[0].server->rss_bytes, 31457280u);
  // A message type that is none is refused, naming it.
  std::string bogus = json;
  bogus.replace(bogus.find("\"UpdateBatch\": 1234"), 13, "\"Bogus\"");
  EXPECT_EQ(report_from_json(bogus, &back), "timeline.1.bytes_in_by_type.Bogus: not a message type");

  EXPECT_NE(report_from_json("{\"x\": 1}", &back).find("not a terrane-bots report"), std::string::npos);
  // A latency with samples but no histogram cannot be merged.
  std::string old = json;
  const auto h = old.find("\"histogram\"", old.find("\"edit_fanout_ms\""));
  old.replace(h, 11, "\"unused\"");
  EXPECT_NE(report_from_json(old, &back).find("edit_fanout_ms: has no histogram"), std::string::npos)
      << report_from_json(old, &back);
}

TEST(BotsMerge, CountsOfBotsBeyondThePartsShardAreRefused) {
  // Part 1 of 3 of 12 bots runs 4; its sums then stay within the scenario's.
  const std::string json = report_json(make_split().parts[1]);
  BotsReport back;
  ASSERT_EQ(report_from_json(json, &back), "");
  const auto with = [&](const std::string& field, const std::string& value) {
    std::string changed = json;
    const auto at = changed.find(field);
    EXPECT_NE(at, std::string::npos) << field;
    const auto from = at + field.size(), to = changed.find_first_of(",}\n", from);
    return changed.replace(from, to - from, value);
  };
  EXPECT_EQ(report_from_json(with("\n  \"bots\": ", "2147483647"), &back), "bots: 2147483647 is not in 0..4");
  EXPECT_EQ(report_from_json(with("\n  \"bots\": ", "-1"), &back), "bots: -1 is not in 0..4");
  EXPECT_EQ(report_from_json(with("\"connect_failures\": ", "5"), &back), "connect_failures: 5 is not in 0..4");
  EXPECT_EQ(report_from_json(with("\"unexpected_disconnects\": ", "2147483647"), &back),
            "unexpected_disconnects: 2147483647 is not in 0..4");
  EXPECT_EQ(report_from_json(with("\"joins_incomplete\": ", "-3"), &back), "joins_incomplete: -3 is not in 0..4");
  EXPECT_EQ(report_from_json(with("\"bots_per_server\": {\"1\": ", "9"), &back), "bots_per_server.1: 9 is not in 0..4");
  EXPECT_EQ(report_from_json(with("{\"t_s\": 1, \"bots\": ", "400"), &back), "timeline.0.bots: 400 is not in 0..4");
}

TEST(BotsMerge, PartsMergeIntoTheWholeCountsExactlyAndPercentilesWithinPrecision) {
  Split s = make_split();
  std::vector<BotsReport> parts;
  for (const BotsReport& p : s.parts) {  // as merge reads them: from their JSON
    parts.emplace_back();
    ASSERT_EQ(report_from_json(report_json(p), &parts.back()), "");
  }
  std::reverse(parts.begin(), parts.end());  // any order
  BotsReport merged;
  ASSERT_EQ(merge_reports(parts, &merged), "");
  EXPECT_EQ(merged.options.shard_count, 1);
  EXPECT_EQ(merged.bots, s.whole.bots);
  EXPECT_EQ(merged.bytes_received, s.whole.bytes_received);
  EXPECT_EQ(merged.edits_sent, s.whole.edits_sent);
  EXPECT_EQ(merged.edits_acked, s.whole.edits_acked);
  EXPECT_EQ(merged.edits_rejected, s.whole.edits_rejected);
  EXPECT_EQ(merged.reject_reasons, s.whole.reject_reasons);
  EXPECT_EQ(merged.replica_regions_checked, s.whole.replica_regions_checked);
  EXPECT_EQ(merged.bots_per_server, s.whole.bots_per_server);
  EXPECT_EQ(merged.by_message_type[2].bytes_in, s.whole.by_message_type[2].bytes_in);
  EXPECT_EQ(merged.duration_s, s.whole.duration_s);
  // Histograms bucket for bucket; percentiles as the whole's and within
  // precision of the exact percentiles of every sample.
  EXPECT_EQ(merged.edit_fanout_ms.histogram, s.whole.edit_fanout_ms.histogram);
  EXPECT_EQ(merged.join_full_ms.histogram, s.whole.join_full_ms.histogram);
  EXPECT_EQ(merged.edit_fanout_ms.count, s.fanout.size());
  for (const auto& [got, p] : {std::pair{merged.edit_fanout_ms.p50, 0.5}, std::pair{merged.edit_fanout_ms.p95, 0.95},
                               std::pair{merged.edit_fanout_ms.p99, 0.99}}) {
    const double want = exact(s.fanout, p);
    EXPECT_LE(std::abs(got - want), want * LatencyHistogram::kRelativePrecision) << p;
  }
  EXPECT_EQ(merged.edit_fanout_ms.p99, s.whole.edit_fanout_ms.p99);
  // Per second too.
  ASSERT_EQ(merged.timeline.size(), 2u);
  for (std::size_t t = 0; t < 2; ++t) {
    EXPECT_EQ(merged.timeline[t].bots_connected, 12);
    EXPECT_EQ(merged.timeline[t].fanout_ms.histogram, s.whole.timeline[t].fanout_ms.histogram);
  }
  // Thresholds judged on the whole.
  ASSERT_EQ(merged.thresholds.size(), 1u);
  EXPECT_EQ(merged.thresholds[0].value, merged.edit_fanout_ms.p99);
  // The merged report is the whole's, bar what the parts cannot know.
  BotsReport whole = s.whole;
  whole.thresholds = evaluate_thresholds(whole.options.thresholds, whole.threshold_values());
  EXPECT_EQ(report_json(merged), report_json(whole));
}

TEST(BotsMerge, PartsThatAreNotTheShardsOfOneScenarioAreRefused) {
  Split s = make_split();
  BotsReport merged;
  EXPECT_EQ(merge_reports({}, &merged), "no reports to merge");
  EXPECT_EQ(merge_reports({s.parts[0], s.parts[2]}, &merged), "shards missing: 1 of 3");
  EXPECT_EQ(merge_reports({s.parts[0], s.parts[1], s.parts[1], s.parts[2]}, &merged),
            "part 3 (shard 1/3): that shard is given twice");
  BotsReport other = s.parts[2];
  other.options.seed = 4;
  EXPECT_EQ(merge_reports({s.parts[0], s.parts[1], other}, &merged), "part 3 (shard 2/3): another scenario than part 1's");
  BotsReport four = s.parts[2];
  four.options.shard_count = 4;
  EXPECT_EQ(merge_reports({s.parts[0], s.parts[1], four}, &merged),
            "part 3 (shard 2/4): another number of shards than part 1's 3");
}

}  // namespace
}  // namespace terrane::bots
