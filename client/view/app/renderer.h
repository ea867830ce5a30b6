// Renderer: the OpenGL 3.3 core side of terrane-view. Holds one GPU mesh
// per render chunk, draws the sky, the terrain and a 2D overlay.
//
// Refinement in place: when a new plan replaces render chunks (the camera
// moved, or finer data arrived), the meshes of chunks that left the plan
// stay drawn until every planned chunk overlapping them has its mesh, so
// the terrain never opens while the worker catches up.
//
// Thread: the GL context's thread only.
#pragma once

#include <epoxy/gl.h>

#include <cstdint>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "client/view/mesh_scheduler.h"

namespace terrane::view {

struct Camera {
  Vec3f pos;
  float yaw = 0;    // radians; 0 looks towards -z, positive turns towards +x
  float pitch = 0;  // radians; positive looks up
  float fov_y = 1.1f;
  Vec3f forward() const;
  Vec3f right() const;
  Vec3f up() const;
};

struct FrameParams {
  int width = 0, height = 0;
  Camera camera;
  float view_distance = 384;
  bool sky_key = false;   // sky in pure magenta (tests count uncovered pixels)
  bool lod_tint = false;  // tint each render chunk by its sample level
};

struct RenderStats {
  std::size_t meshes = 0;       // render chunks with a mesh on the GPU
  std::size_t drawn = 0;        // meshes drawn last frame
  std::uint64_t triangles = 0;  // triangles drawn last frame
  std::size_t retired = 0;      // replaced meshes still shown
};

class Renderer {
 public:
  Renderer() = default;
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Compiles shaders; false with *error set (the GL log) on failure.
  bool init(std::string* error);
  void set_plan(const MeshPlanSnapshot& plan);
  // Uploads a finished mesh (ignored if its chunk left the plan).
  void upload(MeshResult&& result);
  // Every planned chunk has a mesh (or is known to have no surface).
  bool complete() const;
  void draw(const FrameParams& frame);

  // Overlay, in pixels from the top-left; flushed by draw_overlay().
  void overlay_rect(float x, float y, float w, float h, const float rgba[4]);
  // Returns the width drawn.
  float overlay_text(float x, float y, const std::string& text, const float rgba[4], float scale = 2);
  void draw_overlay(int width, int height);

  RenderStats stats() const { return stats_; }

 private:
  struct GpuMesh {
    GLuint vao = 0, vbo = 0, ibo = 0;
    GLsizei count = 0;
    int sample_level = 0;
  };
  void release(GpuMesh& m);
  void evict_retired();

  GLuint terrain_program_ = 0, sky_program_ = 0, overlay_program_ = 0;
  GLuint sky_vao_ = 0, overlay_vao_ = 0, overlay_vbo_ = 0;
  std::unordered_map<NodeKey, GpuMesh, NodeKeyHash> meshes_;   // planned chunks
  std::unordered_map<NodeKey, GpuMesh, NodeKeyHash> retired_;  // left the plan, shown until covered
  std::unordered_set<NodeKey, NodeKeyHash> planned_;
  MeshPlanSnapshot plan_;
  bool evict_pending_ = false;
  std::vector<float> overlay_vertices_;  // x, y, r, g, b, a
  RenderStats stats_;
};

}  // namespace terrane::view
