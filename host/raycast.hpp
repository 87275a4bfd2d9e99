// Ray casting on the OpenCL device (kernels/raycast.cl), GL-free: one
// work-item per pixel, trilinear samples from a plain buffer, front-to-back
// compositing with early termination, gradient shading with the splat
// renderer's light. Renders either the classified opacity u (opacity = u) or
// a raw volume's normalised intensity through a ramp transfer function: the
// paper's Figure 5 (before / after classification) and the first panel of
// its Figure 6. docs/renderers.md.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "cl_runtime.hpp"
#include "image.hpp"
#include "volume.hpp"

namespace softshell {

// A pinhole (or orthographic) camera in world mm; the same convention and
// framing as viewer::OrbitCamera (viewer/camera.hpp), so ray-cast images line
// up with the splat renders pixel for pixel.
struct RayCamera {
  std::array<float, 3> eye{0, 0, -100}, forward{0, 0, 1}, right{1, 0, 0}, up{0, -1, 0};
  float fov_y = 30.0f;          // degrees, vertical (perspective)
  bool orthographic = false;
  float ortho_half_height = 0;  // mm (orthographic)

  // OrbitCamera::fit(lo, hi, margin) then azimuth / elevation in degrees:
  // 0,0 looks down +z from the transducer side, x right, -y up.
  static RayCamera orbit(float azimuth, float elevation, const Vec3d& lo, const Vec3d& hi, float fov_y = 30.0f,
                         float margin = 1.05f);
  // A direction in camera space (x right, y up, z towards the viewer) in world space.
  std::array<float, 3> to_world(const std::array<float, 3>& d) const;
};

struct RaycastParams {
  // Transfer function on the samples (in [0, 1]): opacity per voxel length
  // = tf_max * clamp((s - tf_lo) / (tf_hi - tf_lo), 0, 1). The defaults make
  // the opacity the sample itself (an opacity volume u). Samples below
  // tf_cut are transparent (the faint haze of u far from any surface).
  float tf_lo = 0.0f, tf_hi = 1.0f, tf_max = 1.0f, tf_cut = 0.0f;
  // Sampling distance along the ray, in units of the smallest voxel spacing.
  float step = 0.5f;
  // Stop a ray once its accumulated opacity reaches this (>= 1: never).
  float termination = 0.99f;
  // Crop box, fractions of the volume's extent per axis (as `render --crop`).
  std::array<float, 3> crop_lo{0, 0, 0}, crop_hi{1, 1, 1};
  // Light and material as viewer::RenderSettings (the splat renderer).
  std::array<float, 3> colour{0.92f, 0.76f, 0.62f}, background{0, 0, 0};
  float ambient = 0.22f, diffuse = 0.78f, specular = 0.18f, shininess = 20.0f;
  float light_azimuth = -30.0f, light_elevation = 30.0f;  // degrees, relative to the camera

  // Throws InputError naming the parameter.
  void validate() const;
  double opacity(double s) const;  // the transfer function
};

struct RaycastImage {
  int width = 0, height = 0;
  std::vector<float> rgba;  // premultiplied colour + opacity, rows top to bottom
  const float* pixel(int x, int y) const { return &rgba[(std::size_t(y) * width + x) * 4]; }
  Image rgb(const std::array<float, 3>& background = {0, 0, 0}) const;  // composited over the background
};

// Maps a raw volume's samples to [0, 1] by its intensity map (type range for
// integers, robust min / max for floats), as the classifier does.
Volume unit_samples(const Volume& raw);

// Box (mm, voxel centres) of the voxels inside the crop box whose
// transfer-function opacity exceeds `threshold`; with the default transfer
// function and 0.2, the box `render` frames for splats (u > epsilon). The
// whole volume's box when no voxel qualifies.
std::array<Vec3d, 2> visible_box(const Volume& samples, const RaycastParams& p, float threshold = 0.2f);

class RayCaster {
 public:
  // Uploads `samples` (values in [0, 1]: u, or unit_samples(raw)) and
  // computes their gradients on the device (4 floats per voxel).
  RayCaster(Runtime& rt, const Volume& samples, const RaycastParams& params);

  // Renders and reads back one frame; `kernel_seconds` gets the kernel's
  // device time.
  RaycastImage render(const RayCamera& camera, int width, int height, double* kernel_seconds = nullptr);

  const RaycastParams& params() const { return params_; }
  std::size_t memory_bytes() const { return bytes_; }
  // The kernel's float4 arguments after the grid, as render() sets them
  // (tests use them to reproduce the sampling exactly).
  struct Frame {
    std::array<float, 4> origin, eye, forward, right, up, view, box_lo, box_hi, tf, light, colour, material, misc;
  };
  Frame frame(const RayCamera& camera, int width, int height) const;

 private:
  Runtime& rt_;
  GridDesc grid_;
  Vec3d origin_;
  RaycastParams params_;
  cl::Buffer volume_, gradient_, image_;  // samples, their gradients (float4), the frame
  std::size_t image_pixels_ = 0, bytes_ = 0;
  cl::Kernel kernel_;
};

}  // namespace softshell
