// Oriented / isotropic splat rendering (paper Section 4.1) with OpenGL 3.3
// core: the splat records go to a texture buffer once (host copy: PoCL has no
// cl_khr_gl_sharing, docs/rendering.md), each frame draws 3 vertices per
// splat in a back-to-front order: one of the paper's six presorted lists
// (chosen by the dominant view axis), or an exact per-view depth sort.
#pragma once

#include <array>
#include <future>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "camera.hpp"
#include "gl_context.hpp"
#include "splats.hpp"

namespace softshell::viewer {

enum class SplatMethod { Oriented, Isotropic };
enum class DrawOrder { Lists, Sort };

struct RenderSettings {
  SplatMethod method = SplatMethod::Oriented;
  bool three_normals = true;        // the paper's smoother variant; false: one normal per splat
  DrawOrder order = DrawOrder::Lists;
  glm::vec3 colour{0.92f, 0.76f, 0.62f};
  // Second colour of a per-splat ramp by Splat::t[3] (0: colour, 1: colour2);
  // the generator writes 0, so only hand-made splat sets (tests) use it.
  glm::vec3 colour2{0.4f, 0.6f, 0.95f};
  glm::vec3 background{0.0f};
  float ambient = 0.22f, diffuse = 0.78f, specular = 0.18f, shininess = 20.0f;
  // Light direction relative to the camera, degrees: 0, 0 is a headlight;
  // positive azimuth moves it to the right, positive elevation up.
  float light_azimuth = -30.0f, light_elevation = 30.0f;
  // Crop box as fractions of the volume's extent per axis, and one clip
  // plane (enabled when its normal is nonzero): splats with
  // dot(normal, centre - point) > 0 are dropped.
  glm::vec3 crop_lo{0.0f}, crop_hi{1.0f};
  glm::vec3 clip_normal{0.0f}, clip_point{0.0f};
  // Depth colour map (splats and meshes): colour by z (depth along the beam,
  // mm) from light near depth_lo to dark red-brown at depth_hi, instead of colour.
  bool depth_colour = false;
  float depth_lo = 0.0f, depth_hi = 1.0f;
  // DrawOrder::Sort: sort on a worker thread and draw with the newest order
  // finished (the interactive viewer; one sorted for a nearby eye while the
  // camera moves); false: sort for this eye before drawing (`render`).
  bool async_sort = false;
  // Strength of the splats' ambient occlusion (SplatParams::occlusion):
  // lit colour x (1 - strength x occlusion).
  float occlusion = 0.7f;
};

// What the last draw did.
struct DrawStats {
  std::size_t splats = 0;
  int list = -1;           // presorted list used (2 * axis + descending), -1 with Sort
  double sort_ms = 0;      // CPU depth sort + upload (Sort only); with async_sort the upload alone
  bool stale_order = false;  // async_sort: drawn with an order sorted for an earlier eye
};

class SplatRenderer {
 public:
  SplatRenderer();  // needs a current GL 3.3 context
  ~SplatRenderer();
  SplatRenderer(const SplatRenderer&) = delete;
  SplatRenderer& operator=(const SplatRenderer&) = delete;

  // Uploads the splats (through the host) and forgets the previous lists.
  // Throws InputError when there are more than the GL texture buffer holds.
  void upload(const SplatSet& set);
  const SplatSet& splats() const { return set_; }

  // Draws into the bound framebuffer, viewport width x height (clears it).
  DrawStats draw(const OrbitCamera& camera, const RenderSettings& s, int width, int height);

  // Bytes held on the GL side (splat records and order lists).
  std::size_t memory_bytes() const;

 private:
  void bind_order(GLuint buffer);
  GLuint list_buffer(int list);

  GLuint program_ = 0, vao_ = 0;
  GLuint splat_buffer_ = 0, splat_texture_ = 0, order_texture_ = 0;
  std::array<GLuint, 6> lists_{};
  GLuint sort_buffer_ = 0;
  GLuint bound_order_ = 0;
  std::vector<std::uint32_t> order_;
  // async_sort: the sort in flight and the eye of the order in sort_buffer_.
  std::future<std::vector<std::uint32_t>> sorting_;
  glm::vec3 sorting_eye_{0.0f}, sorted_eye_{0.0f};
  bool have_sorted_ = false;
  void wait_for_sort();
  SplatSet set_;
  std::size_t list_bytes_ = 0;
};

}  // namespace softshell::viewer
