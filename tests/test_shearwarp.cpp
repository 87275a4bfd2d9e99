// Shear-warp through VolPack (host/shearwarp.*): the silhouette of an opaque ball against its
// parallel projection at two views, near voxels in front of far ones, the image orientation of
// the --view convention, determinism, and bad input.
#include <gtest/gtest.h>

#include <cmath>

#include "error.hpp"
#include "shearwarp.hpp"

namespace softshell {
namespace {

// An opaque ball (a linear ramp one voxel wide at its edge), radius R (mm) around c (mm).
Volume ball(Dims3 dims, Vec3d spacing, double R, Vec3d c, Volume* add_to = nullptr) {
  Volume v = add_to ? *add_to : Volume(dims, spacing);
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x) {
        const double p[3] = {spacing[0] * x - c[0], spacing[1] * y - c[1], spacing[2] * z - c[2]};
        const double r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        v.at(x, y, z) = std::max(v.at(x, y, z), float(std::clamp(R - r + 0.5, 0.0, 1.0)));
      }
  return v;
}

struct Disc {
  double radius = 0, cx = 0, cy = 0;
};
Disc disc(const ShearWarpImage& img) {
  double n = 0, sx = 0, sy = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      if (img.pixel(x, y)[3] > 127) n += 1, sx += x + 0.5, sy += y + 0.5;
  return {std::sqrt(n / M_PI), n ? sx / n : 0, n ? sy / n : 0};
}

}  // namespace

TEST(ShearWarp, BallSilhouetteMatchesTheParallelProjection) {
  ASSERT_TRUE(shearwarp_available());
  const double R = 11.0;
  const Vec3d h{1.0, 1.2, 0.9};
  const Dims3 dims{41, 35, 47};
  const Vec3d c{20 * h[0], 17 * h[1], 23 * h[2]};
  ShearWarpRenderer sw(ball(dims, h, R, c));
  EXPECT_GT(sw.voxels_kept(), 4000u);
  EXPECT_GT(sw.timing().preprocess, 0.0);
  ShearWarpView view;
  view.width = view.height = 240;
  view.box = std::array<Vec3d, 2>{Vec3d{c[0] - 20, c[1] - 20, c[2] - 20}, Vec3d{c[0] + 20, c[1] + 20, c[2] + 20}};
  // Visible half height at the target, as the splat camera frames the box.
  const double half_h = 1.05 * 20 * std::sqrt(3.0) / std::cos(15 * M_PI / 180);
  const double want = R / half_h * 120;
  for (auto [az, el] : {std::pair{0.0f, 0.0f}, std::pair{35.0f, 25.0f}}) {
    view.azimuth = az;
    view.elevation = el;
    const Disc d = disc(sw.render(view));
    // alpha > 0.5 lies a little outside R: rays graze several partly opaque voxels of the ramp,
    // and VolPack's opacity correction assumes unit sample spacing (0.6 voxel = 1.9 px).
    EXPECT_NEAR(d.radius, want + 0.5, 1.9) << "view " << az << "," << el;
    EXPECT_NEAR(d.cx, 120, 1.0);
    EXPECT_NEAR(d.cy, 120, 1.0);
    EXPECT_GT(sw.timing().render, 0.0);
  }
}

TEST(ShearWarp, ViewConventionPutsMinusYUpAndXRight) {
  // Ball at high x and low y: at view 0,0 (x right, -y up) it is in the top right quadrant;
  // from azimuth 180 (looking down -z) x points left.
  const Dims3 dims{40, 40, 40};
  const Vec3d h{1, 1, 1};
  ShearWarpRenderer sw(ball(dims, h, 5, {28, 11, 20}));
  ShearWarpView view;
  view.width = view.height = 100;
  view.box = std::array<Vec3d, 2>{Vec3d{0, 0, 0}, Vec3d{39, 39, 39}};
  Disc d = disc(sw.render(view));
  EXPECT_GT(d.cx, 60);
  EXPECT_LT(d.cy, 40);
  view.azimuth = 180;
  d = disc(sw.render(view));
  EXPECT_LT(d.cx, 40);
  EXPECT_LT(d.cy, 40);
}

TEST(ShearWarp, NearOccludesFar) {
  // A small ball near the transducer (small z) in front of a slab far away. Seen from the
  // transducer (view 0,0) the ball's dark lower-right rim shows; composited in the wrong order
  // the slab (lit head-on, uniform) would cover it.
  const Dims3 dims{48, 48, 48};
  Volume v(dims, {1, 1, 1});
  for (std::size_t z = 34; z < 40; ++z)
    for (std::size_t y = 4; y < 44; ++y)
      for (std::size_t x = 4; x < 44; ++x) v.at(x, y, z) = 1.0f;
  v = ball(dims, {1, 1, 1}, 9, {23.5, 23.5, 14}, &v);
  for (float az : {0.0f, 180.0f}) {
    ShearWarpRenderer sw(v);
    ShearWarpView view;
    view.azimuth = az;
    view.width = view.height = 200;
    const ShearWarpImage img = sw.render(view);
    // centre (ball or slab face-on) and a point on the ball's rim towards the lower right
    const Disc d = disc(img);
    const int cx = int(d.cx), cy = int(d.cy);
    const double ring = 9.0 / (1.05 * 0.5 * std::sqrt(40.0 * 40 + 40 * 40 + 36 * 36) / std::cos(15 * M_PI / 180)) * 100;
    const int rx = cx + int(0.62 * ring), ry = cy + int(0.62 * ring);
    const int centre = img.pixel(cx, cy)[0], rim = img.pixel(rx, ry)[0];
    if (az == 0.0f)
      EXPECT_LT(rim, centre - 40) << "ball in front: its rim is darker (" << rim << " vs " << centre << ")";
    else
      EXPECT_NEAR(rim, centre, 25) << "slab in front: uniform (" << rim << " vs " << centre << ")";
  }
}

TEST(ShearWarp, DeterministicAndBadInput) {
  const Volume v = ball({30, 28, 26}, {1, 1, 1}, 8, {15, 14, 13});
  ShearWarpView view;
  view.azimuth = 30;
  view.elevation = -20;
  view.width = 90;
  view.height = 70;
  const ShearWarpImage a = render_shearwarp(v, view), b = render_shearwarp(v, view);
  EXPECT_EQ(a.width, 90);
  EXPECT_EQ(a.height, 70);
  EXPECT_EQ(a.rgba, b.rgba);
  Volume bad = v;
  bad.data[100] = 1.5f;
  EXPECT_THROW(ShearWarpRenderer{bad}, InputError);
  EXPECT_THROW(ShearWarpRenderer{Volume({8, 1, 8})}, InputError);
  ShearWarpRenderer sw(v);
  view.width = 0;
  EXPECT_THROW(sw.render(view), InputError);
}

}  // namespace softshell
