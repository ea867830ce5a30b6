// Headless screenshots of the real server's default world: the picture has
// sky and several materials, a dig changes the pixels where it happened,
// and no sky shows through the terrain (from inside solid rock, or looking
// down across render chunks of several resolutions).
//
// Each test starts bin/terrane-server on a fresh world (127.0.0.1, port 0)
// and runs bin/terrane-view --screenshot, which renders through EGL
// surfaceless with Mesa's software rasteriser.
//
// A "Heavy" suite (label heavy, kept out of the sanitizer run): Mesa's
// driver, unloaded by eglTerminate, leaves allocations LeakSanitizer
// reports in an ASan build of terrane-view (no frame of ours), and under
// ASan each test takes 30-40 s. In a release build each takes 7-18 s.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "client/client.h"
#include "client/view/png.h"
#include "common/world/terrain_generator.h"
#include "common/world/world.h"
#include "tests/support/server_process.h"

namespace terrane::view {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing_support::ServerProcess;

// Generous: the viewer meshes on one worker thread of a shared machine.
constexpr int kViewTimeoutS = 240;

class ScreenshotHeavyTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-view-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    server_ = std::make_unique<ServerProcess>((dir_ / "world").string(), std::vector<std::string>{});
    ASSERT_NE(server_->port(), 0) << server_->output();
    auto gen = TerrainGenerator::from_metadata(default_world_meta().generator_params);
    ASSERT_TRUE(static_cast<bool>(gen));
    gen_.emplace(std::move(*gen));
  }
  void TearDown() override {
    if (server_) {
      EXPECT_EQ(server_->stop(), 0);
      if (HasFailure()) std::fprintf(stderr, "--- server output ---\n%s", server_->output().c_str());
    }
    fs::remove_all(dir_);
  }
  // y just above the highest solid voxel of the generated column.
  int top(int x, int z) const {
    for (int y = 255; y > -128; --y)
      if (occupancy_fraction(gen_->voxel_at({x, y, z})) >= 0.5f) return y + 1;
    return -128;
  }
  // Runs terrane-view --screenshot with extra arguments; the image or a
  // failure with the viewer's output.
  Image shoot(const std::string& name, const std::string& args) {
    const fs::path png = dir_ / (name + ".png"), log = dir_ / (name + ".log");
    std::ostringstream cmd;
    cmd << TERRANE_BIN_DIR << "/terrane-view --connect 127.0.0.1:" << server_->port() << " --screenshot " << png
        << " --timeout " << kViewTimeoutS << " " << args << " > " << log << " 2>&1";
    const int rc = std::system(cmd.str().c_str());
    std::ifstream f(log);
    const std::string out((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    EXPECT_EQ(rc, 0) << cmd.str() << "\n" << out;
    Image img;
    std::string error;
    EXPECT_TRUE(read_png(png.string(), img, &error)) << error << "\n" << out;
    return img;
  }
  static std::size_t count_sky(const Image& img) {
    std::size_t n = 0;
    for (std::size_t i = 0; i + 2 < img.pixels.size(); i += 3)
      n += img.pixels[i] == 255 && img.pixels[i + 1] == 0 && img.pixels[i + 2] == 255;
    return n;
  }

  fs::path dir_;
  std::unique_ptr<ServerProcess> server_;
  std::optional<TerrainGenerator> gen_;
};

std::string camera(float x, float y, float z, float yaw, float pitch) {
  std::ostringstream s;
  s << "--camera " << x << "," << y << "," << z << "," << yaw << "," << pitch;
  return s.str();
}

// Colour classes of lit terrain: grey/white by saturation, else by hue.
std::string colour_class(const std::uint8_t* p) {
  const float r = p[0] / 255.0f, g = p[1] / 255.0f, b = p[2] / 255.0f;
  const float mx = std::max({r, g, b}), mn = std::min({r, g, b});
  const float s = mx > 0 ? (mx - mn) / mx : 0;
  if (s < 0.18f) return mx > 0.8f ? "white" : "grey";
  float h = 0;
  if (mx == r) {
    h = 60 * std::fmod((g - b) / (mx - mn), 6.0f);
  } else if (mx == g) {
    h = 60 * ((b - r) / (mx - mn) + 2);
  } else {
    h = 60 * ((r - g) / (mx - mn) + 4);
  }
  if (h < 0) h += 360;
  if (h < 45) return "red-brown";
  if (h < 75) return "yellow";
  if (h < 170) return "green";
  if (h < 260) return "blue";
  return "purple";
}

TEST_F(ScreenshotHeavyTest, DefaultWorldShowsSkyAndSeveralMaterials) {
  const Image img = shoot("default", "--size 480x320 --wait-full-res --view-distance 256 --sky-key");
  ASSERT_EQ(img.width, 480);
  const std::size_t total = static_cast<std::size_t>(img.width) * img.height, sky = count_sky(img);
  EXPECT_GT(sky, total / 50) << "some sky";
  EXPECT_LT(sky, total * 9 / 10) << "mostly terrain";
  std::map<std::string, std::size_t> classes;
  for (std::size_t i = 0; i + 2 < img.pixels.size(); i += 3) {
    const std::uint8_t* p = &img.pixels[i];
    if (p[0] == 255 && p[1] == 0 && p[2] == 255) continue;
    ++classes[colour_class(p)];
  }
  int big = 0;
  std::string seen;
  for (const auto& [name, n] : classes) {
    seen += name + ":" + std::to_string(n) + " ";
    if (n * 100 >= total - sky) ++big;
  }
  EXPECT_GE(big, 3) << "distinct material colours, each on 1% of the terrain: " << seen;
}

TEST_F(ScreenshotHeavyTest, DigChangesThePixelsWhereItHappened) {
  // Look down at 45 degrees at a point of the ground, from 25 voxels away:
  // the point is in the middle of the picture.
  const int px = 20, pz = 20, py = top(px, pz);
  const std::string view = "--size 320x240 --msaa 1 --wait-full-res --view-distance 160 " +
                           camera(px + 0.5f, static_cast<float>(py) + 25.0f, pz + 0.5f + 25.0f, 0, -45);
  const Image before = shoot("before", view);

  ClientOptions o;
  o.port = server_->port();
  o.name = "digger";
  o.state = ClientStateMsg{{px + 0.5f, static_cast<float>(py), pz + 0.5f}, 64, 32};
  o.start_at_spawn = false;
  Client c(o);
  std::string error;
  ASSERT_TRUE(c.connect(&error)) << error;
  ASSERT_TRUE(c.wait_until([](const ClientView& v) { return v.welcomed; }, 20s));
  // Edits are accepted only where the client holds the world at full
  // resolution: wait for every chunk the sphere reads.
  const Region reads{{px - 8, py - 8, pz - 8}, {px + 9, py + 7, pz + 9}};
  ASSERT_TRUE(c.wait_until(
      [&](const ClientView& v) {
        bool full = true;
        for_each_chunk_in(reads, [&](Vec3i cp) {
          const Holding* cov = v.replica.holding(cp);
          full = full && cov != nullptr && cov->full_resolution();
        });
        return full;
      },
      60s));
  const std::uint32_t id = c.fill_sphere({px + 0.5f, static_cast<float>(py) - 1.0f, pz + 0.5f}, 6.0f, kAir);
  ASSERT_NE(id, 0u);
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.edits.count(id) > 0; }, 20s));
  {
    const auto e = c.wait_until([&](const ClientView& v) { return v.edits.at(id).accepted; }, 1s);
    ASSERT_TRUE(e) << "edit rejected";
  }
  c.disconnect();

  const Image after = shoot("after", view);
  ASSERT_EQ(before.pixels.size(), after.pixels.size());
  const int w = before.width, h = before.height;
  std::size_t changed = 0, border_changed = 0, border = 0;
  double cx = 0, cy = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = (static_cast<std::size_t>(y) * w + x) * 3;
      int d = 0;
      for (int k = 0; k < 3; ++k) d = std::max(d, std::abs(before.pixels[i + k] - after.pixels[i + k]));
      const bool far_out = std::abs(x - w / 2) > w * 3 / 10 || std::abs(y - h / 2) > h * 3 / 10;
      border += far_out;
      if (d > 24) {
        ++changed;
        cx += x;
        cy += y;
        border_changed += far_out;
      }
    }
  ASSERT_GT(changed, static_cast<std::size_t>(w * h / 100)) << "the crater shows";
  cx /= static_cast<double>(changed);
  cy /= static_cast<double>(changed);
  EXPECT_NEAR(cx, w / 2.0, w * 0.15) << "changes centred where the dig happened";
  EXPECT_NEAR(cy, h / 2.0, h * 0.15);
  EXPECT_LT(border_changed * 100, border) << "the rest of the picture is unchanged (" << border_changed << " of "
                                          << border << " outer pixels changed)";
}

TEST_F(ScreenshotHeavyTest, NoSkyFromInsideSolidRock) {
  // Thirty voxels under the spawn: every direction ends in rock, through
  // render chunks of several resolutions (a small full-resolution radius).
  const float y = static_cast<float>(top(0, 0)) - 30.0f;
  for (const auto& [yaw, pitch] : {std::pair{0.0f, 45.0f}, {90.0f, 0.0f}, {200.0f, -40.0f}}) {
    const Image img = shoot("rock", "--size 240x160 --msaa 1 --sky-key --view-distance 256 --full-res-radius 48 " +
                                        camera(0.5f, y, 0.5f, yaw, pitch));
    EXPECT_EQ(count_sky(img), 0u) << "yaw " << yaw << " pitch " << pitch;
  }
}

TEST_F(ScreenshotHeavyTest, NoSkyThroughTheGroundAcrossResolutions) {
  // High above the spawn looking down: the picture crosses render chunks of
  // 1/4 and 1/8 resolution (and their borders); every ray ends on ground.
  const float y = static_cast<float>(top(0, 0)) + 120.0f;
  for (const bool mips : {false, true}) {
    const Image img = shoot("down", std::string("--size 320x240 --msaa 1 --sky-key --view-distance 320 ") +
                                        (mips ? "--mips-only " : "--wait-full-res ") + camera(0.5f, y, 0.5f, 30, -65));
    EXPECT_EQ(count_sky(img), 0u) << (mips ? "mips only" : "full resolution");
  }
}

}  // namespace
}  // namespace terrane::view
