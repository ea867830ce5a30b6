#include "client/view/mesh_scheduler.h"

#include <algorithm>
#include <chrono>

namespace terrane::view {

MeshScheduler::MeshScheduler(SourceAccess access, LodParams params, MesherOptions mesher, EnhanceViewParams enhance)
    : access_(std::move(access)), mesher_(mesher), enhance_(enhance), params_(params) {
  thread_ = std::thread([this] { run(); });
}

MeshScheduler::~MeshScheduler() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void MeshScheduler::set_view(Vec3f camera) {
  std::lock_guard lock(mutex_);
  if (camera == camera_) return;
  camera_ = camera;
  dirty_ = true;
  wake_.notify_all();
}

void MeshScheduler::set_params(const LodParams& params) {
  std::lock_guard lock(mutex_);
  params_ = params;
  dirty_ = true;
  wake_.notify_all();
}

void MeshScheduler::mark_dirty() {
  std::lock_guard lock(mutex_);
  dirty_ = true;
  wake_.notify_all();
}

std::vector<MeshResult> MeshScheduler::take_results() {
  std::lock_guard lock(mutex_);
  std::vector<MeshResult> out;
  out.swap(results_);
  return out;
}

MeshPlanSnapshot MeshScheduler::plan() const {
  std::lock_guard lock(mutex_);
  return plan_;
}

bool MeshScheduler::idle() const {
  std::lock_guard lock(mutex_);
  return !dirty_ && !busy_ && jobs_.empty() && results_.empty();
}

MeshSchedulerStats MeshScheduler::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

void MeshScheduler::replan(std::unique_lock<std::mutex>& lock) {
  dirty_ = false;
  busy_ = true;
  const Vec3f camera = camera_;
  const LodParams params = params_;
  lock.unlock();
  std::vector<NodeKey> keys = select_render_chunks(camera, params);
  std::vector<ChunkPlan> plans(keys.size());
  access_([&](const VoxelSource& source) {
    for (std::size_t i = 0; i < keys.size(); ++i) plans[i] = plan_render_chunk(source, keys[i], params);
  });
  lock.lock();
  busy_ = false;
  MeshPlanSnapshot snap;
  snap.generation = plan_.generation + 1;
  std::unordered_map<NodeKey, std::uint64_t, NodeKeyHash> kept;
  jobs_.clear();
  for (std::size_t i = 0; i < keys.size(); ++i) {
    // Chunks with no known source data are left out altogether.
    if (!plans[i].any_known) continue;
    snap.chunks.push_back(keys[i]);
    snap.sample_levels.push_back(plans[i].sample_level);
    auto it = meshed_.find(keys[i]);
    if (it != meshed_.end() && it->second == plans[i].signature) {
      kept.emplace(keys[i], it->second);
      continue;
    }
    jobs_.push_back(Job{keys[i], plans[i].sample_level, plans[i].signature, plans[i].enhanced});
  }
  std::reverse(jobs_.begin(), jobs_.end());
  meshed_ = std::move(kept);
  plan_ = std::move(snap);
  ++stats_.plans;
}

void MeshScheduler::run() {
  std::unique_lock lock(mutex_);
  while (true) {
    wake_.wait(lock, [&] { return stop_ || dirty_ || !jobs_.empty(); });
    if (stop_) return;
    // While streaming, data changes many times a second; re-plan at most
    // every kMinReplanInterval while there is meshing left to do, so the
    // worker meshes rather than re-plans.
    const auto now = std::chrono::steady_clock::now();
    if (dirty_ && (jobs_.empty() || now - last_plan_ >= kMinReplanInterval)) {
      last_plan_ = now;
      replan(lock);
      continue;
    }
    const Job job = jobs_.back();
    jobs_.pop_back();
    busy_ = true;
    lock.unlock();
    const auto t0 = std::chrono::steady_clock::now();
    SampleGrid samples;
    if (job.enhanced) {
      EnhanceInput input;
      access_([&](const VoxelSource& source) { input = read_enhance_input(source, job.key, enhance_); });
      samples = enhance_samples(input, job.key, enhance_);
    } else {
      access_([&](const VoxelSource& source) { samples = sample_render_chunk(source, job.key, job.sample_level); });
    }
    MeshResult r{job.key, job.signature, job.sample_level, job.enhanced, {}};
    mesh_render_samples(samples, r.mesh, mesher_);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    lock.lock();
    busy_ = false;
    ++stats_.chunks_meshed;
    stats_.enhanced_chunks += job.enhanced ? 1 : 0;
    stats_.triangles += r.mesh.triangle_count();
    stats_.mesh_seconds += secs;
    meshed_[job.key] = job.signature;
    results_.push_back(std::move(r));
  }
}

}  // namespace terrane::view
