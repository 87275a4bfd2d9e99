// The OpenGL splat renderer (viewer/), headless: a hidden GLFW window, run
// under `xvfb-run -a` (scripts/test.sh) with Mesa's llvmpipe. These tests
// need a display and fail without one; they never skip.
//  - the paper's claim: two adjacent unit splats parallel to the image give
//    about 0.95 opacity midway (read from the framebuffer's alpha);
//  - a sphere's silhouette matches the projected sphere;
//  - oriented splats give a thinner silhouette rim than isotropic ones
//    (the paper's Figure 3), in pixels;
//  - back to front: a near red layer over a far blue one shows red, for
//    the presorted lists and the exact sort, from both sides.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <chrono>
#include <memory>
#include <thread>

#include "headless.hpp"
#include "image.hpp"
#include "splats.hpp"
#include "test_support.hpp"

namespace softshell::test {
namespace {

using viewer::HeadlessRenderer;
using viewer::OrbitCamera;
using viewer::RenderSettings;
using viewer::RgbaImage;

// One hidden window per test process (GLFW starts once).
HeadlessRenderer& renderer(int w, int h) {
  static std::unique_ptr<HeadlessRenderer> r;
  if (!r || r->width() != w || r->height() != h) {
    r.reset();
    r = std::make_unique<HeadlessRenderer>(w, h);
    std::cout << "[ gl       ] " << r->description() << '\n';
  }
  return *r;
}

// Unlit white splats on black: the colour channels equal the opacity.
RenderSettings unlit() {
  RenderSettings s;
  s.colour = glm::vec3(1.0f);
  s.ambient = 1.0f;
  s.diffuse = 0.0f;
  s.specular = 0.0f;
  s.background = glm::vec3(0.0f);
  return s;
}

// A hand-made splat parallel to the xy plane (normal -z) at `c`, unit alpha.
Splat flat_splat(glm::vec3 c, double a, float tint = 0.0f, float alpha = 1.0f) {
  Splat s{};
  for (int i = 0; i < 3; ++i) s.centre[i] = c[i];
  s.alpha = alpha;
  s.normal[2] = -1.0f;
  s.s[0] = float(a);
  s.t[1] = float(a);
  s.t[3] = tint;
  for (auto& n : s.vertex_normal) n[2] = -1.0f;
  return s;
}

SplatSet hand_set(std::vector<Splat> splats, Dims3 dims, Vec3d origin, SplatGaussian kind = SplatGaussian::Paper) {
  SplatSet set;
  set.params.gaussian = kind;
  set.lambda = splat_lambda(0.2, kind);
  set.a = splat_size(0.2, kind);
  set.dims = dims;
  set.origin = origin;
  set.splats = std::move(splats);
  return set;
}

OrbitCamera looking_down_z(glm::vec3 target, float distance) {
  OrbitCamera cam;
  cam.target = target;
  cam.distance = distance;
  cam.radius = 5.0f;
  return cam;
}

double opacity_at(const RgbaImage& img, int x, int y) { return img.pixel(x, y)[3] / 255.0; }

TEST(Render, TwoAdjacentSplatsGiveAbout095Midway) {
  const int size = 201;  // odd: the centre pixel sits on the optical axis
  HeadlessRenderer& r = renderer(size, size);
  const OrbitCamera cam = looking_down_z({0, 0, 0}, 8.0f);
  for (SplatGaussian kind : {SplatGaussian::Paper, SplatGaussian::Rim}) {
    SCOPED_TRACE(std::string("gaussian ") + splat_gaussian_name(kind));
    const double a = splat_size(0.2, kind);
    // One splat at the centre: opacity 1 there, and G(half a voxel) = e^-0.25.
    r.upload(hand_set({flat_splat({0, 0, 0}, a)}, {1, 1, 1}, {0, 0, 0}, kind));
    r.render(cam, unlit());
    RgbaImage one = r.read();
    EXPECT_NEAR(opacity_at(one, 100, 100), 1.0, 0.01);
    // Half a voxel to the right, in pixels: the projection of 0.5 mm at 8 mm.
    const double px_per_mm = (size / 2.0) / (8.0 * std::tan(glm::radians(15.0)));
    const int half = int(std::lround(100 + 0.5 * px_per_mm));
    EXPECT_NEAR(opacity_at(one, half, 100), std::exp(-0.25), 0.02);

    // Two splats one voxel apart: midway (the centre pixel) about 0.95.
    r.upload(hand_set({flat_splat({-0.5f, 0, 0}, a), flat_splat({0.5f, 0, 0}, a)}, {2, 1, 1}, {-0.5, 0, 0}, kind));
    r.render(cam, unlit());
    RgbaImage two = r.read();
    const double mid = opacity_at(two, 100, 100);
    std::cout << "[ result   ] gaussian " << splat_gaussian_name(kind) << ": midway opacity " << mid
              << " (paper: about 0.95)\n";
    EXPECT_NEAR(mid, 0.951, 0.015);
    // The colour composited onto black says the same.
    EXPECT_NEAR(two.pixel(100, 100)[0] / 255.0, mid, 0.01);
  }
}

// Opacity volume of a soft spherical shell, u = max(0, 1 - |r - R| / 1.5).
Volume sphere_shell(int n, double radius, Vec3d spacing = {1, 1, 1}) {
  Volume u({std::size_t(n), std::size_t(n), std::size_t(n)}, spacing);
  u.origin = {-10.0, 4.0, 2.5};
  const double c = 0.5 * (n - 1);
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double d = std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + (z - c) * (z - c));
        u.at(x, y, z) = float(std::max(0.0, 1.0 - std::abs(d - radius) / 1.5));
      }
  return u;
}

struct Silhouette {
  double cx = 0, cy = 0;  // centroid of alpha > level
  double radius = 0;      // sqrt(area / pi)
};

Silhouette silhouette(const RgbaImage& img, double level) {
  Silhouette s;
  double n = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      if (opacity_at(img, x, y) > level) n += 1, s.cx += x + 0.5, s.cy += y + 0.5;
  if (n > 0) s.cx /= n, s.cy /= n;
  s.radius = std::sqrt(n / M_PI);
  return s;
}

// Pixel radius of a sphere of radius rho (mm) seen from distance d (mm).
double projected_radius(const OrbitCamera& cam, int height, double rho) {
  const double ang = std::asin(rho / cam.distance);
  return (height / 2.0) * std::tan(ang) / std::tan(glm::radians(cam.fov_y / 2.0));
}

TEST(Render, SphereSilhouetteMatchesProjection) {
  const int size = 240, n = 40;
  const double radius = 13.0;
  HeadlessRenderer& r = renderer(size, size);
  const SplatSet set = generate_splats(runtime(), sphere_shell(n, radius));
  ASSERT_GT(set.splats.size(), 1000u);
  r.upload(set);
  OrbitCamera cam;
  cam.fit(set.box_lo(), set.box_hi());
  for (const auto& [az, el] : {std::pair{0.0f, 0.0f}, std::pair{40.0f, 25.0f}}) {
    cam.azimuth = az;
    cam.elevation = el;
    r.render(cam, unlit());
    const Silhouette s = silhouette(r.read(), 0.5);
    // The shell's mid-surface at radius R; opacity above 0.5 reaches out to
    // about R + 1 (the shell's half-width at 0.5 opacity is 0.75 voxel, plus
    // splat overlap), so the silhouette lies within R and R + 1.5 voxels.
    const double lo = projected_radius(cam, size, radius), hi = projected_radius(cam, size, radius + 1.5);
    std::cout << "[ result   ] view " << az << "," << el << ": silhouette radius " << s.radius << " px, centre ("
              << s.cx << ", " << s.cy << "); projected sphere " << lo << " to " << hi << " px\n";
    EXPECT_GT(s.radius, lo);
    EXPECT_LT(s.radius, hi);
    // The centre of the volume projects to the image centre.
    EXPECT_NEAR(s.cx, size / 2.0, 0.75);
    EXPECT_NEAR(s.cy, size / 2.0, 0.75);
  }
}

TEST(Render, OrientedSplatsGiveAThinnerSilhouetteRimThanIsotropic) {
  const int size = 240, n = 40;
  HeadlessRenderer& r = renderer(size, size);
  const SplatSet set = generate_splats(runtime(), sphere_shell(n, 13.0));
  r.upload(set);
  OrbitCamera cam;
  cam.fit(set.box_lo(), set.box_hi());
  cam.azimuth = 20.0f;
  cam.elevation = 10.0f;
  RenderSettings s = unlit();
  // The rim: how far the faint silhouette (alpha > 0.05) reaches beyond the
  // projected mid-surface of the shell.
  const double mid_surface = projected_radius(cam, size, 13.0);
  auto rim = [&](viewer::SplatMethod m) {
    s.method = m;
    r.render(cam, s);
    return silhouette(r.read(), 0.05).radius - mid_surface;
  };
  const double rim_o = rim(viewer::SplatMethod::Oriented), rim_i = rim(viewer::SplatMethod::Isotropic);
  const double px_per_voxel = projected_radius(cam, size, 1.0);
  std::cout << "[ result   ] silhouette rim beyond the shell's mid-surface: oriented " << rim_o << " px, isotropic "
            << rim_i << " px (" << px_per_voxel << " px per voxel)\n";
  // Isotropic splats reach a/2 = 0.79 voxel beyond the outermost centres;
  // oriented ones lie tangent there and do not: ask for half of that.
  EXPECT_GT(rim_i - rim_o, 0.4 * px_per_voxel);
  EXPECT_GT(rim_o, 0.0);
}

TEST(Render, BackToFrontNearRedOverFarBlue) {
  const int size = 101;
  HeadlessRenderer& r = renderer(size, size);
  const double a = splat_size(0.2);
  // Two 9x9 layers of unit splats, z = 0 (near the default camera, red,
  // ramp 0) and z = 4 (far, blue, ramp 1).
  std::vector<Splat> splats;
  for (int layer = 0; layer < 2; ++layer)
    for (int y = -4; y <= 4; ++y)
      for (int x = -4; x <= 4; ++x) splats.push_back(flat_splat({float(x), float(y), 4.0f * layer}, a, float(layer)));
  // Interleave the layers in the input so no input order is already right.
  std::vector<Splat> mixed;
  for (std::size_t i = 0; i < 81; ++i) mixed.push_back(splats[i % 2 ? i : 81 + i]), mixed.push_back(splats[i % 2 ? 81 + i : i]);
  r.upload(hand_set(mixed, {9, 9, 5}, {-4, -4, 0}));
  RenderSettings s = unlit();
  s.colour = {1, 0, 0};
  s.colour2 = {0, 0, 1};
  for (auto order : {viewer::DrawOrder::Lists, viewer::DrawOrder::Sort})
    for (float az : {0.0f, 180.0f, 25.0f}) {
      OrbitCamera cam = looking_down_z({0, 0, 2}, 40.0f);
      cam.azimuth = az;
      s.order = order;
      r.render(cam, s);
      const RgbaImage img = r.read();  // kept: pixel() points into it
      const std::uint8_t* p = img.pixel(50, 50);
      const bool red_near = std::cos(glm::radians(az)) > 0;  // camera on the -z side
      SCOPED_TRACE(std::string(order == viewer::DrawOrder::Lists ? "lists" : "sort") + ", azimuth " +
                   std::to_string(az));
      if (red_near) {
        EXPECT_GT(p[0], 230) << "red should cover blue";
        EXPECT_LT(p[2], 25);
      } else {
        EXPECT_GT(p[2], 230) << "blue should cover red";
        EXPECT_LT(p[0], 25);
      }
    }
}

// A slab of u = 1, 2.4 voxels thick, tilted by atan(1/4) about y: its faces
// are voxel staircases with a step every 4 voxels along x.
// Luminance of a pixel (Rec. 601 weights).
double luma(const RgbaImage& img, int x, int y) {
  const std::uint8_t* p = img.pixel(x, y);
  return 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2];
}

// The splats of `set`, the camera fitted to them and turned to azimuth,
// elevation; the picture is also written to $SOFTSHELL_TEST_IMAGES/NAME.png
// when that is set.
RgbaImage draw_fitted(HeadlessRenderer& r, const SplatSet& set, float azimuth, float elevation,
                      const RenderSettings& s, const std::string& name) {
  r.upload(set);
  OrbitCamera cam;
  cam.fit(set.box_lo(), set.box_hi());
  cam.azimuth = azimuth;
  cam.elevation = elevation;
  r.render(cam, s);
  RgbaImage img = r.read();
  if (const char* dir = std::getenv("SOFTSHELL_TEST_IMAGES")) write_png(std::string(dir) + "/" + name + ".png", img.rgb());
  return img;
}

Volume tilted_slab(int nx, int ny, int nz) {
  Volume u({std::size_t(nx), std::size_t(ny), std::size_t(nz)});
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) u.at(x, y, z) = std::fabs(z - (6.0 + 0.25 * x)) <= 1.2 ? 1.0f : 0.0f;
  return u;
}

// Banding of an image across x: the luminance of the central rows averaged
// per column over the middle of the slab, its residual from a straight-line
// fit over a window of +-`half` columns (a local trend), and the amplitude
// of its strongest periodic component (periods 8-40 px) over the mean.
double banding(const RgbaImage& img, int x0, int x1, int y0, int y1, int half) {
  std::vector<double> profile;
  for (int x = x0; x < x1; ++x) {
    double sum = 0;
    for (int y = y0; y < y1; ++y) sum += luma(img, x, y);
    profile.push_back(sum / (y1 - y0));
  }
  std::vector<double> residual;
  double mean = 0;
  for (int i = half; i + half < int(profile.size()); ++i) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (int k = -half; k <= half; ++k) {
      sx += k, sy += profile[i + k], sxx += double(k) * k, sxy += k * profile[i + k];
    }
    const int m = 2 * half + 1;
    const double slope = (m * sxy - sx * sy) / (m * sxx - sx * sx);
    residual.push_back(profile[i] - (sy - slope * sx) / m);  // about the local line at k = 0
    mean += profile[i];
  }
  if (residual.empty() || mean <= 0) return 0.0;
  mean /= double(residual.size());
  // The strongest periodic component with a period of 8 to 40 px (the
  // staircase's step), as an amplitude over the mean.
  double best = 0;
  const double pi = std::acos(-1.0);
  for (double period = 8; period <= 40; period += 0.25) {
    double re = 0, im = 0;
    for (std::size_t i = 0; i < residual.size(); ++i) {
      re += residual[i] * std::cos(2 * pi * double(i) / period);
      im += residual[i] * std::sin(2 * pi * double(i) / period);
    }
    best = std::max(best, 2.0 * std::hypot(re, im) / double(residual.size()));
  }
  return best / mean;
}

// Roughness of the slab's lower silhouette: per column, the lowest row
// whose opacity exceeds 0.5; RMS residual (px) about a straight-line fit.
double edge_roughness(const RgbaImage& img, int x0, int x1) {
  std::vector<double> xs, ys;
  for (int x = x0; x < x1; ++x)
    for (int y = img.height - 1; y >= 0; --y)
      if (img.pixel(x, y)[3] > 127) {
        xs.push_back(x);
        ys.push_back(y);
        break;
      }
  const double n = double(xs.size());
  if (n < 3) return 0.0;
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < xs.size(); ++i) sx += xs[i], sy += ys[i], sxx += xs[i] * xs[i], sxy += xs[i] * ys[i];
  const double slope = (n * sxy - sx * sy) / (n * sxx - sx * sx), icpt = (sy - slope * sx) / n;
  double r = 0;
  for (std::size_t i = 0; i < xs.size(); ++i) r += (ys[i] - slope * xs[i] - icpt) * (ys[i] - slope * xs[i] - icpt);
  return std::sqrt(r / n);
}

TEST(Render, ShellCentresRemoveTheBandsOfATiltedSlab) {
  // docs/rendering.md, "Banding": splats on voxel centres draw the slab's
  // staircase as bands across the tilt; moved to the slab's mid-surface
  // (SplatCentres::Shell) they do not.
  const int size = 320;
  HeadlessRenderer& r = renderer(size, size);
  const Volume u = tilted_slab(64, 32, 26);
  double band[2] = {0, 0}, rough[2] = {0, 0};
  for (const SplatCentres c : {SplatCentres::Voxel, SplatCentres::Shell}) {
    SplatParams p;
    p.centres = c;
    RenderSettings s;
    s.background = glm::vec3(0.0f);
    // The slab at a grazing angle (elevation -60), where the bands show.
    const RgbaImage img = draw_fitted(r, generate_splats(runtime(), u, p), 0.0f, -60.0f, s,
                                      std::string("banding-") + splat_centres_name(c));
    // The slab fills the middle of the image; the step period is about
    // 4 voxels = size / 64 * 4 px (fit frames the whole box).
    band[c == SplatCentres::Shell] = banding(img, size / 5, size * 4 / 5, size * 2 / 5, size * 3 / 5, 20);
    rough[c == SplatCentres::Shell] = edge_roughness(img, size / 5, size * 4 / 5);
  }
  std::cout << "[ result   ] banding across the tilt (the strongest periodic component of the luminance / its mean): voxel "
            << "centres " << band[0] << ", shell centres " << band[1] << "; lower silhouette's roughness: voxel "
            << rough[0] << " px, shell " << rough[1] << " px\n";
  EXPECT_GT(band[0], 1.3 * band[1]);
  EXPECT_GT(rough[0], 2.0 * rough[1]);
}

TEST(Render, AsyncSortDrawsTheExactOrderWithoutWaitingForIt) {
  // DrawOrder::Sort with async_sort (the viewer): the first draw sorts at
  // once; after the camera moves, draws go on with the old order (reported
  // stale) while a worker sorts, and once it is done the picture equals a
  // synchronous exact-order draw from the new eye.
  const int size = 101;
  HeadlessRenderer& r = renderer(size, size);
  const double a = splat_size(0.2);
  std::vector<Splat> splats;
  for (int layer = 0; layer < 2; ++layer)
    for (int y = -4; y <= 4; ++y)
      for (int x = -4; x <= 4; ++x) splats.push_back(flat_splat({float(x), float(y), 4.0f * layer}, a, float(layer)));
  r.upload(hand_set(splats, {9, 9, 5}, {-4, -4, 0}));
  RenderSettings s = unlit();
  s.colour = {1, 0, 0};
  s.colour2 = {0, 0, 1};
  s.order = viewer::DrawOrder::Sort;
  OrbitCamera cam = looking_down_z({0, 0, 2}, 40.0f);
  cam.azimuth = 170.0f;
  const RgbaImage want = (r.render(cam, s), r.read());  // synchronous, from the far side
  r.upload(hand_set(splats, {9, 9, 5}, {-4, -4, 0}));   // forget that order
  s.async_sort = true;
  cam.azimuth = 10.0f;
  EXPECT_FALSE(r.render(cam, s).stale_order);  // the first order is sorted at once
  cam.azimuth = 170.0f;
  EXPECT_TRUE(r.render(cam, s).stale_order);   // the sort for the new eye has just started
  bool stale = true;
  for (int i = 0; i < 500 && stale; ++i) {
    stale = r.render(cam, s).stale_order;
    if (stale) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_FALSE(stale) << "the worker's order never arrived";
  const RgbaImage got = r.read();
  EXPECT_EQ(got.rgba, want.rgba);
  EXPECT_GT(got.pixel(50, 50)[2], 230);  // blue, the near layer from this side, covers red
}

TEST(Render, AmbientOcclusionDarkensTheInsideOfACreaseOnly) {
  // Two perpendicular plates of u = 1 (an open book); seen into the
  // crease, the lit colour near it is darker with the occlusion on, and far
  // from it the same.
  const int size = 300, n = 48;
  HeadlessRenderer& r = renderer(size, size);
  Volume u({std::size_t(n), std::size_t(n), std::size_t(n)});
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x)
        u.at(x, y, z) = (std::abs(z - 10) <= 1 && x >= 10) || (std::abs(x - 10) <= 1 && z >= 10) ? 1.0f : 0.0f;
  std::vector<double> column[2];
  for (const bool on : {false, true}) {
    SplatParams p;
    p.occlusion = on;
    const RgbaImage img = draw_fitted(r, generate_splats(runtime(), u, p), 135.0f, -30.0f, RenderSettings{},
                                      std::string("occlusion-") + (on ? "on" : "off"));
    for (int x = 0; x < size; ++x) {
      double sum = 0;
      for (int y = size * 2 / 5; y < size * 3 / 5; ++y) sum += luma(img, x, y);
      column[on].push_back(sum);
    }
  }
  // The crease is the image's middle column; the plates reach a third of the width either side.
  double darkest = 1.0;
  for (int x = size / 2 - 20; x <= size / 2 + 20; ++x)
    if (column[0][x] > 0) darkest = std::min(darkest, column[1][x] / column[0][x]);
  std::cout << "[ result   ] lit colour with / without the occlusion: " << darkest << " at its darkest near the crease";
  EXPECT_LT(darkest, 0.85);
  for (const int x : {size / 2 - 90, size / 2 - 80, size / 2 + 80, size / 2 + 90}) {
    ASSERT_GT(column[0][x], 0) << x;
    std::cout << ", " << column[1][x] / column[0][x] << " at column " << x;
    EXPECT_NEAR(column[1][x] / column[0][x], 1.0, 0.03) << x;
  }
  std::cout << '\n';
}

TEST(Render, RimGaussianClosesTheScreenDoorOfAThinShell) {
  // A thin shell of u = 0.6 (one to two voxels, as the face's back is):
  // the paper's printed lambda cuts each splat off at 0.54 of its peak and
  // leaves a grid of dots between the splats; the rim rule (G = eps at the
  // rim, the CLI's default) covers them. Dots: the RMS of the luminance
  // about its 3x3 mean inside the sphere's image, over the mean.
  const int size = 240, n = 40;
  HeadlessRenderer& r = renderer(size, size);
  Volume u({std::size_t(n), std::size_t(n), std::size_t(n)});
  const double c = (n - 1) / 2.0;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double rr = std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + (z - c) * (z - c));
        u.at(x, y, z) = std::abs(rr - 14.0) < 0.8 ? 0.6f : 0.0f;
      }
  double dots[2] = {0, 0};
  for (const SplatGaussian g : {SplatGaussian::Paper, SplatGaussian::Rim}) {
    SplatParams p;
    p.gaussian = g;
    const RgbaImage img = draw_fitted(r, generate_splats(runtime(), u, p), 180.0f, 10.0f, RenderSettings{},
                                      std::string("screen-door-") + splat_gaussian_name(g));
    const auto lum = [&](int x, int y) { return luma(img, x, y); };
    double rms = 0, mean = 0;
    int count = 0;
    for (int y = size / 2 - 25; y < size / 2 + 25; ++y)  // inside the sphere's image (radius ~45 px)
      for (int x = size / 2 - 25; x < size / 2 + 25; ++x) {
        double local = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) local += lum(x + dx, y + dy) / 9.0;
        rms += (lum(x, y) - local) * (lum(x, y) - local);
        mean += lum(x, y);
        ++count;
      }
    dots[g == SplatGaussian::Rim] = std::sqrt(rms / count) / (mean / count);
  }
  std::cout << "[ result   ] dot pattern on a thin shell's back (RMS about the 3x3 mean / mean): paper " << dots[0]
            << ", rim " << dots[1] << '\n';
  EXPECT_GT(dots[0], 2.0 * dots[1]);
}

TEST(Render, CropBoxDropsSplats) {
  const int size = 101;
  HeadlessRenderer& r = renderer(size, size);
  const double a = splat_size(0.2);
  std::vector<Splat> splats;
  for (int x = -4; x <= 4; ++x) splats.push_back(flat_splat({float(x), 0.0f, 0.0f}, a));
  r.upload(hand_set(splats, {9, 1, 1}, {-4, 0, 0}));
  RenderSettings s = unlit();
  const OrbitCamera cam = looking_down_z({0, 0, 0}, 30.0f);
  r.render(cam, s);
  const double px = (size / 2.0) / (30.0 * std::tan(glm::radians(15.0)));  // per mm
  const int left = int(50 - 3 * px), right = int(50 + 3 * px);
  EXPECT_GT(opacity_at(r.read(), left, 50), 0.9);
  s.crop_lo.x = 0.5f;  // keep x >= 0
  r.render(cam, s);
  const RgbaImage img = r.read();
  EXPECT_LT(opacity_at(img, left, 50), 0.01);
  EXPECT_GT(opacity_at(img, right, 50), 0.9);
}

}  // namespace
}  // namespace softshell::test
