#include "client/view/app/headless.h"

#include <algorithm>
#include <cstring>

namespace terrane::view {

HeadlessContext::~HeadlessContext() {
  if (context_ != EGL_NO_CONTEXT) {
    GLuint rbs[] = {color_, depth_, resolve_color_};
    glDeleteRenderbuffers(3, rbs);
    GLuint fbs[] = {fbo_, resolve_fbo_};
    glDeleteFramebuffers(2, fbs);
    eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(display_, context_);
  }
  if (display_ != EGL_NO_DISPLAY) eglTerminate(display_);
}

bool HeadlessContext::create(int width, int height, int samples, std::string* error) {
  width_ = width;
  height_ = height;
  // eglGetPlatformDisplayEXT: a client extension, usable before any display
  // exists (libepoxy resolves the core 1.5 entry point only per display).
  display_ = eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  if (display_ == EGL_NO_DISPLAY) {
    *error = "EGL: no surfaceless display (is libegl-mesa0 installed?)";
    return false;
  }
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display_, &major, &minor)) {
    *error = "EGL: eglInitialize failed (error " + std::to_string(eglGetError()) + ")";
    return false;
  }
  if (!eglBindAPI(EGL_OPENGL_API)) {
    *error = "EGL: desktop OpenGL is not available";
    return false;
  }
  const EGLint attribs[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 3,
                            EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
  context_ = eglCreateContext(display_, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attribs);
  if (context_ == EGL_NO_CONTEXT) {
    *error = "EGL: cannot create an OpenGL 3.3 core context (error " + std::to_string(eglGetError()) + ")";
    return false;
  }
  if (!eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, context_)) {
    *error = "EGL: eglMakeCurrent without a surface failed (error " + std::to_string(eglGetError()) + ")";
    return false;
  }
  GLint max_samples = 1;
  glGetIntegerv(GL_MAX_SAMPLES, &max_samples);
  samples = std::max(1, std::min(samples, max_samples));
  glGenRenderbuffers(1, &color_);
  glBindRenderbuffer(GL_RENDERBUFFER, color_);
  glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples > 1 ? samples : 0, GL_RGBA8, width, height);
  glGenRenderbuffers(1, &depth_);
  glBindRenderbuffer(GL_RENDERBUFFER, depth_);
  glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples > 1 ? samples : 0, GL_DEPTH_COMPONENT24, width, height);
  glGenFramebuffers(1, &fbo_);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    *error = "GL: the offscreen framebuffer is incomplete";
    return false;
  }
  glGenRenderbuffers(1, &resolve_color_);
  glBindRenderbuffer(GL_RENDERBUFFER, resolve_color_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  glGenFramebuffers(1, &resolve_fbo_);
  glBindFramebuffer(GL_FRAMEBUFFER, resolve_fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, resolve_color_);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  return true;
}

Image HeadlessContext::read_back() {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, resolve_fbo_);
  glBlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, resolve_fbo_);
  std::vector<std::uint8_t> rgba(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  Image img;
  img.width = width_;
  img.height = height_;
  img.channels = 3;
  img.pixels.resize(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) * 3);
  for (int y = 0; y < height_; ++y) {
    const std::uint8_t* src = &rgba[static_cast<std::size_t>(height_ - 1 - y) * static_cast<std::size_t>(width_) * 4];
    std::uint8_t* dst = &img.pixels[static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) * 3];
    for (int x = 0; x < width_; ++x) std::memcpy(dst + x * 3, src + x * 4, 3);
  }
  return img;
}

std::string HeadlessContext::renderer_name() const {
  const GLubyte* r = glGetString(GL_RENDERER);
  return r ? reinterpret_cast<const char*>(r) : "unknown";
}

}  // namespace terrane::view
