#include "client/bots/histogram.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <limits>
#include <sstream>

namespace terrane::bots {

namespace {

constexpr std::uint64_t kSubBuckets = std::uint64_t{1} << LatencyHistogram::kSubBucketBits;  // 64
// Below this every microsecond has a bucket of its own.
constexpr std::uint64_t kLinearTop = 2 * kSubBuckets;  // 128

constexpr std::uint32_t kSubBucketCount = 1u << LatencyHistogram::kSubBucketBits;  // as an index

}  // namespace

// Index layout: [0, 128) one value each; then for each power of two 2^m
// (m >= 7) the 64 buckets of width 2^(m-6) that cover [2^m, 2^(m+1)), at
// 64 * (m - 6) + (v >> (m - 6)), whose second term runs over [64, 128).
std::uint32_t LatencyHistogram::index_of(std::uint64_t us) {
  us = std::min(us, kMaxMicros);
  if (us < kLinearTop) return static_cast<std::uint32_t>(us);
  const int m = static_cast<int>(std::bit_width(us)) - 1;
  const int shift = m - kSubBucketBits;
  return static_cast<std::uint32_t>(kSubBuckets * static_cast<std::uint64_t>(shift) + (us >> shift));
}

std::uint64_t LatencyHistogram::lowest_of(std::uint32_t index) {
  if (index < kLinearTop) return index;
  const std::uint32_t shift = index / kSubBucketCount - 1;
  return (std::uint64_t{index % kSubBucketCount} + kSubBuckets) << shift;
}

std::uint64_t LatencyHistogram::width_of(std::uint32_t index) {
  return index < kLinearTop ? 1 : std::uint64_t{1} << (index / kSubBucketCount - 1);
}

static_assert(LatencyHistogram::kBucketCount == 64 * (39 - 6) + 127 + 1, "index_of(kMaxMicros) + 1");

void LatencyHistogram::record(double ms) {
  if (std::isnan(ms)) return;
  const double us = std::clamp(ms * 1000.0, 0.0, static_cast<double>(kMaxMicros));
  const auto v = static_cast<std::uint64_t>(std::llround(us));
  ++counts_[index_of(v)];
  ++count_;
  min_us_ = std::min(min_us_, v);
  max_us_ = std::max(max_us_, v);
}

void LatencyHistogram::merge(const LatencyHistogram& other) {
  for (const auto& [index, n] : other.counts_) counts_[index] += n;
  count_ += other.count_;
  min_us_ = std::min(min_us_, other.min_us_);
  max_us_ = std::max(max_us_, other.max_us_);
}

double LatencyHistogram::percentile(double p) const {
  if (count_ == 0) return 0;
  const double want = std::ceil(std::clamp(p, 0.0, 1.0) * static_cast<double>(count_));
  const std::uint64_t rank = std::clamp<std::uint64_t>(static_cast<std::uint64_t>(want), 1, count_);
  // The smallest and largest are known exactly.
  if (rank == 1) return min_ms();
  if (rank == count_) return max_ms();
  std::uint64_t seen = 0;
  for (const auto& [index, n] : counts_) {
    seen += n;
    if (seen < rank) continue;
    // The bucket's middle, within what was recorded: a bucket holding the
    // smallest or largest value does not stand for more than was seen.
    const std::uint64_t mid = lowest_of(index) + width_of(index) / 2;
    return static_cast<double>(std::clamp(mid, min_us_, max_us_)) / 1000;
  }
  return max_ms();
}

std::vector<std::pair<std::uint64_t, std::uint64_t>> LatencyHistogram::buckets() const {
  std::vector<std::pair<std::uint64_t, std::uint64_t>> out;
  out.reserve(counts_.size());
  for (const auto& [index, n] : counts_) out.emplace_back(lowest_of(index), n);
  return out;
}

bool LatencyHistogram::add_bucket(std::uint64_t lowest_us, std::uint64_t count) {
  if (lowest_us > kMaxMicros) return false;
  const std::uint32_t index = index_of(lowest_us);
  if (lowest_of(index) != lowest_us) return false;
  if (count == 0) return true;
  if (count > std::numeric_limits<std::uint64_t>::max() - count_) return false;
  counts_[index] += count;
  count_ += count;
  return true;
}

void LatencyHistogram::set_range(std::uint64_t min_us, std::uint64_t max_us) {
  min_us_ = std::min(min_us_, std::min(min_us, kMaxMicros));
  max_us_ = std::max(max_us_, std::min(max_us, kMaxMicros));
}

std::string histogram_json(const LatencyHistogram& h) {
  std::ostringstream j;
  j << "{\"unit\": \"us\", \"sub_buckets\": " << kSubBuckets
    << ", \"relative_precision\": " << LatencyHistogram::kRelativePrecision << ", \"min_us\": " << h.min_micros()
    << ", \"max_us\": " << h.max_micros() << ", \"buckets\": [";
  bool first = true;
  for (const auto& [lowest, n] : h.buckets()) {
    j << (first ? "" : ", ") << "[" << lowest << ", " << n << "]";
    first = false;
  }
  j << "]}";
  return j.str();
}

namespace {

bool parse_u64(const std::string& s, std::uint64_t* v) {
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *v);
  return ec == std::errc() && p == s.data() + s.size();
}

}  // namespace

std::string histogram_from_flat(const std::map<std::string, std::string>& flat, const std::string& prefix,
                                LatencyHistogram* out) {
  *out = LatencyHistogram{};
  auto field = [&](const std::string& key, std::uint64_t* v) -> std::string {
    const auto it = flat.find(prefix + "." + key);
    if (it == flat.end()) return prefix + "." + key + ": missing";
    if (!parse_u64(it->second, v)) return prefix + "." + key + ": '" + it->second + "' is not a whole number";
    return "";
  };
  std::uint64_t sub = 0, min_us = 0, max_us = 0;
  if (auto e = field("sub_buckets", &sub); !e.empty()) return e;
  if (sub != kSubBuckets)
    return prefix + ".sub_buckets: " + std::to_string(sub) + ", this program reads " + std::to_string(kSubBuckets);
  if (auto e = field("min_us", &min_us); !e.empty()) return e;
  if (auto e = field("max_us", &max_us); !e.empty()) return e;
  for (std::size_t i = 0;; ++i) {
    const std::string b = "buckets." + std::to_string(i);
    if (flat.count(prefix + "." + b + ".0") == 0) break;
    if (i >= LatencyHistogram::kBucketCount) return prefix + ".buckets: more than " + std::to_string(i) + " buckets";
    std::uint64_t lowest = 0, n = 0;
    if (auto e = field(b + ".0", &lowest); !e.empty()) return e;
    if (auto e = field(b + ".1", &n); !e.empty()) return e;
    if (lowest > LatencyHistogram::kMaxMicros ||
        LatencyHistogram::lowest_of(LatencyHistogram::index_of(lowest)) != lowest)
      return prefix + "." + b + ": " + std::to_string(lowest) + " us is not the lowest value of a bucket";
    if (!out->add_bucket(lowest, n)) return prefix + "." + b + ": a count of " + std::to_string(n) + " overflows the total";
  }
  if (out->empty()) return "";
  // The smallest and largest values recorded lie in the lowest and highest
  // buckets counted (percentile() reads them as the range of every bucket).
  const auto counted = out->buckets();
  const auto in_bucket = [](std::uint64_t us, std::uint64_t lowest) {
    return LatencyHistogram::index_of(us) == LatencyHistogram::index_of(lowest);
  };
  if (!in_bucket(min_us, counted.front().first))
    return prefix + ".min_us: " + std::to_string(min_us) + " is not in the lowest bucket counted (from " +
           std::to_string(counted.front().first) + " us)";
  if (!in_bucket(max_us, counted.back().first) || max_us < min_us)
    return prefix + ".max_us: " + std::to_string(max_us) + " is not in the highest bucket counted (from " +
           std::to_string(counted.back().first) + " us) at or above min_us";
  out->set_range(min_us, max_us);
  return "";
}

}  // namespace terrane::bots
