// Headless rendering into an offscreen framebuffer.
#include "headless.hpp"

namespace softshell::viewer {

Image RgbaImage::rgb() const {
  Image img(width, height);
  for (std::size_t i = 0; i < std::size_t(width) * height; ++i)
    for (int c = 0; c < 3; ++c) img.rgb[i * 3 + c] = rgba[i * 4 + c];
  return img;
}

// The window itself stays tiny and hidden; frames go to the framebuffer
// object, so the image size is not limited by the (virtual) screen.
HeadlessRenderer::HeadlessRenderer(int width, int height)
    : context_(64, 64, "softshell render", false), renderer_(), fb_(width, height) {}

DrawStats HeadlessRenderer::render(const OrbitCamera& camera, const RenderSettings& settings) {
  fb_.bind();
  const DrawStats stats = renderer_.draw(camera, settings, fb_.width(), fb_.height());
  glFinish();
  return stats;
}

RgbaImage HeadlessRenderer::read() const {
  RgbaImage img;
  img.width = fb_.width();
  img.height = fb_.height();
  img.rgba = fb_.read_rgba();
  return img;
}

}  // namespace softshell::viewer
