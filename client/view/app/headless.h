// Headless OpenGL: a core 3.3 context on EGL's surfaceless platform
// (EGL_MESA_platform_surfaceless; Mesa's llvmpipe renders on the CPU, no
// GPU or display needed), drawing into a multisampled framebuffer object
// that is resolved and read back as an image.
#pragma once

#include <epoxy/egl.h>
#include <epoxy/gl.h>

#include <string>

#include "client/view/png.h"

namespace terrane::view {

class HeadlessContext {
 public:
  HeadlessContext() = default;
  ~HeadlessContext();
  HeadlessContext(const HeadlessContext&) = delete;
  HeadlessContext& operator=(const HeadlessContext&) = delete;

  // Creates the context and a width x height framebuffer with `samples`
  // MSAA samples (1: none) and binds it. False with *error set.
  bool create(int width, int height, int samples, std::string* error);
  // Resolves the framebuffer and reads it back (RGB, top row first).
  Image read_back();
  std::string renderer_name() const;

 private:
  EGLDisplay display_ = EGL_NO_DISPLAY;
  EGLContext context_ = EGL_NO_CONTEXT;
  GLuint fbo_ = 0, color_ = 0, depth_ = 0, resolve_fbo_ = 0, resolve_color_ = 0;
  int width_ = 0, height_ = 0;
};

}  // namespace terrane::view
