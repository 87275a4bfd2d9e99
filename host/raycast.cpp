// Ray casting host side: camera, transfer function, framing box, and the
// wrapper around kernels/raycast.cl.
#include "raycast.hpp"

#include <algorithm>
#include <cmath>

#include "error.hpp"

namespace softshell {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::array<float, 3> normalized(const std::array<float, 3>& v) {
  const float n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return {v[0] / n, v[1] / n, v[2] / n};
}

std::array<float, 3> cross(const std::array<float, 3>& a, const std::array<float, 3>& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

std::array<float, 4> f4(const std::array<float, 3>& v, float w = 0.0f) { return {v[0], v[1], v[2], w}; }

cl_float4 cl4(const std::array<float, 4>& v) { return cl_float4{{v[0], v[1], v[2], v[3]}}; }

}  // namespace

RayCamera RayCamera::orbit(float azimuth, float elevation, const Vec3d& lo, const Vec3d& hi, float fov_y,
                           float margin) {
  // viewer::OrbitCamera::fit, forward(), right(), up(), eye() (float, as GLM).
  RayCamera c;
  c.fov_y = fov_y;
  std::array<float, 3> target{}, ext{};
  for (int a = 0; a < 3; ++a) {
    target[a] = 0.5f * (float(lo[a]) + float(hi[a]));
    ext[a] = float(hi[a]) - float(lo[a]);
  }
  const float radius = std::max(0.5f * std::sqrt(ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]), 1e-3f);
  const float distance = margin * radius / std::sin(float(kPi / 180.0) * 0.5f * fov_y);
  const float az = float(kPi / 180.0) * azimuth, el = float(kPi / 180.0) * std::clamp(elevation, -89.0f, 89.0f);
  c.forward = {-std::sin(az) * std::cos(el), std::sin(el), std::cos(az) * std::cos(el)};
  c.right = normalized(cross(c.forward, {0.0f, -1.0f, 0.0f}));
  c.up = cross(c.right, c.forward);
  for (int a = 0; a < 3; ++a) c.eye[a] = target[a] - distance * c.forward[a];
  // The orthographic variant sees the same extent at the target's depth.
  c.ortho_half_height = distance * std::tan(float(kPi / 180.0) * 0.5f * fov_y);
  return c;
}

std::array<float, 3> RayCamera::to_world(const std::array<float, 3>& d) const {
  std::array<float, 3> w{};
  for (int a = 0; a < 3; ++a) w[a] = d[0] * right[a] + d[1] * up[a] - d[2] * forward[a];
  return w;
}

void RaycastParams::validate() const {
  if (!(tf_lo >= 0.0f && tf_lo < tf_hi && tf_hi <= 1.0f))
    throw InputError("transfer function: need 0 <= --tf-lo < --tf-hi <= 1 (normalised intensity)");
  if (!(tf_cut >= 0.0f && tf_cut < 1.0f)) throw InputError("transfer function: --tf-cut must be in [0, 1)");
  if (!(tf_max > 0.0f && tf_max <= 1.0f)) throw InputError("transfer function: --tf-max must be in (0, 1]");
  if (!(step >= 0.05f && step <= 4.0f)) throw InputError("--step must be in [0.05, 4] voxels");
  if (!(termination > 0.0f)) throw InputError("early-termination opacity must be > 0");
  for (int a = 0; a < 3; ++a)
    if (!(crop_lo[a] >= 0.0f && crop_lo[a] < crop_hi[a] && crop_hi[a] <= 1.0f))
      throw InputError("--crop: each pair must satisfy 0 <= lo < hi <= 1");
}

double RaycastParams::opacity(double s) const {
  if (s < double(tf_cut)) return 0.0;
  return double(tf_max) * std::clamp((s - double(tf_lo)) / (double(tf_hi) - double(tf_lo)), 0.0, 1.0);
}

Image RaycastImage::rgb(const std::array<float, 3>& background) const {
  Image img(width, height);
  for (std::size_t i = 0; i < std::size_t(width) * std::size_t(height); ++i)
    for (int c = 0; c < 3; ++c) {
      const float v = rgba[4 * i + c] + (1.0f - rgba[4 * i + 3]) * background[c];
      img.rgb[3 * i + c] = std::uint8_t(std::lround(255.0f * std::clamp(v, 0.0f, 1.0f)));
    }
  return img;
}

Volume unit_samples(const Volume& raw) {
  const IntensityMap m = raw.intensity_map();
  std::vector<float> s(raw.voxels());
  for (std::size_t i = 0; i < s.size(); ++i) s[i] = float(std::clamp(m.to_unit(raw.data[i]), 0.0, 1.0));
  return raw.with_data(std::move(s), ScalarType::Float32);
}

std::array<Vec3d, 2> visible_box(const Volume& v, const RaycastParams& p, float threshold) {
  Vec3d lo{HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi{-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  std::array<std::size_t, 3> from{}, to{};
  for (int a = 0; a < 3; ++a) {
    // Same test as the splat crop of `render` (fractions, 1e-6 slack).
    const double n1 = double(v.dims[a] - 1);
    from[a] = v.dims[a] > 1 ? std::size_t(std::ceil(std::max(0.0, (p.crop_lo[a] - 1e-6) * n1))) : 0;
    to[a] = v.dims[a] > 1 ? std::size_t(std::floor(std::min(n1, (p.crop_hi[a] + 1e-6) * n1))) : 0;
  }
  for (std::size_t z = from[2]; z <= to[2]; ++z)
    for (std::size_t y = from[1]; y <= to[1]; ++y)
      for (std::size_t x = from[0]; x <= to[0]; ++x) {
        if (!(p.opacity(v.at(x, y, z)) > threshold)) continue;
        const std::size_t i[3] = {x, y, z};
        for (int a = 0; a < 3; ++a) {
          const double c = v.origin[a] + v.spacing[a] * double(i[a]);
          lo[a] = std::min(lo[a], c);
          hi[a] = std::max(hi[a], c);
        }
      }
  if (lo[0] > hi[0])
    for (int a = 0; a < 3; ++a) {
      lo[a] = v.origin[a];
      hi[a] = v.origin[a] + v.spacing[a] * double(v.dims[a] - 1);
    }
  return {lo, hi};
}

RayCaster::RayCaster(Runtime& rt, const Volume& samples, const RaycastParams& params)
    : rt_(rt), grid_(make_grid(samples.dims, samples.spacing)), origin_(samples.origin), params_(params) {
  params_.validate();
  const std::size_t bytes = samples.voxels() * sizeof(float);
  volume_ = rt.buffer(bytes, CL_MEM_READ_ONLY);
  rt.queue().enqueueWriteBuffer(volume_, CL_TRUE, 0, bytes, samples.data.data());
  gradient_ = rt.buffer(4 * bytes);
  cl::Kernel k = rt.kernel("raycast.cl", "raycast_gradients");
  Runtime::set_args(k, volume_, grid_, gradient_);
  rt.enqueue_3d(k, grid_);
  bytes_ = 5 * bytes;
}

RayCaster::Frame RayCaster::frame(const RayCamera& cam, int width, int height) const {
  Frame f{};
  const RaycastParams& p = params_;
  f.origin = {float(origin_[0]), float(origin_[1]), float(origin_[2]), 0.0f};
  f.eye = f4(cam.eye);
  f.forward = f4(cam.forward);
  f.right = f4(cam.right);
  f.up = f4(cam.up);
  const float aspect = float(width) / float(height);
  const float ty = std::tan(float(kPi / 180.0) * 0.5f * cam.fov_y);
  f.view = {ty * aspect, ty, cam.ortho_half_height * aspect, cam.ortho_half_height};
  const int n[3] = {grid_.nx, grid_.ny, grid_.nz};
  for (int a = 0; a < 3; ++a) {
    // Half a voxel of slack beyond a crop plane, as the splat renderer keeps
    // the splats centred on the last voxel inside.
    const float m = float(n[a] - 1);
    f.box_lo[a] = p.crop_lo[a] > 0.0f ? std::max(p.crop_lo[a] * m - 0.5f, 0.0f) : 0.0f;
    f.box_hi[a] = p.crop_hi[a] < 1.0f ? std::min(p.crop_hi[a] * m + 0.5f, m) : m;
  }
  const float hmin = std::min({grid_.hx, grid_.hy, grid_.hz});
  f.tf = {p.tf_lo, p.tf_hi, p.tf_max, p.step * hmin};
  const float laz = float(kPi / 180.0) * p.light_azimuth, lel = float(kPi / 180.0) * p.light_elevation;
  f.light = f4(normalized(cam.to_world(
      {std::sin(laz) * std::cos(lel), std::sin(lel), std::cos(laz) * std::cos(lel)})));
  f.colour = f4(p.colour);
  f.material = {p.ambient, p.diffuse, p.specular, p.shininess};
  // Reference length of the opacity: one voxel (geometric mean spacing).
  f.misc = {std::cbrt(grid_.hx * grid_.hy * grid_.hz), p.termination, p.tf_cut, 0.0f};
  return f;
}

RaycastImage RayCaster::render(const RayCamera& cam, int width, int height, double* kernel_seconds) {
  if (width < 1 || height < 1) throw InputError("image size must be positive");
  const std::size_t pixels = std::size_t(width) * std::size_t(height);
  if (pixels != image_pixels_) {
    image_ = rt_.buffer(pixels * 4 * sizeof(float), CL_MEM_WRITE_ONLY);
    image_pixels_ = pixels;
  }
  const std::string options = cam.orthographic ? "-D RAYCAST_ORTHO=1" : "-D RAYCAST_ORTHO=0";
  kernel_ = rt_.kernel("raycast.cl", "raycast_render", options);
  const Frame f = frame(cam, width, height);
  Runtime::set_args(kernel_, volume_, gradient_, grid_, cl4(f.origin), cl4(f.eye), cl4(f.forward), cl4(f.right), cl4(f.up),
                    cl4(f.view), cl4(f.box_lo), cl4(f.box_hi), cl4(f.tf), cl4(f.light), cl4(f.colour),
                    cl4(f.material), cl4(f.misc), cl_int(width), cl_int(height), image_);
  // 8x8 tiles: neighbouring rays touch the same voxels.
  const std::size_t tile = rt_.info().max_work_group >= 64 ? 8 : 1;
  const cl::NDRange global((std::size_t(width) + tile - 1) / tile * tile, (std::size_t(height) + tile - 1) / tile * tile);
  cl::Event e;
  rt_.queue().enqueueNDRangeKernel(kernel_, cl::NullRange, global, cl::NDRange(tile, tile), nullptr, &e);
  RaycastImage img;
  img.width = width;
  img.height = height;
  img.rgba.resize(pixels * 4);
  rt_.queue().enqueueReadBuffer(image_, CL_TRUE, 0, pixels * 4 * sizeof(float), img.rgba.data());
  if (kernel_seconds) *kernel_seconds = event_seconds(e);
  return img;
}

}  // namespace softshell
