// Shear-warp through VolPack: volume set-up and classification once, a shading table and the
// view matrices per frame (see shearwarp.hpp).
#include "shearwarp.hpp"

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cmath>
#include <stdexcept>
#include <string>

#include "error.hpp"

#ifdef SOFTSHELL_HAVE_VOLPACK
#include <volpack.h>
#endif

namespace softshell {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

using V3 = std::array<double, 3>;
V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V3 normalize(const V3& a) {
  const double l = std::sqrt(dot(a, a));
  return l > 0 ? V3{a[0] / l, a[1] / l, a[2] / l} : a;
}

// viewer/camera.cpp's OrbitCamera, in double and without GLM (the core has no GL dependency).
struct CameraFrame {
  V3 forward, right, up;
  CameraFrame(double az_deg, double el_deg) {
    const double az = az_deg * M_PI / 180.0, el = std::clamp(el_deg, -89.0, 89.0) * M_PI / 180.0;
    forward = {-std::sin(az) * std::cos(el), std::sin(el), std::cos(az) * std::cos(el)};
    right = normalize(cross(forward, {0, -1, 0}));
    up = cross(right, forward);
  }
  V3 to_world(const V3& d) const {  // camera space: x right, y up, z towards the viewer
    V3 w;
    for (int a = 0; a < 3; ++a) w[a] = d[0] * right[a] + d[1] * up[a] - d[2] * forward[a];
    return w;
  }
};

}  // namespace

Image ShearWarpImage::rgb() const {
  Image img(width, height);
  for (std::size_t i = 0; i < std::size_t(width) * height; ++i)
    for (int c = 0; c < 3; ++c) img.rgb[i * 3 + c] = rgba[i * 4 + c];
  return img;
}

std::array<Vec3d, 2> opacity_box(const Volume& u, float threshold) {
  std::array<Vec3d, 2> box{Vec3d{1e300, 1e300, 1e300}, Vec3d{-1e300, -1e300, -1e300}};
  bool any = false;
  for (std::size_t z = 0; z < u.dims[2]; ++z)
    for (std::size_t y = 0; y < u.dims[1]; ++y)
      for (std::size_t x = 0; x < u.dims[0]; ++x) {
        if (!(u.at(x, y, z) > threshold)) continue;
        any = true;
        const std::size_t i[3] = {x, y, z};
        for (int a = 0; a < 3; ++a) {
          const double p = u.origin[a] + u.spacing[a] * double(i[a]);
          box[0][a] = std::min(box[0][a], p);
          box[1][a] = std::max(box[1][a], p);
        }
      }
  if (!any)
    for (int a = 0; a < 3; ++a) {
      box[0][a] = u.origin[a];
      box[1][a] = u.origin[a] + u.spacing[a] * double(u.dims[a] > 0 ? u.dims[a] - 1 : 0);
    }
  return box;
}

#ifdef SOFTSHELL_HAVE_VOLPACK

bool shearwarp_available() { return true; }

namespace {

// The raw voxel VolPack reads: field 0 the encoded normal (shading), field 1 the 8-bit opacity
// (classification).
struct RawVoxel {
  std::uint16_t normal;
  std::uint8_t opacity;
  std::uint8_t pad;
};
static_assert(sizeof(RawVoxel) == 4, "VolPack voxel layout");

void vp_check(vpContext* vpc, vpResult r, const char* call) {
  if (r != VP_OK)
    throw std::runtime_error(std::string("VolPack ") + call + " failed: " + vpGetErrorString(vpGetError(vpc)));
}

}  // namespace

struct ShearWarpRenderer::Impl {
  vpContext* vpc = nullptr;
  std::vector<RawVoxel> voxels;
  std::vector<float> opacity_ramp = std::vector<float>(VP_OPACITY_MAX + 1);
  std::vector<float> shade_table = std::vector<float>(std::size_t(VP_NORM_MAX + 1) * 3);
  Dims3 dims{};
  Vec3d spacing{}, origin{};
  std::array<Vec3d, 2> default_box{};
  std::size_t kept = 0;
  std::vector<std::uint8_t> image;
  ~Impl() {
    if (vpc) vpDestroyContext(vpc);
  }
};

ShearWarpRenderer::ShearWarpRenderer(const Volume& u, const ShearWarpClassify& classify) : impl_(new Impl) {
  const auto t0 = Clock::now();
  for (int a = 0; a < 3; ++a)
    if (u.dims[a] < 2 || u.dims[a] > VP_MAX_VOLUME_DIM)
      throw InputError("shear-warp (VolPack) needs 2 to " + std::to_string(VP_MAX_VOLUME_DIM) +
                       " samples along every axis (dims " + std::to_string(u.dims[0]) + "x" +
                       std::to_string(u.dims[1]) + "x" + std::to_string(u.dims[2]) + ")");
  if (!(classify.min_opacity >= 0.0f && classify.min_opacity < 1.0f))
    throw InputError("shear-warp minimum opacity must be in [0, 1)");
  Impl& m = *impl_;
  m.dims = u.dims;
  m.spacing = u.spacing;
  m.origin = u.origin;
  m.default_box = opacity_box(u, 0.2f);
  const std::size_t nx = u.dims[0], ny = u.dims[1], nz = u.dims[2];

  // Quantised opacity and the encoded normal of grad u (per mm, as kernels/gradient.cl).
  m.voxels.resize(u.voxels());
  const int zero_normal = vpNormalIndex(0.0, 0.0, -1.0);  // no gradient: face the transducer
  auto deriv = [&](std::size_t i, std::size_t c, std::size_t n, std::size_t stride, double h) {
    if (c == 0) return (double(u.data[i + stride]) - double(u.data[i])) / h;
    if (c == n - 1) return (double(u.data[i]) - double(u.data[i - stride])) / h;
    return (double(u.data[i + stride]) - double(u.data[i - stride])) / (2 * h);
  };
  for (std::size_t z = 0; z < nz; ++z)
    for (std::size_t y = 0; y < ny; ++y)
      for (std::size_t x = 0; x < nx; ++x) {
        const std::size_t i = u.index(x, y, z);
        const float v = u.data[i];
        if (!(v >= -1e-6f && v <= 1.0f + 1e-6f))
          throw InputError("shear-warp: opacity " + std::to_string(v) + " outside [0, 1] at voxel (" +
                           std::to_string(x) + ", " + std::to_string(y) + ", " + std::to_string(z) + ")");
        RawVoxel& r = m.voxels[i];
        r.opacity = std::uint8_t(std::lround(std::clamp(v, 0.0f, 1.0f) * VP_OPACITY_MAX));
        r.pad = 0;
        if (r.opacity == 0) {
          r.normal = std::uint16_t(zero_normal);
          continue;
        }
        const V3 g{deriv(i, x, nx, 1, u.spacing[0]), deriv(i, y, ny, nx, u.spacing[1]),
                   deriv(i, z, nz, nx * ny, u.spacing[2])};
        const double len = std::sqrt(dot(g, g));
        r.normal = std::uint16_t(len > 0 ? vpNormalIndex(g[0] / len, g[1] / len, g[2] / len) : zero_normal);
        if (double(r.opacity) >= classify.min_opacity * VP_OPACITY_MAX) ++m.kept;
      }

  // Identity ramp: u is the opacity.
  for (int k = 0; k <= VP_OPACITY_MAX; ++k) m.opacity_ramp[k] = float(k) / float(VP_OPACITY_MAX);

  m.vpc = vpCreateContext();
  if (!m.vpc) throw std::runtime_error("VolPack vpCreateContext failed");
  vpContext* vpc = m.vpc;
  vp_check(vpc, vpSetVolumeSize(vpc, int(nx), int(ny), int(nz)), "vpSetVolumeSize");
  vp_check(vpc, vpSetVoxelSize(vpc, sizeof(RawVoxel), 2, 1, 1), "vpSetVoxelSize");
  vp_check(vpc, vpSetVoxelField(vpc, 0, sizeof(std::uint16_t), offsetof(RawVoxel, normal), VP_NORM_MAX),
           "vpSetVoxelField(normal)");
  vp_check(vpc, vpSetVoxelField(vpc, 1, sizeof(std::uint8_t), offsetof(RawVoxel, opacity), VP_OPACITY_MAX),
           "vpSetVoxelField(opacity)");
  vp_check(vpc,
           vpSetRawVoxels(vpc, m.voxels.data(), int(m.voxels.size() * sizeof(RawVoxel)), int(sizeof(RawVoxel)),
                          int(nx * sizeof(RawVoxel)), int(nx * ny * sizeof(RawVoxel))),
           "vpSetRawVoxels");
  vp_check(vpc, vpSetClassifierTable(vpc, 0, 1, m.opacity_ramp.data(), int(m.opacity_ramp.size() * sizeof(float))),
           "vpSetClassifierTable");
  vp_check(vpc, vpSetd(vpc, VP_MIN_VOXEL_OPACITY, classify.min_opacity), "vpSetd(VP_MIN_VOXEL_OPACITY)");
  vp_check(vpc, vpClassifyVolume(vpc), "vpClassifyVolume");
  vp_check(vpc,
           vpSetLookupShader(vpc, 3, 1, 0, m.shade_table.data(), int(m.shade_table.size() * sizeof(float)), 0,
                             nullptr, 0),
           "vpSetLookupShader");
  timing_.preprocess = since(t0);
}

ShearWarpRenderer::~ShearWarpRenderer() = default;

std::size_t ShearWarpRenderer::voxels_kept() const { return impl_->kept; }

ShearWarpImage ShearWarpRenderer::render(const ShearWarpView& view) {
  if (view.width < 1 || view.height < 1 || view.width > 8192 || view.height > 8192)
    throw InputError("shear-warp image size must be 1..8192 pixels per side");
  Impl& m = *impl_;
  vpContext* vpc = m.vpc;
  const auto t0 = Clock::now();
  const CameraFrame cam(view.azimuth, view.elevation);

  // Shading table for this view: one colour per encoded normal, the splat renderer's lighting.
  const double laz = view.light_azimuth * M_PI / 180.0, lel = view.light_elevation * M_PI / 180.0;
  const V3 light = normalize(cam.to_world({std::sin(laz) * std::cos(lel), std::sin(lel), std::cos(laz) * std::cos(lel)}));
  const V3 eye_dir{-cam.forward[0], -cam.forward[1], -cam.forward[2]};  // parallel projection
  const V3 half = normalize({light[0] + eye_dir[0], light[1] + eye_dir[1], light[2] + eye_dir[2]});
  for (int k = 0; k <= VP_NORM_MAX; ++k) {
    V3 n;
    vpNormal(k, &n[0], &n[1], &n[2]);
    if (dot(n, eye_dir) < 0) n = {-n[0], -n[1], -n[2]};  // two-sided, as the splats
    const double d = std::max(dot(n, light), 0.0);
    const double s = d > 0 ? std::pow(std::max(dot(n, half), 0.0), double(view.shininess)) : 0.0;
    for (int c = 0; c < 3; ++c)
      m.shade_table[std::size_t(k) * 3 + c] =
          float(255.0 * std::min(1.0, view.colour[c] * (view.ambient + view.diffuse * d) + view.specular * s));
  }
  timing_.shade = since(t0);

  // Matrices. VolPack maps voxel (i, j, k) to object space (unit cube scaled by the largest
  // side, centred); the model matrix undoes that and applies spacing and origin, so world
  // coordinates are the volume's mm. The view matrix is the orbit camera's frame around the
  // framed box's centre, the projection a parallel window.
  const std::array<Vec3d, 2> box = view.box ? *view.box : m.default_box;
  V3 target, diag;
  for (int a = 0; a < 3; ++a) target[a] = 0.5 * (box[0][a] + box[1][a]), diag[a] = box[1][a] - box[0][a];
  const double radius = std::max(0.5 * std::sqrt(dot(diag, diag)), 1e-3);
  const double half_h = view.margin * radius / std::cos(0.5 * view.fov_y * M_PI / 180.0);
  const double half_w = half_h * double(view.width) / double(view.height);
  const double maxdim = double(std::max({m.dims[0], m.dims[1], m.dims[2]}));
  vpMatrix4 model{}, eye{};
  for (int a = 0; a < 3; ++a) {
    model[a][a] = m.spacing[a] * maxdim;
    model[a][3] = m.origin[a] + m.spacing[a] * 0.5 * double(m.dims[a]);
  }
  model[3][3] = 1;
  // Row 3 is +forward: with eye z growing away from the viewer VolPack composites the near
  // slices first (checked by ShearWarp.NearOccludesFar; its manual suggests the opposite sign).
  const V3 rows[3] = {cam.right, cam.up, cam.forward};
  for (int r = 0; r < 3; ++r) {
    for (int a = 0; a < 3; ++a) eye[r][a] = rows[r][a];
    eye[r][3] = -dot(rows[r], target);
  }
  eye[3][3] = 1;
  vp_check(vpc, vpCurrentMatrix(vpc, VP_MODEL), "vpCurrentMatrix");
  vp_check(vpc, vpSetMatrix(vpc, model), "vpSetMatrix(model)");
  vp_check(vpc, vpCurrentMatrix(vpc, VP_VIEW), "vpCurrentMatrix");
  vp_check(vpc, vpSetMatrix(vpc, eye), "vpSetMatrix(view)");
  vp_check(vpc, vpCurrentMatrix(vpc, VP_PROJECT), "vpCurrentMatrix");
  vp_check(vpc, vpIdentityMatrix(vpc), "vpIdentityMatrix");
  vp_check(vpc, vpWindow(vpc, VP_PARALLEL, -half_w, half_w, -half_h, half_h, -2 * radius, 2 * radius), "vpWindow");
  vp_check(vpc, vpCurrentMatrix(vpc, VP_MODEL), "vpCurrentMatrix");

  m.image.assign(std::size_t(view.width) * view.height * 4, 0);
  vp_check(vpc, vpSetImage(vpc, m.image.data(), view.width, view.height, view.width * 4, VP_RGBA), "vpSetImage");
  vp_check(vpc, vpSetd(vpc, VP_MAX_RAY_OPACITY, view.max_ray_opacity), "vpSetd(VP_MAX_RAY_OPACITY)");
  const auto tr = Clock::now();
  vp_check(vpc, vpRenderClassifiedVolume(vpc), "vpRenderClassifiedVolume");
  timing_.render = since(tr);

  // VolPack's rows run bottom to top and hold colour premultiplied by opacity: flip, and
  // composite over the background.
  ShearWarpImage out;
  out.width = view.width;
  out.height = view.height;
  out.rgba.resize(m.image.size());
  for (int y = 0; y < view.height; ++y) {
    const std::uint8_t* src = &m.image[std::size_t(view.height - 1 - y) * view.width * 4];
    std::uint8_t* dst = &out.rgba[std::size_t(y) * view.width * 4];
    for (int x = 0; x < view.width; ++x, src += 4, dst += 4) {
      const double a = src[3] / 255.0;
      for (int c = 0; c < 3; ++c)
        dst[c] = std::uint8_t(std::lround(std::min(255.0, src[c] + (1.0 - a) * 255.0 * view.background[c])));
      dst[3] = src[3];
    }
  }
  return out;
}

#else  // no VolPack

bool shearwarp_available() { return false; }

struct ShearWarpRenderer::Impl {};

ShearWarpRenderer::ShearWarpRenderer(const Volume&, const ShearWarpClassify&) {
  throw InputError("shear-warp is unavailable: softshell was built without VolPack (install libvolpack1-dev "
                   "and reconfigure)");
}
ShearWarpRenderer::~ShearWarpRenderer() = default;
std::size_t ShearWarpRenderer::voxels_kept() const { return 0; }
ShearWarpImage ShearWarpRenderer::render(const ShearWarpView&) { return {}; }

#endif

ShearWarpImage render_shearwarp(const Volume& u, const ShearWarpView& view, ShearWarpTiming* timing,
                                const ShearWarpClassify& classify) {
  ShearWarpRenderer r(u, classify);
  ShearWarpImage img = r.render(view);
  if (timing) *timing = r.timing();
  return img;
}

}  // namespace softshell
