// A latency distribution kept as log-linear buckets (the layout of
// HdrHistogram): values are counted in whole microseconds; below 128 us each
// value has a bucket of its own, and each power of two above is cut into 64
// equal buckets. A bucket's width is at most 1/64 of its lowest value, so
// the value a bucket stands for (its middle, held within the smallest and
// largest values recorded) is within kRelativePrecision (1/128, under 1 %)
// of every value in it, and a percentile read from the buckets is within
// that of the exact sample at the same rank (after rounding to 1 us).
//
// Histograms of the same layout merge by adding counts: merging parts in
// any order and grouping gives the same histogram, which is what lets the
// reports of several processes be combined (averaging their percentiles
// would be wrong). Memory is bounded whatever the samples: at most
// kBucketCount buckets, and only those that counted something are held.
//
// Thread-safety: a value type; callers guard shared ones.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace terrane::bots {

class LatencyHistogram {
 public:
  // 64 buckets per power of two: a bucket's width over its lowest value
  // is at most 1/64; its middle is within half of that of any value in it.
  static constexpr int kSubBucketBits = 6;
  static constexpr double kRelativePrecision = 1.0 / 128;
  // Values above are counted as this (about 12.7 days): no latency we
  // measure comes near, and it bounds the bucket count.
  static constexpr std::uint64_t kMaxMicros = (std::uint64_t{1} << 40) - 1;
  static constexpr std::uint32_t kBucketCount = 2240;  // index_of(kMaxMicros) + 1

  // Counts one value in milliseconds (rounded to 1 us; a negative one as 0,
  // NaN not at all).
  void record(double ms);
  // Adds every count of other to this.
  void merge(const LatencyHistogram& other);

  std::uint64_t count() const { return count_; }
  bool empty() const { return count_ == 0; }
  // Nearest rank (the ceil(p * count)-th smallest value, at least the
  // first) for p in [0, 1], in ms; 0 when empty. The first and last ranks
  // are exact (the smallest and largest value recorded).
  double percentile(double p) const;
  double min_ms() const { return empty() ? 0 : static_cast<double>(min_us_) / 1000; }
  double max_ms() const { return static_cast<double>(max_us_) / 1000; }
  std::uint64_t min_micros() const { return empty() ? 0 : min_us_; }
  std::uint64_t max_micros() const { return max_us_; }

  // The buckets that counted something, ascending: (the lowest value of
  // the bucket in us, count). The form the JSON report writes.
  std::vector<std::pair<std::uint64_t, std::uint64_t>> buckets() const;
  // Reading a histogram back: adds count to the bucket whose lowest value
  // is lowest_us, and widens the recorded range to [min_us, max_us] with
  // set_range. Returns false (nothing added) when lowest_us is not the
  // lowest value of a bucket or the count would overflow.
  bool add_bucket(std::uint64_t lowest_us, std::uint64_t count);
  void set_range(std::uint64_t min_us, std::uint64_t max_us);

  // Bucket layout, exposed for the tests.
  static std::uint32_t index_of(std::uint64_t us);
  static std::uint64_t lowest_of(std::uint32_t index);
  static std::uint64_t width_of(std::uint32_t index);

  friend bool operator==(const LatencyHistogram& a, const LatencyHistogram& b) {
    return a.counts_ == b.counts_ && a.count_ == b.count_ && a.min_micros() == b.min_micros() &&
           a.max_us_ == b.max_us_;
  }

 private:
  std::map<std::uint32_t, std::uint64_t> counts_;  // bucket index -> count, no zero counts
  std::uint64_t count_ = 0;
  std::uint64_t min_us_ = ~std::uint64_t{0}, max_us_ = 0;
};

// The histogram as a JSON object: {"unit": "us", "sub_buckets": 64,
// "relative_precision": ..., "min_us": ..., "max_us": ..., "buckets":
// [[lowest_us, count], ...]}.
std::string histogram_json(const LatencyHistogram& h);

// Reads back what histogram_json wrote, from a report flattened by
// flatten_json (report.h) under prefix (e.g. "edit_fanout_ms.histogram").
// A file is input: each bucket must be one of the layout's, the counts
// must not overflow, and min_us and max_us must lie in the lowest and
// highest buckets counted. Returns "" or what is wrong, naming the key.
std::string histogram_from_flat(const std::map<std::string, std::string>& flat, const std::string& prefix,
                                LatencyHistogram* out);

}  // namespace terrane::bots
