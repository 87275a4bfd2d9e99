// Headless rendering: the same SplatRenderer drawing into an offscreen
// framebuffer of a hidden GLFW window (works under `xvfb-run -a` with Mesa's
// llvmpipe), read back as an image.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "camera.hpp"
#include "gl_context.hpp"
#include "image.hpp"
#include "splat_renderer.hpp"

namespace softshell::viewer {

struct RgbaImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgba;  // rows top to bottom; alpha = accumulated opacity
  const std::uint8_t* pixel(int x, int y) const { return &rgba[(std::size_t(y) * width + x) * 4]; }
  Image rgb() const;  // drops alpha (colour is already composited on the background)
};

class HeadlessRenderer {
 public:
  // Throws InputError "no display: ..." when no X server is reachable.
  HeadlessRenderer(int width, int height);

  void upload(const SplatSet& set) { renderer_.upload(set); }
  const SplatSet& splats() const { return renderer_.splats(); }
  // Renders one frame and waits for it (glFinish); read it with read().
  DrawStats render(const OrbitCamera& camera, const RenderSettings& settings);
  RgbaImage read() const;
  std::string description() const { return context_.description(); }
  int width() const { return fb_.width(); }
  int height() const { return fb_.height(); }

 private:
  GlContext context_;
  SplatRenderer renderer_;
  Framebuffer fb_;
};

}  // namespace softshell::viewer
