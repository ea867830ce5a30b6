// The benchmarks' datasets, as one box of voxels each: "generated" (the
// default generator over 512 x 256 x 512 voxels from (-256, -64, -256)) or
// a file of tests/data (NAME.vxraw.gz). A file that cannot be read ends the
// benchmark with its error, naming bench. Header-only.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>

#include "common/voxel/box.h"
#include "common/world/terrain_generator.h"
#include "common/vxraw/vxraw.h"

namespace terrane::bench {

// The dataset name's voxels into box, with their origin.
inline void load_dataset(const std::string& name, const char* bench, Box& box, Vec3i& origin) {
  if (name == "generated") {
    const Region r{{-256, -64, -256}, {256, 192, 256}};
    TerrainGenerator(GeneratorParams{}).generate(r, box);
    origin = r.min;
    return;
  }
  const std::string path = std::string(TERRANE_TEST_DATA_DIR) + "/" + name + ".vxraw.gz";
  auto file = vxraw_read_file(path, VxrawLimits{});
  if (!file) {
    std::fprintf(stderr, "%s: %s\n", bench, file.error().message.c_str());
    std::exit(1);
  }
  origin = file->origin;
  box = std::move(file->box);
}

}  // namespace terrane::bench
