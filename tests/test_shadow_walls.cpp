// Shadow walls (host/shadow_walls.hpp): known answers on synthetic scenes --
// the sides of a shadow under a bright bar are weighted down below the gap
// and nowhere else, an object in fluid keeps every edge, unscanned voxels
// neither occlude nor shade; a thin echo's underside weighted down where asked,
// its top, a thick layer's far side and a cyst's top wall not -- the
// parameters' scaling, the product of two weights, and classify's switch
// (drawn with keep, not with remove).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <vector>

#include "mask.hpp"
#include "shadow_walls.hpp"
#include "test_support.hpp"
#include "variational.hpp"

namespace softshell {
namespace {

constexpr double kH = 0.5;  // mm

// Speckle-like samples (test::speckled) of a factor 0.85-1.15, grain 2
// voxels across the beam (z).
template <class Mean>
Volume scene(Dims3 dims, Mean mean, std::uint64_t seed) {
  return test::speckled(dims, kH, mean, seed, 0.85, 1.15, 2);
}

// Tissue (150) with a bright bar (240) 8-10 mm deep under x in [10, 14) mm
// (along y), and its shadow (20) below it to the bottom.
Volume bar_over_shadow(std::uint64_t seed) {
  return scene({48, 24, 64},
               [](double x, double, double z) {
                 if (x >= 10.0 && x < 14.0) return z < 8.0 ? 150.0 : z < 10.0 ? 240.0 : 20.0;
                 return 150.0;
               },
               seed);
}

float at_mm(const std::vector<float>& w, const Volume& v, double x, double y, double z) {
  return w[v.index(std::size_t(std::lround(x / kH)), std::size_t(std::lround(y / kH)), std::size_t(std::lround(z / kH)))];
}

TEST(ShadowWalls, TheSidesOfAShadowAreWeightedDownBelowTheGapAndNothingElse) {
  const Volume v = bar_over_shadow(test::seed());
  ShadowWallReport r;
  const std::vector<float> w = shadow_wall_weight(test::runtime(), v, nullptr, 85.0, ShadowWallParams{}, &r);
  ASSERT_EQ(w.size(), v.voxels());
  // The shadow: 4 mm of 24 across x, from 3 mm below the bar (13 mm: it
  // lasts to the bottom) down to 32 mm: 1/6 x 19/32 of the voxels.
  EXPECT_NEAR(r.shadow_share, (4.0 / 24.0) * (19.0 / 32.0), 0.01);
  for (double z : {18.0, 24.0, 30.0}) {
    EXPECT_LT(at_mm(w, v, 10.0, 6.0, z), 0.5f) << "left wall at " << z << " mm";
    EXPECT_LT(at_mm(w, v, 13.5, 6.0, z), 0.5f) << "right wall at " << z << " mm";
    EXPECT_FLOAT_EQ(at_mm(w, v, 20.0, 6.0, z), 1.0f) << "tissue away from the shadow";
    EXPECT_FLOAT_EQ(at_mm(w, v, 4.0, 6.0, z), 1.0f) << "tissue away from the shadow";
  }
  // The bar's top (an edge along the beam) and the shadow's first 1.5 mm.
  EXPECT_FLOAT_EQ(at_mm(w, v, 12.0, 6.0, 7.5), 1.0f);
  EXPECT_GT(at_mm(w, v, 10.0, 6.0, 11.5), 0.99f);
  EXPECT_GT(r.wall_share, 0.0);
  // Without the lasting shadow's shorter gap (lasting_gap_mm = gap_mm) the
  // shadow starts 6 mm under the bar, as before it.
  ShadowWallParams same;
  same.lasting_gap_mm = same.gap_mm;
  ShadowWallReport rs;
  const std::vector<float> ws = shadow_wall_weight(test::runtime(), v, nullptr, 85.0, same, &rs);
  EXPECT_NEAR(rs.shadow_share, (4.0 / 24.0) * (16.0 / 32.0), 0.01);
  EXPECT_GT(at_mm(ws, v, 10.0, 6.0, 14.0), 0.99f);
  EXPECT_LT(at_mm(ws, v, 10.0, 6.0, 18.0), 0.5f);
  // A larger gap moves where the walls start.
  ShadowWallParams deep;
  deep.gap_mm = deep.lasting_gap_mm = 16.0;
  const std::vector<float> wd = shadow_wall_weight(test::runtime(), v, nullptr, 85.0, deep);
  EXPECT_GT(at_mm(wd, v, 10.0, 6.0, 18.0), 0.99f);
  EXPECT_LT(at_mm(wd, v, 10.0, 6.0, 30.0), 0.5f);
}

TEST(ShadowWalls, AShadowThatLastsStartsThreeMillimetresUnderItsOccluderACystsInsideSix) {
  // Two dark columns under the same bright bar (240, 8-10 mm deep): on the
  // left (x 10-14 mm) a shadow to the bottom; on the right (x 30-34 mm) a
  // cyst's dark inside, 10 mm tall, with tissue below it (its far wall).
  // The shadow's sides are walls from 3 mm under the bar (lasting_gap_mm),
  // the cyst's only from 6 mm (gap_mm), so a small cyst keeps its walls.
  const Volume v = scene({96, 24, 64},
                         [](double x, double, double z) {
                           const bool left = x >= 10.0 && x < 14.0, right = x >= 30.0 && x < 34.0;
                           if (!left && !right) return 150.0;
                           if (z < 8.0) return 150.0;
                           if (z < 10.0) return 240.0;
                           return left || z < 20.0 ? 20.0 : 150.0;
                         },
                         test::seed() + 21);
  const std::vector<float> w = shadow_wall_weight(test::runtime(), v, nullptr, 85.0);
  for (double z : {14.0, 15.0}) {
    EXPECT_LT(at_mm(w, v, 10.0, 6.0, z), 0.5f) << "the shadow's left wall at " << z << " mm";
    EXPECT_LT(at_mm(w, v, 13.5, 6.0, z), 0.5f) << "the shadow's right wall at " << z << " mm";
    EXPECT_GT(at_mm(w, v, 30.0, 6.0, z), 0.99f) << "the cyst's left wall at " << z << " mm";
    EXPECT_GT(at_mm(w, v, 33.5, 6.0, z), 0.99f) << "the cyst's right wall at " << z << " mm";
  }
  // Deeper than 6 mm under the bar the cyst's inside is a shadow too (the
  // rule before the lasting gap): its sides there are weighted down.
  EXPECT_LT(std::min(at_mm(w, v, 30.0, 6.0, 17.5), at_mm(w, v, 33.5, 6.0, 17.5)), 0.5f);
  // The tissue under the cyst is no shadow.
  EXPECT_FLOAT_EQ(at_mm(w, v, 32.0, 6.0, 26.0), 1.0f);
}

TEST(ShadowWalls, AWallWhoseBrightSideLiesJustUnderTheIsovalueIsAWallWithBrightMm) {
  // The isovalue (160) between the tissue (150) and the bar (240): the
  // tissue beside the shadow lies under it, but within 1 mm of it by the
  // gradient. With bright_mm 1 its walls are weighted down; by default
  // (bright_mm 0: the bright side above the isovalue) they are not. The
  // lowpassed bar's flank over the tissue beside it also counts as an
  // occluder at this isovalue, so the weighted band reaches about 1 mm into
  // the tissue: each side's minimum within 2 mm of the shadow's edge is
  // looked at. Tissue away from the shadow and the shadow's first 6 mm keep
  // their edges either way.
  // (At this isovalue the tissue beside the shadow is dark to the bottom
  // too, so the lasting shadow's shorter gap would start the band 3 mm under
  // the flank; it is set to gap_mm here, the rule this test is about.)
  const Volume v = bar_over_shadow(test::seed() + 11);
  ShadowWallParams base;
  base.lasting_gap_mm = base.gap_mm;
  ShadowWallParams near = base;
  near.bright_mm = 1.0;
  const std::vector<float> w = shadow_wall_weight(test::runtime(), v, nullptr, 160.0, near);
  const std::vector<float> w0 = shadow_wall_weight(test::runtime(), v, nullptr, 160.0, base);
  const auto lowest = [&](const std::vector<float>& m, double x0, double x1, double z) {
    float lo = 1.0f;
    for (double x = x0; x <= x1 + 1e-9; x += kH) lo = std::min(lo, at_mm(m, v, x, 6.0, z));
    return lo;
  };
  for (double z : {18.0, 24.0, 30.0}) {
    EXPECT_LT(lowest(w, 8.0, 10.5, z), 0.5f) << "left wall at " << z << " mm";
    EXPECT_LT(lowest(w, 13.5, 16.0, z), 0.5f) << "right wall at " << z << " mm";
    EXPECT_GT(lowest(w0, 8.0, 10.5, z), 0.99f) << "left wall at " << z << " mm, bright side above the isovalue";
    EXPECT_GT(lowest(w0, 13.5, 16.0, z), 0.99f) << "right wall at " << z << " mm, bright side above the isovalue";
    EXPECT_FLOAT_EQ(at_mm(w, v, 20.0, 6.0, z), 1.0f) << "tissue away from the shadow";
    EXPECT_FLOAT_EQ(at_mm(w, v, 3.0, 6.0, z), 1.0f) << "tissue away from the shadow";
  }
  EXPECT_GT(lowest(w, 8.0, 16.0, 12.0), 0.99f);  // the shadow's first 6 mm
}

TEST(ShadowWalls, AStripBetweenTwoShadowsNarrowerThanTheReachIsWalledAcrossItsWidth) {
  // Two bright bars (240, 8-10 mm deep) under x in [8, 14) and [16, 22)
  // mm, each with its shadow (20) below it to the bottom; between them a
  // strip of tissue 2 mm wide, the beam passing between two bones. Lowpassed
  // by 1.5 mm the strip stays above the isovalue (70) over about 1.2 mm, less
  // than the reach (1.5 mm each way): probed at the reach only, the bright
  // side of a wall voxel past the strip's edge lands in the other shadow, and
  // the strip's middle keeps its edges. With the near probe (bright_near
  // 0.5, the default) the strip is weighted down across its width. Tissue
  // away from the shadows keeps every edge either way.
  const Volume v = scene({64, 24, 64},
                         [](double x, double, double z) {
                           const bool bar = (x >= 8.0 && x < 14.0) || (x >= 16.0 && x < 22.0);
                           if (!bar || z < 8.0) return 150.0;
                           return z < 10.0 ? 240.0 : 20.0;
                         },
                         test::seed() + 31);
  ShadowWallParams far_only;
  far_only.bright_near = 0.0;
  const std::vector<float> w = shadow_wall_weight(test::runtime(), v, nullptr, 70.0);
  const std::vector<float> w0 = shadow_wall_weight(test::runtime(), v, nullptr, 70.0, far_only);
  const auto mean_over = [&](const std::vector<float>& m, double x0, double x1) {
    double s = 0;
    int k = 0;
    for (double z = 16.0; z <= 28.0 + 1e-9; z += kH)
      for (double x = x0; x <= x1 + 1e-9; x += kH) s += at_mm(m, v, x, 6.0, z), ++k;
    return s / k;
  };
  const double strip = mean_over(w, 14.0, 16.0), strip0 = mean_over(w0, 14.0, 16.0);
  EXPECT_LT(strip, 0.35) << "the strip with the near probe";
  EXPECT_GT(strip0, strip + 0.25) << "the strip probed at the reach only";
  EXPECT_GT(mean_over(w, 28.0, 30.0), 0.999) << "tissue away from the shadows";
  EXPECT_GT(mean_over(w0, 28.0, 30.0), 0.999) << "tissue away from the shadows";
  // An outer wall (a shadow beside wide tissue) is a wall with either probe.
  EXPECT_LT(mean_over(w, 7.0, 8.0), 0.5);
  EXPECT_LT(mean_over(w0, 7.0, 8.0), 0.5);
  std::printf("strip mean weight %.3f (near probe) / %.3f (reach only); outer wall %.3f / %.3f\n", strip, strip0,
              mean_over(w, 7.0, 8.0), mean_over(w0, 7.0, 8.0));
}

TEST(ShadowWalls, AnObjectInFluidKeepsEveryEdge) {
  // A bright block (150) in dark fluid (20): its sides have fluid beside
  // them with nothing bright above; the fluid under it is "shadow", but the
  // block's bottom is an edge along the beam and the fluid's own speckle
  // edges have shadow on both sides. No weight below 1.
  const Volume v = scene({48, 24, 64},
                         [](double x, double, double z) {
                           return x >= 8.0 && x < 16.0 && z >= 8.0 && z < 16.0 ? 150.0 : 20.0;
                         },
                         test::seed() + 1);
  ShadowWallReport r;
  const std::vector<float> w = shadow_wall_weight(test::runtime(), v, nullptr, 85.0, ShadowWallParams{}, &r);
  EXPECT_GT(r.shadow_share, 0.05);  // the fluid under the block, 6 mm below it
  const auto lo = std::min_element(w.begin(), w.end());
  const std::size_t i = std::size_t(lo - w.begin());
  EXPECT_GT(*lo, 0.99f) << "at " << i % 48 << " " << (i / 48) % 24 << " " << i / (48 * 24);
}

TEST(ShadowWalls, UnscannedVoxelsNeitherOccludeNorShade) {
  // The bar and the tissue above it unscanned: nothing occludes the dark
  // column, which is then no shadow.
  // (Their samples continue the dark column, as fill_unscanned would.)
  Volume v = bar_over_shadow(test::seed() + 2);
  std::vector<std::uint8_t> scanned(v.voxels(), 1);
  for (std::size_t z = 0; z < 20; ++z)
    for (std::size_t y = 0; y < v.dims[1]; ++y)
      for (std::size_t x = 20; x < 28; ++x) scanned[v.index(x, y, z)] = 0, v.at(x, y, z) = 20;
  ShadowWallReport r;
  const std::vector<float> w = shadow_wall_weight(test::runtime(), v, &scanned, 85.0, ShadowWallParams{}, &r);
  EXPECT_EQ(r.shadow_share, 0.0);
  EXPECT_GT(*std::min_element(w.begin(), w.end()), 0.99f);
  EXPECT_THROW(shadow_wall_weight(test::runtime(), v, &scanned, 85.0, ShadowWallParams{.axis = 3}), std::invalid_argument);
  scanned.resize(5);
  EXPECT_THROW(shadow_wall_weight(test::runtime(), v, &scanned, 85.0), std::invalid_argument);
}

TEST(ShadowWalls, TheBeamAxisIsHonoured) {
  // The same scene with the beam along y (the volume's axes swapped): the
  // walls are found with axis 1, not with axis 2.
  const Volume z_beam = bar_over_shadow(test::seed() + 3);
  Volume v({z_beam.dims[0], z_beam.dims[2], z_beam.dims[1]}, z_beam.spacing, ScalarType::UInt8);
  for (std::size_t z = 0; z < z_beam.dims[2]; ++z)
    for (std::size_t y = 0; y < z_beam.dims[1]; ++y)
      for (std::size_t x = 0; x < z_beam.dims[0]; ++x) v.at(x, z, y) = z_beam.at(x, y, z);
  ShadowWallParams p;
  p.axis = 1;
  const std::vector<float> w = shadow_wall_weight(test::runtime(), v, nullptr, 85.0, p);
  EXPECT_LT(w[v.index(20, 48, 12)], 0.5f);  // x 10 mm, depth 24 mm, y 6 mm
  p.axis = 2;
  ShadowWallReport r;
  shadow_wall_weight(test::runtime(), v, nullptr, 85.0, p, &r);
  EXPECT_LT(r.wall_share, 0.002);
}

// A sector of a fan in x-z, the same for every y: beams from the apex
// (x 24 mm, z -10 mm), half-angle 0.7 rad (40 degrees).
constexpr double kApexX = 24.0, kApexZ = -10.0, kHalf = 0.7;
double beam_angle(double x, double z) { return std::atan2(x - kApexX, z - kApexZ); }
double beam_radius(double x, double z) { return std::hypot(x - kApexX, z - kApexZ); }
std::vector<std::uint8_t> sector_mask(const Dims3& dims) {
  std::vector<std::uint8_t> m(dims[0] * dims[1] * dims[2]);
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x)
        m[x + dims[0] * (y + dims[1] * z)] = std::fabs(beam_angle(double(x) * kH, double(z) * kH)) < kHalf;
  return m;
}

// A scene of the sector on {96, 8, 64} voxels: `inside(angle, radius)`
// within it, 0 outside (unscanned); `seen` is what the classifier sees, the
// unscanned samples continuing the scanned ones (host/mask.hpp).
struct SectorScene {
  std::vector<std::uint8_t> scanned;
  Volume v, seen;
};
template <class Inside>
SectorScene sector_scene(Inside inside, std::uint64_t seed) {
  const Dims3 dims{96, 8, 64};
  SectorScene s;
  s.scanned = sector_mask(dims);
  s.v = scene(dims,
              [&](double x, double, double z) {
                const double a = beam_angle(x, z);
                return std::fabs(a) >= kHalf ? 0.0 : inside(a, beam_radius(x, z));
              },
              seed);
  s.seen = fill_unscanned(s.v, s.scanned);
  return s;
}
// The shadow walls' weights of a sector scene at `iso`.
std::vector<float> sector_walls(const SectorScene& s, double iso, const ShadowWallParams& p, ShadowWallReport* r) {
  return shadow_wall_weight(test::runtime(), s.seen, &s.scanned, iso, p, r);
}
// A weight at `radius` mm from the apex on the beam at `angle` (y 2 mm).
float at_beam(const std::vector<float>& w, const Volume& v, double angle, double radius) {
  return at_mm(w, v, kApexX + radius * std::sin(angle), 2.0, kApexZ + radius * std::cos(angle));
}

TEST(FanBeams, ASectorsApexIsFoundAndALinearScanOrARaggedSweepHasNone) {
  const Dims3 dims{96, 12, 64};
  const FanBeams f = fan_beams(sector_mask(dims), dims, {kH, kH, kH}, 2);
  ASSERT_TRUE(f.found);
  EXPECT_TRUE(f.spreads[0]);
  EXPECT_FALSE(f.spreads[1]);
  EXPECT_FALSE(f.spreads[2]);
  EXPECT_NEAR(f.apex[0] * kH, kApexX, 0.5);
  EXPECT_NEAR(f.apex[2] * kH, kApexZ, 2.0);
  EXPECT_LE(f.rms_voxels, kFanMaxRms);
  // The same sector with the beam along y: found on y's planes, not on z's.
  std::vector<std::uint8_t> turned(dims[0] * dims[1] * dims[2]);
  const Dims3 td{dims[0], dims[2], dims[1]};
  const std::vector<std::uint8_t> m = sector_mask(dims);
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x) turned[x + td[0] * (z + td[1] * y)] = m[x + dims[0] * (y + dims[1] * z)];
  EXPECT_TRUE(fan_beams(turned, td, {kH, kH, kH}, 1).found);
  EXPECT_FALSE(fan_beams(turned, td, {kH, kH, kH}, 2).found);
  // A linear array: every voxel scanned, or a band of constant width.
  EXPECT_FALSE(fan_beams(std::vector<std::uint8_t>(m.size(), 1), dims, {kH, kH, kH}, 2).found);
  std::vector<std::uint8_t> band(m.size(), 0);
  for (std::size_t i = 0; i < band.size(); ++i) band[i] = (i % dims[0]) >= 10 && (i % dims[0]) < 50;
  EXPECT_FALSE(fan_beams(band, dims, {kH, kH, kH}, 2).found);
  // A freehand sweep's ragged sides (each plane's extent drawn at random)
  // fit no line.
  std::mt19937_64 rng(test::seed());
  std::uniform_int_distribution<int> side(4, 36);
  std::vector<std::uint8_t> ragged(m.size(), 0);
  for (std::size_t z = 0; z < dims[2]; ++z) {
    const std::size_t a = std::size_t(side(rng)), b = dims[0] - std::size_t(side(rng));
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = a; x < b; ++x) ragged[x + dims[0] * (y + dims[1] * z)] = 1;
  }
  EXPECT_FALSE(fan_beams(ragged, dims, {kH, kH, kH}, 2).found);
  // A sector that narrows with depth is no fan.
  std::vector<std::uint8_t> flipped(m.size());
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t i = 0; i < dims[0] * dims[1]; ++i)
      flipped[i + dims[0] * dims[1] * z] = m[i + dims[0] * dims[1] * (dims[2] - 1 - z)];
  EXPECT_FALSE(fan_beams(flipped, dims, {kH, kH, kH}, 2).found);
  EXPECT_THROW(fan_beams(m, dims, {kH, kH, kH}, 3), std::invalid_argument);
}

TEST(ShadowWalls, InAFanTheShadowFollowsTheBeamsAndBothItsSidesAreWalls) {
  // In the sector: tissue (150), a bright arc (240) 20-22 mm from the apex
  // between beam angles 0.45 and 0.6 rad, and its shadow (20) beyond it
  // along the same beams. The shadow leans 26-34 degrees off z: its outer
  // wall's gradient lies more than 30 degrees off the across-z plane, so
  // down z it is no edge across the beam.
  const SectorScene s = sector_scene(
      [](double a, double r) { return a < 0.45 || a > 0.6 || r < 20.0 ? 150.0 : r < 22.0 ? 240.0 : 20.0; },
      test::seed() + 5);
  ShadowWallReport r, r0;
  const std::vector<float> w = sector_walls(s, 85.0, ShadowWallParams{}, &r);
  ASSERT_TRUE(r.fan.found);
  ShadowWallParams straight;
  straight.fan = false;
  const std::vector<float> w0 = sector_walls(s, 85.0, straight, &r0);
  EXPECT_FALSE(r0.fan.found);
  // The lowest weight within 1.5 mm across the beam of the point on the
  // beam at `angle`, `radius` from the apex.
  const auto lowest = [&](const std::vector<float>& m, double angle, double radius) {
    float lo = 1.0f;
    for (double da = -0.06; da <= 0.06 + 1e-9; da += 0.01)
      if (std::fabs(da) * radius <= 1.5) lo = std::min(lo, at_beam(m, s.v, angle + da, radius));
    return lo;
  };
  for (double radius : {32.0, 35.0, 38.0}) {
    EXPECT_LT(lowest(w, 0.45, radius), 0.5f) << "the wall nearer the axis at " << radius << " mm";
    EXPECT_LT(lowest(w, 0.6, radius), 0.5f) << "the outer wall at " << radius << " mm";
    EXPECT_GT(lowest(w0, 0.6, radius), 0.5f) << "the outer wall, down z, at " << radius << " mm";
    EXPECT_FLOAT_EQ(lowest(w, -0.3, radius), 1.0f) << "tissue away from the shadow";
  }
  // The shadow is where it is: beyond the gap, between the bar's beams.
  EXPECT_GT(r.shadow_share, 0.02);
}

TEST(ShadowWalls, InAFanTheBrightLayerUnderTheProbeShadesNothing) {
  // A bright skin layer (240) in the first 2 mm of every beam, then dark
  // fluid (40) with a block of tissue (150) in it, 24-30 mm from the apex
  // between beam angles -0.1 and 0.1. The fan's beams all pass the layer:
  // if it occluded, the fluid beside the block would be "shadow" and the
  // block's sides walls. It lies within fan_skip_mm of each beam's first
  // scanned voxel, so it does not.
  const SectorScene s = sector_scene(
      [](double a, double r) {
        if (r < -kApexZ / std::cos(a) + 2.0) return 240.0;
        return std::fabs(a) < 0.1 && r >= 24.0 && r < 30.0 ? 150.0 : 40.0;
      },
      test::seed() + 6);
  ShadowWallReport r, r0;
  const std::vector<float> w = sector_walls(s, 95.0, ShadowWallParams{}, &r);
  ASSERT_TRUE(r.fan.found);
  ShadowWallParams shaded;
  shaded.fan_skip_mm = 0.0;
  const std::vector<float> w0 = sector_walls(s, 95.0, shaded, &r0);
  // The block's sides, 25-29 mm from the apex.
  float lo = 1.0f, lo0 = 1.0f;
  for (double radius = 25.0; radius <= 29.0; radius += 0.5)
    for (double a : {-0.12, -0.1, -0.08, 0.08, 0.1, 0.12})
      lo = std::min(lo, at_beam(w, s.v, a, radius)), lo0 = std::min(lo0, at_beam(w0, s.v, a, radius));
  EXPECT_GT(lo, 0.99f) << "the block's sides in fluid are no walls";
  EXPECT_LT(lo0, 0.5f) << "with the layer occluding, they would be";
  EXPECT_LT(r.shadow_share, 0.2 * r0.shadow_share);
}

// Dark fluid (10) down to 10 mm, a bright layer (250) `thick` mm thick,
// medium tissue (100) under it: a skull's echo seen from the amniotic fluid.
Volume layer_in_fluid(double thick, std::uint64_t seed) {
  return scene({24, 12, 64}, [thick](double, double, double z) { return z < 10.0 ? 10.0 : z < 10.0 + thick ? 250.0 : 100.0; },
               seed);
}

// The smallest weight at x = 6 mm, y = 3 mm, z in [z0, z1] mm.
float min_along_beam(const std::vector<float>& w, const Volume& v, double z0, double z1) {
  float lo = 1.0f;
  for (double z = z0; z <= z1 + 1e-9; z += kH) lo = std::min(lo, at_mm(w, v, 6.0, 3.0, z));
  return lo;
}

TEST(ShadowWalls, TheUndersideOfAThinEchoIsWeightedDownItsTopAndAThickLayersAreNot) {
  // At an isovalue of 140 the 3 mm layer's two flanks both cross it: its top
  // (rising along the beam, the surface) and its underside (falling, the
  // layer's far side over the tissue). Up the beam from the underside's bright
  // side the data fall under the isovalue again within 3 mm (the fluid), so
  // with `underside` on that edge is weighted down; the top keeps its weight.
  const Volume v = layer_in_fluid(3.0, test::seed() + 21);
  ShadowWallParams on;
  on.underside = true;
  ShadowWallReport r;
  const std::vector<float> w = shadow_wall_weight(test::runtime(), v, nullptr, 140.0, on, &r);
  EXPECT_LT(min_along_beam(w, v, 12.5, 15.0), 0.5f) << "the underside";
  EXPECT_GT(min_along_beam(w, v, 7.0, 11.0), 0.99f) << "the top";
  EXPECT_GT(r.underside_share, 0.0);
  // Off (the default of ShadowWallParams): nothing is weighted down.
  ShadowWallReport r0;
  const std::vector<float> w0 = shadow_wall_weight(test::runtime(), v, nullptr, 140.0, ShadowWallParams{}, &r0);
  EXPECT_GT(*std::min_element(w0.begin(), w0.end()), 0.99f);
  EXPECT_EQ(r0.underside_share, 0.0);
  // No reach up the beam: none.
  ShadowWallParams no_reach = on;
  no_reach.underside_mm = 0.0;
  const std::vector<float> wn = shadow_wall_weight(test::runtime(), v, nullptr, 140.0, no_reach);
  EXPECT_GT(min_along_beam(wn, v, 12.5, 15.0), 0.99f);
  // A layer 8 mm thick: its far side lies more than 3 mm under its top, and
  // is kept.
  const Volume thick = layer_in_fluid(8.0, test::seed() + 22);
  const std::vector<float> wt = shadow_wall_weight(test::runtime(), thick, nullptr, 140.0, on);
  EXPECT_GT(*std::min_element(wt.begin(), wt.end()), 0.99f);
}

TEST(ShadowWalls, ACystsTopWallIsNoUnderside) {
  // Tissue (150) over an anechoic cyst (10) from 16 mm: the cyst's top wall
  // falls along the beam, but the tissue above it stays over the isovalue
  // (85): no thin echo, its weight stays.
  const Volume v = scene({24, 12, 64}, [](double, double, double z) { return z < 16.0 ? 150.0 : 10.0; }, test::seed() + 23);
  ShadowWallParams on;
  on.underside = true;
  ShadowWallReport r;
  const std::vector<float> w = shadow_wall_weight(test::runtime(), v, nullptr, 85.0, on, &r);
  EXPECT_GT(*std::min_element(w.begin(), w.end()), 0.99f);
  EXPECT_EQ(r.underside_share, 0.0);
}

TEST(ShadowWalls, TheUndersideRuleAppliesWhereTheStrongEdgesAreStepsUpFromFluid) {
  EXPECT_TRUE(underside_applies(0.10, 0.70));   // a head in fluid
  EXPECT_TRUE(underside_applies(0.0, 0.5));
  EXPECT_FALSE(underside_applies(0.18, 0.68));  // 0.26: the bone nearest to the heads seen so far
  EXPECT_FALSE(underside_applies(0.45, 0.45));  // bone echoes over shadow
  EXPECT_FALSE(underside_applies(0.0, 0.0));    // no strong edges
}

TEST(ShadowWalls, ParametersFollowTheClassifiersLowpass) {
  VariationalParams p;
  const ShadowWallParams d = shadow_wall_params(p, 1);
  EXPECT_EQ(d.axis, 1);
  EXPECT_EQ(d.sigma_mm, p.grad_sigma_mm);
  EXPECT_EQ(d.grad_sigma_mm, p.grad_sigma_mm);
  EXPECT_EQ(d.reach_mm, ShadowWallParams{}.reach_mm);
  p.sigma_mm = 0.5, p.grad_sigma_mm = 0;
  const ShadowWallParams s = shadow_wall_params(p, 2);
  EXPECT_EQ(s.sigma_mm, 0.5);
  EXPECT_DOUBLE_EQ(s.gap_mm, 0.5 * ShadowWallParams{}.gap_mm);
  EXPECT_DOUBLE_EQ(s.lasting_gap_mm, 0.5 * ShadowWallParams{}.lasting_gap_mm);
  EXPECT_DOUBLE_EQ(s.reach_mm, 0.5 * ShadowWallParams{}.reach_mm);
  EXPECT_DOUBLE_EQ(s.smooth_mm, 0.5 * ShadowWallParams{}.smooth_mm);
  EXPECT_DOUBLE_EQ(s.fan_skip_mm, 0.5 * ShadowWallParams{}.fan_skip_mm);
  EXPECT_DOUBLE_EQ(s.underside_mm, 0.5 * ShadowWallParams{}.underside_mm);
  EXPECT_FALSE(s.underside);  // the caller decides (underside_applies)
}

TEST(ShadowWalls, CombinedWeightsAreTheProduct) {
  auto a = std::make_shared<const std::vector<float>>(std::vector<float>{1.0f, 0.5f, 0.0f});
  auto b = std::make_shared<const std::vector<float>>(std::vector<float>{0.5f, 0.5f, 1.0f});
  EXPECT_EQ(combine_edge_weights(nullptr, nullptr), nullptr);
  EXPECT_EQ(combine_edge_weights(a, nullptr), a);
  EXPECT_EQ(combine_edge_weights(nullptr, b), b);
  const auto c = combine_edge_weights(a, b);
  EXPECT_EQ(*c, (std::vector<float>{0.5f, 0.25f, 0.0f}));
  EXPECT_THROW(combine_edge_weights(a, std::make_shared<const std::vector<float>>(2, 1.0f)), std::invalid_argument);
}

}  // namespace
}  // namespace softshell
