// Ray casting (kernels/raycast.cl, host/raycast.*) on the OpenCL device, no GL:
//  - individual pixels against a float64 CPU ray with the same sampling
//    (odd anisotropic volume with an origin, perspective and orthographic,
//    the identity and a ramp transfer function, a crop box);
//  - the sphere phantom's shell u = exp(-sdf^2 / 2): the silhouette matches
//    the projected sphere;
//  - early termination on an opaque slab changes the image by less than the
//    opacity left over, and the step size does not change the image (opacity
//    correction).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <cstdint>

#include "error.hpp"
#include "phantom.hpp"
#include "raycast.hpp"
#include "test_support.hpp"

namespace softshell::test {
namespace {

using D3 = std::array<double, 3>;

D3 d3(const std::array<float, 4>& v) { return {v[0], v[1], v[2]}; }
double dot(const D3& a, const D3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
D3 unit(const D3& v) {
  const double n = std::sqrt(dot(v, v));
  return {v[0] / n, v[1] / n, v[2] / n};
}

// ---- float64 reference of raycast.cl ------------------------------------
void axis(double p, int n, int& i0, int& i1, double& w) {
  const double q = std::clamp(p, 0.0, double(n - 1));
  int a = int(std::floor(q));
  if (a > n - 2) a = std::max(n - 2, 0);
  i0 = a;
  i1 = std::min(a + 1, n - 1);
  w = q - a;
}

double sample(const Volume& v, const D3& p) {
  int x0, x1, y0, y1, z0, z1;
  double wx, wy, wz;
  axis(p[0], int(v.dims[0]), x0, x1, wx);
  axis(p[1], int(v.dims[1]), y0, y1, wy);
  axis(p[2], int(v.dims[2]), z0, z1, wz);
  auto f = [&](int x, int y, int z) { return double(v.at(x, y, z)); };
  auto lerp = [](double a, double b, double w) { return a + w * (b - a); };
  return lerp(lerp(lerp(f(x0, y0, z0), f(x1, y0, z0), wx), lerp(f(x0, y1, z0), f(x1, y1, z0), wx), wy),
              lerp(lerp(f(x0, y0, z1), f(x1, y0, z1), wx), lerp(f(x0, y1, z1), f(x1, y1, z1), wx), wy), wz);
}

D3 gradient_at(const Volume& v, int x, int y, int z) {
  const int c[3] = {x, y, z};
  D3 g{};
  for (int a = 0; a < 3; ++a) {
    const int n = int(v.dims[a]);
    if (n < 2) continue;
    int lo[3] = {x, y, z}, hi[3] = {x, y, z};
    lo[a] = std::max(c[a] - 1, 0);
    hi[a] = std::min(c[a] + 1, n - 1);
    g[a] = (double(v.at(hi[0], hi[1], hi[2])) - double(v.at(lo[0], lo[1], lo[2]))) / (double(hi[a] - lo[a]) * v.spacing[a]);
  }
  return g;
}

// The voxel's central differences averaged over its 3x3x3 neighbours with
// weights (2 - |dx|)(2 - |dy|)(2 - |dz|) (clamped at the border), as
// raycast_gradients.
D3 smoothed_gradient_at(const Volume& v, int x, int y, int z) {
  D3 acc{};
  double wsum = 0;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int xx = std::clamp(x + dx, 0, int(v.dims[0]) - 1), yy = std::clamp(y + dy, 0, int(v.dims[1]) - 1),
                  zz = std::clamp(z + dz, 0, int(v.dims[2]) - 1);
        const double w = (2 - std::abs(dx)) * (2 - std::abs(dy)) * (2 - std::abs(dz));
        const D3 g = gradient_at(v, xx, yy, zz);
        for (int a = 0; a < 3; ++a) acc[a] += w * g[a];
        wsum += w;
      }
  for (int a = 0; a < 3; ++a) acc[a] /= wsum;
  return acc;
}

// The pixel's sampling offset in [0, 1) steps (raycast_render's hash).
double jitter(int px, int py) {
  std::uint32_t h = std::uint32_t(px) * 0x9E3779B1u ^ std::uint32_t(py) * 0x85EBCA77u;
  h ^= h >> 15;
  h *= 0x2C1B3C6Du;
  h ^= h >> 12;
  h *= 0x297A2D39u;
  h ^= h >> 15;
  return double(h >> 8) / 16777216.0;
}

D3 gradient(const Volume& v, const D3& p) {
  int i0[3], i1[3];
  double w[3];
  for (int a = 0; a < 3; ++a) axis(p[a], int(v.dims[a]), i0[a], i1[a], w[a]);
  D3 g{};
  for (int k = 0; k < 8; ++k) {
    const int x = k & 1 ? i1[0] : i0[0], y = k & 2 ? i1[1] : i0[1], z = k & 4 ? i1[2] : i0[2];
    const double wk = (k & 1 ? w[0] : 1 - w[0]) * (k & 2 ? w[1] : 1 - w[1]) * (k & 4 ? w[2] : 1 - w[2]);
    const D3 gk = smoothed_gradient_at(v, x, y, z);
    for (int a = 0; a < 3; ++a) g[a] += wk * gk[a];
  }
  return g;
}

std::array<double, 4> reference_pixel(const Volume& v, const RayCaster::Frame& f, bool ortho, int width, int height,
                                      int px, int py) {
  const double sx = 2.0 * (px + 0.5) / width - 1.0, sy = 1.0 - 2.0 * (py + 0.5) / height;
  const D3 fw = d3(f.forward), rt = d3(f.right), up = d3(f.up), eye = d3(f.eye);
  D3 dir, start;
  for (int a = 0; a < 3; ++a) {
    dir[a] = ortho ? fw[a] : fw[a] + sx * f.view[0] * rt[a] + sy * f.view[1] * up[a];
    start[a] = ortho ? eye[a] + sx * f.view[2] * rt[a] + sy * f.view[3] * up[a] : eye[a];
  }
  dir = unit(dir);
  D3 o, d;
  for (int a = 0; a < 3; ++a) o[a] = (start[a] - f.origin[a]) / v.spacing[a], d[a] = dir[a] / v.spacing[a];
  double t0 = ortho ? -HUGE_VAL : 0.0, t1 = HUGE_VAL;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-12) {
      if (o[a] < f.box_lo[a] || o[a] > f.box_hi[a]) t1 = -HUGE_VAL;
      continue;
    }
    const double ta = (f.box_lo[a] - o[a]) / d[a], tb = (f.box_hi[a] - o[a]) / d[a];
    t0 = std::max(t0, std::min(ta, tb));
    t1 = std::min(t1, std::max(ta, tb));
  }
  std::array<double, 4> c{0, 0, 0, 0};
  const double dt = f.tf[3], ref = f.misc[0];
  const double j = jitter(px, py);
  t0 = (std::ceil(t0 / dt - j) + j) * dt;
  if (!(t0 <= t1)) return c;

  const D3 view = {-dir[0], -dir[1], -dir[2]}, light = d3(f.light);
  const D3 half = unit({light[0] + view[0], light[1] + view[1], light[2] + view[2]});
  const int steps = int(std::floor((t1 - t0) / dt)) + 1;
  for (int k = 0; k < steps; ++k) {
    const double t = t0 + k * dt;
    const D3 q = {o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]};
    const double s = sample(v, q);
    const double alpha = s < f.misc[2] ? 0.0 : f.tf[2] * std::clamp((s - f.tf[0]) / (f.tf[1] - f.tf[0]), 0.0, 1.0);
    if (alpha <= 0) continue;
    const double a = alpha >= 1 ? 1.0 : 1.0 - std::pow(1.0 - alpha, dt / ref);
    const D3 g = gradient(v, q);
    const double len = std::sqrt(dot(g, g));
    D3 n = len > 1e-12 ? D3{g[0] / len, g[1] / len, g[2] / len} : view;
    if (dot(n, view) < 0) n = {-n[0], -n[1], -n[2]};
    const double diffuse = std::max(dot(n, light), 0.0);
    const double spec = diffuse > 0 ? std::pow(std::max(dot(n, half), 0.0), f.material[3]) : 0.0;
    const double w = (1 - c[3]) * a;
    for (int ch = 0; ch < 3; ++ch) c[ch] += w * (f.colour[ch] * (f.material[0] + f.material[1] * diffuse) + f.material[2] * spec);
    c[3] += w;
    if (c[3] >= f.misc[1]) break;
  }
  return c;
}

// A smooth blobby field in [0, 1], zero on the border (so a sample on the
// box's surface, which float and double may count differently, adds nothing).
Volume blobs(Dims3 dims, Vec3d spacing) {
  Volume v(dims, spacing);
  v.origin = {-3.5, 2.0, 10.25};
  const double cx[3] = {0.35, 0.6, 0.5}, cy[3] = {0.4, 0.55, 0.7}, cz[3] = {0.5, 0.35, 0.6}, s[3] = {0.18, 0.12, 0.15};
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x) {
        const bool border = x == 0 || y == 0 || z == 0 || x + 1 == dims[0] || y + 1 == dims[1] || z + 1 == dims[2];
        double f = 0;
        for (int b = 0; b < 3; ++b) {
          const double dx = double(x) / (dims[0] - 1) - cx[b], dy = double(y) / (dims[1] - 1) - cy[b],
                       dz = double(z) / (dims[2] - 1) - cz[b];
          f += std::exp(-(dx * dx + dy * dy + dz * dz) / (2 * s[b] * s[b]));
        }
        v.at(x, y, z) = border ? 0.0f : float(std::min(1.0, 0.8 * f));
      }
  return v;
}

std::array<Vec3d, 2> volume_box(const Volume& v) {
  Vec3d lo = v.origin, hi;
  for (int a = 0; a < 3; ++a) hi[a] = v.origin[a] + v.spacing[a] * double(v.dims[a] - 1);
  return {lo, hi};
}

TEST(Raycast, PixelsMatchCpuReferenceRay) {
  Runtime& rt = runtime();
  struct Case {
    Dims3 dims;
    Vec3d spacing;
    float az, el;
    bool ortho;
    float tf_lo, tf_hi, tf_max, tf_cut, step;
    std::array<float, 3> crop_lo, crop_hi;
  };
  const Case cases[] = {
      {{13, 9, 7}, {0.8, 1.1, 1.3}, 30, 20, false, 0, 1, 1, 0, 0.5f, {0, 0, 0}, {1, 1, 1}},
      {{17, 11, 15}, {1.0, 1.0, 1.0}, -50, -35, false, 0.3f, 0.7f, 0.8f, 0, 0.37f, {0, 0, 0}, {1, 1, 1}},
      {{15, 12, 9}, {0.6, 0.6, 1.2}, 120, 10, true, 0.0f, 0.9f, 0.5f, 0.2f, 0.5f, {0.1f, 0, 0.2f}, {0.9f, 0.7f, 1}},
  };
  const int w = 40, h = 30;
  for (const Case& c : cases) {
    const Volume v = blobs(c.dims, c.spacing);
    RaycastParams p;
    p.tf_lo = c.tf_lo, p.tf_hi = c.tf_hi, p.tf_max = c.tf_max, p.tf_cut = c.tf_cut, p.step = c.step, p.termination = 2.0f;
    p.crop_lo = c.crop_lo, p.crop_hi = c.crop_hi;
    const auto box = volume_box(v);
    RayCamera cam = RayCamera::orbit(c.az, c.el, box[0], box[1]);
    cam.orthographic = c.ortho;
    RayCaster rc(rt, v, p);
    const RaycastImage img = rc.render(cam, w, h);
    const RayCaster::Frame f = rc.frame(cam, w, h);
    int hits = 0;
    for (int py = 1; py < h; py += 3)
      for (int px = 2; px < w; px += 3) {
        const auto ref = reference_pixel(v, f, c.ortho, w, h, px, py);
        hits += ref[3] > 0.05;
        for (int ch = 0; ch < 4; ++ch)
          ASSERT_NEAR(img.pixel(px, py)[ch], ref[ch], 2e-3)
              << "pixel (" << px << ", " << py << ") channel " << ch << ", volume " << c.dims[0] << "x" << c.dims[1]
              << "x" << c.dims[2] << (c.ortho ? " orthographic" : " perspective");
      }
    EXPECT_GT(hits, 10) << "too few pixels see the blobs";
  }
}

// Impact parameter (voxels) at which a ray through the shell u = exp(-s^2/2),
// s = |x| - R, reaches opacity 0.5.
double silhouette_voxels(double R) {
  auto opacity = [&](double b) {
    double log_t = 0;
    const double dt = 0.01;
    for (double t = -(R + 8); t <= R + 8; t += dt) {
      const double s = std::sqrt(b * b + t * t) - R, u = std::exp(-0.5 * s * s);
      log_t += u >= 1 ? -1e30 : std::log1p(-u) * dt;
    }
    return 1 - std::exp(log_t);
  };
  double lo = R, hi = R + 6;
  for (int i = 0; i < 40; ++i) (opacity(0.5 * (lo + hi)) > 0.5 ? lo : hi) = 0.5 * (lo + hi);
  return 0.5 * (lo + hi);
}

TEST(Raycast, SpherePhantomSilhouetteMatchesProjection) {
  Runtime& rt = runtime();
  PhantomParams pp;
  pp.shape = PhantomShape::Sphere;
  pp.size = 48;
  const Phantom ph = make_phantom(rt, pp);
  // u from the truth: a soft shell on the sphere's surface.
  Volume u = ph.truth_sdf;
  double n_in = 0;
  Vec3d centre{0, 0, 0};
  for (std::size_t z = 0; z < u.dims[2]; ++z)
    for (std::size_t y = 0; y < u.dims[1]; ++y)
      for (std::size_t x = 0; x < u.dims[0]; ++x) {
        const double s = ph.truth_sdf.at(x, y, z);
        u.at(x, y, z) = float(std::exp(-0.5 * s * s));
        if (s < 0) {
          n_in += 1;
          const std::size_t i[3] = {x, y, z};
          for (int a = 0; a < 3; ++a) centre[a] += u.origin[a] + u.spacing[a] * double(i[a]);
        }
      }
  ASSERT_GT(n_in, 100);
  for (double& c : centre) c /= n_in;
  const double h = u.spacing[0];
  const double radius = std::cbrt(3.0 * n_in / (4.0 * M_PI)) * h;  // mm

  RaycastParams p;
  RaycastParams visible = p;
  const auto box = visible_box(u, visible);
  RayCaster rc(rt, u, p);
  const int size = 128;
  for (const auto& view : {std::array<float, 2>{0, 0}, std::array<float, 2>{40, 25}}) {
    const RayCamera cam = RayCamera::orbit(view[0], view[1], box[0], box[1]);
    const RaycastImage img = rc.render(cam, size, size);
    // Projected sphere: centre and apparent radius in pixels.
    D3 rel;
    for (int a = 0; a < 3; ++a) rel[a] = centre[a] - cam.eye[a];
    const double depth = rel[0] * cam.forward[0] + rel[1] * cam.forward[1] + rel[2] * cam.forward[2];
    const double dist = std::sqrt(dot(rel, rel));
    const double focal = 0.5 * size / std::tan(0.5 * cam.fov_y * M_PI / 180.0);
    const double cx = 0.5 * size + focal * (rel[0] * cam.right[0] + rel[1] * cam.right[1] + rel[2] * cam.right[2]) / depth;
    const double cy = 0.5 * size - focal * (rel[0] * cam.up[0] + rel[1] * cam.up[1] + rel[2] * cam.up[2]) / depth;
    auto projected = [&](double r) { return focal * std::tan(std::asin(r / dist)); };
    // Silhouette: opacity > 0.5; its area-equivalent radius and centroid.
    double n = 0, mx = 0, my = 0;
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x)
        if (img.pixel(x, y)[3] > 0.5f) n += 1, mx += x + 0.5, my += y + 0.5;
    ASSERT_GT(n, 100);
    const double r_px = std::sqrt(n / M_PI);
    std::cout << "[ sphere   ] view " << view[0] << "," << view[1] << ": silhouette radius " << r_px
              << " px, projected sphere " << projected(radius) << " px, predicted "
              << projected(silhouette_voxels(radius / h) * h) << " px, centre (" << mx / n << ", " << my / n
              << ") vs (" << cx << ", " << cy << ")\n";
    // The shell is seen edge-on at the silhouette: a ray passing the centre
    // at b voxels crosses exp(-sdf^2/2) along a chord, and its opacity
    // 1 - exp(integral of ln(1 - u) dt) (per voxel length, as the kernel's
    // correction) reaches 0.5 at b*, found here by bisection.
    EXPECT_GE(r_px, projected(radius)) << "view " << view[0] << "," << view[1];
    EXPECT_NEAR(r_px, projected(silhouette_voxels(radius / h) * h), 1.0) << "view " << view[0] << "," << view[1];
    EXPECT_NEAR(mx / n, cx, 0.75);
    EXPECT_NEAR(my / n, cy, 0.75);
  }
}

// An opaque slab in front of a half-transparent one, both parallel to xy.
Volume slabs() {
  Volume v({24, 24, 32}, {1.0, 1.0, 1.0});
  for (std::size_t z = 0; z < 32; ++z)
    for (std::size_t y = 2; y < 22; ++y)
      for (std::size_t x = 2; x < 22; ++x) v.at(x, y, z) = z >= 6 && z <= 10 ? 1.0f : z >= 18 && z <= 24 ? 0.5f : 0.0f;
  return v;
}

TEST(Raycast, EarlyTerminationOnOpaqueSlabChangesLittle) {
  Runtime& rt = runtime();
  const Volume v = slabs();
  const auto box = volume_box(v);
  const RayCamera cam = RayCamera::orbit(15, 10, box[0], box[1]);
  RaycastParams on, off;
  off.termination = 2.0f;
  RayCaster a(rt, v, on), b(rt, v, off);
  const RaycastImage ia = a.render(cam, 64, 64), ib = b.render(cam, 64, 64);
  double worst = 0;
  for (std::size_t i = 0; i < ia.rgba.size(); ++i) worst = std::max(worst, double(std::abs(ia.rgba[i] - ib.rgba[i])));
  // What is left after 0.99 opacity: at most 0.01 of the brightest shade.
  EXPECT_LT(worst, 0.01 * 1.2) << "largest channel difference";
  EXPECT_GE(ia.pixel(32, 32)[3], 0.99f) << "the front slab is opaque";
}

TEST(Raycast, StepSizeDoesNotChangeTheImage) {
  Runtime& rt = runtime();
  const Volume v = blobs({20, 18, 16}, {1.0, 1.0, 1.0});
  const auto box = volume_box(v);
  const RayCamera cam = RayCamera::orbit(25, 15, box[0], box[1]);
  RaycastParams fine, coarse;
  fine.step = 0.125f;
  coarse.step = 0.5f;
  fine.tf_max = coarse.tf_max = 0.3f;  // semi-transparent: the correction matters
  RayCaster a(rt, v, fine), b(rt, v, coarse);
  const RaycastImage ia = a.render(cam, 48, 48), ib = b.render(cam, 48, 48);
  double sum = 0, worst = 0;
  for (std::size_t i = 3; i < ia.rgba.size(); i += 4) {
    sum += ia.rgba[i];
    worst = std::max(worst, double(std::abs(ia.rgba[i] - ib.rgba[i])));
  }
  EXPECT_GT(sum / (48 * 48), 0.1);
  EXPECT_LT(worst, 0.03) << "opacity with step 1/8 vs 1/2 voxel";
}

TEST(Raycast, ThinTiltedShellShadesWithoutWoodGrain) {
  // A thin (0.6 voxel) planar shell tilted against the grid, seen nearly head-on: its shade
  // should be even. Sampling every ray at the same distances from the eye and shading with
  // the plain central difference printed rings across it (the hit moves through the shell's
  // profile with the sampling phase, and the normal changes from voxel layer to voxel
  // layer); the per-pixel sampling offset and the averaged gradient leave fine noise, which
  // a 7x7 box filter removes. Measured: banding 0.0196 before, 0.0058 after.
  Runtime& rt = runtime();
  const Dims3 d{48, 48, 48};
  Volume v(d, {1.0, 1.0, 1.0});
  const double nn = std::sqrt(0.08 * 0.08 + 0.05 * 0.05 + 1.0), n[3] = {0.08 / nn, 0.05 / nn, 1.0 / nn};
  for (std::size_t z = 0; z < d[2]; ++z)
    for (std::size_t y = 0; y < d[1]; ++y)
      for (std::size_t x = 0; x < d[0]; ++x) {
        const double dist = n[0] * (double(x) - 23.5) + n[1] * (double(y) - 23.5) + n[2] * (double(z) - 23.5);
        v.at(x, y, z) = float(std::exp(-0.5 * (dist / 0.6) * (dist / 0.6)));
      }
  const auto box = volume_box(v);
  const RayCamera cam = RayCamera::orbit(0, 0, box[0], box[1]);
  RaycastParams p;
  RayCaster rc(rt, v, p);
  const int w = 160, h = 160;
  const RaycastImage img = rc.render(cam, w, h);
  std::vector<double> shade(std::size_t(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* px = img.pixel(x, y);
      shade[std::size_t(y) * w + x] = (px[0] + px[1] + px[2]) / 3.0;
    }
  // The middle of the image: the plane, drawn everywhere there. Banding is the shade's
  // variation between the scale of the noise (a 7x7 box removes it) and that of the smooth
  // changes a perspective view and the light bring (a 25x25 box keeps only those).
  auto box_mean = [&](int cx, int cy, int r) {
    double b = 0;
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx) b += shade[std::size_t(cy + dy) * w + (cx + dx)];
    return b / double((2 * r + 1) * (2 * r + 1));
  };
  double sum = 0, sum2 = 0;
  int count = 0;
  for (int y = 50; y < 110; ++y)
    for (int x = 50; x < 110; ++x) {
      ASSERT_GT(img.pixel(x, y)[3], 0.5f) << "the plane covers the middle";
      const double band = box_mean(x, y, 3) - box_mean(x, y, 12);
      sum += box_mean(x, y, 3), sum2 += band * band, ++count;
    }
  const double mean = sum / count, spread = std::sqrt(sum2 / count);
  std::cout << "[ raycast  ] tilted thin shell: shade " << mean << ", banding (rms of 7x7 minus 25x25 box) " << spread << '\n';
  EXPECT_GT(mean, 0.2);
  EXPECT_LT(spread, 0.01) << "banding (wood grain) across a flat surface";
}

TEST(Raycast, BadParametersThrow) {
  RaycastParams p;
  p.tf_lo = 0.5f, p.tf_hi = 0.4f;
  EXPECT_THROW(p.validate(), InputError);
  p = {};
  p.step = 0.0f;
  EXPECT_THROW(p.validate(), InputError);
  p = {};
  p.crop_lo[1] = 0.9f, p.crop_hi[1] = 0.2f;
  EXPECT_THROW(p.validate(), InputError);
}

}  // namespace
}  // namespace softshell::test
