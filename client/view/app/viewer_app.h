// The terrane-view application: options, the connection and the two
// front ends (a GLFW window, or one headless screenshot through EGL).
#pragma once

#include <optional>
#include <string>

#include "client/client.h"
#include "client/view/app/renderer.h"
#include "client/view/mesh_scheduler.h"

namespace terrane::view {

struct ViewerOptions {
  std::string host = "127.0.0.1";
  std::uint16_t port = 0;
  std::string token;                      // --token: auth token for the server
  std::string screenshot;                 // headless when set
  std::optional<Camera> camera;           // --camera; else looking at the spawn
  bool wait_full_res = false;
  bool mips_only = false;
  int width = 1280, height = 720;
  int view_distance = 2048;  // the server's default: the whole horizon (estimated where never generated)
  int full_res_radius = 128;
  double timeout_s = 120;
  bool sky_key = false;
  bool overlay = false;   // headless: draw the overlay into the picture
  bool lod_tint = false;
  bool enhance = false;  // detail enhancement + snowflake lighting near the camera
  int msaa = 4;
  std::string chunk_cache;  // --chunk-cache DIR: chunks kept across sessions (client/chunk_cache.h)
};

// Parses argv; returns 0 to go on, -1 after printing --help (exit 0), or 2
// after printing an error naming the flag (bad usage).
int parse_viewer_options(int argc, char** argv, ViewerOptions& out);

// The connection and the mesher, shared by both front ends.
class ViewerSession {
 public:
  explicit ViewerSession(const ViewerOptions& options);
  // Connects and waits for the Welcome; false with *error set.
  bool start(std::string* error, double timeout_s);
  Client& client() { return *client_; }
  MeshScheduler& scheduler() { return *scheduler_; }
  const WelcomeMsg& welcome() const { return welcome_; }
  Camera& camera() { return camera_; }
  LodParams lod() const { return lod_; }
  // Sends the camera position to the server and the mesher.
  void send_camera();
  void set_enhance(bool on);
  std::int32_t view_distance() const;
  std::int32_t full_res_radius() const;

 private:
  ViewerOptions options_;
  std::unique_ptr<Client> client_;
  std::unique_ptr<MeshScheduler> scheduler_;
  WelcomeMsg welcome_;
  Camera camera_;
  LodParams lod_;
};

int run_screenshot(const ViewerOptions& options);
int run_window(const ViewerOptions& options);

// The overlay: FPS, bandwidth, counts of chunks by form, a top-down map of which
// chunk columns are held at full resolution and which as mips, and the
// tool line. Shared by both front ends.
struct OverlayInfo {
  double fps = 0;  // < 0: headless (no frame rate; the renderer's name instead)
  std::string renderer;
  double bytes_in_per_s = 0;
  std::string tool;
  std::string status;
};
void draw_overlay(Renderer& renderer, ViewerSession& session, const OverlayInfo& info, int width, int height);

}  // namespace terrane::view
