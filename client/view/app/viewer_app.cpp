#include "client/view/app/viewer_app.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <thread>
#include <unordered_map>

#include "client/view/app/headless.h"
#include "client/view/png.h"
#include "client/view/replica_source.h"
#include "common/cli/cli.h"
#include "common/voxel/chunk.h"

namespace terrane::view {
namespace {

constexpr const char* kUsage = R"(usage: terrane-view --connect HOST:PORT [options]

Renders a Terrane world streamed from a terrane-server.

  --connect HOST:PORT      server to join (required)
  --token T                auth token (the server's --auth-token, or this
                           viewer's name "terrane-view" in its tokens file)
  --screenshot FILE.png    render one picture headless (EGL, no display) and exit
  --camera X,Y,Z,YAW,PITCH camera position (voxels) and angles (degrees; yaw 0
                           looks towards -z, 90 towards +x; pitch up positive);
                           default: above the spawn point, looking at it
  --size WxH               image or window size (default 1280x720)
  --wait-full-res          screenshot: wait until streaming has refined every
                           chunk to the level its distance asks for
                           (default: shoot once every chunk has its first mip)
  --mips-only              ask for no full-resolution data and mesh mips only
  --view-distance N        voxels (default 2048, capped by the server's maximum)
  --full-res-radius N      voxels (default 128)
  --timeout S              screenshot: give up after S seconds (default 120)
  --msaa N                 screenshot: samples per pixel (default 4, 1 = off)
  --chunk-cache DIR        keep the chunks seen in DIR (at most 1 GiB) and join
                           from them next time: the server sends only what
                           changed since (default: none)
  --overlay                screenshot: draw the overlay into the picture
  --enhance                detail enhancement (2x2x2 fragments per voxel by
                           recursive subdivision) with snowflake lighting for
                           the full-resolution render chunks near the camera
  --lod-tint               tint render chunks by resolution (green full, yellow
                           mip 1, orange mip 2, red mip 3, purple coarser)
  --sky-key                paint the sky pure magenta (tests count sky pixels)
  --help                   this text

Window controls: W A S D move, Space / C up / down, Shift fast, hold the right
mouse button to look, left click applies the tool at the crosshair, Q switches
dig / build, 1-9 pick the build material, [ ] brush radius, L resolution tint,
E detail enhancement, F1 overlay, Ctrl+Z / Ctrl+Y undo / redo of this
viewer's edits (on the server), Esc quits.
)";

float radians(float deg) { return deg * 3.14159265f / 180.0f; }

bool parse_floats(const std::string& text, float* out, int n) {
  std::size_t at = 0;
  for (int i = 0; i < n; ++i) {
    const std::size_t end = text.find(',', at);
    const std::string part = text.substr(at, end == std::string::npos ? std::string::npos : end - at);
    try {
      std::size_t used = 0;
      out[i] = std::stof(part, &used);
      if (used != part.size() || !std::isfinite(out[i])) return false;
    } catch (...) {
      return false;
    }
    if (i + 1 < n) {
      if (end == std::string::npos) return false;
      at = end + 1;
    } else if (end != std::string::npos) {
      return false;
    }
  }
  return true;
}

int usage_error(const std::string& message) {
  std::fprintf(stderr, "terrane-view: %s\n(terrane-view --help lists the options)\n", message.c_str());
  return 2;
}

}  // namespace

int parse_viewer_options(int argc, char** argv, ViewerOptions& o) {
  CommandLine cl({"connect", "token", "screenshot", "camera", "size", "view-distance", "full-res-radius", "timeout", "msaa", "chunk-cache"},
                 {"help", "wait-full-res", "mips-only", "sky-key", "overlay", "lod-tint", "enhance"});
  if (std::string err = cl.parse(argc, argv, 1); !err.empty()) return usage_error(err);
  if (cl.flag("help")) {
    std::fputs(kUsage, stdout);
    return -1;
  }
  if (!cl.positional().empty()) return usage_error("unexpected argument '" + cl.positional()[0] + "'");
  if (!cl.has("connect")) return usage_error("--connect HOST:PORT is required");
  const std::string c = cl.get("connect");
  const auto colon = c.rfind(':');
  int port = 0;
  if (colon == std::string::npos || colon == 0 || !parse_int_list<int>(std::string_view(c).substr(colon + 1), &port, 1) ||
      port <= 0 || port > 65535)
    return usage_error("--connect: expected HOST:PORT, got '" + c + "'");
  o.host = c.substr(0, colon);
  o.port = static_cast<std::uint16_t>(port);
  o.screenshot = cl.get("screenshot");
  if (cl.has("token")) o.token = cl.get("token");
  if (cl.has("camera")) {
    float v[5];
    if (!parse_floats(cl.get("camera"), v, 5))
      return usage_error("--camera: expected X,Y,Z,YAW,PITCH numbers, got '" + cl.get("camera") + "'");
    Camera cam;
    cam.pos = {v[0], v[1], v[2]};
    cam.yaw = radians(v[3]);
    cam.pitch = radians(std::clamp(v[4], -89.0f, 89.0f));
    o.camera = cam;
  }
  if (cl.has("size")) {
    const std::string s = cl.get("size");
    const auto x = s.find('x');
    int w = 0, h = 0;
    if (x == std::string::npos || !parse_int_list<int>(std::string_view(s).substr(0, x), &w, 1) ||
        !parse_int_list<int>(std::string_view(s).substr(x + 1), &h, 1) || w < 16 || h < 16 || w > 8192 || h > 8192)
      return usage_error("--size: expected WxH with each in 16..8192, got '" + s + "'");
    o.width = w;
    o.height = h;
  }
  std::string err;
  o.view_distance = static_cast<int>(cl.get_int("view-distance", o.view_distance, 32, 4096, &err));
  o.full_res_radius = static_cast<int>(cl.get_int("full-res-radius", o.full_res_radius, 1, 4096, &err));
  o.timeout_s = cl.get_double("timeout", o.timeout_s, 1, 3600, &err);
  o.msaa = static_cast<int>(cl.get_int("msaa", o.msaa, 1, 16, &err));
  if (!err.empty()) return usage_error(err);
  o.wait_full_res = cl.flag("wait-full-res");
  o.mips_only = cl.flag("mips-only");
  o.sky_key = cl.flag("sky-key");
  o.overlay = cl.flag("overlay");
  o.lod_tint = cl.flag("lod-tint");
  o.enhance = cl.flag("enhance");
  if (cl.has("chunk-cache")) {
    o.chunk_cache = cl.get("chunk-cache");
    if (o.chunk_cache.empty()) return usage_error("--chunk-cache: expected a directory");
  }
  if (o.mips_only && o.wait_full_res) return usage_error("--mips-only and --wait-full-res exclude each other");
  if (o.screenshot.empty() && (cl.flag("wait-full-res") || cl.has("timeout") || cl.has("msaa") || cl.flag("overlay")))
    return usage_error("--wait-full-res, --timeout, --msaa and --overlay need --screenshot");
  return 0;
}

ViewerSession::ViewerSession(const ViewerOptions& options) : options_(options) {}

std::int32_t ViewerSession::view_distance() const {
  return std::min<std::int32_t>(options_.view_distance, welcome_.max_view_distance);
}
std::int32_t ViewerSession::full_res_radius() const {
  // Mips only: a radius of one voxel (0 would ask for the server's default)
  // and the mesher never samples level 0.
  const std::int32_t want = options_.mips_only ? 1 : options_.full_res_radius;
  return std::min({want, welcome_.max_full_res_radius, view_distance()});
}

namespace {
// Where the camera starts without --camera: up and back from the spawn.
constexpr Vec3f kDefaultCameraOffset{-70.0f, 45.0f, 70.0f};
}  // namespace

bool ViewerSession::start(std::string* error, double timeout_s) {
  ClientOptions co;
  co.host = options_.host;
  co.port = options_.port;
  co.name = "terrane-view";
  co.auth_token = options_.token;
  co.state.view_distance = options_.view_distance;
  co.state.full_res_radius = options_.mips_only ? 1 : options_.full_res_radius;
  if (options_.camera) {
    co.state.position = options_.camera->pos;
    co.start_at_spawn = false;
  } else {
    // The first position the server sees is the default camera's: it
    // limits how fast a client moves after that.
    co.spawn_offset = kDefaultCameraOffset;
  }
  if (!options_.chunk_cache.empty()) {
    auto cache = ChunkCache::open(options_.chunk_cache, std::uint64_t{1} << 30);
    if (!cache) {
      *error = "--chunk-cache: " + cache.error().message;
      return false;
    }
    co.chunk_cache = std::move(*cache);
  }
  client_ = std::make_unique<Client>(co);
  if (!client_->connect(error)) {
    *error = "cannot connect to " + options_.host + ":" + std::to_string(options_.port) + ": " + *error;
    return false;
  }
  const auto deadline = std::chrono::milliseconds(static_cast<std::int64_t>(timeout_s * 1000));
  if (!client_->wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, deadline) ||
      !client_->welcome()) {
    *error = client_->closed() ? "the server closed the connection: " + client_->disconnect_reason()
                               : "no Welcome from the server within the timeout";
    return false;
  }
  welcome_ = *client_->welcome();
  if (options_.camera) {
    camera_ = *options_.camera;
  } else {
    const Vec3f s = welcome_.spawn;
    camera_.pos = {s.x + kDefaultCameraOffset.x, s.y + kDefaultCameraOffset.y, s.z + kDefaultCameraOffset.z};
    const Vec3f d = s - camera_.pos;
    camera_.yaw = std::atan2(d.x, -d.z);
    camera_.pitch = std::atan2(d.y, std::sqrt(d.x * d.x + d.z * d.z));
  }
  lod_.view_distance = static_cast<float>(view_distance());
  lod_.min_y = welcome_.bounds_min_y;
  lod_.max_y = welcome_.bounds_max_y;
  lod_.min_sample_level = options_.mips_only ? 1 : 0;
  lod_.enhance = options_.enhance;
  Client* client = client_.get();
  scheduler_ = std::make_unique<MeshScheduler>(
      [client](const std::function<void(const VoxelSource&)>& fn) {
        client->with_replica([&](const Replica& r) {
          ReplicaSource source(r);
          fn(source);
          return 0;
        });
      },
      lod_);
  send_camera();
  return true;
}

void ViewerSession::send_camera() {
  ClientStateMsg st;
  st.position = camera_.pos;
  st.view_distance = options_.view_distance;
  st.full_res_radius = options_.mips_only ? 1 : options_.full_res_radius;
  client_->set_state(st);
  scheduler_->set_view(camera_.pos);
}

void ViewerSession::set_enhance(bool on) {
  lod_.enhance = on;
  scheduler_->set_params(lod_);
}

void draw_overlay(Renderer& r, ViewerSession& session, const OverlayInfo& info, int width, int height) {
  static constexpr float kText[4] = {1, 1, 1, 1};
  static constexpr float kPanel[4] = {0, 0, 0, 0.45f};
  const ClientCounters c = session.client().counters();
  // Finest level per chunk column near the camera, for the map.
  const Vec3f cam = session.camera().pos;
  const int radius = std::min(32, session.view_distance() / kChunkSize + 1);
  const Vec3i cc = chunk_of(Vec3i{static_cast<std::int32_t>(std::floor(cam.x)), 0,
                                  static_cast<std::int32_t>(std::floor(cam.z))});
  const int side = 2 * radius + 1;
  std::vector<int> column(static_cast<std::size_t>(side * side), -2);  // -2 none, -1 empty, 0 full, 1.. coarser
  const ViewCoverage n = session.client().coverage().value_or(ViewCoverage{});
  session.client().with_replica([&](const Replica& rep) {
    rep.for_each_holding([&](Vec3i cp, const Holding& cov) {
      const int level = cov.form == HoldingForm::kEmpty ? -1 : cov.level();
      const int dx = cp.x - cc.x + radius, dz = cp.z - cc.z + radius;
      if (dx < 0 || dz < 0 || dx >= side || dz >= side) return;
      int& col = column[static_cast<std::size_t>(dz * side + dx)];
      if (level >= 0 && (col < 0 || level < col)) col = level;
      if (level < 0 && col == -2) col = -1;
    });
    return 0;
  });
  const MeshSchedulerStats ms = session.scheduler().stats();
  const RenderStats rs = r.stats();
  char line[256];
  std::vector<std::string> lines;
  if (info.fps < 0) {
    std::snprintf(line, sizeof line, "HEADLESS (EGL, %s)", info.renderer.c_str());
  } else {
    std::snprintf(line, sizeof line, "FPS %.1f", info.fps);
  }
  lines.emplace_back(line);
  std::snprintf(line, sizeof line, "IN %.1f KB/S  TOTAL %.2f MB", info.bytes_in_per_s / 1024.0,
                static_cast<double>(c.bytes_in) / (1024.0 * 1024.0));
  lines.emplace_back(line);
  // The chunks in view, by what is held of them.
  std::snprintf(line, sizeof line, "VIEW %zu CHUNKS  HELD %zu  SETTLED %zu  NONE %zu", n.in_view, n.held(), n.settled,
                n.not_held);
  lines.emplace_back(line);
  std::snprintf(line, sizeof line, "FULL %zu  EMPTY %zu  MIP1 %zu  MIP2 %zu  MIP3 %zu", n.full, n.empty, n.mip1, n.mip2,
                n.mip3);
  lines.emplace_back(line);
  std::snprintf(line, sizeof line, "ESTIMATE %zu  HORIZON %zu", n.estimate, n.horizon);
  lines.emplace_back(line);
  std::snprintf(line, sizeof line, "RENDER CHUNKS %zu  DRAWN %zu  TRIS %.2fM  MESHED %llu", rs.meshes, rs.drawn,
                static_cast<double>(rs.triangles) / 1e6, static_cast<unsigned long long>(ms.chunks_meshed));
  lines.emplace_back(line);
  std::snprintf(line, sizeof line, "POS %.0f %.0f %.0f  ENHANCE %s (%llu CHUNKS)", static_cast<double>(cam.x),
                static_cast<double>(cam.y), static_cast<double>(cam.z), session.lod().enhance ? "ON" : "OFF",
                static_cast<unsigned long long>(ms.enhanced_chunks));
  lines.emplace_back(line);
  if (!info.tool.empty()) lines.push_back(info.tool);
  if (!info.status.empty()) lines.push_back(info.status);
  const float scale = 2, lh = 9 * scale;
  r.overlay_rect(6, 6, 6 * scale * 62, lh * static_cast<float>(lines.size()) + 8, kPanel);
  for (std::size_t i = 0; i < lines.size(); ++i) r.overlay_text(10, 10 + lh * static_cast<float>(i), lines[i], kText, scale);

  // Map: one square per chunk column, north (-z) up.
  const float cell = std::max(2.0f, 160.0f / static_cast<float>(side));
  // Bottom right, clear of the text.
  const float mx = static_cast<float>(width) - cell * static_cast<float>(side) - 10,
              my = static_cast<float>(height) - cell * static_cast<float>(side) - lh - 14;
  r.overlay_rect(mx - 4, my - 4, cell * static_cast<float>(side) + 8, cell * static_cast<float>(side) + 8 + lh + 4, kPanel);
  static constexpr float kLevel[4][4] = {
      {0.10f, 0.80f, 0.15f, 0.9f}, {0.95f, 0.85f, 0.10f, 0.9f}, {0.95f, 0.45f, 0.05f, 0.9f}, {0.85f, 0.08f, 0.08f, 0.9f}};
  static constexpr float kEmptyCol[4] = {0.5f, 0.5f, 0.55f, 0.5f};
  for (int z = 0; z < side; ++z)
    for (int x = 0; x < side; ++x) {
      const int v = column[static_cast<std::size_t>(z * side + x)];
      if (v == -2) continue;
      r.overlay_rect(mx + static_cast<float>(x) * cell, my + static_cast<float>(z) * cell, cell - 0.5f, cell - 0.5f,
                     v < 0 ? kEmptyCol : kLevel[v]);
    }
  static constexpr float kMe[4] = {1, 1, 1, 1};
  r.overlay_rect(mx + static_cast<float>(radius) * cell - 1, my + static_cast<float>(radius) * cell - 1, cell + 2, cell + 2, kMe);
  float lx = mx;
  const float ly = my + cell * static_cast<float>(side) + 4;
  const char* names[4] = {"FULL", "M1", "M2", "M3"};
  for (int i = 0; i < 4; ++i) lx += r.overlay_text(lx, ly, names[i], kLevel[i], scale) + 8;
}

int run_screenshot(const ViewerOptions& options) {
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  const auto deadline = t0 + std::chrono::milliseconds(static_cast<std::int64_t>(options.timeout_s * 1000));
  std::string error;
  // Connect first: a wrong address fails before any driver is loaded.
  ViewerSession session(options);
  if (!session.start(&error, options.timeout_s)) {
    std::fprintf(stderr, "terrane-view: %s\n", error.c_str());
    return 1;
  }
  HeadlessContext gl;
  if (!gl.create(options.width, options.height, options.msaa, &error)) {
    std::fprintf(stderr, "terrane-view: %s\n", error.c_str());
    return 1;
  }
  Renderer renderer;
  if (!renderer.init(&error)) {
    std::fprintf(stderr, "terrane-view: %s\n", error.c_str());
    return 1;
  }
  std::uint64_t frames_seen = 0;
  auto last_change = clock::now();
  bool data_ready = false;
  ViewCoverage progress;
  // Without news from the server for this long, streaming is taken as done
  // (a world with horizontal bounds never sends the chunks beyond them).
  constexpr auto kQuiet = std::chrono::seconds(3);
  while (true) {
    const ClientCounters c = session.client().counters();
    if (session.client().closed()) {
      std::fprintf(stderr, "terrane-view: the server closed the connection: %s\n",
                   session.client().disconnect_reason().c_str());
      return 1;
    }
    if (c.frames_in != frames_seen) {
      frames_seen = c.frames_in;
      last_change = clock::now();
      if (!data_ready) session.scheduler().mark_dirty();
    }
    if (!data_ready) {
      // The view the camera's last ClientState asked for.
      progress = session.client().coverage().value_or(ViewCoverage{});
      const bool waited = options.wait_full_res || options.mips_only ? progress.complete : progress.not_held == 0;
      if (waited || (progress.held() > 0 && clock::now() - last_change > kQuiet)) {
        data_ready = true;
        session.scheduler().mark_dirty();
      }
    }
    renderer.set_plan(session.scheduler().plan());
    for (MeshResult& r : session.scheduler().take_results()) renderer.upload(std::move(r));
    renderer.set_plan(session.scheduler().plan());
    if (data_ready && session.scheduler().idle() && renderer.complete()) break;
    if (clock::now() > deadline) {
      const MeshSchedulerStats ms = session.scheduler().stats();
      std::fprintf(stderr,
                   "terrane-view: timed out after %.0f s: %zu of %zu chunks in view received, %zu at their final level "
                   "(%s), %llu render chunks meshed\n",
                   options.timeout_s, progress.held(), progress.in_view, progress.settled,
                   data_ready ? "data complete, meshing unfinished" : "waiting for data",
                   static_cast<unsigned long long>(ms.chunks_meshed));
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const double wait_s = std::chrono::duration<double>(clock::now() - t0).count();
  FrameParams f;
  f.width = options.width;
  f.height = options.height;
  f.camera = session.camera();
  f.view_distance = static_cast<float>(session.view_distance());
  f.sky_key = options.sky_key;
  f.lod_tint = options.lod_tint;
  renderer.draw(f);
  if (options.overlay) {
    OverlayInfo info;
    info.fps = -1;
    info.renderer = gl.renderer_name().substr(0, gl.renderer_name().find(' '));
    info.status = options.mips_only ? "MIPS ONLY" : (options.wait_full_res ? "FULL RESOLUTION" : "");
    if (options.enhance) info.status += "  DETAIL ENHANCED, SNOWFLAKE LIGHTING";
    draw_overlay(renderer, session, info, options.width, options.height);
    renderer.draw_overlay(options.width, options.height);
  }
  const Image img = gl.read_back();
  if (!write_png(options.screenshot, img, &error)) {
    std::fprintf(stderr, "terrane-view: %s\n", error.c_str());
    return 1;
  }
  const MeshSchedulerStats ms = session.scheduler().stats();
  const RenderStats rs = renderer.stats();
  const ClientCounters c = session.client().counters();
  std::printf(
      "terrane-view: wrote %s (%dx%d, %s) after %.1f s: %zu/%zu chunks in view (%zu settled), %.2f MB received, "
      "%zu render chunks (%llu meshed in %.2f s), %.2fM triangles\n",
      options.screenshot.c_str(), options.width, options.height, gl.renderer_name().c_str(), wait_s, progress.held(),
      progress.in_view, progress.settled, static_cast<double>(c.bytes_in) / (1024.0 * 1024.0), rs.meshes,
      static_cast<unsigned long long>(ms.chunks_meshed), ms.mesh_seconds, static_cast<double>(rs.triangles) / 1e6);
  session.client().disconnect();
  return 0;
}

}  // namespace terrane::view
