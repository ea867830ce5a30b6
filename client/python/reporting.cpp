#include "client/python/reporting.h"

#include "client/python/edit_future.h"

namespace terrane::python {

void Reporting::record_voxel_changes(std::int64_t max_voxels) {
  if (max_voxels < 0 || max_voxels > kMaxRecordedVoxels)
    raise(PyExc_ValueError, "record_voxel_changes: max_voxels must be 0..524288 (0: stop recording)");
  recorded_voxels_ = max_voxels;
  c_->capture_voxel_changes(static_cast<std::size_t>(max_voxels));
}

}  // namespace terrane::python
