// A GLFW window with an OpenGL 3.3 core context, visible (the interactive
// viewer) or hidden (headless rendering into a framebuffer object), plus the
// small GL helpers the renderer needs: shader programs with checked compile
// and link logs, and an offscreen RGBA8 framebuffer with read-back.
#pragma once

#include <epoxy/gl.h>
// GLFW after epoxy (GLFW_INCLUDE_NONE is set by the build).
#include <GLFW/glfw3.h>

#include <cstdint>
#include <string>
#include <vector>

namespace softshell::viewer {

class GlContext {
 public:
  // Initialises GLFW and opens the window. Throws InputError "no display: ..."
  // when GLFW cannot start (no X server) and InputError when no OpenGL 3.3
  // core context can be had.
  GlContext(int width, int height, const std::string& title, bool visible);
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  GLFWwindow* window() const { return window_; }
  // "OpenGL 4.5 (Core Profile) Mesa 22.3.6, llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string description() const;

 private:
  GLFWwindow* window_ = nullptr;
};

// A linked program from vertex + fragment sources; a compile or link error
// throws std::runtime_error with the stage and the driver's log.
GLuint build_program(const std::string& vertex_name, const std::string& vertex_src,
                     const std::string& fragment_name, const std::string& fragment_src);

// An RGBA8 colour attachment of width x height (no depth: splats are
// blended in order, not depth-tested).
class Framebuffer {
 public:
  Framebuffer(int width, int height);
  ~Framebuffer();
  Framebuffer(const Framebuffer&) = delete;
  Framebuffer& operator=(const Framebuffer&) = delete;

  void bind() const;  // binds it as the draw and read framebuffer, sets the viewport
  int width() const { return width_; }
  int height() const { return height_; }
  // RGBA8, rows top to bottom.
  std::vector<std::uint8_t> read_rgba() const;

 private:
  int width_, height_;
  GLuint fbo_ = 0, colour_ = 0;
};

// Reads the bound read framebuffer's [0, w) x [0, h) as RGBA8, rows top to
// bottom.
std::vector<std::uint8_t> read_pixels_rgba(int width, int height);

}  // namespace softshell::viewer
