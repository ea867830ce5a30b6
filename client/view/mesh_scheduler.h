// MeshScheduler: keeps the meshes of the current render chunks up to date
// on one worker thread, off the render thread.
//
// The render thread sets the camera (set_view) and says when the source's
// data may have changed (mark_dirty); the worker then re-plans: it selects
// the render chunks for the camera (select_render_chunks), computes each
// one's plan (sample level and signature: the levels and revisions of the
// source chunks it reads) and remeshes only the chunks whose plan differs
// from the mesh it last produced, nearest first. Source reads happen inside
// the SourceAccess callback (for a Client: under its lock); meshing happens
// outside it. Finished meshes are collected with take_results().
//
// Threading: every public method is thread-safe. One mutex guards the
// shared state (view, flags, plan, results) because the render thread and
// the worker exchange small values at frame rate; meshing never holds it.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <vector>

#include "client/view/enhanced_chunk.h"
#include "client/view/render_chunk.h"

namespace terrane::view {

struct MeshResult {
  NodeKey key;
  std::uint64_t signature = 0;
  int sample_level = 0;
  bool enhanced = false;
  Mesh mesh;
};

struct MeshPlanSnapshot {
  std::uint64_t generation = 0;  // bumps with every new plan
  std::vector<NodeKey> chunks;   // render chunks of the plan, nearest first
  std::vector<int> sample_levels;
};

struct MeshSchedulerStats {
  std::uint64_t chunks_meshed = 0;
  std::uint64_t triangles = 0;   // of the meshes produced
  double mesh_seconds = 0;       // sampling + meshing
  std::uint64_t plans = 0;
  std::uint64_t enhanced_chunks = 0;  // of chunks_meshed
};

class MeshScheduler {
 public:
  using SourceAccess = std::function<void(const std::function<void(const VoxelSource&)>&)>;

  MeshScheduler(SourceAccess access, LodParams params, MesherOptions mesher = {}, EnhanceViewParams enhance = {});
  ~MeshScheduler();
  MeshScheduler(const MeshScheduler&) = delete;
  MeshScheduler& operator=(const MeshScheduler&) = delete;

  void set_view(Vec3f camera);
  void set_params(const LodParams& params);
  void mark_dirty();
  // Meshes finished since the last call (empty meshes included: the chunk
  // has no surface).
  std::vector<MeshResult> take_results();
  MeshPlanSnapshot plan() const;
  // True when the last plan is current (nothing marked dirty since) and
  // every chunk of it has been meshed and handed out by take_results().
  bool idle() const;
  MeshSchedulerStats stats() const;

 private:
  void run();
  void replan(std::unique_lock<std::mutex>& lock);

  SourceAccess access_;
  MesherOptions mesher_;
  EnhanceViewParams enhance_;

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  // Nothing to plan until told where (set_view, set_params or mark_dirty):
  // planning for a default camera first meshed chunks of a plan about to
  // be replaced.
  bool dirty_ = false;
  bool busy_ = false;
  LodParams params_;
  Vec3f camera_;
  MeshPlanSnapshot plan_;
  struct Job {
    NodeKey key;
    int sample_level;
    std::uint64_t signature;
    bool enhanced;
  };
  std::vector<Job> jobs_;      // pending, nearest last (popped from the back)
  std::vector<MeshResult> results_;
  std::unordered_map<NodeKey, std::uint64_t, NodeKeyHash> meshed_;  // signature of the last mesh made
  MeshSchedulerStats stats_;
  static constexpr std::chrono::milliseconds kMinReplanInterval{100};
  std::chrono::steady_clock::time_point last_plan_{};
  std::thread thread_;
};

}  // namespace terrane::view
