// A WorldStore that passes everything to another one, except that reading a
// chunk named in its gate waits until the gate opens (on every connection
// reopened from it): a load that takes as long as a test wants. The gate
// can also make reads of a chunk fail (as a disk that cannot be read, not
// a damaged row) until it is healed, and make every save fail with an
// error of the test's.
#pragma once

#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <unordered_set>

#include "common/world/world_store.h"

namespace terrane::testing_support {

class StoreGate {
 public:
  explicit StoreGate(std::unordered_set<Vec3i, Vec3iHash> closed) : closed_(std::move(closed)) {}
  // Blocks while pos is closed; counts the reads that waited.
  void pass(Vec3i pos) {
    std::unique_lock lock(m_);
    if (closed_.count(pos) == 0) return;
    ++waited_;
    cv_.notify_all();
    cv_.wait(lock, [&] { return closed_.count(pos) == 0; });
  }
  void open() {
    std::lock_guard lock(m_);
    closed_.clear();
    cv_.notify_all();
  }
  // Whether a read is waiting or has waited at the gate (so it stands
  // closed in front of a load under way).
  bool reached() {
    std::lock_guard lock(m_);
    return waited_ > 0;
  }
  // From now on every save fails with e (nullopt: saves pass).
  void fail_saves(std::optional<FileError> e) {
    std::lock_guard lock(m_);
    save_failure_ = std::move(e);
  }
  std::optional<FileError> save_failure() {
    std::lock_guard lock(m_);
    return save_failure_;
  }

  // Reads of pos fail until heal(pos).
  void fail(Vec3i pos) {
    std::lock_guard lock(m_);
    failing_.insert(pos);
  }
  void heal(Vec3i pos) {
    std::lock_guard lock(m_);
    failing_.erase(pos);
  }
  // Whether a read of pos fails now (counted).
  bool fails(Vec3i pos) {
    std::lock_guard lock(m_);
    if (failing_.count(pos) == 0) return false;
    ++failed_;
    return true;
  }
  int failed_reads() {
    std::lock_guard lock(m_);
    return failed_;
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  std::unordered_set<Vec3i, Vec3iHash> closed_, failing_;
  int waited_ = 0;
  int failed_ = 0;
  std::optional<FileError> save_failure_;
};

class GatedStore final : public WorldStore {
 public:
  GatedStore(std::unique_ptr<WorldStore> inner, std::shared_ptr<StoreGate> gate)
      : inner_(std::move(inner)), gate_(std::move(gate)) {}

  const std::string& where() const override { return inner_->where(); }
  FileResult<std::unique_ptr<WorldStore>> reopen() const override {
    auto s = inner_->reopen();
    if (!s) return s;
    return std::unique_ptr<WorldStore>(std::make_unique<GatedStore>(std::move(*s), gate_));
  }
  const WorldMeta& meta() const override { return inner_->meta(); }
  FileStatus set_epoch(std::uint64_t epoch) override { return inner_->set_epoch(epoch); }
  FileResult<std::uint64_t> name_world(std::uint64_t candidate) override { return inner_->name_world(candidate); }
  FileStatus set_bounds(const WorldBounds& bounds) override { return inner_->set_bounds(bounds); }
  FileResult<std::optional<StoredChunk>> load_chunk(Vec3i pos) override {
    gate_->pass(pos);
    if (gate_->fails(pos)) return FileError{"the test's disk cannot be read", std::nullopt};
    return inner_->load_chunk(pos);
  }
  FileResult<std::vector<CoarseEntry>> load_coarse(Vec3i region) override { return inner_->load_coarse(region); }
  FileResult<std::vector<CoarseEntry>> load_coarse_as_kept(Vec3i region) override {
    return inner_->load_coarse_as_kept(region);
  }
  FileResult<std::vector<Vec3i>> quarantined_in(Vec3i region) override { return inner_->quarantined_in(region); }
  FileResult<std::vector<Vec3i>> stored_in(Vec3i region) override { return inner_->stored_in(region); }
  FileStatus begin_read() override { return inner_->begin_read(); }
  void end_read() override { inner_->end_read(); }
  FileStatus save_chunks(std::span<const ChunkWrite> writes, bool overwrite = true,
                         std::span<const EditLogEntry> log = {}) override {
    if (auto e = gate_->save_failure()) return *e;
    return inner_->save_chunks(writes, overwrite, log);
  }
  void set_coarse_behind(bool on) override { inner_->set_coarse_behind(on); }
  FileResult<std::size_t> catch_up_coarse(std::size_t max_regions, std::chrono::steady_clock::duration min_age) override {
    return inner_->catch_up_coarse(max_regions, min_age);
  }
  std::size_t coarse_pending() const override { return inner_->coarse_pending(); }
  bool coarse_read_behind() const override { return inner_->coarse_read_behind(); }
  void repair_coarse(Vec3i region) override { inner_->repair_coarse(region); }
  FileResult<std::vector<EditLogEntry>> edit_log(const EditLogQuery& q) override { return inner_->edit_log(q); }
  FileResult<std::int64_t> prune_edit_log(std::int64_t before_ms, std::uint64_t max_bytes,
                                          std::int64_t max_rows = 10000) override {
    return inner_->prune_edit_log(before_ms, max_bytes, max_rows);
  }
  FileResult<EditLogSize> edit_log_size() override { return inner_->edit_log_size(); }
  FileResult<std::optional<std::uint64_t>> quarantine_chunk(Vec3i pos, const std::string& reason) override {
    return inner_->quarantine_chunk(pos, reason);
  }
  FileResult<std::optional<std::uint64_t>> quarantined_revision(Vec3i pos) override {
    return inner_->quarantined_revision(pos);
  }
  FileStatus for_each_chunk(
      const std::function<void(Vec3i, std::uint64_t, std::span<const std::uint8_t>)>& fn) override {
    return inner_->for_each_chunk(fn);
  }
  FileResult<std::int64_t> stored_chunk_count() override { return inner_->stored_chunk_count(); }
  FileResult<std::vector<std::pair<std::string, std::string>>> access_entries() override {
    return inner_->access_entries();
  }
  FileStatus put_access(const std::string& key, const std::string& value) override {
    return inner_->put_access(key, value);
  }
  FileStatus erase_access(const std::string& key) override { return inner_->erase_access(key); }

 private:
  std::unique_ptr<WorldStore> inner_;
  std::shared_ptr<StoreGate> gate_;
};

}  // namespace terrane::testing_support
