// Mesher invariants: closed two-manifold surfaces for closed solids, no
// NaNs, outward winding, and triangle counts that follow surface area.
#include "client/view/mesher.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <utility>

#include "common/voxel/voxel.h"

namespace terrane::view {
namespace {

SampleGrid sphere_grid(int n, float radius, Material m = materials::kRock) {
  SampleGrid g({n, n, n}, {0, 0, 0}, 1.0f);
  const float c = static_cast<float>(n - 1) / 2.0f;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const float dx = static_cast<float>(x) - c, dy = static_cast<float>(y) - c, dz = static_cast<float>(z) - c;
        // Smooth occupancy: 1 inside, ramping to 0 over one voxel.
        const float occ = std::clamp(radius - std::sqrt(dx * dx + dy * dy + dz * dz) + 0.5f, 0.0f, 1.0f);
        g.set(x, y, z, occ, occ > 0 ? m : kAir);
      }
  return g;
}

// Every undirected edge is used by exactly two triangles, once in each
// direction (closed, consistently oriented two-manifold).
void expect_closed(const Mesh& mesh) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  for (std::size_t t = 0; t < mesh.indices.size(); t += 3)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = mesh.indices[t + static_cast<std::size_t>(k)];
      const std::uint32_t b = mesh.indices[t + static_cast<std::size_t>((k + 1) % 3)];
      ASSERT_NE(a, b) << "degenerate triangle";
      ++directed[{a, b}];
    }
  for (const auto& [e, count] : directed) {
    ASSERT_EQ(count, 1) << "edge " << e.first << "-" << e.second << " used twice in one direction";
    ASSERT_EQ(directed.count({e.second, e.first}), 1u) << "edge " << e.first << "-" << e.second << " has one triangle";
  }
}

void expect_finite(const Mesh& mesh) {
  for (const MeshVertex& v : mesh.vertices) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_TRUE(std::isfinite(v.pos[k]));
      ASSERT_TRUE(std::isfinite(v.normal[k]));
    }
    const float len = std::sqrt(v.normal[0] * v.normal[0] + v.normal[1] * v.normal[1] + v.normal[2] * v.normal[2]);
    ASSERT_NEAR(len, 1.0f, 1e-3f);
  }
}

// Signed volume by the divergence theorem: positive when triangles wind
// counter-clockwise seen from outside.
double signed_volume(const Mesh& mesh) {
  double v = 0;
  for (std::size_t t = 0; t < mesh.indices.size(); t += 3) {
    const float* a = mesh.vertices[mesh.indices[t]].pos;
    const float* b = mesh.vertices[mesh.indices[t + 1]].pos;
    const float* c = mesh.vertices[mesh.indices[t + 2]].pos;
    v += (static_cast<double>(a[0]) * (b[1] * c[2] - b[2] * c[1]) - static_cast<double>(a[1]) * (b[0] * c[2] - b[2] * c[0]) +
          static_cast<double>(a[2]) * (b[0] * c[1] - b[1] * c[0])) /
         6.0;
  }
  return v;
}

TEST(Mesher, SphereIsClosedFiniteAndOutward) {
  for (const Material m : {materials::kRock, materials::kSand}) {
    Mesh mesh;
    mesh_samples(sphere_grid(24, 8.0f, m), mesh);
    ASSERT_FALSE(mesh.empty());
    expect_closed(mesh);
    expect_finite(mesh);
    const double expected = 4.0 / 3.0 * 3.14159265 * 8.0 * 8.0 * 8.0;
    EXPECT_NEAR(signed_volume(mesh), expected, expected * 0.15) << int{m};
  }
}

TEST(Mesher, SolidCutByTheGridIsClosed) {
  // All solid: the hull of the whole block (outside the grid is Air).
  SampleGrid g({6, 5, 4}, {10, 20, 30}, 2.0f);
  for (auto& o : g.occupancy) o = 1.0f;
  for (auto& m : g.material) m = materials::kGrass;
  Mesh mesh;
  mesh_samples(g, mesh);
  expect_closed(mesh);
  expect_finite(mesh);
  // The hull encloses every sample (the box through the outer samples) and
  // stays within half a sample beyond them (corners are bevelled).
  const double v = signed_volume(mesh);
  EXPECT_GT(v, 5.0 * 2 * 4 * 2 * 3 * 2);
  EXPECT_LE(v, 6.0 * 2 * 5 * 2 * 4 * 2 + 1e-3);
}

TEST(Mesher, ShapingKeepsTopology) {
  Mesh plain, shaped;
  const SampleGrid g = sphere_grid(20, 6.5f, materials::kBasalt);
  mesh_samples(g, plain, MesherOptions{false});
  mesh_samples(g, shaped, MesherOptions{true});
  EXPECT_EQ(plain.indices.size(), shaped.indices.size());
  expect_closed(shaped);
  bool moved = false;
  for (std::size_t i = 0; i < plain.vertices.size(); ++i)
    moved = moved || plain.vertices[i].pos[0] != shaped.vertices[i].pos[0];
  EXPECT_TRUE(moved) << "a sharp material shapes the surface";
}

TEST(Mesher, EmptyGridHasNoTriangles) {
  Mesh mesh;
  mesh_samples(SampleGrid({8, 8, 8}, {0, 0, 0}, 1.0f), mesh);
  EXPECT_TRUE(mesh.empty());
  EXPECT_TRUE(mesh.vertices.empty());
}

TEST(Mesher, TrianglesGrowWithAreaNotVolume) {
  // A solid slab: doubling the grid's side quadruples the top area and
  // multiplies the volume by eight; triangles must follow the area.
  const auto slab = [](int n) {
    SampleGrid g({n, n, n}, {0, 0, 0}, 1.0f);
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n / 2; ++y)
        for (int x = 0; x < n; ++x) g.set(x, y, z, 1.0f, materials::kGround);
    Mesh m;
    mesh_samples(g, m);
    return static_cast<double>(m.triangle_count());
  };
  const double r = slab(32) / slab(16);
  EXPECT_GT(r, 3.5);
  EXPECT_LT(r, 4.5);
  // Spheres: radius x2 gives about 4x the triangles.
  Mesh small, big;
  mesh_samples(sphere_grid(20, 6.0f), small, MesherOptions{false});
  mesh_samples(sphere_grid(36, 12.0f), big, MesherOptions{false});
  const double rs = static_cast<double>(big.triangle_count()) / static_cast<double>(small.triangle_count());
  EXPECT_GT(rs, 3.3);
  EXPECT_LT(rs, 4.7);
}

TEST(Mesher, MaterialAndColourComeFromTheSolid) {
  Mesh mesh;
  mesh_samples(sphere_grid(12, 3.5f, materials::kSand), mesh);
  ASSERT_FALSE(mesh.empty());
  for (const MeshVertex& v : mesh.vertices) EXPECT_GT(v.rgba[0], 150) << "sand is light";  // 214 +- 7%
}

}  // namespace
}  // namespace terrane::view
