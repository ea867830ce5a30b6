#include "server/tools/enhance_command.h"

#include <unistd.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
#include <utility>

#include "common/cli/cli.h"
#include "common/enhance/enhance.h"
#include "common/enhance/lighting.h"
#include "common/vxraw/vxraw.h"

namespace terrane {
namespace {

constexpr const char* kEnhanceHelp =
    "usage: terrane-world enhance --in FILE --out FILE --method subdivide|resample [options]\n"
    "\n"
    "Voxel detail enhancement (common/enhance/ENHANCE.md): every voxel of the input VXRAW box (plain or\n"
    "gzip) becomes factor^3 full-or-Air fragments in the output box, whose origin is the input\n"
    "origin times the factor. The output is gzip-compressed when its name ends in .gz.\n"
    "\n"
    "  --in FILE          input VXRAW file\n"
    "  --out FILE         output VXRAW file (written to a temporary name, then renamed)\n"
    "  --method M         subdivide: recursive 2x subdivision with the 128-configuration table\n"
    "                     resample:  direct resampling with a random probe pattern\n"
    "  --factor N         expansion per axis; subdivide: 2, 4, 8, 16, 32 or 64 (default 4);\n"
    "                     resample: 1..32 (default 16)\n"
    "  --threshold T      subdivide: activation threshold 1..4 (default 2), or LOW,EVEN,ODD@Y:\n"
    "                     LOW below coarse altitude Y, EVEN/ODD alternating by fragment y above\n"
    "                     (the paper's Figure 1: 1,3,4@Y)\n"
    "                     resample: solid when more than this fraction of the probes hit solid\n"
    "                     voxels, 0 <= T < 1 or a percentage like 25% (default 0.25)\n"
    "  --probes N         resample: probes in the pattern, 1..4096 (default 64)\n"
    "  --spread S         resample: probe offsets in [-S, S] coarse voxels, 0 < S <= 4 (default 1)\n"
    "  --seed N           seed of the probe pattern and of the lighting particles (default 1)\n"
    "  --light            also light the fragments by snowflake tracing and write OUT.light\n"
    "                     (format in common/enhance/ENHANCE.md)\n"
    "\n"
    "Exit status: 0 success, 1 a file could not be read or written, 2 bad usage.\n";

// Outputs beyond this many fragments are refused (3 bytes of working memory
// per fragment during subdivision: 768 MiB at the limit).
constexpr std::int64_t kMaxOutputVoxels = std::int64_t{1} << 28;

int usage_error(const std::string& message) {
  std::fprintf(stderr, "terrane-world enhance: %s\n\n%s", message.c_str(), kEnhanceHelp);
  return 2;
}

int failure(const std::string& message) {
  std::fprintf(stderr, "terrane-world enhance: %s\n", message.c_str());
  return 1;
}

bool ends_with(std::string_view s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}

// A progress line on stderr: redrawn in place on a terminal, a line every
// 10% otherwise, and nothing for jobs under two seconds.
class Progress {
 public:
  explicit Progress(std::string what)
      : what_(std::move(what)), tty_(isatty(2) != 0), start_(std::chrono::steady_clock::now()) {}
  void update(std::uint64_t done, std::uint64_t total) {
    const int pct = total ? static_cast<int>(done * 100 / total) : 100;
    const double t = elapsed();
    if (t < 2.0 && !shown_) return;
    shown_ = true;
    if (tty_) {
      const auto now = std::chrono::steady_clock::now();
      if (done != total && now - last_draw_ < std::chrono::milliseconds(100)) return;
      last_draw_ = now;
      std::fprintf(stderr, "\r%s: %3d%% %.1fs", what_.c_str(), pct, t);
      if (done == total) std::fputc('\n', stderr);
    } else if (pct / 10 != last_decile_) {
      last_decile_ = pct / 10;
      std::fprintf(stderr, "%s: %d%% %.1fs\n", what_.c_str(), pct, t);
    }
  }
  double elapsed() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }

 private:
  std::string what_;
  bool tty_;
  bool shown_ = false;
  int last_decile_ = -1;
  std::chrono::steady_clock::time_point start_, last_draw_{};
};

// "T" or "LOW,EVEN,ODD@Y".
bool parse_subdivision_threshold(std::string_view text, SubdivisionThreshold* out) {
  const auto parse_int = [](std::string_view s, int* v) {
    const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *v);
    return ec == std::errc() && p == s.data() + s.size();
  };
  const std::size_t at = text.find('@');
  if (at == std::string_view::npos) {
    int t = 0;
    if (!parse_int(text, &t)) return false;
    *out = SubdivisionThreshold::constant(t);
    return true;
  }
  int v[3];
  if (!parse_int_list(text.substr(0, at), v, 3)) return false;
  std::int32_t y = 0;
  if (!parse_int(text.substr(at + 1), &y)) return false;
  *out = {v[0], v[1], v[2], y};
  return true;
}

void paste(const Box& part, const Region& part_region, Box& dst, const Region& dst_region) {
  const Region r = intersect(part_region, dst_region);
  for (std::int32_t y = r.min.y; y < r.max.y; ++y)
    for (std::int32_t z = r.min.z; z < r.max.z; ++z) {
      const Voxel* s = part.read_row(y - part_region.min.y, z - part_region.min.z) + (r.min.x - part_region.min.x);
      std::copy(s, s + (r.max.x - r.min.x),
                dst.write_row(y - dst_region.min.y, z - dst_region.min.z) + (r.min.x - dst_region.min.x));
    }
}

void put_u32(std::string& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}

// The light sidecar (common/enhance/ENHANCE.md, "Light file"), written to a
// temporary name and renamed into place.
bool write_light_file(const std::string& path, const LightMap& map, std::string* error) {
  std::string header = "TLGT";
  put_u32(header, 1);
  const Vec3i s = map.region.size();
  for (const std::int32_t v : {s.x, s.y, s.z, map.region.min.x, map.region.min.y, map.region.min.z})
    put_u32(header, static_cast<std::uint32_t>(v));
  const std::string tmp = path + ".tmp";
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) {
    *error = "cannot create " + tmp;
    return false;
  }
  bool ok = std::fwrite(header.data(), 1, header.size(), f) == header.size() &&
            std::fwrite(map.light.data(), 1, map.light.size(), f) == map.light.size();
  ok = (std::fclose(f) == 0) && ok;
  if (!ok || std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    *error = "cannot write " + path;
    return false;
  }
  return true;
}

}  // namespace

int run_enhance_command(int argc, char** argv) {
  CommandLine cl({"in", "out", "method", "factor", "threshold", "probes", "spread", "seed"}, {"help", "light"});
  if (auto e = cl.parse(argc, argv, 2); !e.empty()) return usage_error(e);
  if (cl.flag("help")) return std::printf("%s", kEnhanceHelp), 0;
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'");
  for (const char* required : {"in", "out", "method"})
    if (!cl.has(required)) return usage_error(std::string("--") + required + " is required");
  const std::string method = cl.get("method");
  const bool subdividing = method == "subdivide";
  if (!subdividing && method != "resample")
    return usage_error("--method must be subdivide or resample, not '" + method + "'");
  if (subdividing) {
    for (const char* only : {"probes", "spread"})
      if (cl.has(only)) return usage_error(std::string("--") + only + " applies to --method resample only");
  }

  std::string err;
  const auto seed = cl.get_int("seed", 1, 0, INT64_MAX, &err);
  if (!err.empty()) return usage_error(err);
  SubdivisionParams sub;
  ResampleParams res;
  int factor = 0;
  if (subdividing) {
    factor = static_cast<int>(cl.get_int("factor", 4, 2, 64, &err));
    if (!err.empty()) return usage_error(err);
    if ((factor & (factor - 1)) != 0)
      return usage_error("--factor " + cl.get("factor") + ": subdivide needs a power of two (2, 4, ..., 64)");
    sub.levels = std::countr_zero(static_cast<unsigned>(factor));
    if (cl.has("threshold") && !parse_subdivision_threshold(cl.get("threshold"), &sub.threshold))
      return usage_error("--threshold '" + cl.get("threshold") + "': expected T or LOW,EVEN,ODD@Y");
    if (const std::string v = validate(sub); !v.empty())
      return usage_error("--threshold '" + cl.get("threshold") + "': each value must be in [1, 4]");
  } else {
    res.factor = static_cast<int>(cl.get_int("factor", 16, 1, 32, &err));
    res.probes = static_cast<int>(cl.get_int("probes", 64, 1, 4096, &err));
    res.spread = static_cast<float>(cl.get_double("spread", 1.0, 0.0, 4.0, &err));
    if (!err.empty()) return usage_error(err);
    if (!(res.spread > 0.0f)) return usage_error("--spread " + cl.get("spread") + ": must be greater than 0");
    if (cl.has("threshold")) {
      std::string t = cl.get("threshold");
      const bool percent = ends_with(t, "%");
      if (percent) t.pop_back();
      double v = 0;
      const auto [p, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
      if (ec != std::errc() || p != t.data() + t.size() || t.empty())
        return usage_error("--threshold '" + cl.get("threshold") + "': expected a fraction like 0.25 or 25%");
      if (percent) v /= 100.0;
      if (!(v >= 0.0 && v < 1.0))
        return usage_error("--threshold '" + cl.get("threshold") + "': must be at least 0 and below 1 (100%)");
      res.threshold = static_cast<float>(v);
    }
    res.seed = static_cast<std::uint64_t>(seed);
    factor = res.factor;
  }

  const std::string in = cl.get("in"), out = cl.get("out");
  auto file = vxraw_read_file(in, VxrawLimits{});
  if (!file) return failure(file.error().message);
  const Box& coarse = file->box;
  const Vec3i origin = file->origin;
  if (coarse.empty()) return failure(in + ": the box is empty");

  // Output size and coordinates must fit.
  const Vec3i cs = coarse.size();
  const std::int64_t volume = std::int64_t{cs.x} * cs.y * cs.z * factor * factor * factor;
  if (volume > kMaxOutputVoxels)
    return usage_error("--factor " + std::to_string(factor) + ": the output would have " + std::to_string(volume) +
                       " voxels, more than the limit of " + std::to_string(kMaxOutputVoxels));
  for (const std::int64_t c :
       {std::int64_t{origin.x}, std::int64_t{origin.y}, std::int64_t{origin.z}, std::int64_t{origin.x} + cs.x,
        std::int64_t{origin.y} + cs.y, std::int64_t{origin.z} + cs.z}) {
    if (c * factor > INT32_MAX || c * factor < INT32_MIN)
      return failure(in + ": origin times --factor " + std::to_string(factor) + " is outside 32-bit coordinates");
  }

  // Enhance in slabs of coarse layers so progress can be reported; every
  // fragment depends only on the coarse map, so slabs join seamlessly.
  const Region fine_region = fine_region_of(coarse, origin, factor);
  Box fine(fine_region.size());
  EnhanceStats stats;
  Resampler resampler(subdividing ? ResampleParams{} : res);
  Progress progress("enhance");
  constexpr int kSlabLayers = 4;
  Box part;
  for (int y0 = 0; y0 < cs.y; y0 += kSlabLayers) {
    const int y1 = std::min(cs.y, y0 + kSlabLayers);
    Region slab = fine_region;
    slab.min.y = (origin.y + y0) * factor;
    slab.max.y = (origin.y + y1) * factor;
    if (subdividing)
      subdivide_region(coarse, origin, sub, slab, part, &stats);
    else
      resampler.resample_region(coarse, origin, slab, part, &stats);
    paste(part, slab, fine, fine_region);
    progress.update(static_cast<std::uint64_t>(y1), static_cast<std::uint64_t>(cs.y));
  }
  const double enhance_s = progress.elapsed();

  if (auto s = vxraw_write_file(out, fine, fine_region.min, ends_with(out, ".gz")); !s)
    return failure(s.error().message);
  const std::uint64_t fragments = fine.voxel_count();
  std::printf("wrote %s: %dx%dx%d fragments at (%d,%d,%d), %llu solid (%.1f%%; input %.1f%%)\n", out.c_str(),
              fine_region.size().x, fine_region.size().y, fine_region.size().z, fine_region.min.x, fine_region.min.y,
              fine_region.min.z, static_cast<unsigned long long>(stats.solid_fragments),
              100.0 * static_cast<double>(stats.solid_fragments) / static_cast<double>(fragments),
              100.0 * static_cast<double>(count_solid(coarse)) / static_cast<double>(coarse.voxel_count()));
  std::printf("%s x%d: %llu source voxels evaluated, %llu skipped (uniform), %.2f s, %.1f M fragments/s\n",
              method.c_str(), factor, static_cast<unsigned long long>(stats.voxels_evaluated),
              static_cast<unsigned long long>(stats.voxels_skipped), enhance_s,
              static_cast<double>(fragments) / std::max(enhance_s, 1e-9) / 1e6);

  if (cl.flag("light")) {
    LightingParams lp;
    lp.seed = static_cast<std::uint64_t>(seed);
    Progress light_progress("light");
    const LightMap map = compute_lighting(fine, fine_region.min, lp,
                                          [&](std::uint64_t d, std::uint64_t t) { light_progress.update(d, t); });
    std::uint64_t lit = 0, sum = 0;
    for (const std::uint8_t v : map.light) {
      lit += v != 0;
      sum += v;
    }
    const std::string light_path = out + ".light";
    if (!write_light_file(light_path, map, &err)) return failure(err);
    std::printf("wrote %s: %llu lit fragments, mean light %.1f/255, %.2f s\n", light_path.c_str(),
                static_cast<unsigned long long>(lit), lit ? static_cast<double>(sum) / static_cast<double>(lit) : 0.0,
                light_progress.elapsed());
  }
  return 0;
}

}  // namespace terrane
