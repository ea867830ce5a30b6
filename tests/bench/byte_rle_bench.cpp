// Byte RLE and LZ4 on real terrain: every full 32^3 unit of mc-1.16.
// Throughput counts 2 bytes per voxel (the unpacked size); "bytes/voxel" is
// the encoded size over all units divided by their voxel count.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <vector>

#include "common/codec/byte_rle.h"
#include "common/codec/lz4_block.h"
#include "common/vxraw/vxraw.h"

namespace terrane {
namespace {

constexpr int kUnit = 32;
constexpr std::size_t kUnitVoxels = kUnit * kUnit * kUnit;

struct Units {
  std::vector<std::vector<Voxel>> voxels;  // each kUnitVoxels, box order
  std::string error;
};

const Units& units() {
  static const Units u = [] {
    Units out;
    auto file = vxraw_read_file(TERRANE_TEST_DATA_DIR "/mc-1.16.vxraw.gz", {});
    if (!file.ok()) {
      out.error = file.error().message;
      return out;
    }
    const Box& box = file->box;
    const Vec3i n{box.size().x / kUnit, box.size().y / kUnit, box.size().z / kUnit};
    for (int uy = 0; uy < n.y; ++uy) {
      for (int uz = 0; uz < n.z; ++uz) {
        for (int ux = 0; ux < n.x; ++ux) {
          std::vector<Voxel> unit;
          unit.reserve(kUnitVoxels);
          for (int y = 0; y < kUnit; ++y) {
            for (int z = 0; z < kUnit; ++z) {
              const Voxel* row = box.read_row(uy * kUnit + y, uz * kUnit + z) + ux * kUnit;
              unit.insert(unit.end(), row, row + kUnit);
            }
          }
          out.voxels.push_back(std::move(unit));
        }
      }
    }
    return out;
  }();
  return u;
}

bool ready(benchmark::State& state) {
  if (!units().error.empty()) {
    state.SkipWithError(units().error.c_str());
    return false;
  }
  return true;
}

void report(benchmark::State& state, std::size_t encoded_bytes) {
  const auto voxels = static_cast<double>(units().voxels.size() * kUnitVoxels);
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) *
                          static_cast<std::int64_t>(units().voxels.size() * kUnitVoxels * 2));
  state.counters["bytes/voxel"] = static_cast<double>(encoded_bytes) / voxels;
  state.counters["units"] = static_cast<double>(units().voxels.size());
}

std::vector<std::vector<std::uint8_t>> encode_all(bool lz4) {
  std::vector<std::vector<std::uint8_t>> out;
  for (const auto& u : units().voxels) {
    out.emplace_back();
    if (lz4) {
      byte_rle_lz4_encode(u, out.back());
    } else {
      byte_rle_encode(u, out.back());
    }
  }
  return out;
}

std::size_t total_size(const std::vector<std::vector<std::uint8_t>>& v) {
  std::size_t n = 0;
  for (const auto& b : v) n += b.size();
  return n;
}

void BM_ByteRleEncode(benchmark::State& state) {
  if (!ready(state)) return;
  std::vector<std::uint8_t> out;
  out.reserve(byte_rle_max_encoded_size(kUnitVoxels));
  std::size_t bytes = 0;
  for (auto _ : state) {
    bytes = 0;
    for (const auto& u : units().voxels) {
      out.clear();
      byte_rle_encode(u, out);
      bytes += out.size();
      benchmark::DoNotOptimize(out.data());
    }
  }
  report(state, bytes);
}
BENCHMARK(BM_ByteRleEncode);

void BM_ByteRleEncodeTo(benchmark::State& state) {
  if (!ready(state)) return;
  std::vector<std::uint8_t> out(byte_rle_max_encoded_size(kUnitVoxels));
  std::size_t bytes = 0;
  for (auto _ : state) {
    bytes = 0;
    for (const auto& u : units().voxels) {
      bytes += byte_rle_encode_to(u, out);
      benchmark::DoNotOptimize(out.data());
    }
  }
  report(state, bytes);
}
BENCHMARK(BM_ByteRleEncodeTo);

void BM_ByteRleDecode(benchmark::State& state) {
  if (!ready(state)) return;
  const auto encoded = encode_all(false);
  std::vector<Voxel> out(kUnitVoxels);
  for (auto _ : state) {
    for (const auto& e : encoded) {
      if (!byte_rle_decode(e, out).ok()) state.SkipWithError("decode failed");
      benchmark::DoNotOptimize(out.data());
    }
  }
  report(state, total_size(encoded));
}
BENCHMARK(BM_ByteRleDecode);

void BM_ByteRleLz4Encode(benchmark::State& state) {
  if (!ready(state)) return;
  std::vector<std::uint8_t> out, scratch;
  std::size_t bytes = 0;
  for (auto _ : state) {
    bytes = 0;
    for (const auto& u : units().voxels) {
      out.clear();
      byte_rle_lz4_encode(u, out, scratch);
      bytes += out.size();
      benchmark::DoNotOptimize(out.data());
    }
  }
  report(state, bytes);
}
BENCHMARK(BM_ByteRleLz4Encode);

void BM_ByteRleLz4Decode(benchmark::State& state) {
  if (!ready(state)) return;
  const auto encoded = encode_all(true);
  std::vector<Voxel> out(kUnitVoxels);
  std::vector<std::uint8_t> scratch;
  for (auto _ : state) {
    for (const auto& e : encoded) {
      if (!byte_rle_lz4_decode(e, out, scratch).ok()) state.SkipWithError("decode failed");
      benchmark::DoNotOptimize(out.data());
    }
  }
  report(state, total_size(encoded));
}
BENCHMARK(BM_ByteRleLz4Decode);

// Baseline: LZ4 straight on the two-byte voxels, no RLE.
std::span<const std::uint8_t> raw_bytes(const std::vector<Voxel>& u) {
  return {reinterpret_cast<const std::uint8_t*>(u.data()), u.size() * sizeof(Voxel)};
}

void BM_Lz4RawEncode(benchmark::State& state) {
  if (!ready(state)) return;
  std::vector<std::uint8_t> out;
  std::size_t bytes = 0;
  for (auto _ : state) {
    bytes = 0;
    for (const auto& u : units().voxels) {
      out.clear();
      lz4_compress(raw_bytes(u), out);
      bytes += out.size();
      benchmark::DoNotOptimize(out.data());
    }
  }
  report(state, bytes);
}
BENCHMARK(BM_Lz4RawEncode);

void BM_Lz4RawDecode(benchmark::State& state) {
  if (!ready(state)) return;
  std::vector<std::vector<std::uint8_t>> encoded;
  for (const auto& u : units().voxels) {
    encoded.emplace_back();
    lz4_compress(raw_bytes(u), encoded.back());
  }
  std::vector<std::uint8_t> out(kUnitVoxels * sizeof(Voxel));
  for (auto _ : state) {
    for (const auto& e : encoded) {
      if (!lz4_decompress_into(e, out).ok()) state.SkipWithError("decode failed");
      benchmark::DoNotOptimize(out.data());
    }
  }
  report(state, total_size(encoded));
}
BENCHMARK(BM_Lz4RawDecode);

}  // namespace
}  // namespace terrane

BENCHMARK_MAIN();
