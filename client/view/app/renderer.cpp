#include "client/view/app/renderer.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "client/view/app/font.h"

namespace terrane::view {
namespace {

using Mat4 = std::array<float, 16>;  // column-major

Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int row = 0; row < 4; ++row) {
      float s = 0;
      for (int k = 0; k < 4; ++k) s += a[static_cast<std::size_t>(k * 4 + row)] * b[static_cast<std::size_t>(c * 4 + k)];
      r[static_cast<std::size_t>(c * 4 + row)] = s;
    }
  return r;
}

Mat4 perspective(float fov_y, float aspect, float near_z, float far_z) {
  const float f = 1.0f / std::tan(fov_y / 2);
  Mat4 m{};
  m[0] = f / aspect;
  m[5] = f;
  m[10] = (far_z + near_z) / (near_z - far_z);
  m[11] = -1;
  m[14] = 2 * far_z * near_z / (near_z - far_z);
  return m;
}

float dot(Vec3f a, Vec3f b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

Mat4 look(const Camera& c) {
  const Vec3f f = c.forward(), r = c.right(), u = c.up();
  Mat4 m{};
  m[0] = r.x, m[4] = r.y, m[8] = r.z;
  m[1] = u.x, m[5] = u.y, m[9] = u.z;
  m[2] = -f.x, m[6] = -f.y, m[10] = -f.z;
  m[12] = -dot(r, c.pos);
  m[13] = -dot(u, c.pos);
  m[14] = dot(f, c.pos);
  m[15] = 1;
  return m;
}

constexpr const char* kTerrainVs = R"(#version 330 core
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec4 a_color;
uniform mat4 u_view_proj;
out vec3 v_pos;
out vec3 v_normal;
out vec4 v_color;
void main() {
  v_pos = a_pos;
  v_normal = a_normal;
  v_color = a_color;
  gl_Position = u_view_proj * vec4(a_pos, 1.0);
}
)";

// Lighting: a warm sun, a blue sky dome from above, bounce light from
// below; sharp materials blend towards flat per-triangle normals. Back
// faces (seen from inside solid matter) are a dark rock colour.
constexpr const char* kTerrainFs = R"(#version 330 core
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_color;
uniform vec3 u_camera;
uniform vec3 u_sun;
uniform vec3 u_fog_color;
uniform vec2 u_fog;        // start, end (world units)
uniform vec4 u_tint;       // rgb, amount
out vec4 o_color;
void main() {
  if (!gl_FrontFacing) { o_color = vec4(0.11, 0.10, 0.09, 1.0); return; }
  vec3 n = normalize(v_normal);
  vec3 flat_n = normalize(cross(dFdx(v_pos), dFdy(v_pos)));
  if (dot(flat_n, n) < 0.0) flat_n = -flat_n;
  n = normalize(mix(n, flat_n, v_color.a * 0.85));
  vec3 base = pow(v_color.rgb, vec3(2.2));
  base = mix(base, u_tint.rgb, u_tint.a);
  float sun = max(dot(n, u_sun), 0.0);
  float sky = 0.55 + 0.45 * n.y;
  float bounce = 0.5 - 0.5 * n.y;
  vec3 light = vec3(1.00, 0.93, 0.80) * sun * 1.25 + vec3(0.36, 0.46, 0.64) * sky * 0.75 +
               vec3(0.30, 0.26, 0.20) * bounce * 0.25;
  vec3 c = base * light;
  float d = length(v_pos - u_camera);
  float fog = clamp((d - u_fog.x) / max(u_fog.y - u_fog.x, 1.0), 0.0, 0.9);
  c = mix(c, pow(u_fog_color, vec3(2.2)), fog * fog);
  o_color = vec4(pow(c, vec3(1.0 / 2.2)), 1.0);
}
)";

constexpr const char* kSkyVs = R"(#version 330 core
out vec2 v_ndc;
void main() {
  vec2 p = vec2((gl_VertexID == 1) ? 3.0 : -1.0, (gl_VertexID == 2) ? 3.0 : -1.0);
  v_ndc = p;
  gl_Position = vec4(p, 1.0, 1.0);
}
)";

constexpr const char* kSkyFs = R"(#version 330 core
in vec2 v_ndc;
uniform vec3 u_forward;
uniform vec3 u_right;  // scaled by tan(fov/2) * aspect
uniform vec3 u_up;     // scaled by tan(fov/2)
uniform vec3 u_sun;
uniform int u_key;
out vec4 o_color;
void main() {
  if (u_key != 0) { o_color = vec4(1.0, 0.0, 1.0, 1.0); return; }
  vec3 dir = normalize(u_forward + v_ndc.x * u_right + v_ndc.y * u_up);
  vec3 zenith = vec3(0.24, 0.45, 0.80), horizon = vec3(0.74, 0.84, 0.94), ground = vec3(0.55, 0.60, 0.64);
  vec3 c = dir.y >= 0.0 ? mix(horizon, zenith, pow(dir.y, 0.55)) : mix(horizon, ground, min(-dir.y * 4.0, 1.0));
  float s = max(dot(dir, u_sun), 0.0);
  c += vec3(1.0, 0.9, 0.7) * (pow(s, 600.0) * 1.5 + pow(s, 12.0) * 0.18);
  o_color = vec4(min(c, vec3(1.0)), 1.0);
}
)";

constexpr const char* kOverlayVs = R"(#version 330 core
layout(location = 0) in vec2 a_pos;
layout(location = 1) in vec4 a_color;
uniform vec2 u_screen;
out vec4 v_color;
void main() {
  v_color = a_color;
  gl_Position = vec4(a_pos.x / u_screen.x * 2.0 - 1.0, 1.0 - a_pos.y / u_screen.y * 2.0, 0.0, 1.0);
}
)";

constexpr const char* kOverlayFs = R"(#version 330 core
in vec4 v_color;
out vec4 o_color;
void main() { o_color = v_color; }
)";

const Vec3f kSun = [] {
  const Vec3f s{0.45f, 0.62f, 0.38f};
  const float l = std::sqrt(dot(s, s));
  return s * (1.0f / l);
}();
constexpr float kFogColor[3] = {0.74f, 0.84f, 0.94f};  // the sky's horizon

GLuint compile(GLenum type, const char* src, std::string* error) {
  const GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &src, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[2048];
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    *error = std::string("shader compile failed: ") + log;
    glDeleteShader(s);
    return 0;
  }
  return s;
}

GLuint link(const char* vs, const char* fs, std::string* error) {
  const GLuint v = compile(GL_VERTEX_SHADER, vs, error);
  if (!v) return 0;
  const GLuint f = compile(GL_FRAGMENT_SHADER, fs, error);
  if (!f) return 0;
  const GLuint p = glCreateProgram();
  glAttachShader(p, v);
  glAttachShader(p, f);
  glLinkProgram(p);
  glDeleteShader(v);
  glDeleteShader(f);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[2048];
    glGetProgramInfoLog(p, sizeof log, nullptr, log);
    *error = std::string("shader link failed: ") + log;
    return 0;
  }
  return p;
}

GLint loc(GLuint program, const char* name) { return glGetUniformLocation(program, name); }

const void* offset(std::size_t bytes) { return reinterpret_cast<const void*>(bytes); }

bool overlaps(const Region& a, const Region& b) { return !intersect(a, b).empty(); }

// The six clip planes of a view-projection matrix (Gribb and Hartmann),
// each (a, b, c, d) with inside meaning a x + b y + c z + d >= 0.
std::array<std::array<float, 4>, 6> frustum_planes(const Mat4& m) {
  const auto row = [&](int r, int c) { return m[static_cast<std::size_t>(c * 4 + r)]; };
  std::array<std::array<float, 4>, 6> p{};
  for (int i = 0; i < 3; ++i)
    for (int sgn = 0; sgn < 2; ++sgn) {
      auto& pl = p[static_cast<std::size_t>(i * 2 + sgn)];
      for (int c = 0; c < 4; ++c) pl[static_cast<std::size_t>(c)] = row(3, c) + (sgn ? -row(i, c) : row(i, c));
    }
  return p;
}

// False when the box lies wholly outside one plane.
bool box_visible(const std::array<std::array<float, 4>, 6>& planes, const Region& r, float margin) {
  for (const auto& p : planes) {
    const float x = p[0] >= 0 ? static_cast<float>(r.max.x) + margin : static_cast<float>(r.min.x) - margin;
    const float y = p[1] >= 0 ? static_cast<float>(r.max.y) + margin : static_cast<float>(r.min.y) - margin;
    const float z = p[2] >= 0 ? static_cast<float>(r.max.z) + margin : static_cast<float>(r.min.z) - margin;
    if (p[0] * x + p[1] * y + p[2] * z + p[3] < 0) return false;
  }
  return true;
}

}  // namespace

Vec3f Camera::forward() const {
  return {std::sin(yaw) * std::cos(pitch), std::sin(pitch), -std::cos(yaw) * std::cos(pitch)};
}
Vec3f Camera::right() const { return {std::cos(yaw), 0.0f, std::sin(yaw)}; }
Vec3f Camera::up() const {
  const Vec3f f = forward(), r = right();
  return {r.y * f.z - r.z * f.y, r.z * f.x - r.x * f.z, r.x * f.y - r.y * f.x};
}

Renderer::~Renderer() {
  for (auto& [k, m] : meshes_) release(m);
  for (auto& [k, m] : retired_) release(m);
  if (terrain_program_) glDeleteProgram(terrain_program_);
  if (sky_program_) glDeleteProgram(sky_program_);
  if (overlay_program_) glDeleteProgram(overlay_program_);
  if (sky_vao_) glDeleteVertexArrays(1, &sky_vao_);
  if (overlay_vao_) glDeleteVertexArrays(1, &overlay_vao_);
  if (overlay_vbo_) glDeleteBuffers(1, &overlay_vbo_);
}

bool Renderer::init(std::string* error) {
  terrain_program_ = link(kTerrainVs, kTerrainFs, error);
  if (!terrain_program_) return false;
  sky_program_ = link(kSkyVs, kSkyFs, error);
  if (!sky_program_) return false;
  overlay_program_ = link(kOverlayVs, kOverlayFs, error);
  if (!overlay_program_) return false;
  glGenVertexArrays(1, &sky_vao_);
  glGenVertexArrays(1, &overlay_vao_);
  glGenBuffers(1, &overlay_vbo_);
  glBindVertexArray(overlay_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, overlay_vbo_);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, 6 * sizeof(float), offset(0));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 4, GL_FLOAT, GL_FALSE, 6 * sizeof(float), offset(2 * sizeof(float)));
  glBindVertexArray(0);
  return true;
}

void Renderer::release(GpuMesh& m) {
  if (m.vao) glDeleteVertexArrays(1, &m.vao);
  if (m.vbo) glDeleteBuffers(1, &m.vbo);
  if (m.ibo) glDeleteBuffers(1, &m.ibo);
  m = GpuMesh{};
}

void Renderer::set_plan(const MeshPlanSnapshot& plan) {
  if (plan.generation == plan_.generation) return;
  plan_ = plan;
  planned_.clear();
  planned_.insert(plan.chunks.begin(), plan.chunks.end());
  for (auto it = meshes_.begin(); it != meshes_.end();) {
    if (planned_.count(it->first)) {
      ++it;
      continue;
    }
    // Left the plan: keep it drawn until the chunks replacing it are meshed.
    auto [rit, fresh] = retired_.try_emplace(it->first, it->second);
    if (!fresh) {
      release(rit->second);
      rit->second = it->second;
    }
    it = meshes_.erase(it);
  }
  evict_pending_ = true;
}

void Renderer::upload(MeshResult&& r) {
  if (!planned_.count(r.key)) return;
  GpuMesh& m = meshes_[r.key];
  m.sample_level = r.sample_level;
  if (r.mesh.empty()) {
    release(m);
    m.sample_level = r.sample_level;
  } else {
    if (!m.vao) {
      glGenVertexArrays(1, &m.vao);
      glGenBuffers(1, &m.vbo);
      glGenBuffers(1, &m.ibo);
    }
    glBindVertexArray(m.vao);
    glBindBuffer(GL_ARRAY_BUFFER, m.vbo);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(r.mesh.vertices.size() * sizeof(MeshVertex)),
                 r.mesh.vertices.data(), GL_STATIC_DRAW);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, m.ibo);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(r.mesh.indices.size() * sizeof(std::uint32_t)),
                 r.mesh.indices.data(), GL_STATIC_DRAW);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(MeshVertex), offset(offsetof(MeshVertex, pos)));
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, sizeof(MeshVertex), offset(offsetof(MeshVertex, normal)));
    glEnableVertexAttribArray(2);
    glVertexAttribPointer(2, 4, GL_UNSIGNED_BYTE, GL_TRUE, sizeof(MeshVertex), offset(offsetof(MeshVertex, rgba)));
    glBindVertexArray(0);
    m.count = static_cast<GLsizei>(r.mesh.indices.size());
  }
  evict_pending_ = true;
}

bool Renderer::complete() const {
  for (const NodeKey& k : plan_.chunks)
    if (!meshes_.count(k)) return false;
  return true;
}

void Renderer::evict_retired() {
  if (!evict_pending_) return;
  evict_pending_ = false;
  for (auto it = retired_.begin(); it != retired_.end();) {
    const Region r = it->first.region();
    bool covered = true;
    for (const NodeKey& k : plan_.chunks) {
      if (!meshes_.count(k) && overlaps(k.region(), r)) {
        covered = false;
        break;
      }
    }
    if (covered) {
      release(it->second);
      it = retired_.erase(it);
    } else {
      ++it;
    }
  }
}

void Renderer::draw(const FrameParams& f) {
  evict_retired();
  glViewport(0, 0, f.width, f.height);
  glClearColor(0, 0, 0, 1);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  const float aspect = static_cast<float>(f.width) / static_cast<float>(std::max(f.height, 1));
  const float t = std::tan(f.camera.fov_y / 2);

  // Sky: a full-screen triangle behind everything.
  glDisable(GL_DEPTH_TEST);
  glUseProgram(sky_program_);
  const Vec3f fw = f.camera.forward(), rt = f.camera.right() * (t * aspect), up = f.camera.up() * t;
  glUniform3f(loc(sky_program_, "u_forward"), fw.x, fw.y, fw.z);
  glUniform3f(loc(sky_program_, "u_right"), rt.x, rt.y, rt.z);
  glUniform3f(loc(sky_program_, "u_up"), up.x, up.y, up.z);
  glUniform3f(loc(sky_program_, "u_sun"), kSun.x, kSun.y, kSun.z);
  glUniform1i(loc(sky_program_, "u_key"), f.sky_key ? 1 : 0);
  glBindVertexArray(sky_vao_);
  glDrawArrays(GL_TRIANGLES, 0, 3);

  // Terrain: both faces (back faces are the inside of solid matter).
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_CULL_FACE);
  glUseProgram(terrain_program_);
  const Mat4 vp = multiply(perspective(f.camera.fov_y, aspect, 0.1f, f.view_distance * 2.5f + 64.0f), look(f.camera));
  glUniformMatrix4fv(loc(terrain_program_, "u_view_proj"), 1, GL_FALSE, vp.data());
  glUniform3f(loc(terrain_program_, "u_camera"), f.camera.pos.x, f.camera.pos.y, f.camera.pos.z);
  glUniform3f(loc(terrain_program_, "u_sun"), kSun.x, kSun.y, kSun.z);
  glUniform3f(loc(terrain_program_, "u_fog_color"), kFogColor[0], kFogColor[1], kFogColor[2]);
  glUniform2f(loc(terrain_program_, "u_fog"), f.view_distance * 0.35f, f.view_distance * 1.1f);
  const GLint tint = loc(terrain_program_, "u_tint");
  // Sample level 0 (full resolution) green, then yellow, orange, red, purple.
  static constexpr float kTints[5][3] = {
      {0.10f, 0.80f, 0.15f}, {0.95f, 0.85f, 0.10f}, {0.95f, 0.45f, 0.05f}, {0.85f, 0.08f, 0.08f}, {0.55f, 0.15f, 0.75f}};
  stats_ = RenderStats{meshes_.size(), 0, 0, retired_.size()};
  const auto planes = frustum_planes(vp);
  const auto draw_mesh = [&](const NodeKey& k, const GpuMesh& m) {
    if (m.count == 0) return;
    // A chunk's mesh reaches one sample (at most 16 voxels) beyond its cube.
    if (!box_visible(planes, k.region(), 17.0f)) return;
    const auto& c = kTints[std::clamp(m.sample_level, 0, 4)];
    glUniform4f(tint, c[0], c[1], c[2], f.lod_tint ? 0.55f : 0.0f);
    glBindVertexArray(m.vao);
    glDrawElements(GL_TRIANGLES, m.count, GL_UNSIGNED_INT, nullptr);
    ++stats_.drawn;
    stats_.triangles += static_cast<std::uint64_t>(m.count / 3);
  };
  for (const auto& [k, m] : meshes_) draw_mesh(k, m);
  for (const auto& [k, m] : retired_) draw_mesh(k, m);
  glBindVertexArray(0);
}

void Renderer::overlay_rect(float x, float y, float w, float h, const float c[4]) {
  const float v[6][2] = {{x, y}, {x + w, y}, {x + w, y + h}, {x, y}, {x + w, y + h}, {x, y + h}};
  for (const auto& p : v) overlay_vertices_.insert(overlay_vertices_.end(), {p[0], p[1], c[0], c[1], c[2], c[3]});
}

float Renderer::overlay_text(float x, float y, const std::string& text, const float c[4], float scale) {
  float cx = x;
  for (const char ch : text) {
    if (const Glyph* g = find_glyph(ch)) {
      for (int row = 0; row < 7; ++row)
        for (int col = 0; col < 5; ++col)
          if ((g->rows[static_cast<std::size_t>(row)] >> (4 - col)) & 1)
            overlay_rect(cx + static_cast<float>(col) * scale, y + static_cast<float>(row) * scale, scale, scale, c);
    }
    cx += 6 * scale;
  }
  return cx - x;
}

void Renderer::draw_overlay(int width, int height) {
  if (overlay_vertices_.empty()) return;
  glDisable(GL_DEPTH_TEST);
  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  glUseProgram(overlay_program_);
  glUniform2f(loc(overlay_program_, "u_screen"), static_cast<float>(width), static_cast<float>(height));
  glBindVertexArray(overlay_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, overlay_vbo_);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(overlay_vertices_.size() * sizeof(float)),
               overlay_vertices_.data(), GL_STREAM_DRAW);
  glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(overlay_vertices_.size() / 6));
  glBindVertexArray(0);
  glDisable(GL_BLEND);
  overlay_vertices_.clear();
}

}  // namespace terrane::view
