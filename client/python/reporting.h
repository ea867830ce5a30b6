// Reporting: what a client's io side reports beyond the default events, as
// the script asked. Both are off by default, when applying what the server
// sends costs nothing more:
//   - the voxels each update batch changed, old and new, at most a cap per
//     event (the Client records them in the pass that applies the batch:
//     Client::capture_voxel_changes);
//   - Loaded events, the chunks newly held at full resolution (the io
//     side's on_chunks_loaded reads the flag).
// Python side: set and read with the GIL held; the flag is atomic because
// the io side reads it.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>

#include "client/client.h"

namespace terrane::python {

class Reporting {
 public:
  // A batch's most: 16 chunks of 32^3.
  static constexpr std::int64_t kMaxRecordedVoxels = 16 * 32768;
  static constexpr std::int64_t kDefaultRecordedVoxels = 4096;

  // Set once the client is made (the io side's callback holds the flag
  // before that: loaded_flag()).
  void bind(std::shared_ptr<Client> c) { c_ = std::move(c); }

  // Update events carry the voxels each batch changed, before and after,
  // at most max_voxels per event (0: no longer). ValueError beyond
  // kMaxRecordedVoxels.
  void record_voxel_changes(std::int64_t max_voxels);
  std::int64_t recorded_voxels() const { return recorded_voxels_; }
  // Loaded events are queued and passed to callbacks from now on (or no
  // longer).
  void report_loaded(bool on) { loaded_->store(on); }
  bool reporting_loaded() const { return loaded_->load(); }
  // What the io side's on_chunks_loaded reads.
  std::shared_ptr<const std::atomic<bool>> loaded_flag() const { return loaded_; }

 private:
  std::shared_ptr<Client> c_;
  std::int64_t recorded_voxels_ = 0;
  std::shared_ptr<std::atomic<bool>> loaded_ = std::make_shared<std::atomic<bool>>(false);
};

}  // namespace terrane::python
