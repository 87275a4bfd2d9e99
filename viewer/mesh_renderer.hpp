// Marching Cubes meshes (host/mesh.hpp) with OpenGL 3.3 core: one vertex buffer (position +
// normal), one index buffer, a depth test, and the splat renderer's camera and lighting
// (RenderSettings: colour, material, light direction relative to the view; two-sided), so the
// mesh panel lines up with and is lit like the splat panels. Headless: MeshHeadless draws into
// its own RGBA8 + depth framebuffer of a hidden window.
#pragma once

#include <array>
#include <cstddef>
#include <string>

#include <glm/glm.hpp>

#include "camera.hpp"
#include "gl_context.hpp"
#include "headless.hpp"
#include "mesh.hpp"
#include "splat_renderer.hpp"

namespace softshell::viewer {

class MeshRenderer {
 public:
  MeshRenderer();  // needs a current GL 3.3 context
  ~MeshRenderer();
  MeshRenderer(const MeshRenderer&) = delete;
  MeshRenderer& operator=(const MeshRenderer&) = delete;

  void upload(const Mesh& mesh);  // copies positions, normals and indices to GL buffers
  std::size_t triangles() const { return triangles_; }
  // Clears colour (alpha 0) and depth, draws opaque triangles (alpha 1). Fragments outside
  // [crop_lo, crop_hi] (mm) are dropped; the defaults keep everything. Uses s.colour,
  // background, material and light; the splat-only fields are ignored.
  void draw(const OrbitCamera& camera, const RenderSettings& s, int width, int height,
            glm::vec3 crop_lo = glm::vec3(-1e30f), glm::vec3 crop_hi = glm::vec3(1e30f));

 private:
  GLuint program_ = 0, vao_ = 0, vbo_ = 0, ebo_ = 0;
  std::size_t triangles_ = 0;
};

// Offscreen mesh rendering: a hidden GLFW window for the context (InputError "no display: ..."
// without an X server), an RGBA8 colour + 24-bit depth framebuffer of width x height.
class MeshHeadless {
 public:
  MeshHeadless(int width, int height);
  ~MeshHeadless();
  MeshHeadless(const MeshHeadless&) = delete;
  MeshHeadless& operator=(const MeshHeadless&) = delete;

  void upload(const Mesh& mesh);
  // Draws one frame and waits for it (glFinish); returns the seconds that took.
  double render(const OrbitCamera& camera, const RenderSettings& settings,
                glm::vec3 crop_lo = glm::vec3(-1e30f), glm::vec3 crop_hi = glm::vec3(1e30f));
  RgbaImage read() const;
  std::string description() const { return context_.description(); }

 private:
  GlContext context_;
  int width_, height_;
  GLuint fbo_ = 0, colour_ = 0, depth_ = 0;
  MeshRenderer renderer_;
};

struct MeshFrameTiming {
  double upload = 0;  // vertex and index buffers to GL
  double draw = 0;    // one frame, glFinish included (the second of two: the first warms up)
};

// One-shot for figure code: renders `mesh` with `camera` and `settings` at width x height.
// Creates (and destroys) its own hidden context; call it where no other GL context must stay
// current.
RgbaImage render_mesh_image(const Mesh& mesh, const OrbitCamera& camera, const RenderSettings& settings, int width,
                            int height, MeshFrameTiming* timing = nullptr);

}  // namespace softshell::viewer
