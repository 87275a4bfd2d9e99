// Shear-warp volume rendering (Lacroute & Levoy 1994) of an opacity volume through Stanford's
// VolPack, the library the paper used for Figure 6 (Debian libvolpack1-dev). GL-free, in
// softshell_core; without VolPack at build time shearwarp_available() is false and rendering
// throws InputError.
//
// What goes in: u itself is the opacity (quantised to 8 bits; VolPack's classifier table is the
// identity ramp, voxels below `min_opacity` are skipped by its run-length encoding), and the
// shading normal of each voxel is grad u (central differences per mm, one-sided on the border,
// as kernels/gradient.cl) encoded with vpNormalIndex. The colour table of vpSetLookupShader is
// filled here, per view, with the splat renderer's lighting (viewer/splat_renderer.hpp
// RenderSettings: ambient 0.22, diffuse 0.78, Blinn specular 0.18 with exponent 20, light 30
// degrees up-left of the view direction, two-sided), so only the compositing differs.
//
// View: the same AZ,EL convention as viewer/camera.hpp (0,0 looks down +z from the transducer,
// x right, -y up). VolPack 1.x only projects in parallel, so the view is orthographic with the
// scale the 30-degree perspective camera has at its target when it frames the same box (the
// box's bounding sphere, margin 1.05). The image is rendered straight at WxH.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "image.hpp"
#include "volume.hpp"

namespace softshell {

bool shearwarp_available();  // built with VolPack

// Bounding box (mm) of the voxel centres with u > threshold: what the splat renderer frames
// (SplatSet::splat_box); the whole volume when no voxel passes.
std::array<Vec3d, 2> opacity_box(const Volume& u, float threshold = 0.2f);

struct ShearWarpView {
  float azimuth = 0.0f, elevation = 0.0f;  // degrees, viewer/camera.hpp convention
  int width = 400, height = 400;
  // Box (mm) to frame; unset: opacity_box(u, 0.2), as `render --method splat` frames.
  std::optional<std::array<Vec3d, 2>> box;
  float fov_y = 30.0f, margin = 1.05f;  // the perspective camera whose scale is matched
  std::array<float, 3> colour{0.92f, 0.76f, 0.62f}, background{0.0f, 0.0f, 0.0f};
  float ambient = 0.22f, diffuse = 0.78f, specular = 0.18f, shininess = 20.0f;
  float light_azimuth = -30.0f, light_elevation = 30.0f;  // relative to the view, degrees
  float max_ray_opacity = 0.95f;  // VolPack's early ray termination
};

struct ShearWarpClassify {
  float min_opacity = 0.2f;  // VP_MIN_VOXEL_OPACITY: lighter voxels are left out of the encoding (the
                             // splats' epsilon, so u's faint floor is no haze; the ray caster cuts there too)
};

// RGBA8 frame, rows top to bottom; colour composited over the background, alpha = accumulated
// opacity.
struct ShearWarpImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgba;
  const std::uint8_t* pixel(int x, int y) const { return &rgba[(std::size_t(y) * width + x) * 4]; }
  Image rgb() const;
};

struct ShearWarpTiming {
  double preprocess = 0;  // quantise u, normals, vpClassifyVolume (run-length encoding, 3 axes)
  double shade = 0;       // per frame: colour table for the view
  double render = 0;      // per frame: vpRenderClassifiedVolume (shear, composite, warp)
};

// One VolPack context holding the classified volume: construct once (the preprocessing), render
// many views. Throws InputError for a volume VolPack cannot take (a side over 1024 samples, or
// opacities outside [0, 1]) or when built without VolPack.
class ShearWarpRenderer {
 public:
  explicit ShearWarpRenderer(const Volume& u, const ShearWarpClassify& classify = {});
  ~ShearWarpRenderer();
  ShearWarpRenderer(const ShearWarpRenderer&) = delete;
  ShearWarpRenderer& operator=(const ShearWarpRenderer&) = delete;

  ShearWarpImage render(const ShearWarpView& view);
  const ShearWarpTiming& timing() const { return timing_; }  // preprocess, and the last frame
  std::size_t voxels_kept() const;  // voxels at or above min_opacity

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  ShearWarpTiming timing_;
};

// One frame: preprocessing + render (timings of both in `timing`).
ShearWarpImage render_shearwarp(const Volume& u, const ShearWarpView& view, ShearWarpTiming* timing = nullptr,
                                const ShearWarpClassify& classify = {});

}  // namespace softshell
