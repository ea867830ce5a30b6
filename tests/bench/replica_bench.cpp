// A client's replica taking stream records, as a moving client does: the
// cost a bot pays per record (decode and apply), the largest part of the
// bots' CPU in the world scenario (docs/results.md).
//   MipChurn/N N replicas, each holding a view of 4^3 mips (radius 16
//              chunks, 12 high: ~9,600 chunks), take turns to move one
//              chunk along x: the slice behind is Released, the slice
//              ahead arrives as Mip 3 records (one StreamBatch each way).
//              With 64 the replicas' maps are far beyond the caches, as
//              in the bots process. The mips are of codec version 2, as a
//              server sends a coarse image's.
//   MipChurnShared/64 the same, the replicas sharing a DecodedChunks: each
//              decodes every record and keeps the mip its bytes are.
//   MipChurnKnown/64 the same, the decoder skipping a record whose unit a
//              replica of the process holds (DecodedMips::known_unit).
//   Full       Full records of generated terrain chunks, each then
//              Released (the ring at full resolution a move brings).
//   FullDerivedMips the same, the replica's full chunks deriving their mips
//              when read (Chunk::Mips::kDerived, as terrane-bots' are).
//   FullShared the same, with the replica's decoded chunks shared through
//              a DecodedChunks cache warmed by another replica (the bots
//              process: another bot took the same bytes a moment before).
//   Updates    40 replicas holding the same 64 chunks each apply 64 ticks'
//              UpdateBatches (two 4^3 units of one chunk a tick, as a
//              small edit near 40 bots in a crowd), each replica on its
//              own copies.
//   UpdatesDerivedMips Updates, the replicas' chunks deriving their mips.
//   UpdatesShared the same replicas sharing their chunks (DecodedChunks):
//              the first to apply a tick's units makes the result, the
//              others take it (client/shared_updates.h).
// Counters: records_per_s, ns_per_record; for Updates, ns_per_apply (one
// replica applying one batch).
//   terrane-bench-replica --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>

#include <memory>
#include <vector>

#include "client/decoded_chunks.h"
#include "client/replica.h"
#include "common/codec/net_codec.h"
#include "common/codec/update_batch.h"
#include "common/voxel/chunk.h"
#include "common/world/terrain_generator.h"
#include "protocol/stream_batch.h"
#include "tests/support/stream_records.h"

namespace terrane {
namespace {

constexpr int kRadius = 16;  // chunks: view distance 512
constexpr int kMinY = -4, kMaxY = 8;

std::span<const std::uint8_t> records_of(const Frame& f) {
  auto m = verify_message(std::span<const std::uint8_t>(f).subspan(kFrameHeaderBytes));
  if (!m.ok()) std::abort();
  auto r = parse_stream_batch(*(*m)->body_as_StreamBatch());
  if (!r.ok()) std::abort();
  return *r;
}

const TerrainGenerator& generator() {
  static const TerrainGenerator g{GeneratorParams{}};
  return g;
}

Chunk chunk_at(Vec3i cp) {
  Box b;
  generator().generate(Region{chunk_origin(cp), chunk_origin(cp) + Vec3i{kChunkSize, kChunkSize, kChunkSize}}, b);
  return Chunk::from_box(b);
}

// The Mip 3 payload of a chunk (its coarsest unit; a uniform chunk's
// encodes its one material).
std::vector<std::uint8_t> mip3_payload(const Chunk& c) {
  Box m;
  c.read_level(3, m);
  std::vector<std::uint8_t> out;
  net_codec_encode(4, m.voxels(), out, kNetCodecVersion2);  // as the server sends a coarse image's
  return out;
}

std::vector<std::uint8_t> full_payload(const Chunk& c) {
  Box voxels({kChunkSize, kChunkSize, kChunkSize});
  c.read_box({0, 0, 0}, voxels, {0, 0, 0}, {kChunkSize, kChunkSize, kChunkSize});
  return testing_support::full_payload(voxels);
}

struct Applier {
  Replica replica;
  StreamDecodeScratch scratch;
  KnownPayloadFn known;  // as the client passes it: the shared cache's (or none)
  void apply(const Frame& f) {
    const Status st = decode_stream_batch(
        records_of(f), scratch,
        [&](const StreamRecord& r) -> Status {
          replica.apply_stream_record(r);
          return Ok{};
        },
        known);
    if (!st.ok()) std::abort();
  }
};

// The chunks of column (x, z) of the view around centre column cx.
template <class F>
void for_each_view_chunk(int cx, F&& f) {
  for (int x = cx - kRadius; x <= cx + kRadius; ++x)
    for (int z = -kRadius; z <= kRadius; ++z)
      if ((x - cx) * (x - cx) + z * z <= kRadius * kRadius)
        for (int y = kMinY; y < kMaxY; ++y) f(Vec3i{x, y, z});
}

// state.range(0) replicas take the same moves in turn, as the bots'
// replicas do in one process: their maps no longer fit in the caches.
// Shared: the replicas share one DecodedChunks (the bots' way), and with
// known the decoder skips the mips it holds (DecodedMips::known_unit).
void run_mip_churn(benchmark::State& state, bool shared = false, bool known = false) {
  const auto replicas = static_cast<std::size_t>(state.range(0));
  // Payloads by column height only (x, z vary the terrain little at 4^3 for
  // this purpose; the bytes are real mips of real terrain).
  std::vector<std::vector<std::uint8_t>> by_y;
  for (int y = kMinY; y < kMaxY; ++y) by_y.push_back(mip3_payload(chunk_at({3, y, 5})));
  auto mip = [&](StreamBatchWriter& w, Vec3i cp) {
    w.add(StreamRecordKind::kMip3, cp, 1, by_y[static_cast<std::size_t>(cp.y - kMinY)]);
  };
  std::vector<std::unique_ptr<Applier>> appliers;
  const auto decoded = shared ? std::make_shared<DecodedChunks>() : nullptr;
  for (std::size_t i = 0; i < replicas; ++i) {
    appliers.push_back(std::make_unique<Applier>());
    appliers.back()->replica.share_decoded(decoded);
    if (known)
      appliers.back()->known = [decoded](StreamRecordKind kind, std::span<const std::uint8_t> rest) {
        return decoded->known(kind, rest);
      };
  }
  {
    StreamBatchWriter w;
    std::vector<Frame> view;
    for_each_view_chunk(0, [&](Vec3i cp) {
      mip(w, cp);
      if (w.records() >= kMaxStreamRecords) view.push_back(w.finish().flatten());
    });
    if (!w.empty()) view.push_back(w.finish().flatten());
    for (auto& a : appliers)
      for (const Frame& f : view) a->apply(f);
  }
  // Frames of the moves, made ahead: leaving and entering slices for
  // centres 1..kMoves, then back (so the replica stays at steady size).
  constexpr int kMoves = 64;
  std::vector<Frame> frames;
  std::size_t records = 0;
  auto move = [&](int from, int to) {
    StreamBatchWriter leave, enter;
    for (int z = -kRadius; z <= kRadius; ++z) {
      for (int x = from - kRadius - 1; x <= from + kRadius + 1; ++x) {
        const bool was = (x - from) * (x - from) + z * z <= kRadius * kRadius;
        const bool is = (x - to) * (x - to) + z * z <= kRadius * kRadius;
        for (int y = kMinY; y < kMaxY && was != is; ++y) {
          if (was) leave.add(StreamRecordKind::kReleased, {x, y, z}, 0, {});
          else mip(enter, {x, y, z});
        }
      }
    }
    records += leave.records() + enter.records();
    frames.push_back(leave.finish().flatten());
    frames.push_back(enter.finish().flatten());
  };
  for (int c = 0; c < kMoves; ++c) move(c, c + 1);
  for (int c = kMoves; c > 0; --c) move(c, c - 1);
  // Each replica takes its next move (both frames), then the next replica
  // its own; an iteration is as many moves as there are.
  std::vector<std::size_t> next(replicas, 0);
  std::size_t turn = 0;
  for (auto _ : state) {
    for (std::size_t m = 0; m < frames.size() / 2; ++m) {
      const std::size_t i = turn++ % replicas;
      Applier& a = *appliers[i];
      a.apply(frames[2 * next[i]]);
      a.apply(frames[2 * next[i] + 1]);
      next[i] = (next[i] + 1) % (frames.size() / 2);
    }
  }
  state.counters["records_per_s"] =
      benchmark::Counter(static_cast<double>(records), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["ns_per_record"] = benchmark::Counter(
      static_cast<double>(records), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["chunks_held"] = static_cast<double>(appliers[0]->replica.chunk_count());
}
void BM_MipChurn(benchmark::State& state) { run_mip_churn(state); }
BENCHMARK(BM_MipChurn)->Arg(1)->Arg(64)->Unit(benchmark::kMillisecond);
void BM_MipChurnShared(benchmark::State& state) { run_mip_churn(state, true); }
BENCHMARK(BM_MipChurnShared)->Arg(64)->Unit(benchmark::kMillisecond);
void BM_MipChurnKnown(benchmark::State& state) { run_mip_churn(state, true, true); }
BENCHMARK(BM_MipChurnKnown)->Arg(64)->Unit(benchmark::kMillisecond);

// Full records of 64 terrain chunks (a few columns' worth, as near a
// moving client), then each Released.
struct FullFrames {
  Frame full, released;
  std::size_t records = 0;
};
const FullFrames& full_frames() {
  static const FullFrames f = [] {
    FullFrames out;
    StreamBatchWriter w, r;
    for (int x = 0; x < 4; ++x)
      for (int z = 0; z < 4; ++z)
        for (int y = -1; y < 3; ++y) {
          const Vec3i cp{x, y, z};
          const Chunk c = chunk_at(cp);
          if (c.empty()) continue;
          w.add(StreamRecordKind::kFull, cp, 1, full_payload(c));
          r.add(StreamRecordKind::kReleased, cp, 0, {});
        }
    out.records = w.records() + r.records();
    out.full = w.finish().flatten();
    out.released = r.finish().flatten();
    return out;
  }();
  return f;
}

// known: the decoder skips the bytes the shared cache knows (the client's
// way); without, it decodes every record and the replica finds the chunk
// by its bytes afterwards.
void run_full(benchmark::State& state, std::shared_ptr<DecodedChunks> shared, bool known = false,
              Chunk::Mips mips = Chunk::Mips::kKept) {
  const FullFrames& f = full_frames();
  Applier a;
  a.replica.share_decoded(shared);
  a.replica.set_full_chunk_mips(mips);
  if (known)
    a.known = [shared](StreamRecordKind kind, std::span<const std::uint8_t> rest) { return shared->known(kind, rest); };
  if (shared) {
    Applier warm;  // another client took the same bytes first
    warm.replica.share_decoded(shared);
    warm.apply(f.full);
  }
  for (auto _ : state) {
    a.apply(f.full);
    a.apply(f.released);
  }
  state.counters["records_per_s"] =
      benchmark::Counter(static_cast<double>(f.records), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["ns_per_record"] = benchmark::Counter(
      static_cast<double>(f.records), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_Full(benchmark::State& state) { run_full(state, nullptr); }
// The bots' way: chunks whose mips are derived when read (none made).
void BM_FullDerivedMips(benchmark::State& state) { run_full(state, nullptr, false, Chunk::Mips::kDerived); }

void run_updates(benchmark::State& state, bool share, Chunk::Mips mips = Chunk::Mips::kKept) {
  constexpr std::size_t kReplicas = 40;
  constexpr int kTicks = 64;
  const FullFrames& f = full_frames();
  std::shared_ptr<DecodedChunks> shared = share ? std::make_shared<DecodedChunks>() : nullptr;
  std::vector<std::unique_ptr<Applier>> appliers;
  for (std::size_t i = 0; i < kReplicas; ++i) {
    appliers.push_back(std::make_unique<Applier>());
    appliers.back()->replica.share_decoded(shared);
    appliers.back()->replica.set_full_chunk_mips(mips);
    appliers.back()->apply(f.full);
  }
  std::vector<Vec3i> held;
  appliers[0]->replica.grid().for_each_chunk([&](Vec3i cp, const Chunk&) { held.push_back(cp); });
  // Each tick digs one unit and fills its neighbour in one chunk, in turn.
  std::vector<std::vector<std::uint8_t>> data(kTicks);
  std::vector<UpdateBatchMsg> ticks;
  for (int t = 0; t < kTicks; ++t) {
    const Vec3i cp = held[static_cast<std::size_t>(t) % held.size()];
    std::vector<UnitUpdate> ups(2);
    for (std::size_t u = 0; u < 2; ++u) {
      ups[u].chunk_pos = cp;
      ups[u].unit_index = static_cast<std::uint16_t>((t * 37 + static_cast<int>(u)) % 512);
      ups[u].voxels.fill(u == 0 ? Voxel{} : make_voxel(materials::kRock, 255));
    }
    net_codec_encode_update_batch(ups, data[static_cast<std::size_t>(t)]);
    ticks.push_back(UpdateBatchMsg{static_cast<std::uint64_t>(t), data[static_cast<std::size_t>(t)],
                                   {ChunkRevisionMsg{cp, static_cast<std::uint64_t>(t + 2)}}});
  }
  for (auto _ : state)
    for (const UpdateBatchMsg& m : ticks)
      for (auto& a : appliers)
        if (!a->replica.apply_update_batch(m).ok()) std::abort();
  state.counters["ns_per_apply"] =
      benchmark::Counter(static_cast<double>(kTicks * kReplicas),
                         benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_Updates(benchmark::State& state) { run_updates(state, false); }
BENCHMARK(BM_Updates)->Unit(benchmark::kMillisecond);

void BM_UpdatesShared(benchmark::State& state) { run_updates(state, true); }
BENCHMARK(BM_UpdatesShared)->Unit(benchmark::kMillisecond);
void BM_UpdatesDerivedMips(benchmark::State& state) { run_updates(state, false, Chunk::Mips::kDerived); }
BENCHMARK(BM_UpdatesDerivedMips)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Full)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FullDerivedMips)->Unit(benchmark::kMillisecond);

void BM_FullShared(benchmark::State& state) { run_full(state, std::make_shared<DecodedChunks>()); }
BENCHMARK(BM_FullShared)->Unit(benchmark::kMillisecond);
void BM_FullKnown(benchmark::State& state) { run_full(state, std::make_shared<DecodedChunks>(), true); }
BENCHMARK(BM_FullKnown)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace terrane
BENCHMARK_MAIN();
