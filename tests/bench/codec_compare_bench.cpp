// Side-by-side comparison of the voxel unit codecs on the same 16^3 units:
// byte RLE, byte RLE + LZ4, byte RLE + zstd-3, a Minecraft-style paletted
// section + zlib-6, and Terrane's network codec (common/codec/net_codec.h) in
// format versions 1 and 2; plus
// 4^3 update batches for random small sphere edits.
//
// Prints tables (sizes are exact, timings are wall clock on this machine).
//   terrane-bench-codec-compare [--quick] [--world-sample K]
// --quick times 4 rounds instead of 15 (each codec keeps its best round); --world-sample K uses K x K columns of
// 16^3 units of the generated world around the origin (default: the whole
// default world box, 32 x 32 columns).
#include <zlib.h>

#include "tests/bench/paletted_section.h"
#include <zstd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "common/codec/byte_rle.h"
#include "common/codec/lz4_block.h"
#include "common/codec/net_codec.h"
#include "common/codec/update_batch.h"
#include "common/voxel/box.h"
#include "common/vxraw/vxraw.h"
#include "common/world/terrain_generator.h"

using namespace terrane;

namespace {

constexpr int kN = 16;
constexpr int kVolume = kN * kN * kN;

struct Dataset {
  std::string name;
  Box box;
  Vec3i origin;
  std::vector<std::vector<Voxel>> units;  // every complete 16^3 unit
  std::vector<bool> uniform;
};

void cut_units(Dataset& d) {
  const Vec3i s = d.box.size();
  for (int uy = 0; uy + kN <= s.y; uy += kN) {
    for (int uz = 0; uz + kN <= s.z; uz += kN) {
      for (int ux = 0; ux + kN <= s.x; ux += kN) {
        std::vector<Voxel> u(kVolume);
        for (int y = 0; y < kN; ++y) {
          for (int z = 0; z < kN; ++z) {
            std::memcpy(&u[static_cast<std::size_t>((y * kN + z) * kN)], d.box.read_row(uy + y, uz + z) + ux,
                        kN * sizeof(Voxel));
          }
        }
        bool uni = std::all_of(u.begin(), u.end(), [&](Voxel v) { return v == u[0]; });
        d.units.push_back(std::move(u));
        d.uniform.push_back(uni);
      }
    }
  }
}

// ---------------------------------------------------------------------------
// Codecs under test. Each encodes one unit (appending to out) and decodes one
// unit from exactly its bytes.

struct Codec {
  std::string name;
  std::function<void(std::span<const Voxel>, std::vector<std::uint8_t>&)> encode;
  std::function<bool(std::span<const std::uint8_t>, std::span<Voxel>)> decode;
};

std::vector<std::uint8_t> g_scratch;
ZSTD_CCtx* g_zc = nullptr;
ZSTD_DCtx* g_zd = nullptr;
z_stream g_deflate{};
z_stream g_inflate{};

void zstd_encode(std::span<const Voxel> v, std::vector<std::uint8_t>& out) {
  g_scratch.clear();
  byte_rle_encode(v, g_scratch);
  const std::size_t start = out.size();
  out.resize(start + ZSTD_compressBound(g_scratch.size()));
  const std::size_t n = ZSTD_compressCCtx(g_zc, out.data() + start, out.size() - start, g_scratch.data(),
                                          g_scratch.size(), 3);
  out.resize(start + n);
}
bool zstd_decode(std::span<const std::uint8_t> in, std::span<Voxel> out) {
  g_scratch.resize(byte_rle_max_encoded_size(out.size()));
  const std::size_t n = ZSTD_decompressDCtx(g_zd, g_scratch.data(), g_scratch.size(), in.data(), in.size());
  if (ZSTD_isError(n)) return false;
  return byte_rle_decode(std::span<const std::uint8_t>(g_scratch.data(), n), out).ok();
}

// Minecraft-style paletted section (tests/bench/paletted_section.h), then
// zlib level 6 over the whole section.
void palette_encode(std::span<const Voxel> v, std::vector<std::uint8_t>& out) {
  paletted_section(v, g_scratch);
  const std::size_t start = out.size();
  out.resize(start + compressBound(static_cast<uLong>(g_scratch.size())));
  deflateReset(&g_deflate);
  g_deflate.next_in = g_scratch.data();
  g_deflate.avail_in = static_cast<uInt>(g_scratch.size());
  g_deflate.next_out = out.data() + start;
  g_deflate.avail_out = static_cast<uInt>(out.size() - start);
  deflate(&g_deflate, Z_FINISH);
  out.resize(out.size() - g_deflate.avail_out);
}
bool palette_decode(std::span<const std::uint8_t> in, std::span<Voxel> out) {
  g_scratch.resize(2 + 2 * 4096 + 8 * 4096);
  inflateReset(&g_inflate);
  g_inflate.next_in = const_cast<Bytef*>(in.data());  // NOLINT: zlib's API is not const
  g_inflate.avail_in = static_cast<uInt>(in.size());
  g_inflate.next_out = g_scratch.data();
  g_inflate.avail_out = static_cast<uInt>(g_scratch.size());
  if (inflate(&g_inflate, Z_FINISH) != Z_STREAM_END) return false;
  const std::size_t n = g_scratch.size() - g_inflate.avail_out;
  if (n < 2) return false;
  const std::size_t count = g_scratch[0] | (std::size_t{g_scratch[1]} << 8);
  if (count == 0 || n < 2 + 2 * count) return false;
  std::array<Voxel, 4096> pal;  // NOLINT
  for (std::size_t p = 0; p < count && p < pal.size(); ++p) pal[p] = Voxel{g_scratch[2 + 2 * p], g_scratch[3 + 2 * p]};
  if (count == 1) {
    std::fill(out.begin(), out.end(), pal[0]);
    return true;
  }
  int bits = 4;
  while ((std::size_t{1} << bits) < count) ++bits;
  const int per_word = 64 / bits;
  const std::uint8_t* words = g_scratch.data() + 2 + 2 * count;
  const std::size_t word_count = (out.size() + static_cast<std::size_t>(per_word) - 1) / static_cast<std::size_t>(per_word);
  if (n < 2 + 2 * count + 8 * word_count) return false;
  const std::uint64_t mask = (std::uint64_t{1} << bits) - 1;
  std::size_t i = 0;
  for (std::size_t wi = 0; wi < word_count; ++wi) {
    std::uint64_t w;
    std::memcpy(&w, words + 8 * wi, 8);
    for (int k = 0; k < per_word && i < out.size(); ++k, ++i) {
      const std::size_t p = (w >> (k * bits)) & mask;
      if (p >= count) return false;
      out[i] = pal[p];
    }
  }
  return true;
}

std::vector<Codec> make_codecs() {
  std::vector<Codec> c;
  c.push_back({"byte RLE", [](auto v, auto& o) { byte_rle_encode(v, o); },
               [](auto in, auto out) { return byte_rle_decode(in, out).ok(); }});
  c.push_back({"byte RLE + LZ4", [](auto v, auto& o) { byte_rle_lz4_encode(v, o, g_scratch); },
               [](auto in, auto out) { return byte_rle_lz4_decode(in, out, g_scratch).ok(); }});
  c.push_back({"byte RLE + zstd-3", zstd_encode, zstd_decode});
  c.push_back({"palette + zlib-6", palette_encode, palette_decode});
  c.push_back({"Terrane net codec", [](auto v, auto& o) { net_codec_encode(kN, v, o, kNetCodecVersion1); },
               [](auto in, auto out) { return net_codec_decode(kN, in, out).ok(); }});
  c.push_back({"Terrane net codec 2", [](auto v, auto& o) { net_codec_encode(kN, v, o, kNetCodecVersion2); },
               [](auto in, auto out) { return net_codec_decode(kN, in, out).ok(); }});
  return c;
}

// ---------------------------------------------------------------------------

struct Row {
  double all_bpv = 0, nonuni_bpv = 0, enc_mbs = 0, dec_mbs = 0;
};

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

Row measure(const Codec& c, const Dataset& d) {
  Row row;
  std::vector<std::vector<std::uint8_t>> enc(d.units.size());
  std::size_t all = 0, nonuni = 0, nonuni_units = 0;
  std::vector<Voxel> back(kVolume);
  for (std::size_t u = 0; u < d.units.size(); ++u) {
    c.encode(d.units[u], enc[u]);
    all += enc[u].size();
    if (!d.uniform[u]) nonuni += enc[u].size(), ++nonuni_units;
    if (!c.decode(enc[u], back) || back != d.units[u]) {
      std::printf("ROUND TRIP FAILED: %s unit %zu\n", c.name.c_str(), u);
      std::exit(1);
    }
  }
  row.all_bpv = static_cast<double>(all) / (static_cast<double>(d.units.size()) * kVolume);
  row.nonuni_bpv = nonuni_units ? static_cast<double>(nonuni) / (static_cast<double>(nonuni_units) * kVolume) : 0;
  return row;
}

// Timing on non-uniform units only: rounds interleave the codecs so that
// load from other processes hits them alike, and each codec keeps its best
// round (the least disturbed).
void time_codecs(const std::vector<Codec>& codecs, const Dataset& d, int rounds, std::vector<Row>& rows) {
  std::vector<std::size_t> ids;
  for (std::size_t u = 0; u < d.units.size(); ++u) {
    if (!d.uniform[u]) ids.push_back(u);
  }
  if (ids.empty()) return;
  const double mb = static_cast<double>(ids.size()) * kVolume * 2 / 1e6;
  std::vector<std::vector<std::vector<std::uint8_t>>> enc(codecs.size());
  for (std::size_t c = 0; c < codecs.size(); ++c) {
    for (std::size_t u : ids) {
      enc[c].emplace_back();
      codecs[c].encode(d.units[u], enc[c].back());
    }
  }
  std::vector<std::uint8_t> out;
  out.reserve(1 << 16);
  std::vector<Voxel> back(kVolume);
  for (int round = 0; round < rounds; ++round) {
    for (std::size_t c = 0; c < codecs.size(); ++c) {
      double t0 = now_s();
      for (std::size_t u : ids) {
        out.clear();
        codecs[c].encode(d.units[u], out);
      }
      double t1 = now_s();
      rows[c].enc_mbs = std::max(rows[c].enc_mbs, mb / (t1 - t0));
      t0 = now_s();
      for (const auto& e : enc[c]) {
        if (!codecs[c].decode(e, back)) std::exit(2);
      }
      t1 = now_s();
      rows[c].dec_mbs = std::max(rows[c].dec_mbs, mb / (t1 - t0));
    }
  }
}

// ---------------------------------------------------------------------------
// 4^3 update batches from random small sphere edits.

struct UpdateFigures {
  double net_p50 = 0, net_p99 = 0, rle_p50 = 0, rle_p99 = 0, net_mean = 0, rle_mean = 0;
  double net2_p50 = 0, net2_p99 = 0, net2_mean = 0;  // format version 2
  std::size_t edits = 0, units = 0;
};

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const auto k = static_cast<std::size_t>(std::min<double>(static_cast<double>(v.size() - 1), std::floor(p * static_cast<double>(v.size()))));
  return v[k];
}

UpdateFigures measure_updates(const Dataset& d, int edits, std::uint32_t seed) {
  std::mt19937 rng(seed);
  const Vec3i s = d.box.size();
  std::vector<Material> mats;
  for (Voxel v : d.box.voxels()) {
    if (v.material != kAir && std::find(mats.begin(), mats.end(), v.material) == mats.end()) mats.push_back(v.material);
  }
  UpdateFigures f;
  std::vector<double> net_sizes, net2_sizes, rle_sizes;
  std::vector<std::uint8_t> bytes;
  for (int e = 0; e < edits; ++e) {
    // Centre: a random column's surface (highest non-Air voxel).
    const int cx = static_cast<int>(rng() % static_cast<unsigned>(s.x));
    const int cz = static_cast<int>(rng() % static_cast<unsigned>(s.z));
    int cy = s.y - 1;
    while (cy > 0 && d.box.get(cx, cy, cz).material == kAir) --cy;
    const float radius = 1.5f + static_cast<float>(rng() % 1000) / 1000.0f * 2.5f;  // 1.5 .. 4 voxels
    const bool dig = rng() % 2 == 0;
    const Material mat = mats.empty() ? Material{1} : mats[rng() % mats.size()];
    const int r = static_cast<int>(std::ceil(radius)) + 1;
    // World-space 4-aligned bounds of the affected units.
    const Vec3i wmin = d.origin + Vec3i{cx - r, cy - r, cz - r};
    const Vec3i wmax = d.origin + Vec3i{cx + r + 1, cy + r + 1, cz + r + 1};
    const Vec3i umin = floor_div(wmin, 4), umax = floor_div(wmax - Vec3i{1, 1, 1}, 4);
    std::vector<UnitUpdate> updates;
    for (int uy = umin.y; uy <= umax.y; ++uy) {
      for (int uz = umin.z; uz <= umax.z; ++uz) {
        for (int ux = umin.x; ux <= umax.x; ++ux) {
          UnitUpdate up;
          bool changed = false, inside = true;
          for (int y = 0; y < 4 && inside; ++y) {
            for (int z = 0; z < 4 && inside; ++z) {
              for (int x = 0; x < 4; ++x) {
                const Vec3i w{ux * 4 + x, uy * 4 + y, uz * 4 + z};
                const Vec3i l = w - d.origin;
                if (l.x < 0 || l.y < 0 || l.z < 0 || l.x >= s.x || l.y >= s.y || l.z >= s.z) {
                  inside = false;
                  break;
                }
                Voxel v = d.box.get(l);
                const float dx = static_cast<float>(l.x - cx), dy = static_cast<float>(l.y - cy), dz = static_cast<float>(l.z - cz);
                const float amount = std::clamp(radius - std::sqrt(dx * dx + dy * dy + dz * dz) + 0.5f, 0.0f, 1.0f);
                if (amount > 0) {
                  const float cur = occupancy_fraction(v);
                  if (dig) {
                    const float left = std::min(cur, 1.0f - amount);
                    v = left <= 0.0f || occupancy_byte(left) == 0 ? Voxel{} : make_voxel(v.material, occupancy_byte(left));
                  } else if (amount > cur) {
                    v = make_voxel(mat, occupancy_byte(amount));
                  }
                }
                const Voxel old = d.box.get(l);
                changed |= !(v == old);
                up.voxels[static_cast<std::size_t>((y * 4 + z) * 4 + x)] = v;
              }
            }
          }
          if (!inside || !changed) continue;
          up.chunk_pos = floor_div(Vec3i{ux, uy, uz}, 8);
          const Vec3i in_chunk = floor_mod(Vec3i{ux, uy, uz}, 8);
          up.unit_index = static_cast<std::uint16_t>((in_chunk.y * 8 + in_chunk.z) * 8 + in_chunk.x);
          updates.push_back(up);
        }
      }
    }
    if (updates.empty()) continue;
    ++f.edits;
    // The batch, and each entry's share: its coordinates plus its unit.
    bytes.clear();
    net_codec_encode_update_batch(updates, bytes);
    std::vector<UnitUpdate> decoded(updates.size());
    auto n = net_codec_decode_update_batch(bytes, decoded);
    if (!n || *n != updates.size()) {
      std::printf("UPDATE BATCH ROUND TRIP FAILED\n");
      std::exit(1);
    }
    std::sort(updates.begin(), updates.end(), update_batch_order);
    Vec3i prev_chunk{};
    int prev_unit = -1;
    for (const UnitUpdate& u : updates) {
      std::vector<std::uint8_t> coords, net, net2, rle;
      net_codec_put_update_coords(u.chunk_pos, u.unit_index, prev_chunk, prev_unit, coords);
      net_codec_encode(4, u.voxels, net, kNetCodecVersion1);
      net_codec_encode(4, u.voxels, net2, kNetCodecVersion2);
      byte_rle_encode(u.voxels, rle);
      net_sizes.push_back(static_cast<double>(coords.size() + net.size()));
      net2_sizes.push_back(static_cast<double>(coords.size() + net2.size()));
      rle_sizes.push_back(static_cast<double>(coords.size() + rle.size()));
      prev_chunk = u.chunk_pos;
      prev_unit = u.unit_index;
    }
  }
  f.units = net_sizes.size();
  f.net_p50 = percentile(net_sizes, 0.5);
  f.net_p99 = percentile(net_sizes, 0.99);
  f.net2_p50 = percentile(net2_sizes, 0.5);
  f.net2_p99 = percentile(net2_sizes, 0.99);
  f.net2_mean = net2_sizes.empty() ? 0 : std::accumulate(net2_sizes.begin(), net2_sizes.end(), 0.0) / static_cast<double>(net2_sizes.size());
  f.rle_p50 = percentile(rle_sizes, 0.5);
  f.rle_p99 = percentile(rle_sizes, 0.99);
  for (double x : net_sizes) f.net_mean += x / static_cast<double>(f.units);
  for (double x : rle_sizes) f.rle_mean += x / static_cast<double>(f.units);
  return f;
}

bool load_vxraw(Dataset& d, const std::string& file) {
  const std::string path = std::string(TERRANE_TEST_DATA_DIR) + "/" + file;
  auto r = vxraw_read_file(path, VxrawLimits{});
  if (!r) {
    std::printf("cannot read %s\n", path.c_str());
    return false;
  }
  d.box = std::move(r->box);
  d.origin = r->origin;
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  int rounds = 15;
  int world_cols = 32;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) rounds = 4;
    if (std::strcmp(argv[i], "--world-sample") == 0 && i + 1 < argc) world_cols = std::atoi(argv[++i]);
  }
  g_zc = ZSTD_createCCtx();
  g_zd = ZSTD_createDCtx();
  deflateInit(&g_deflate, 6);
  inflateInit(&g_inflate);

  std::vector<Dataset> sets;
  {
    Dataset d;
    const int half = world_cols * kN / 2;
    const Region region{{-half, -64, -half}, {half, 192, half}};
    d.name = "generated " + std::to_string(2 * half) + "x256x" + std::to_string(2 * half);
    TerrainGenerator gen(GeneratorParams{});
    gen.generate(region, d.box);
    d.origin = region.min;
    sets.push_back(std::move(d));
  }
  for (const char* f : {"mc-1.9.vxraw.gz", "mc-1.16.vxraw.gz"}) {
    Dataset d;
    d.name = std::string(f).substr(0, std::string(f).find(".vxraw"));
    if (!load_vxraw(d, f)) return 1;
    sets.push_back(std::move(d));
  }
  for (Dataset& d : sets) cut_units(d);

  const auto codecs = make_codecs();
  for (const Dataset& d : sets) {
    const auto uniform_count = static_cast<std::size_t>(std::count(d.uniform.begin(), d.uniform.end(), true));
    std::printf("\n== %s: %zu units of 16^3, %zu non-uniform\n", d.name.c_str(), d.units.size(),
                d.units.size() - uniform_count);
    std::printf("%-20s %12s %12s %10s %10s %9s %9s\n", "codec", "B/vox all", "B/vox nonuni", "enc MB/s",
                "dec MB/s", "enc/LZ4", "dec/LZ4");
    std::vector<Row> rows;
    for (const Codec& c : codecs) rows.push_back(measure(c, d));
    time_codecs(codecs, d, rounds, rows);
    const Row& lz4 = rows[1];
    for (std::size_t i = 0; i < codecs.size(); ++i) {
      const Row& r = rows[i];
      std::printf("%-20s %12.5f %12.5f %10.0f %10.0f %9.2f %9.2f\n", codecs[i].name.c_str(), r.all_bpv, r.nonuni_bpv,
                  r.enc_mbs, r.dec_mbs, r.enc_mbs / lz4.enc_mbs, r.dec_mbs / lz4.dec_mbs);
    }
    // The best of the reference codecs (the first four) on all units, and
    // Terrane's versions against it.
    double best = rows[0].all_bpv;
    for (std::size_t i = 1; i < 4; ++i) best = std::min(best, rows[i].all_bpv);
    std::printf("against the best reference (%.5f B/vox): version 1 %.3fx, version 2 %.3fx\n", best,
                rows[4].all_bpv / best, rows[5].all_bpv / best);
    const UpdateFigures f = measure_updates(d, 2000, 12345);
    std::printf("4^3 updates (%zu sphere edits r 1.5-4, %zu changed units), bytes per changed unit incl. coords:\n",
                f.edits, f.units);
    std::printf("  %-18s p50 %6.1f  p99 %6.1f  mean %6.2f\n", "Terrane net codec", f.net_p50, f.net_p99, f.net_mean);
    std::printf("  %-18s p50 %6.1f  p99 %6.1f  mean %6.2f\n", "Terrane codec 2", f.net2_p50, f.net2_p99, f.net2_mean);
    std::printf("  %-18s p50 %6.1f  p99 %6.1f  mean %6.2f\n", "byte RLE", f.rle_p50, f.rle_p99, f.rle_mean);
  }
  ZSTD_freeCCtx(g_zc);
  ZSTD_freeDCtx(g_zd);
  deflateEnd(&g_deflate);
  inflateEnd(&g_inflate);
  return 0;
}
