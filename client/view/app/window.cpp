// The interactive front end: a GLFW window with an OpenGL 3.3 core context.
// libepoxy's header must come before GLFW's (which otherwise pulls GL/gl.h).
#include <epoxy/gl.h>
#include <GLFW/glfw3.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "client/view/app/viewer_app.h"

namespace terrane::view {
namespace {

// Build materials on keys 1..9.
constexpr std::array<Material, 9> kPalette = {materials::kGrass, materials::kRock,  materials::kSand,
                                              materials::kSnow,  materials::kBrick, materials::kConcrete,
                                              materials::kBasalt, materials::kWoodPlanks, materials::kIce};

struct InputState {
  bool dig = true;  // tool: dig (fill with Air) or build
  int material = 1;
  float radius = 4;
  bool overlay = true;
  bool lod_tint = false;
  bool enhance = false;
  bool enhance_changed = false;
  bool click = false;
  bool undo = false, redo = false;
  std::string status;
  double status_until = 0;
};

InputState* input_of(GLFWwindow* w) { return static_cast<InputState*>(glfwGetWindowUserPointer(w)); }

void on_key(GLFWwindow* w, int key, int, int action, int mods) {
  if (action != GLFW_PRESS) return;
  InputState& in = *input_of(w);
  const bool ctrl = (mods & GLFW_MOD_CONTROL) != 0;
  if (key == GLFW_KEY_ESCAPE) glfwSetWindowShouldClose(w, GLFW_TRUE);
  if (key == GLFW_KEY_Q) in.dig = !in.dig;
  if (key >= GLFW_KEY_1 && key <= GLFW_KEY_9) {
    in.material = key - GLFW_KEY_1;
    in.dig = false;
  }
  if (key == GLFW_KEY_LEFT_BRACKET) in.radius = std::max(1.0f, in.radius - 1);
  if (key == GLFW_KEY_RIGHT_BRACKET) in.radius = std::min(24.0f, in.radius + 1);
  if (key == GLFW_KEY_L) in.lod_tint = !in.lod_tint;
  if (key == GLFW_KEY_F1) in.overlay = !in.overlay;
  if (key == GLFW_KEY_E) {
    in.enhance = !in.enhance;
    in.enhance_changed = true;
  }
  // Undo and redo run on the server, per connection: only voxels still as
  // this viewer left them are restored.
  if (ctrl && key == GLFW_KEY_Z) in.undo = true;
  if (ctrl && key == GLFW_KEY_Y) in.redo = true;
}

void on_mouse(GLFWwindow* w, int button, int action, int) {
  if (button == GLFW_MOUSE_BUTTON_LEFT && action == GLFW_PRESS) input_of(w)->click = true;
}

}  // namespace

int run_window(const ViewerOptions& options) {
  if (!glfwInit()) {
    std::fprintf(stderr, "terrane-view: GLFW cannot initialise (no display? use --screenshot for headless)\n");
    return 1;
  }
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_SAMPLES, 4);
  GLFWwindow* window = glfwCreateWindow(options.width, options.height, "terrane-view", nullptr, nullptr);
  if (!window) {
    std::fprintf(stderr, "terrane-view: cannot open an OpenGL 3.3 core window\n");
    glfwTerminate();
    return 1;
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(1);
  int rc = 0;
  {
    Renderer renderer;
    std::string error;
    ViewerSession session(options);
    if (!renderer.init(&error) || !session.start(&error, options.timeout_s)) {
      std::fprintf(stderr, "terrane-view: %s\n", error.c_str());
      rc = 1;
    } else {
      InputState in;
      in.lod_tint = options.lod_tint;
      in.enhance = options.enhance;
      glfwSetWindowUserPointer(window, &in);
      glfwSetKeyCallback(window, on_key);
      glfwSetMouseButtonCallback(window, on_mouse);
      double last = glfwGetTime(), fps_t = last, mx = 0, my = 0, fps = 0, bw = 0, last_sent = 0;
      int frames = 0;
      std::uint64_t bytes_at = 0, frames_seen = 0;
      Vec3f sent_pos = session.camera().pos;
      bool looking = false;
      while (!glfwWindowShouldClose(window) && !session.client().closed()) {
        glfwPollEvents();
        const double now = glfwGetTime();
        const float dt = static_cast<float>(std::min(now - last, 0.1));
        last = now;
        Camera& cam = session.camera();
        // Look: hold the right button.
        double cx = 0, cy = 0;
        glfwGetCursorPos(window, &cx, &cy);
        const bool rb = glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS;
        if (rb && looking) {
          cam.yaw += static_cast<float>(cx - mx) * 0.003f;
          cam.pitch = std::clamp(cam.pitch - static_cast<float>(cy - my) * 0.003f, -1.55f, 1.55f);
        }
        looking = rb;
        mx = cx;
        my = cy;
        const float speed = (glfwGetKey(window, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS ? 120.0f : 30.0f) * dt;
        const auto key = [&](int k) { return glfwGetKey(window, k) == GLFW_PRESS ? 1.0f : 0.0f; };
        const Vec3f f = cam.forward(), r = cam.right();
        cam.pos = cam.pos + f * ((key(GLFW_KEY_W) - key(GLFW_KEY_S)) * speed) +
                  r * ((key(GLFW_KEY_D) - key(GLFW_KEY_A)) * speed) +
                  Vec3f{0, (key(GLFW_KEY_SPACE) - key(GLFW_KEY_C)) * speed, 0};
        const Vec3f moved = cam.pos - sent_pos;
        if (std::sqrt(moved.x * moved.x + moved.y * moved.y + moved.z * moved.z) > 4.0f && now - last_sent > 0.2) {
          session.send_camera();
          sent_pos = cam.pos;
          last_sent = now;
        }
        if (in.click) {
          in.click = false;
          if (auto hit = session.client().raycast(cam.pos, f, 512.0f)) {
            const Vec3i at = in.dig ? hit->voxel : hit->voxel + hit->normal;
            const Vec3f centre{static_cast<float>(at.x) + 0.5f, static_cast<float>(at.y) + 0.5f,
                               static_cast<float>(at.z) + 0.5f};
            if (session.client().fill_sphere(centre, in.radius,
                                             in.dig ? kAir : kPalette[static_cast<std::size_t>(in.material)]) == 0) {
              in.status = "EDIT NOT SENT (QUEUE FULL OR CLOSED)";
              in.status_until = now + 3;
            }
          } else {
            in.status = "NOTHING AT FULL RESOLUTION UNDER THE CROSSHAIR";
            in.status_until = now + 2;
          }
        }
        if (in.undo || in.redo) {
          const bool redo = in.redo;
          in.undo = in.redo = false;
          if ((redo ? session.client().redo() : session.client().undo()) == 0) {
            in.status = "EDIT NOT SENT (QUEUE FULL OR CLOSED)";
            in.status_until = now + 3;
          }
        }
        if (in.enhance_changed) {
          in.enhance_changed = false;
          session.set_enhance(in.enhance);
        }
        const ClientCounters c = session.client().counters();
        if (c.frames_in != frames_seen) {
          frames_seen = c.frames_in;
          session.scheduler().mark_dirty();
        }
        renderer.set_plan(session.scheduler().plan());
        for (MeshResult& m : session.scheduler().take_results()) renderer.upload(std::move(m));
        int w = 0, h = 0;
        glfwGetFramebufferSize(window, &w, &h);
        FrameParams fp;
        fp.width = w;
        fp.height = h;
        fp.camera = cam;
        fp.view_distance = static_cast<float>(session.view_distance());
        fp.lod_tint = in.lod_tint;
        renderer.draw(fp);
        ++frames;
        if (now - fps_t >= 0.5) {
          fps = frames / (now - fps_t);
          bw = static_cast<double>(c.bytes_in - bytes_at) / (now - fps_t);
          bytes_at = c.bytes_in;
          frames = 0;
          fps_t = now;
        }
        // Crosshair.
        static constexpr float kWhite[4] = {1, 1, 1, 0.8f};
        renderer.overlay_rect(static_cast<float>(w) / 2 - 8, static_cast<float>(h) / 2 - 1, 16, 2, kWhite);
        renderer.overlay_rect(static_cast<float>(w) / 2 - 1, static_cast<float>(h) / 2 - 8, 2, 16, kWhite);
        if (in.overlay) {
          OverlayInfo info;
          info.fps = fps;
          info.bytes_in_per_s = bw;
          char tool[128];
          std::snprintf(tool, sizeof tool, "TOOL %s  RADIUS %.0f  MATERIAL %d %s", in.dig ? "DIG" : "BUILD",
                        static_cast<double>(in.radius), in.material + 1,
                        std::string(kDefaultMaterialNames[kPalette[static_cast<std::size_t>(in.material)]]).c_str());
          info.tool = tool;
          if (now < in.status_until) info.status = in.status;
          draw_overlay(renderer, session, info, w, h);
        }
        renderer.draw_overlay(w, h);
        glfwSwapBuffers(window);
      }
      if (session.client().closed())
        std::fprintf(stderr, "terrane-view: disconnected: %s\n", session.client().disconnect_reason().c_str());
      session.client().disconnect();
    }
  }
  glfwDestroyWindow(window);
  glfwTerminate();
  return rc;
}

}  // namespace terrane::view
