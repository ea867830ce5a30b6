// Detail-enhanced render chunks: the viewer's toggle for common/enhance/
// (enhance.h and lighting.h; A. M. Smith, "Two Methods for Voxel Detail
// Enhancement"). A full-resolution render chunk is subdivided into 2x2x2
// fragments per voxel by recursive subdivision, its surface fragments are
// lit by snowflake tracing (particles wandering towards the sun and the
// sky), and the fragments are meshed at half-voxel spacing with each
// vertex's colour scaled by its fragment's light.
//
// Work is split so that source reads stay short: read_enhance_input() (under
// the source's lock) copies the voxels the chunk's fragments and light
// depend on; enhance_samples() (anywhere) does the rest.
#pragma once

#include "client/view/mesher.h"
#include "client/view/render_chunk.h"
#include "common/enhance/enhance.h"
#include "common/enhance/lighting.h"

namespace terrane::view {

struct EnhanceViewParams {
  SubdivisionParams subdivision{1, SubdivisionThreshold::constant(3)};
  LightingParams lighting{{0.45f, 0.62f, 0.38f}, 16, 16, 16, 0.75f, 0.6f, 1};
  // Light never darkens a vertex below this share of its colour (caves
  // would otherwise be black: the renderer has no bounce light).
  float min_light = 0.3f;
};

struct EnhanceInput {
  Vec3i origin;  // world voxel coordinates of coarse's (0, 0, 0)
  Box coarse;
};

// The voxels (full resolution where held, nearest mip voxel elsewhere,
// Air where unknown) around a level-0 render chunk that its fragments and
// their light read.
EnhanceInput read_enhance_input(const VoxelSource& source, const NodeKey& key, const EnhanceViewParams& params);

// The fragment samples of the chunk (spacing 1 / 2^levels, one ring of
// neighbouring fragments, as sample_render_chunk) with their light.
SampleGrid enhance_samples(const EnhanceInput& input, const NodeKey& key, const EnhanceViewParams& params);

}  // namespace terrane::view
