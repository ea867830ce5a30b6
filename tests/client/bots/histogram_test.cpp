// LatencyHistogram (client/bots/histogram.h): percentiles against the exact
// nearest-rank percentiles of random samples, within the stated precision;
// merging in any order and grouping; the empty and one-value cases; the
// bucket layout; bounded memory; the JSON round trip.
#include "client/bots/histogram.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "client/bots/report.h"

namespace terrane::bots {
namespace {

// The exact ceil(p * n)-th smallest sample (at least the first), in ms
// rounded to 1 us as the histogram counts it.
double exact_percentile(std::vector<double> ms, double p) {
  for (double& v : ms) v = std::round(v * 1000) / 1000;
  std::sort(ms.begin(), ms.end());
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(ms.size())));
  return ms[std::clamp<std::size_t>(rank, 1, ms.size()) - 1];
}

void expect_within_precision(double got, double exact, const char* what) {
  EXPECT_LE(std::abs(got - exact), exact * LatencyHistogram::kRelativePrecision + 1e-9)
      << what << ": " << got << " vs exact " << exact;
}

TEST(LatencyHistogram, PercentilesAreWithinTheStatedPrecisionOfTheExactOnes) {
  std::mt19937_64 rng(7);
  // Latencies as they come: log-normal around 20 ms with a long tail, a
  // uniform spread, and values under a millisecond (exact buckets).
  std::lognormal_distribution<double> lognormal(std::log(20.0), 1.2);
  std::uniform_real_distribution<double> uniform(0.0, 5000.0);
  std::uniform_real_distribution<double> small(0.0, 0.2);
  for (int kind = 0; kind < 3; ++kind) {
    for (const std::size_t n : {1u, 2u, 7u, 100u, 10000u, 200000u}) {
      std::vector<double> samples;
      LatencyHistogram h;
      for (std::size_t i = 0; i < n; ++i) {
        const double v = kind == 0 ? lognormal(rng) : kind == 1 ? uniform(rng) : small(rng);
        samples.push_back(v);
        h.record(v);
      }
      ASSERT_EQ(h.count(), n);
      for (const double p : {0.0, 0.01, 0.5, 0.9, 0.95, 0.99, 0.999, 1.0})
        expect_within_precision(h.percentile(p), exact_percentile(samples, p), "percentile");
      EXPECT_DOUBLE_EQ(h.max_ms(), exact_percentile(samples, 1.0));
      EXPECT_DOUBLE_EQ(h.min_ms(), exact_percentile(samples, 0.0));
    }
  }
}

TEST(LatencyHistogram, EveryValueIsWithinHalfABucketOfWhatItsBucketStandsFor) {
  // Each bucket: its lowest value maps to it, the one below to the bucket
  // before, its width is at most 1/64 of its lowest value.
  for (std::uint32_t i = 1; i < LatencyHistogram::kBucketCount; ++i) {
    const std::uint64_t lo = LatencyHistogram::lowest_of(i);
    ASSERT_EQ(LatencyHistogram::index_of(lo), i);
    ASSERT_EQ(LatencyHistogram::index_of(lo - 1), i - 1);
    ASSERT_EQ(LatencyHistogram::lowest_of(i - 1) + LatencyHistogram::width_of(i - 1), lo);
    if (lo >= 128) {
      ASSERT_LE(LatencyHistogram::width_of(i) * 64, lo);
    }
  }
  EXPECT_EQ(LatencyHistogram::index_of(LatencyHistogram::kMaxMicros), LatencyHistogram::kBucketCount - 1);
  EXPECT_EQ(LatencyHistogram::index_of(~std::uint64_t{0}), LatencyHistogram::kBucketCount - 1);
}

TEST(LatencyHistogram, EmptyAndSingleValue) {
  LatencyHistogram empty;
  EXPECT_TRUE(empty.empty());
  EXPECT_EQ(empty.percentile(0.5), 0);
  EXPECT_EQ(empty.max_ms(), 0);
  EXPECT_EQ(empty.min_ms(), 0);
  EXPECT_TRUE(empty.buckets().empty());

  // One value: every percentile is that value exactly (the bucket's middle
  // is held within what was recorded).
  LatencyHistogram one;
  one.record(123.456);
  for (const double p : {0.0, 0.5, 0.99, 1.0}) EXPECT_DOUBLE_EQ(one.percentile(p), 123.456);
  ASSERT_EQ(one.buckets().size(), 1u);
  EXPECT_EQ(one.buckets()[0].second, 1u);

  // Merging an empty histogram changes nothing, either way round.
  LatencyHistogram a = one;
  a.merge(empty);
  EXPECT_EQ(a, one);
  LatencyHistogram b = empty;
  b.merge(one);
  EXPECT_EQ(b, one);

  // Negative values count as 0, NaN not at all, huge ones at the top.
  LatencyHistogram odd;
  odd.record(-5);
  odd.record(std::nan(""));
  odd.record(1e300);
  EXPECT_EQ(odd.count(), 2u);
  EXPECT_EQ(odd.min_ms(), 0);
  EXPECT_DOUBLE_EQ(odd.max_ms(), static_cast<double>(LatencyHistogram::kMaxMicros) / 1000);
}

TEST(LatencyHistogram, MergingIsAssociativeAndEqualsRecordingEverything) {
  std::mt19937_64 rng(11);
  std::lognormal_distribution<double> d(std::log(50.0), 1.0);
  LatencyHistogram parts[3], all;
  for (int i = 0; i < 30000; ++i) {
    const double v = d(rng);
    parts[i % 3].record(v);
    all.record(v);
  }
  LatencyHistogram left = parts[0];  // (a + b) + c
  left.merge(parts[1]);
  left.merge(parts[2]);
  LatencyHistogram bc = parts[1];  // a + (b + c)
  bc.merge(parts[2]);
  LatencyHistogram right = parts[0];
  right.merge(bc);
  LatencyHistogram reversed = parts[2];  // c + b + a
  reversed.merge(parts[1]);
  reversed.merge(parts[0]);
  EXPECT_EQ(left, right);
  EXPECT_EQ(left, reversed);
  EXPECT_EQ(left, all);
  EXPECT_EQ(left.percentile(0.99), all.percentile(0.99));
}

TEST(LatencyHistogram, MemoryIsBoundedWhateverTheSamples) {
  // Values over the whole range: never more than kBucketCount buckets.
  LatencyHistogram h;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> exponent(-3, 13);  // 1 us .. 10^13 ms
  for (int i = 0; i < 500000; ++i) h.record(std::pow(10.0, exponent(rng)));
  EXPECT_LE(h.buckets().size(), LatencyHistogram::kBucketCount);
  // A million samples of a narrow distribution take a few dozen buckets.
  LatencyHistogram narrow;
  std::normal_distribution<double> n(40, 2);
  for (int i = 0; i < 1000000; ++i) narrow.record(n(rng));
  EXPECT_LT(narrow.buckets().size(), 200u);
  EXPECT_EQ(narrow.count(), 1000000u);
}

TEST(LatencyHistogram, JsonRoundTripGivesTheSameHistogram) {
  LatencyHistogram h;
  std::mt19937_64 rng(5);
  std::lognormal_distribution<double> d(std::log(10.0), 1.5);
  for (int i = 0; i < 5000; ++i) h.record(d(rng));
  std::map<std::string, std::string> flat;
  ASSERT_EQ(flatten_json("{\"x\": {\"histogram\": " + histogram_json(h) + "}}", &flat), "");
  LatencyHistogram back;
  ASSERT_EQ(histogram_from_flat(flat, "x.histogram", &back), "");
  EXPECT_EQ(back, h);
  EXPECT_EQ(back.percentile(0.95), h.percentile(0.95));

  // A bucket bound that is not a bucket's lowest value is named.
  flat["x.histogram.buckets.0.0"] = "129";
  EXPECT_NE(histogram_from_flat(flat, "x.histogram", &back).find("x.histogram.buckets.0: 129 us"),
            std::string::npos);
  flat["x.histogram.sub_buckets"] = "32";
  EXPECT_NE(histogram_from_flat(flat, "x.histogram", &back).find("sub_buckets"), std::string::npos);
}

TEST(LatencyHistogram, AReadBackRangeOutsideItsBucketsOrCountsThatOverflowAreRefused) {
  LatencyHistogram h;
  for (const double ms : {1.0, 5.0, 100.0}) h.record(ms);
  std::map<std::string, std::string> flat;
  ASSERT_EQ(flatten_json("{\"x\": {\"histogram\": " + histogram_json(h) + "}}", &flat), "");
  LatencyHistogram back;
  ASSERT_EQ(histogram_from_flat(flat, "x.histogram", &back), "");
  const auto refused = [&](const std::string& key, const std::string& value, const std::string& named) {
    auto changed = flat;
    changed["x.histogram." + key] = value;
    const std::string e = histogram_from_flat(changed, "x.histogram", &back);
    EXPECT_EQ(e.rfind(named, 0), 0u) << key << " = " << value << ": '" << e << "'";
  };
  // The smallest and largest values in the lowest and highest buckets, in order.
  refused("min_us", "0", "x.histogram.min_us: 0 is not in the lowest bucket");
  refused("min_us", "5000", "x.histogram.min_us: 5000 is not in the lowest bucket");
  refused("max_us", "5000", "x.histogram.max_us: 5000 is not in the highest bucket");
  refused("max_us", "99999999", "x.histogram.max_us: 99999999 is not in the highest bucket");
  auto narrow = flat;  // every count in one bucket of width 2 (128..129 us): max below min within it
  for (const char* b : {"0", "1", "2"}) narrow["x.histogram.buckets." + std::string(b) + ".0"] = "128";
  narrow["x.histogram.min_us"] = "129";
  narrow["x.histogram.max_us"] = "128";
  EXPECT_EQ(histogram_from_flat(narrow, "x.histogram", &back).rfind("x.histogram.max_us: 128", 0), 0u)
      << histogram_from_flat(narrow, "x.histogram", &back);
  // Counts whose total overflows.
  auto huge = flat;
  huge["x.histogram.buckets.0.1"] = huge["x.histogram.buckets.1.1"] = std::to_string(std::uint64_t{1} << 63);
  EXPECT_EQ(histogram_from_flat(huge, "x.histogram", &back),
            "x.histogram.buckets.1: a count of 9223372036854775808 overflows the total");
}

}  // namespace
}  // namespace terrane::bots
