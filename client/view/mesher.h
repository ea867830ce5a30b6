// Mesher: the smooth occupancy surface of a block of samples, by surface
// nets (one vertex per cell the 0.5 occupancy level crosses, one quad per
// sample edge it crosses).
//
// Input is a SampleGrid: occupancy and material at sample points spaced
// `spacing` apart. Everything outside the grid is Air, so the mesh of any
// grid is a closed surface: every solid part of the block is wrapped,
// including where the block is cut off. That is how render chunks of
// different resolutions stay crack-free without stitching (see
// client/view/VIEWER.md): each render chunk meshes its own cells plus one
// ring of its neighbours' samples, so its closed solid overlaps its
// neighbours and any gap between two resolutions is covered by one of the
// two closed solids.
//
// Vertices carry a position (world units), a unit normal, the material's
// colour and its sharpness (client/view/materials.h). Triangles are wound
// counter-clockwise seen from the Air side.
#pragma once

#include <cstdint>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/voxel/voxel.h"

namespace terrane::view {

// Samples in x-fastest order: index (z * dims.y + y) * dims.x + x.
struct SampleGrid {
  Vec3i dims;          // samples per axis, each >= 1
  Vec3f origin;        // world position of sample (0, 0, 0)
  float spacing = 1;   // world units between neighbouring samples
  std::vector<float> occupancy;       // [0, 1]; solid when >= 0.5
  std::vector<Material> material;     // material of each sample (Air where empty)
  // Optional light per sample (255 = unshaded); empty: none. A vertex's
  // colour is scaled by the brightest light among its cell's solid samples
  // (so buried samples may carry 0).
  std::vector<std::uint8_t> light;

  SampleGrid() = default;
  SampleGrid(Vec3i d, Vec3f o, float s);
  std::size_t index(int x, int y, int z) const {
    return (static_cast<std::size_t>(z) * static_cast<std::size_t>(dims.y) + static_cast<std::size_t>(y)) *
               static_cast<std::size_t>(dims.x) +
           static_cast<std::size_t>(x);
  }
  void set(int x, int y, int z, float occ, Material m) {
    occupancy[index(x, y, z)] = occ;
    material[index(x, y, z)] = m;
  }
  // Counts of samples at or above / below the 0.5 level.
  std::size_t solid_count() const;
};

struct MeshVertex {
  float pos[3];
  float normal[3];
  std::uint8_t rgba[4];  // sRGB colour; a = sharpness * 255
};
static_assert(sizeof(MeshVertex) == 28);

struct Mesh {
  std::vector<MeshVertex> vertices;
  std::vector<std::uint32_t> indices;  // triangles
  bool empty() const { return indices.empty(); }
  std::size_t triangle_count() const { return indices.size() / 3; }
};

struct MesherOptions {
  // Apply the material's sharpness (vertex pull and jitter). Off: the plain
  // surface nets vertex, for tests that reason about exact positions.
  bool material_shaping = true;
};

// Meshes the grid (out is cleared first). A grid that is all solid or all
// Air gives an empty mesh... except that an all-solid grid still has its
// closed hull; callers that know a block is buried skip it (see
// build_render_chunk in client/view/render_chunk.h).
void mesh_samples(const SampleGrid& grid, Mesh& out, const MesherOptions& options = {});

}  // namespace terrane::view
