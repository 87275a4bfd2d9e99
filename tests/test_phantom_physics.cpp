// The phantom with physics in physical units (`softshell phantom --physics`,
// host/phantom_physics.cpp, host/phantom_scan.cpp, kernels/phantom_scan.cl):
// the random draw and the presets, determinism, size independence, the truth
// under a pose, the near-field band, the fan's sector, the TGC mismatch,
// shadows along the beams, and the command's contract.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "error.hpp"
#include "io.hpp"
#include "phantom.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

using test::CliTest;
using test::RunResult;
using test::runtime;
using test::slurp;
namespace fs = std::filesystem;

PhantomParams physics_params(PhantomShape shape, int size, const std::string& name, std::uint64_t seed = 1) {
  PhantomParams p;
  p.shape = shape;
  p.size = size;
  p.seed = seed;
  p.physics_name = name;
  p.physics = phantom_physics(name, shape, seed);
  return p;
}

// The "physics_parameters" object of a phantom.json text.
std::string physics_block(const std::string& json) {
  const std::size_t a = json.find("\"physics_parameters\": {");
  const std::size_t b = json.find('}', a);
  return a == std::string::npos ? std::string() : json.substr(a, b - a);
}

double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

double mean(const std::vector<double>& v) { return v.empty() ? NAN : std::accumulate(v.begin(), v.end(), 0.0) / v.size(); }

// World position (mm) of a voxel centre (PhantomPhysics' frame).
double world_xy(std::size_t i, std::size_t n, double h) { return (i + 0.5 - 0.5 * n) * h; }
double world_z(std::size_t k, double h) { return (k + 0.5) * h; }

// Trilinear sample of a volume at voxel coordinates (clamped).
double trilinear(const Volume& v, double x, double y, double z) {
  auto c = [](double t, std::size_t n) { return std::clamp(t, 0.0, double(n) - 1.0); };
  x = c(x, v.dims[0]), y = c(y, v.dims[1]), z = c(z, v.dims[2]);
  const std::size_t i = std::min<std::size_t>(std::size_t(x), v.dims[0] - 2),
                    j = std::min<std::size_t>(std::size_t(y), v.dims[1] - 2),
                    k = std::min<std::size_t>(std::size_t(z), v.dims[2] - 2);
  const double tx = x - i, ty = y - j, tz = z - k;
  auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
  const double x00 = lerp(v.at(i, j, k), v.at(i + 1, j, k), tx), x10 = lerp(v.at(i, j + 1, k), v.at(i + 1, j + 1, k), tx);
  const double x01 = lerp(v.at(i, j, k + 1), v.at(i + 1, j, k + 1), tx),
               x11 = lerp(v.at(i, j + 1, k + 1), v.at(i + 1, j + 1, k + 1), tx);
  return lerp(lerp(x00, x10, ty), lerp(x01, x11, ty), tz);
}

// ---- the draw and the presets ------------------------------------------------------

TEST(PhantomPhysicsDraw, DeterministicWithinRangesAndAsOftenAsDocumented) {
  std::map<std::string, int> count;
  const int n = 3000;
  for (PhantomShape shape : {PhantomShape::Face, PhantomShape::Spine, PhantomShape::Sphere})
    for (int s = 0; s < n; ++s) {
      const PhantomPhysics p = *phantom_physics("random", shape, s);
      const PhantomPhysics q = *phantom_physics("random", shape, s);
      ASSERT_EQ(phantom_physics_json(p, 0), phantom_physics_json(q, 0)) << "seed " << s;
      ASSERT_NO_THROW(validate_phantom_physics(p)) << "seed " << s;
      EXPECT_GE(p.dynamic_range_db, 30);
      EXPECT_LE(p.dynamic_range_db, 60);
      EXPECT_GE(p.tissue_grey, 60);
      EXPECT_LE(p.tissue_grey, 220);
      EXPECT_GE(p.psf_lateral_mm, 0.35);
      EXPECT_LE(p.psf_lateral_mm, 1.3);
      EXPECT_GE(p.psf_axial_mm, 0.25 * p.psf_lateral_mm - 1e-12);
      EXPECT_LE(p.psf_elevation_mm, 2.5 * p.psf_lateral_mm + 1e-12);
      EXPECT_LE(std::max(std::fabs(p.tgc_slope_db), 2 * std::fabs(p.tgc_bow_db)), 10);
      if (p.near_field_mm > 0) {
        EXPECT_GE(p.near_field_mm, 3);
        EXPECT_LE(p.near_field_mm, 11);
        EXPECT_LT(p.skin_mm + p.fat_mm, p.near_field_mm);
      }
      const double tilt = shape == PhantomShape::Spine ? 10 : 20;
      EXPECT_LE(std::fabs(p.pitch_deg), tilt);
      EXPECT_LE(std::fabs(p.roll_deg), tilt);
      EXPECT_LE(std::fabs(p.yaw_deg), 30);
      if (p.geometry == BeamGeometry::Fan3d) EXPECT_EQ(p.jitter_mm, 0) << "a volume probe is not swept by hand";
      count["linear"] += p.geometry == BeamGeometry::Linear;
      count["fan"] += p.geometry == BeamGeometry::Fan;
      count["no near field"] += p.near_field_mm == 0;
      count["no specular"] += p.specular == 0;
      if (shape == PhantomShape::Spine) EXPECT_GE(p.specular, 0.7) << "bone always reflects";
      count["jitter"] += p.jitter_mm > 0;
      count["under-exposed"] += p.tissue_grey < 90;
      count["saturating"] += p.tissue_grey > 190;
    }
  auto share = [&](const char* k) { return count[k] / (3.0 * n); };
  EXPECT_NEAR(share("linear"), 0.4, 0.03);
  EXPECT_NEAR(share("fan"), 0.3, 0.03);
  EXPECT_NEAR(share("no near field"), 0.1, 0.02);
  EXPECT_NEAR(share("no specular"), 0.2 * 2 / 3, 0.02);  // face and sphere only
  EXPECT_NEAR(share("jitter"), 0.35, 0.03);  // half of the 70 % swept by hand
  EXPECT_NEAR(share("under-exposed"), 30.0 / 160, 0.02);
  EXPECT_NEAR(share("saturating"), 30.0 / 160, 0.02);
  // Seeds differ.
  EXPECT_NE(phantom_physics_json(*phantom_physics("random", PhantomShape::Face, 1), 0),
            phantom_physics_json(*phantom_physics("random", PhantomShape::Face, 2), 0));
}

TEST(PhantomPhysicsDraw, NamesPresetsAndOverrides) {
  for (const std::string& name : phantom_physics_names())
    for (PhantomShape shape : {PhantomShape::Face, PhantomShape::Spine, PhantomShape::Sphere}) {
      const auto p = phantom_physics(name, shape, 3);
      EXPECT_EQ(p.has_value(), name != "default") << name;
      if (p) EXPECT_NO_THROW(validate_phantom_physics(*p)) << name;
    }
  // Presets ignore the seed.
  EXPECT_EQ(phantom_physics_json(*phantom_physics("harsh", PhantomShape::Face, 1), 0),
            phantom_physics_json(*phantom_physics("harsh", PhantomShape::Face, 99), 0));
  EXPECT_EQ(phantom_physics("obstetric", PhantomShape::Face, 1)->geometry, BeamGeometry::Fan3d);
  EXPECT_EQ(phantom_physics("curvilinear", PhantomShape::Face, 1)->geometry, BeamGeometry::Fan);
  EXPECT_EQ(phantom_physics("harsh", PhantomShape::Face, 1)->dynamic_range_db, 30);
  try {
    phantom_physics("ct", PhantomShape::Face, 1);
    ADD_FAILURE() << "accepted an unknown name";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("random"), std::string::npos) << e.what();
  }
  PhantomPhysics p = *phantom_physics("clean", PhantomShape::Face, 1);
  apply_physics_settings(p, "near_field_mm=6, geometry=fan3d,shift_mm[2]=4");
  EXPECT_EQ(p.near_field_mm, 6);
  EXPECT_EQ(p.geometry, BeamGeometry::Fan3d);
  EXPECT_EQ(p.shift_mm[2], 4);
  EXPECT_NE(phantom_physics_json(p, 2).find("\"shift_mm\": [0, 0, 4]"), std::string::npos) << phantom_physics_json(p, 2);
  for (const char* bad : {"nonsense=1", "near_field_mm", "near_field_mm=abc", "geometry=cone"})
    EXPECT_THROW(apply_physics_settings(p, bad), InputError) << bad;
  p.near_field_wave = 0.5;  // interfaces could cross
  EXPECT_THROW(validate_phantom_physics(p), InputError);
  p = *phantom_physics("clean", PhantomShape::Face, 1);
  p.sector_deg = 50;  // beyond the kernels' angle range
  EXPECT_THROW(validate_phantom_physics(p), InputError);
}

// ---- determinism, size independence, lanes --------------------------------------------

TEST(PhantomPhysicsImage, BitIdenticalTwiceAndTheSeedMatters) {
  Runtime& rt = runtime();
  const PhantomParams par = physics_params(PhantomShape::Face, 40, "random", 11);
  const Phantom a = make_phantom(rt, par), b = make_phantom(rt, par);
  EXPECT_TRUE(a.volume.data == b.volume.data);
  EXPECT_TRUE(a.truth_sdf.data == b.truth_sdf.data);
  EXPECT_TRUE(a.labels.data == b.labels.data);
  const Phantom c = make_phantom(rt, physics_params(PhantomShape::Face, 40, "random", 12));
  std::size_t differ = 0;
  for (std::size_t i = 0; i < a.volume.data.size(); ++i) differ += a.volume.data[i] != c.volume.data[i];
  EXPECT_GT(differ, a.volume.data.size() / 4);
}

TEST(PhantomPhysicsImage, ScalarAndVectorPathsAgree) {
  Runtime& rt = runtime();
  for (const char* name : {"obstetric", "curvilinear", "spine"}) {
    PhantomParams p = physics_params(PhantomShape::Face, 37, name, 3);
    p.lanes = 1;
    const Phantom one = make_phantom(rt, p);
    p.lanes = 8;
    const Phantom eight = make_phantom(rt, p);
    SCOPED_TRACE(name);
    std::size_t grey_differs = 0, label_differs = 0;
    double worst_sdf = 0;
    for (std::size_t i = 0; i < one.volume.data.size(); ++i) {
      worst_sdf = std::max(worst_sdf, double(std::fabs(one.truth_sdf.data[i] - eight.truth_sdf.data[i])));
      grey_differs += std::fabs(one.volume.data[i] - eight.volume.data[i]) > 1;
      label_differs += one.labels.data[i] != eight.labels.data[i];
    }
    EXPECT_LT(worst_sdf, 1e-3);
    EXPECT_LT(grey_differs, one.volume.data.size() / 1000) << "grey levels differ by more than 1";
    EXPECT_LT(label_differs, one.volume.data.size() / 1000);
  }
}

// The same seed at two sizes: the same physics (phantom.json's parameters,
// text-identical) and the object in the same physical place (the truth of the
// coarse grid against the fine one resampled at its voxel centres, in mm), the
// same labels.
TEST(PhantomPhysicsImage, PhysicsAndAnatomyDoNotDependOnTheSize) {
  Runtime& rt = runtime();
  for (std::uint64_t seed : {5u, 8u}) {
    const PhantomParams pa = physics_params(PhantomShape::Face, 40, "random", seed);
    const PhantomParams pb = physics_params(PhantomShape::Face, 72, "random", seed);
    const Phantom a = make_phantom(rt, pa), b = make_phantom(rt, pb);
    SCOPED_TRACE("seed " + std::to_string(seed));
    EXPECT_EQ(physics_block(phantom_json(pa, a)), physics_block(phantom_json(pb, b)));
    EXPECT_FALSE(physics_block(phantom_json(pa, a)).empty());
    const double ha = a.volume.spacing[0], hb = b.volume.spacing[0];
    EXPECT_NEAR(ha * 40, hb * 72, 1e-9) << "same field of view";
    std::vector<double> err;
    std::size_t labels_same = 0, labels_compared = 0;
    for (std::size_t k = 0; k < 40; ++k)
      for (std::size_t j = 0; j < 40; ++j)
        for (std::size_t i = 0; i < 40; ++i) {
          const double x = world_xy(i, 40, ha), y = world_xy(j, 40, ha), z = world_z(k, ha);
          const double bi = x / hb + 36 - 0.5, bj = y / hb + 36 - 0.5, bk = z / hb - 0.5;
          const double sa = a.truth_sdf.at(i, j, k) * ha;
          if (std::fabs(sa) < 3 * ha) err.push_back(std::fabs(sa - trilinear(b.truth_sdf, bi, bj, bk) * hb));
          // Labels away from their boundaries (nearest voxel of the fine grid).
          const float la = a.labels.at(i, j, k);
          const float lb = b.labels.at(std::size_t(std::lround(std::clamp(bi, 0.0, 71.0))),
                                       std::size_t(std::lround(std::clamp(bj, 0.0, 71.0))),
                                       std::size_t(std::lround(std::clamp(bk, 0.0, 71.0))));
          bool interior = true;
          for (int d = 0; d < 3 && interior; ++d)
            for (int s = -1; s <= 1; s += 2) {
              std::size_t c[3] = {i, j, k};
              const long v = long(c[d]) + s;
              if (v < 0 || v >= 40) continue;
              c[d] = std::size_t(v);
              interior = interior && a.labels.at(c[0], c[1], c[2]) == la;
            }
          if (interior) ++labels_compared, labels_same += la == lb;
        }
    ASSERT_GT(err.size(), 2000u);
    std::sort(err.begin(), err.end());
    EXPECT_LT(err[err.size() / 2], 0.05 * ha) << "median |sdf difference| (mm)";
    EXPECT_LT(err[err.size() * 99 / 100], 0.3 * ha) << "99th percentile (mm)";
    EXPECT_GT(double(labels_same), 0.995 * labels_compared);
    // Grey-level statistics agree too (not the speckle itself).
    EXPECT_NEAR(a.tissue_median, b.tissue_median, 12);
  }
}

// ---- truth ------------------------------------------------------------------------------

TEST(PhantomPhysicsTruth, PosedGradientIsUnitNearTheSurfaceAndTheNearFieldIsNotInIt) {
  Runtime& rt = runtime();
  PhantomParams par = physics_params(PhantomShape::Face, 64, "harsh");  // yaw 25, pitch -18, roll 15
  const Phantom p = make_phantom(rt, par);
  std::vector<double> g;
  const std::size_t n = 64;
  for (std::size_t z = 1; z + 1 < n; ++z)
    for (std::size_t y = 1; y + 1 < n; ++y)
      for (std::size_t x = 1; x + 1 < n; ++x) {
        if (std::fabs(p.truth_sdf.at(x, y, z)) > 3) continue;
        const double gx = 0.5 * (p.truth_sdf.at(x + 1, y, z) - p.truth_sdf.at(x - 1, y, z));
        const double gy = 0.5 * (p.truth_sdf.at(x, y + 1, z) - p.truth_sdf.at(x, y - 1, z));
        const double gz = 0.5 * (p.truth_sdf.at(x, y, z + 1) - p.truth_sdf.at(x, y, z - 1));
        g.push_back(std::sqrt(gx * gx + gy * gy + gz * gz));
      }
  ASSERT_GT(g.size(), 10000u);
  std::sort(g.begin(), g.end());
  EXPECT_NEAR(g[g.size() / 2], 1.0, 0.03);
  EXPECT_GT(g[g.size() / 20], 0.85);
  EXPECT_LT(g[g.size() * 19 / 20], 1.1);
  // The truth is the posed shape's alone: without the near field, other
  // speckle, another gain, it is bit for bit the same.
  par.physics->near_field_mm = par.physics->skin_mm = par.physics->fat_mm = 0;
  par.physics->tissue_grey = 90;
  par.seed = 2;
  const Phantom q = make_phantom(rt, par);
  EXPECT_TRUE(p.truth_sdf.data == q.truth_sdf.data);
  // And the pose moved it: the unposed face differs.
  par.physics->yaw_deg = par.physics->pitch_deg = par.physics->roll_deg = 0;
  const Phantom r = make_phantom(rt, par);
  std::size_t moved = 0;
  for (std::size_t i = 0; i < r.truth_sdf.data.size(); ++i) moved += (r.truth_sdf.data[i] < 0) != (p.truth_sdf.data[i] < 0);
  EXPECT_GT(moved, r.truth_sdf.data.size() / 50);
}

// ---- near field -------------------------------------------------------------------------

TEST(PhantomPhysicsNearField, BandIsBrightLayeredWhereDrawnAndClearOfTheObject) {
  Runtime& rt = runtime();
  for (PhantomShape shape : {PhantomShape::Spine, PhantomShape::Face}) {
    const PhantomParams par = physics_params(shape, 64, "spine");  // linear, 10 mm, +9 dB
    const Phantom p = make_phantom(rt, par);
    const PhantomPhysics& phys = *par.physics;
    SCOPED_TRACE(phantom_shape_name(shape));
    const double h = p.volume.spacing[0];
    std::vector<double> band, below;
    double deepest = 0, shallowest_below = 1e9, band_to_object = 1e9;
    for (std::size_t k = 0; k < 64; ++k)
      for (std::size_t j = 0; j < 64; ++j)
        for (std::size_t i = 0; i < 64; ++i) {
          const float l = p.labels.at(i, j, k);
          const double z = world_z(k, h);
          if (l == 2) {
            band.push_back(p.volume.at(i, j, k));
            deepest = std::max(deepest, z);
            band_to_object = std::min(band_to_object, double(p.truth_sdf.at(i, j, k)) * h);
          } else {
            shallowest_below = std::min(shallowest_below, z);
            if (l == 0 && z < 2 * phys.near_field_mm + 5) below.push_back(p.volume.at(i, j, k));
          }
          ASSERT_NE(l, 3.0f) << "a linear sweep scans everything";
        }
    ASSERT_GT(band.size(), 1000u);
    // Its depth: the drawn thickness, undulating by at most the drawn wave.
    EXPECT_LE(deepest, phys.near_field_mm * (1 + phys.near_field_wave) + h);
    EXPECT_GE(shallowest_below, phys.near_field_mm * (1 - phys.near_field_wave) - h);
    // Bright: above what lies under it, and above the background.
    EXPECT_GT(median(band), median(below) + 20) << "band " << median(band) << " below " << median(below);
    EXPECT_GT(median(band), p.fluid_median + 20);
    // Not the object, and clear of it.
    EXPECT_GT(band_to_object, 2.0) << "mm between the band and the object";
  }
  // Random cases: the band never touches the object (the pose and thickness
  // limits are chosen for that).
  for (std::uint64_t seed = 1; seed <= 12; ++seed)
    for (PhantomShape shape : {PhantomShape::Face, PhantomShape::Spine, PhantomShape::Sphere}) {
      const Phantom p = make_phantom(rt, physics_params(shape, 32, "random", seed));
      double closest = 1e9;
      for (std::size_t i = 0; i < p.labels.data.size(); ++i)
        if (p.labels.data[i] == 2) closest = std::min(closest, double(p.truth_sdf.data[i]) * p.volume.spacing[0]);
      EXPECT_GT(closest, 2.0) << phantom_shape_name(shape) << " seed " << seed;
    }
}

// ---- fans ------------------------------------------------------------------------------

TEST(PhantomPhysicsFan, OutsideTheSectorIsZeroAndLabelledThree) {
  Runtime& rt = runtime();
  for (const char* name : {"curvilinear", "obstetric"}) {
    PhantomParams par = physics_params(PhantomShape::Sphere, 48, name);
    par.physics->jitter_mm = 0;  // the sector itself, undisplaced
    const Phantom p = make_phantom(rt, par);
    SCOPED_TRACE(name);
    const double h = p.volume.spacing[0];
    std::size_t outside = 0, inside_nonzero = 0, mismatched = 0;
    for (std::size_t k = 0; k < 48; ++k)
      for (std::size_t j = 0; j < 48; ++j)
        for (std::size_t i = 0; i < 48; ++i) {
          const float l = p.labels.at(i, j, k);
          if (l == 3) {
            ++outside;
            ASSERT_EQ(p.volume.at(i, j, k), 0.0f) << i << "," << j << "," << k;
          } else if (p.volume.at(i, j, k) > 0) {
            ++inside_nonzero;
          }
          // The host's geometry agrees, but for voxels within 0.01 mm of the edge.
          const double x = world_xy(i, 48, h), y = world_xy(j, 48, h), z = world_z(k, h);
          const bool scanned = phantom_beam_at(*par.physics, x, y, z).scanned;
          if (scanned != (l != 3)) {
            bool near_edge = false;
            for (double e : {-0.01, 0.01})
              for (int a = 0; a < 3; ++a) {
                double q[3] = {x, y, z};
                q[a] += e;
                near_edge = near_edge || phantom_beam_at(*par.physics, q[0], q[1], q[2]).scanned != scanned;
              }
            mismatched += !near_edge;
          }
        }
    EXPECT_GT(outside, 48u * 48 * 48 / 100) << "the corners lie outside";
    EXPECT_GT(inside_nonzero, 48u * 48 * 48 / 3);
    EXPECT_EQ(mismatched, 0u);
  }
}

// Shadows follow the beams: below an attenuating sphere (tissue in fluid), the
// shadow fans out. Voxels beside it whose beam (from the apex) crossed 5 mm of
// the sphere but whose vertical column missed it are darker than voxels at the
// same depths whose beam and column both missed it; a vertical shadow would
// leave them alike.
TEST(PhantomPhysicsFan, ShadowsFollowTheBeams) {
  Runtime& rt = runtime();
  PhantomParams par = physics_params(PhantomShape::Sphere, 64, "curvilinear");
  PhantomPhysics& phys = *par.physics;
  phys.jitter_mm = 0, phys.near_field_mm = phys.skin_mm = phys.fat_mm = 0;
  phys.probe_radius_mm = 20, phys.sector_deg = 40, phys.scan_depth_mm = phys.fov_mm * 1.2;
  phys.attenuation_db_cm_mhz = 0.7, phys.frequency_mhz = 3;  // 0.42 dB/mm two-way in the sphere
  phys.tissue_grey = 100, phys.dynamic_range_db = 60;        // nothing saturates
  phys.shift_mm[0] = phys.shift_mm[1] = phys.shift_mm[2] = 0;
  const Phantom p = make_phantom(rt, par);
  const double h = p.volume.spacing[0];
  const std::size_t n = 64;
  auto inside = [&](double x, double y, double z) {
    return trilinear(p.truth_sdf, x / h + n / 2.0 - 0.5, y / h + n / 2.0 - 0.5, z / h - 0.5) < 0;
  };
  int deepest = 0;
  for (std::size_t i = 0; i < p.truth_sdf.data.size(); ++i)
    if (p.truth_sdf.data[i] < 0) deepest = std::max<int>(deepest, int(i / (n * n)));
  std::vector<double> by_ray_only, clear, shadow_ray, shadow_clear;
  const double step = 0.25;  // mm
  for (std::size_t k = deepest + 3; k < n; ++k)
    for (std::size_t j = n / 2 - 4; j < n / 2 + 4; ++j)
      for (std::size_t i = 0; i < n; ++i) {
        if (p.labels.at(i, j, k) == 3) continue;
        const double x = world_xy(i, n, h), y = world_xy(j, n, h), z = world_z(k, h);
        const double R = phys.probe_radius_mm, len = std::hypot(x, z + R);
        double ray = 0, column = 0;  // mm inside the sphere along the beam (apex line to voxel) and the column
        for (double s = step / 2; s < len; s += step) {
          const double t = s / len, zz = -R + t * (z + R);
          if (zz > 0 && inside(t * x, y, zz)) ray += step;
        }
        for (double zc = step / 2; zc < z; zc += step) column += inside(x, y, zc) ? step : 0;
        if (column > 0) continue;
        if (ray > 5) by_ray_only.push_back(p.volume.at(i, j, k)), shadow_ray.push_back(p.shadow_db.at(i, j, k));
        if (ray == 0) clear.push_back(p.volume.at(i, j, k)), shadow_clear.push_back(p.shadow_db.at(i, j, k));
      }
  ASSERT_GT(by_ray_only.size(), 50u);
  ASSERT_GT(clear.size(), 50u);
  EXPECT_LT(mean(by_ray_only), mean(clear) - 20) << "beam crossed " << mean(by_ray_only) << ", clear " << mean(clear);
  // shadow_db.nrrd: enhancement (< 0) below fluid, less of it behind the sphere.
  EXPECT_LT(mean(shadow_clear), -3);
  EXPECT_GT(mean(shadow_ray), mean(shadow_clear) + 3);
  // Outside the scanned region nothing can be seen: a loss of 1000 dB there
  // (evaluate's recall_visible leaves those surface voxels out).
  for (std::size_t i = 0; i < p.labels.data.size(); ++i)
    if (p.labels.data[i] == 3)
      ASSERT_EQ(p.shadow_db.data[i], 1000.0f);
    else
      ASSERT_LT(p.shadow_db.data[i], 200.0f);
}

// ---- speckle ----------------------------------------------------------------------------

// Speckle density: few scatterers per resolution cell give bright isolated
// points (intensity contrast std / mean well above 1, non-Rayleigh), many give
// fully developed speckle (exponential intensity: contrast 1).
TEST(PhantomPhysicsSpeckle, SparseScatterersAreNonRayleighDenseAreRayleigh) {
  Runtime& rt = runtime();
  auto contrast = [&](double per_cell) {
    PhantomParams par = physics_params(PhantomShape::Spine, 64, "clean");
    PhantomPhysics& phys = *par.physics;
    phys.scatterers_per_cell = per_cell, phys.texture = 0, phys.noise_db = -90, phys.specular = 0.7;
    phys.dynamic_range_db = 100, phys.tissue_grey = 128;  // 0.39 dB per grey level, nothing clips
    const Phantom p = make_phantom(rt, par);
    // Muscle in the columns that miss the bone (and its shadow) by 4 voxels.
    const std::size_t n = 64, plane = n * n;
    std::vector<bool> clear(plane, true);
    for (std::size_t k = 0; k < n; ++k)
      for (std::size_t i = 0; i < plane; ++i) clear[i] = clear[i] && p.truth_sdf.data[k * plane + i] > 4;
    double sum = 0, sum2 = 0;
    std::size_t count = 0;
    for (std::size_t k = 0; k < n; ++k)  // up to the faces: the PSF keeps the mean power there too
      for (std::size_t i = 0; i < plane; ++i) {
        if (!clear[i]) continue;
        const double intensity = std::pow(10.0, (p.volume.data[k * plane + i] / 255.0 - 1) * 100 / 10);
        sum += intensity, sum2 += intensity * intensity, ++count;
      }
    EXPECT_GT(count, 20000u);
    const double m = sum / count;
    return std::sqrt(sum2 / count - m * m) / m;
  };
  const double dense = contrast(50), sparse = contrast(0.5);
  EXPECT_NEAR(dense, 1.0, 0.1) << "fully developed speckle";
  EXPECT_GT(sparse, 1.6) << "sparse scatterers";
}

// ---- TGC mismatch and shadows ----------------------------------------------------------

// On homogeneous muscle (the spine's background; columns that miss the bone),
// the median grey level against depth follows the TGC mismatch: set, and as
// drawn by random seeds (with their dynamic range and gain; the near field,
// texture and noise off, a linear probe, so that only the drift remains).
TEST(PhantomPhysicsTgc, MedianGreyFollowsTheDrawnDrift) {
  Runtime& rt = runtime();
  std::vector<PhantomParams> cases;
  for (auto [slope, bow] : {std::pair{8.0, -4.0}, std::pair{-9.0, 3.0}}) {
    PhantomParams par = physics_params(PhantomShape::Spine, 64, "clean");
    PhantomPhysics& phys = *par.physics;
    phys.tgc_slope_db = slope, phys.tgc_bow_db = bow;
    phys.dynamic_range_db = 60, phys.tissue_grey = 120;
    phys.frequency_mhz = 6;  // 36 dB of attenuation over the depth, compensated
    cases.push_back(par);
  }
  for (std::uint64_t seed : {3u, 9u, 21u}) {
    PhantomParams par = physics_params(PhantomShape::Spine, 64, "random", seed);
    PhantomPhysics& phys = *par.physics;
    phys.geometry = BeamGeometry::Linear, phys.jitter_mm = 0;
    phys.near_field_mm = phys.skin_mm = phys.fat_mm = 0;
    cases.push_back(par);
  }
  for (PhantomParams& par : cases) {
    PhantomPhysics& phys = *par.physics;
    phys.texture = 0, phys.scatterers_per_cell = 50, phys.noise_db = -80, phys.specular = 0.7;
    const Phantom p = make_phantom(rt, par);
    const double slope = phys.tgc_slope_db, bow = phys.tgc_bow_db, range = phys.dynamic_range_db;
    SCOPED_TRACE("seed " + std::to_string(par.seed) + " slope " + std::to_string(slope) + " bow " +
                 std::to_string(bow) + " range " + std::to_string(range) + " grey " + std::to_string(phys.tissue_grey));
    const std::size_t n = 64;
    const double h = p.volume.spacing[0], depth = phys.fov_mm;
    std::vector<bool> clear(n * n, true);
    for (std::size_t k = 0; k < n; ++k)
      for (std::size_t i = 0; i < n * n; ++i) clear[i] = clear[i] && p.truth_sdf.data[k * n * n + i] > 4;
    auto drift = [&](double d) {
      const double t = d / depth;
      return slope * t + bow * 4 * t * (1 - t);
    };
    // Rayleigh speckle of mean power P has its median at P - 1.59 dB.
    const double per_db = 255 / range, g0 = phys.tissue_grey - 1.59 * per_db;
    double worst_db = 0;
    int compared = 0;
    for (std::size_t k0 = 4; k0 + 4 < n; k0 += 4) {
      std::vector<double> grey;
      for (std::size_t k = k0; k < k0 + 4; ++k)
        for (std::size_t i = 0; i < n * n; ++i)
          if (clear[i]) grey.push_back(p.volume.data[k * n * n + i]);
      ASSERT_GT(grey.size(), 1000u);
      const double want = g0 + per_db * drift((k0 + 2) * h);
      if (want < 30 || want > 225) continue;  // a clipped median says nothing
      worst_db = std::max(worst_db, std::fabs(median(grey) - want) / per_db);
      ++compared;
    }
    EXPECT_GE(compared, 8);
    EXPECT_LT(worst_db, 1.0) << "dB";
  }
}

TEST(PhantomPhysicsShadow, BoneDarkensWhatLiesBelowItAndMoreWhenItAttenuatesMore) {
  Runtime& rt = runtime();
  auto under_minus_beside = [&](double bone_atten) {
    PhantomParams par = physics_params(PhantomShape::Spine, 56, "spine");
    par.physics->bone_atten_db_mm = bone_atten;
    par.physics->jitter_mm = 0;
    const Phantom p = make_phantom(rt, par);
    const std::size_t n = 56;
    std::vector<int> column(n * n, 0);  // 1: crosses bone, 2: clear by 3 voxels
    int deepest = 0;
    for (std::size_t i = 0; i < n * n; ++i) {
      float lo = 1e9f;
      for (std::size_t k = 0; k < n; ++k) {
        lo = std::min(lo, p.truth_sdf.data[k * n * n + i]);
        if (p.truth_sdf.data[k * n * n + i] < 0) deepest = std::max<int>(deepest, int(k));
      }
      column[i] = lo < -1 ? 1 : (lo > 3 ? 2 : 0);
    }
    std::vector<double> under, beside, shadow_under, shadow_beside;
    for (std::size_t k = deepest + 4; k < n; ++k)
      for (std::size_t i = 0; i < n * n; ++i) {
        const std::size_t v = k * n * n + i;
        if (column[i] == 1) under.push_back(p.volume.data[v]), shadow_under.push_back(p.shadow_db.data[v]);
        if (column[i] == 2) beside.push_back(p.volume.data[v]), shadow_beside.push_back(p.shadow_db.data[v]);
      }
    EXPECT_GT(under.size(), 200u);
    EXPECT_GT(beside.size(), 200u);
    // shadow_db.nrrd says the same: beside the bone the TGC restores muscle
    // exactly (after the near field's excess loss, a few dB).
    EXPECT_GT(mean(shadow_under), mean(shadow_beside) + 10);
    EXPECT_NEAR(median(shadow_beside), 0, 6);
    return mean(under) - mean(beside);
  };
  const double strong = under_minus_beside(8), weak = under_minus_beside(1);
  EXPECT_LT(strong, -25) << "under the bone vs beside it";
  EXPECT_LT(strong, weak - 10) << "strong " << strong << ", weak " << weak;
}

// ---- the command -----------------------------------------------------------------------

class CliPhantomPhysics : public CliTest {};

TEST_F(CliPhantomPhysics, RandomWritesLabelsAndEveryParameter) {
  const std::string dir = file("r");
  const RunResult r = run({"phantom", "--physics", "random", "--seed", "4", "--size", "24", "-o", dir});
  ASSERT_EQ(r.status, 0) << r.err;
  for (const char* s : {"physics random", "geometry", "near", "pose"}) EXPECT_NE(r.out.find(s), std::string::npos) << s;
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"labels.nrrd", "phantom.json", "shadow_db.nrrd", "truth_sdf.nrrd",
                                             "volume.nrrd"}));
  const Volume labels = read_volume(dir + "/labels.nrrd");
  EXPECT_EQ(labels.source_type, ScalarType::UInt8);
  EXPECT_EQ(labels.dims, (Dims3{24, 24, 24}));
  const std::string json = slurp(dir + "/phantom.json");
  const PhantomPhysics drawn = *phantom_physics("random", PhantomShape::Face, 4);
  EXPECT_NE(json.find(phantom_physics_json(drawn, 4)), std::string::npos) << "every parameter, as drawn:\n" << json;
  for (const char* field : {"\"physics\": \"random\"", "\"beam_geometry\"", "\"rule\"", "\"label_values\"",
                            "\"near_field_median\"", "\"world_frame\"", "\"beam_cells\""})
    EXPECT_NE(json.find(field), std::string::npos) << field;
}

TEST_F(CliPhantomPhysics, DefaultIsTodaysPhysicsPlusLabels) {
  ASSERT_EQ(run({"phantom", "--shape", "spine", "--size", "24", "--seed", "3", "-q", "-o", file("plain")}).status, 0);
  const RunResult r =
      run({"phantom", "--shape", "spine", "--size", "24", "--seed", "3", "--physics", "default", "-q", "-o", file("d")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(slurp(file("plain/volume.nrrd")), slurp(file("d/volume.nrrd")));
  EXPECT_EQ(slurp(file("plain/truth_sdf.nrrd")), slurp(file("d/truth_sdf.nrrd")));
  EXPECT_FALSE(fs::exists(file("plain/labels.nrrd")));
  const Volume labels = read_volume(file("d/labels.nrrd")), sdf = read_volume(file("d/truth_sdf.nrrd"));
  for (std::size_t i = 0; i < labels.data.size(); ++i) ASSERT_EQ(labels.data[i], sdf.data[i] < 0 ? 1.0f : 0.0f);
  const std::string json = slurp(file("d/phantom.json"));
  EXPECT_NE(json.find("\"physics\": \"default\""), std::string::npos);
  EXPECT_NE(json.find("\"kind\": \"linear\""), std::string::npos);
  EXPECT_EQ(json.find("physics_parameters"), std::string::npos);
  // A fan's geometry and its rule for the beam direction.
  ASSERT_EQ(run({"phantom", "--physics", "obstetric", "--size", "20", "-q", "-o", file("o")}).status, 0);
  const std::string fan = slurp(file("o/phantom.json"));
  for (const char* s : {"\"kind\": \"fan3d\"", "\"apex_mm\": [0, 0, -40]", "\"apex_voxels\"", "unit((i, j, k) - apex_voxels)"})
    EXPECT_NE(fan.find(s), std::string::npos) << s << " in " << fan;
}

TEST_F(CliPhantomPhysics, OverridesAndBadOptionsAreOneLineErrors) {
  const RunResult ok = run({"phantom", "--physics", "clean", "--physics-set", "near_field_mm=5,skin_mm=1,fat_mm=2",
                            "--fov", "90", "--size", "20", "-q", "-o", file("ok")});
  ASSERT_EQ(ok.status, 0) << ok.err;
  const std::string json = slurp(file("ok/phantom.json"));
  EXPECT_NE(json.find("\"near_field_mm\": 5"), std::string::npos);
  EXPECT_NE(json.find("\"fov_mm\": 90"), std::string::npos);
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--physics", "ct"}, "--physics"},
      {{"--physics", "random", "--speckle", "0.5,1"}, "--speckle"},
      {{"--physics", "harsh", "--noise", "0.1"}, "--noise"},
      {{"--physics", "random", "--dims", "20,20,30"}, "--dims"},
      {{"--physics-set", "near_field_mm=3"}, "--physics-set"},
      {{"--physics", "default", "--physics-set", "near_field_mm=3"}, "--physics-set"},
      {{"--physics", "random", "--physics-set", "depth=3"}, "depth"},
      {{"--physics", "random", "--physics-set", "near_field_mm"}, "NAME=VALUE"},
      {{"--physics", "random", "--physics-set", "tissue_grey=bright"}, "tissue_grey"},
      {{"--physics", "random", "--physics-set", "dynamic_range_db=5"}, "dynamic_range_db"},
      {{"--physics", "random", "--physics-set", "geometry=cone"}, "geometry"},
      {{"--physics", "clean", "--fov", "5"}, "fov_mm"},
  };
  for (const auto& [extra, option] : cases) {
    std::vector<std::string> args{"phantom", "--size", "16", "-o", file("bad")};
    args.insert(args.end(), extra.begin(), extra.end());
    SCOPED_TRACE(extra[0] + " " + extra[1]);
    expect_one_line_error(run(args), {option});
    EXPECT_FALSE(fs::exists(file("bad"))) << "nothing written for bad options";
  }
}

}  // namespace
}  // namespace softshell
