#include "server/storage/notices.h"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <limits>

namespace terrane {

namespace {

constexpr char kBase64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

std::string base64(std::span<const std::uint8_t> bytes) {
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const std::size_t n = std::min<std::size_t>(3, bytes.size() - i);
    std::uint32_t v = static_cast<std::uint32_t>(bytes[i]) << 16;
    if (n > 1) v |= static_cast<std::uint32_t>(bytes[i + 1]) << 8;
    if (n > 2) v |= bytes[i + 2];
    for (std::size_t k = 0; k < 4; ++k) out += k <= n ? kBase64[(v >> (18 - 6 * k)) & 63] : '=';
  }
  return out;
}

// nullopt unless text is padded base64 of at least one byte.
std::optional<std::vector<std::uint8_t>> from_base64(std::string_view text) {
  if (text.empty() || text.size() % 4 != 0) return std::nullopt;
  std::vector<std::uint8_t> out;
  out.reserve(text.size() / 4 * 3);
  for (std::size_t i = 0; i < text.size(); i += 4) {
    const bool last = i + 4 == text.size();
    std::uint32_t v = 0;
    int pad = 0;
    for (std::size_t k = 0; k < 4; ++k) {
      const char c = text[i + k];
      int d = -1;
      if (c >= 'A' && c <= 'Z') d = c - 'A';
      else if (c >= 'a' && c <= 'z') d = c - 'a' + 26;
      else if (c >= '0' && c <= '9') d = c - '0' + 52;
      else if (c == '+') d = 62;
      else if (c == '/') d = 63;
      else if (c == '=' && last && k >= 2) d = 0, ++pad;
      if (d < 0 || (pad > 0 && c != '=')) return std::nullopt;
      v = (v << 6) | static_cast<std::uint32_t>(d);
    }
    out.push_back(static_cast<std::uint8_t>(v >> 16));
    if (pad < 2) out.push_back(static_cast<std::uint8_t>(v >> 8));
    if (pad < 1) out.push_back(static_cast<std::uint8_t>(v));
  }
  return out;
}

}  // namespace

std::vector<std::string> change_notices(std::span<const ChunkWrite> chunks, std::span<const RegionSeq> regions) {
  std::vector<std::string> out;
  std::string payload;
  auto add = [&](const std::string& entry) {
    if (!payload.empty() && payload.size() + 1 + entry.size() > kMaxChangeNoticeBytes) {
      out.push_back(std::move(payload));
      payload.clear();
    }
    if (!payload.empty()) payload += ' ';
    payload += entry;
  };
  for (const RegionSeq& r : regions) add(fmt::format("r,{},{},{},{}", r.region.x, r.region.y, r.region.z, r.seq));
  for (const ChunkWrite& w : chunks) {
    std::string entry = fmt::format("{},{},{},{}", w.pos.x, w.pos.y, w.pos.z, w.revision);
    if (!w.units.empty() && (w.units.size() + 2) / 3 * 4 <= kMaxNoticeUnitsBytes)
      entry += fmt::format(",{},{}", w.tick, base64(w.units));
    add(entry);
  }
  if (!payload.empty()) out.push_back(std::move(payload));
  return out;
}

std::optional<ChangeNotice> parse_change_notice(std::string_view payload) {
  ChangeNotice out;
  while (!payload.empty()) {
    const std::size_t end = std::min(payload.find(' '), payload.size());
    std::string_view entry = payload.substr(0, end);
    payload.remove_prefix(std::min(end + 1, payload.size()));
    const bool region = entry.substr(0, 2) == "r,";
    if (region) entry.remove_prefix(2);
    // x, y, z, revision (or seq); a chunk's may be followed by a tick and
    // its units.
    const bool with_units = !region && std::count(entry.begin(), entry.end(), ',') >= 5;
    const int numbers = with_units ? 5 : 4;
    std::int64_t v[5] = {};
    for (int i = 0; i < numbers; ++i) {
      const std::size_t comma = i < numbers - 1 || with_units ? entry.find(',') : entry.size();
      if (comma == std::string_view::npos) return std::nullopt;
      const auto [at, ec] = std::from_chars(entry.data(), entry.data() + comma, v[i]);
      if (ec != std::errc{} || at != entry.data() + comma) return std::nullopt;
      entry.remove_prefix(std::min(comma + 1, entry.size()));
    }
    if (v[4] < 0) return std::nullopt;
    std::vector<std::uint8_t> units;
    if (with_units) {
      // Units that do not read leave the chunk to be read again, like a
      // notice without them; the rest of the notice stands.
      auto read = entry.size() <= kMaxNoticeUnitsBytes ? from_base64(entry) : std::nullopt;
      if (read)
        units = std::move(*read);
      else
        ++out.units_unread;
    }
    const auto fits = [](std::int64_t c) { return c >= std::numeric_limits<std::int32_t>::min() &&
                                                  c <= std::numeric_limits<std::int32_t>::max(); };
    if (!fits(v[0]) || !fits(v[1]) || !fits(v[2]) || v[3] < 0) return std::nullopt;
    const Vec3i p{static_cast<std::int32_t>(v[0]), static_cast<std::int32_t>(v[1]), static_cast<std::int32_t>(v[2])};
    if (region)
      out.regions.push_back(RegionSeq{p, static_cast<std::uint64_t>(v[3])});
    else
      out.chunks.push_back(ChunkChange{p, static_cast<std::uint64_t>(v[3]), std::move(units),
                                       static_cast<std::uint64_t>(v[4])});
  }
  return out;
}

std::string answer_notice(const ForwardAnswer& a) {
  std::string reason = a.reason.substr(0, 256);
  return fmt::format("{} {} {} {} {}", a.from, a.id, a.accepted ? 1 : 0, a.tick, reason);
}

std::optional<ForwardAnswer> parse_answer_notice(std::string_view payload) {
  ForwardAnswer a;
  std::int64_t v[4];
  for (int i = 0; i < 4; ++i) {
    const std::size_t end = std::min(payload.find(' '), payload.size());
    const auto [at, ec] = std::from_chars(payload.data(), payload.data() + end, v[i]);
    if (ec != std::errc{} || at != payload.data() + end) return std::nullopt;
    payload.remove_prefix(std::min(end + 1, payload.size()));
  }
  if (v[0] < 0 || v[0] > std::numeric_limits<std::int32_t>::max() || v[1] < 1 || (v[2] != 0 && v[2] != 1) || v[3] < 0)
    return std::nullopt;
  a.from = static_cast<std::uint32_t>(v[0]);
  a.id = v[1];
  a.accepted = v[2] == 1;
  a.tick = static_cast<std::uint64_t>(v[3]);
  a.reason = std::string(payload);
  return a;
}

}  // namespace terrane
