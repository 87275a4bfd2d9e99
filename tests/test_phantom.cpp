// The ultrasound phantom (host/phantom.*, kernels/phantom.cl): physics checks
// that can fail — determinism, the truth SDF against analytic and brute-force
// references, fluid/tissue contrast, speckle anisotropy, angle-dependent
// boundary echoes, depth attenuation, shadowing behind bone, log compression —
// and the `softshell phantom` command's contract.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <string>
#include <unordered_map>
#include <vector>

#include "cli_fixture.hpp"
#include "error.hpp"
#include "image.hpp"
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

PhantomParams params(PhantomShape shape, int size, std::uint64_t seed = 1) {
  PhantomParams p;
  p.shape = shape;
  p.size = size;
  p.seed = seed;
  return p;
}

// Design coordinates (the volume spans [-50, 50]^3; kernels/phantom.cl) of a voxel centre.
double design(std::size_t i, std::size_t n) { return (i + 0.5 - 0.5 * n) * 100.0 / n; }

double mean_of(const std::vector<double>& v) {
  return v.empty() ? 0 : std::accumulate(v.begin(), v.end(), 0.0) / v.size();
}

// Samples of the B-mode volume where pred(x, y, z) holds.
template <class Pred>
std::vector<double> samples(const Volume& v, Pred pred) {
  std::vector<double> out;
  for (std::size_t z = 0; z < v.dims[2]; ++z)
    for (std::size_t y = 0; y < v.dims[1]; ++y)
      for (std::size_t x = 0; x < v.dims[0]; ++x)
        if (pred(x, y, z)) out.push_back(v.at(x, y, z));
  return out;
}

// ---- parameters ----------------------------------------------------------------------

TEST(PhantomParams, ShapeNamesRoundTrip) {
  for (PhantomShape s : {PhantomShape::Face, PhantomShape::Spine, PhantomShape::Sphere}) {
    PhantomShape back = PhantomShape::Sphere;
    ASSERT_TRUE(parse_phantom_shape(phantom_shape_name(s), back));
    EXPECT_EQ(back, s);
  }
  PhantomShape out;
  EXPECT_FALSE(parse_phantom_shape("cube", out));
  EXPECT_DOUBLE_EQ(phantom_default_fov(PhantomShape::Face), 100.0);
}

TEST(PhantomParams, OutOfRangeValuesNameTheOption) {
  struct Bad {
    void (*set)(PhantomParams&);
    const char* option;
  } cases[] = {
      {[](PhantomParams& p) { p.size = 15; }, "--size"},
      {[](PhantomParams& p) { p.size = 513; }, "--size"},
      {[](PhantomParams& p) { p.noise = -0.1; }, "--noise"},
      {[](PhantomParams& p) { p.dynamic_range_db = 9; }, "--dynamic-range"},
      {[](PhantomParams& p) { p.dynamic_range_db = 101; }, "--dynamic-range"},
      {[](PhantomParams& p) { p.psf_axial = 0.1; }, "--speckle"},
      {[](PhantomParams& p) { p.psf_lateral = 9; }, "--speckle"},
      {[](PhantomParams& p) { p.fov_mm = -1; }, "--fov"},
      {[](PhantomParams& p) { p.attenuation = -1; }, "--attenuation"},
      {[](PhantomParams& p) { p.specular = NAN; }, "--specular"},
  };
  for (const Bad& b : cases) {
    PhantomParams p;
    b.set(p);
    try {
      validate_phantom_params(p);
      ADD_FAILURE() << "accepted a bad " << b.option;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(b.option), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(validate_phantom_params(PhantomParams{}));
}

// ---- determinism -----------------------------------------------------------------------

TEST(PhantomDeterminism, BitIdenticalTwiceAndTheSeedMatters) {
  Runtime& rt = runtime();
  const Phantom a = make_phantom(rt, params(PhantomShape::Face, 40, 7));
  const Phantom b = make_phantom(rt, params(PhantomShape::Face, 40, 7));
  ASSERT_EQ(a.volume.data.size(), std::size_t(40 * 40 * 40));
  EXPECT_TRUE(a.volume.data == b.volume.data) << "two runs differ";
  EXPECT_TRUE(a.truth_sdf.data == b.truth_sdf.data) << "two runs differ in the truth";
  const Phantom c = make_phantom(rt, params(PhantomShape::Face, 40, 8));
  EXPECT_TRUE(a.truth_sdf.data == c.truth_sdf.data) << "the geometry must not depend on the seed";
  std::size_t differ = 0;
  for (std::size_t i = 0; i < a.volume.data.size(); ++i) differ += a.volume.data[i] != c.volume.data[i];
  EXPECT_GT(differ, a.volume.data.size() / 2) << "another seed should give other speckle";
}

// The scalar path (one voxel per work-item, used on GPUs) and the 8-lane path
// (CPUs) compute the same thing; only float contraction may differ.
TEST(PhantomDeterminism, ScalarAndVectorPathsAgree) {
  Runtime& rt = runtime();
  PhantomParams p = params(PhantomShape::Face, 37, 3);  // 37: partial lane groups at every row end
  p.lanes = 1;
  const Phantom one = make_phantom(rt, p);
  p.lanes = 8;
  const Phantom eight = make_phantom(rt, p);
  double worst_sdf = 0;
  std::size_t grey_differs = 0;
  for (std::size_t i = 0; i < one.volume.data.size(); ++i) {
    worst_sdf = std::max(worst_sdf, double(std::fabs(one.truth_sdf.data[i] - eight.truth_sdf.data[i])));
    grey_differs += std::fabs(one.volume.data[i] - eight.volume.data[i]) > 1;
  }
  EXPECT_LT(worst_sdf, 1e-3);  // bit-identical on PoCL; a compiler may contract differently
  EXPECT_EQ(grey_differs, 0u) << "grey levels differ by more than 1";
}

// ---- truth SDF -------------------------------------------------------------------------

TEST(PhantomSdf, SphereMatchesTheAnalyticDistance) {
  for (int n : {33, 48}) {
    const Phantom p = make_phantom(runtime(), params(PhantomShape::Sphere, n));
    const double vox = 100.0 / n;
    double worst_near = 0, worst_far = 0;
    for (std::size_t z = 0; z < std::size_t(n); ++z)
      for (std::size_t y = 0; y < std::size_t(n); ++y)
        for (std::size_t x = 0; x < std::size_t(n); ++x) {
          const double want = (std::hypot(design(x, n), design(y, n), design(z, n)) - 30.0) / vox;
          const double got = p.truth_sdf.at(x, y, z);
          if (std::fabs(want) > 0.05)
            ASSERT_EQ(got < 0, want < 0) << "sign at (" << x << "," << y << "," << z << ") got " << got << " want "
                                         << want;
          (std::fabs(want) < 4 ? worst_near : worst_far) =
              std::max(std::fabs(want) < 4 ? worst_near : worst_far, std::fabs(got - want));
        }
    EXPECT_LT(worst_near, 0.15) << "size " << n;
    EXPECT_LT(worst_far, 0.3) << "size " << n;
  }
}

TEST(PhantomSdf, SignConventionNegativeInsideTissue) {
  const int n = 40;
  const Phantom f = make_phantom(runtime(), params(PhantomShape::Face, n));
  auto at_design = [&](double x, double y, double z) {
    auto idx = [&](double d) { return std::size_t(std::lround(d * n / 100.0 + 0.5 * n - 0.5)); };
    return f.truth_sdf.at(idx(x), idx(y), idx(z));
  };
  EXPECT_LT(at_design(0, -8, 7), -5) << "middle of the head";
  EXPECT_GT(at_design(0, 0, -40), 5) << "fluid between the transducer and the face";
  EXPECT_LT(at_design(0, 0, 48), -1) << "uterine wall at the far side";
  EXPECT_GT(at_design(40, -40, 20), 3) << "fluid beside the head";
  const Phantom s = make_phantom(runtime(), params(PhantomShape::Spine, n));
  EXPECT_GT(s.truth_sdf.at(0, 0, 0), 3) << "soft tissue around the spine is outside";
}

// Brute-force reference: the zero set of the raw implicit function sampled on
// a grid 3x finer than the voxels (crossings located by linear interpolation)
// and, for sampled voxels near the surface, the distance to the nearest
// crossing. Its own error is below ~0.12 voxel.
struct SdfErrors {
  std::size_t n = 0, over = 0;
  double mean = 0, worst = 0;
};

SdfErrors compare_with_reference(const PhantomParams& par) {
  Runtime& rt = runtime();
  const int size = par.size;
  const Phantom ph = make_phantom(rt, par);
  const int fine = 3, m = size * fine;
  auto fine_coord = [&](double i) { return float((i + 0.5) / fine - 0.5); };  // voxel coordinates
  std::vector<std::array<float, 3>> surface;
  std::vector<float> prev;
  for (int k = 0; k < m; ++k) {
    std::vector<std::array<float, 3>> pts;
    pts.reserve(std::size_t(m) * m);
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) pts.push_back({fine_coord(i), fine_coord(j), fine_coord(k)});
    const std::vector<float> cur = phantom_implicit(rt, par, pts);
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const float a = cur[std::size_t(j) * m + i];
        auto cross = [&](float b, double ci, double cj, double ck) {
          if ((a < 0) != (b < 0)) surface.push_back({fine_coord(ci), fine_coord(cj), fine_coord(ck)});
        };
        if (i + 1 < m) {
          const float b = cur[std::size_t(j) * m + i + 1];
          cross(b, i + a / (a - b), j, k);
        }
        if (j + 1 < m) {
          const float b = cur[std::size_t(j + 1) * m + i];
          cross(b, i, j + a / (a - b), k);
        }
        if (k > 0) {
          const float b = prev[std::size_t(j) * m + i];
          cross(b, i, j, k - 1 + b / (b - a));
        }
      }
    prev = cur;
  }
  std::unordered_map<long long, std::vector<std::size_t>> cells;
  auto key = [](long long a, long long b, long long c) { return (a + 4) + 4096 * ((b + 4) + 4096 * (c + 4)); };
  for (std::size_t i = 0; i < surface.size(); ++i)
    cells[key(std::lround(surface[i][0]), std::lround(surface[i][1]), std::lround(surface[i][2]))].push_back(i);

  SdfErrors e;
  std::uint32_t s = 12345;
  auto next = [&] { return (s = s * 1664525u + 1013904223u) >> 8; };
  for (int t = 0; t < 200000 && e.n < 6000; ++t) {
    const int x = next() % size, y = next() % size, z = next() % size;
    const double got = ph.truth_sdf.at(x, y, z);
    if (std::fabs(got) > 4.5) continue;
    // Posed, the uterine wall meets the volume's faces at a slant: the nearest
    // surface point of a voxel near a face may lie outside the volume, where
    // the reference does not look.
    const int border = std::min({x, y, z, size - 1 - x, size - 1 - y, size - 1 - z});
    if (par.physics && border < std::fabs(got) + 1.5) continue;
    const int r = int(std::ceil(std::fabs(got))) + 2;
    double best = 1e30;
    for (int c = -r; c <= r; ++c)
      for (int b = -r; b <= r; ++b)
        for (int a = -r; a <= r; ++a) {
          const auto it = cells.find(key(x + a, y + b, z + c));
          if (it == cells.end()) continue;
          for (std::size_t i : it->second) {
            const double dx = surface[i][0] - x, dy = surface[i][1] - y, dz = surface[i][2] - z;
            best = std::min(best, dx * dx + dy * dy + dz * dz);
          }
        }
    const double ref = std::copysign(std::sqrt(best), got);
    if (std::fabs(ref) >= 4) continue;
    const double err = std::fabs(got - ref);
    e.mean += err;
    e.worst = std::max(e.worst, err);
    e.over += err > 0.3;
    ++e.n;
  }
  e.mean /= std::max<std::size_t>(e.n, 1);
  return e;
}

TEST(PhantomSdf, FaceAndSpineMatchABruteForceReference) {
  for (PhantomShape shape : {PhantomShape::Face, PhantomShape::Spine}) {
    const SdfErrors e = compare_with_reference(params(shape, 56));
    SCOPED_TRACE(phantom_shape_name(shape));
    ASSERT_GT(e.n, 3000u);
    EXPECT_LT(e.mean, 0.04);
    EXPECT_LT(double(e.over), 0.01 * e.n) << "share of |error| > 0.3 voxel";
    EXPECT_LT(e.worst, 0.75);
  }
}

// The same under a rigid pose (`--physics`: rotated and shifted; the seeds are
// rotated back to the volume's frame to 1/64 voxel), against the posed raw
// implicit function.
TEST(PhantomSdf, PosedShapesMatchABruteForceReference) {
  for (PhantomShape shape : {PhantomShape::Face, PhantomShape::Spine}) {
    PhantomParams par = params(shape, 48, 7);
    par.physics_name = "random";
    par.physics = phantom_physics("random", shape, 7);
    par.physics->yaw_deg = 27, par.physics->pitch_deg = shape == PhantomShape::Spine ? -9 : -17;
    par.physics->roll_deg = shape == PhantomShape::Spine ? 8 : 14;
    const SdfErrors e = compare_with_reference(par);
    SCOPED_TRACE(phantom_shape_name(shape));
    ASSERT_GT(e.n, 3000u);
    EXPECT_LT(e.mean, 0.05);
    EXPECT_LT(double(e.over), 0.015 * e.n) << "share of |error| > 0.3 voxel";
    EXPECT_LT(e.worst, 0.75);
  }
}

TEST(PhantomSdf, NonCubicDimsAreTheCentredCropOfTheCube) {
  // dims 40x24x20 = the middle of the 40^3 phantom (offsets 8 and 10): the
  // same geometry at the same voxel size, so the truth agrees away from the
  // crop's faces (redistancing looks REDIST_RADIUS + 2 voxels around).
  PhantomParams cube;
  cube.size = 40;
  PhantomParams crop = cube;
  crop.dims = {40, 24, 20};
  const Phantom a = make_phantom(runtime(), cube), b = make_phantom(runtime(), crop);
  ASSERT_EQ(b.truth_sdf.dims, (Dims3{40, 24, 20}));
  EXPECT_DOUBLE_EQ(a.truth_sdf.spacing[0], b.truth_sdf.spacing[0]);
  std::size_t compared = 0;
  for (std::size_t z = 8; z + 8 < 20; ++z)
    for (std::size_t y = 8; y + 8 < 24; ++y)
      for (std::size_t x = 8; x + 8 < 40; ++x) {
        ASSERT_NEAR(b.truth_sdf.at(x, y, z), a.truth_sdf.at(x, y + 8, z + 10), 1e-4) << x << "," << y << "," << z;
        ++compared;
      }
  EXPECT_GT(compared, 500u);
}

TEST(PhantomSdf, FaceGradientIsUnitNearTheSurface) {
  const int n = 64;
  const Phantom p = make_phantom(runtime(), params(PhantomShape::Face, n));
  std::vector<double> g;
  for (std::size_t z = 1; z + 1 < std::size_t(n); ++z)
    for (std::size_t y = 1; y + 1 < std::size_t(n); ++y)
      for (std::size_t x = 1; x + 1 < std::size_t(n); ++x) {
        if (std::fabs(p.truth_sdf.at(x, y, z)) > 3) continue;
        const double gx = 0.5 * (p.truth_sdf.at(x + 1, y, z) - p.truth_sdf.at(x - 1, y, z));
        const double gy = 0.5 * (p.truth_sdf.at(x, y + 1, z) - p.truth_sdf.at(x, y - 1, z));
        const double gz = 0.5 * (p.truth_sdf.at(x, y, z + 1) - p.truth_sdf.at(x, y, z - 1));
        g.push_back(std::sqrt(gx * gx + gy * gy + gz * gz));
      }
  ASSERT_GT(g.size(), 10000u);
  std::sort(g.begin(), g.end());
  EXPECT_NEAR(g[g.size() / 2], 1.0, 0.03) << "median |grad sdf|";
  EXPECT_GT(g[g.size() / 20], 0.85) << "5th percentile";
  EXPECT_LT(g[g.size() * 19 / 20], 1.1) << "95th percentile";
}

// ---- image formation -------------------------------------------------------------------

TEST(PhantomImage, FluidIsDarkTissueBright) {
  for (PhantomShape shape : {PhantomShape::Face, PhantomShape::Sphere}) {
    const Phantom p = make_phantom(runtime(), params(shape, 48));
    SCOPED_TRACE(phantom_shape_name(shape));
    EXPECT_LT(p.fluid_median, 40);
    EXPECT_GT(p.tissue_median, p.fluid_median + 70);
  }
  // Spine: soft tissue around bone is mid grey; bone surfaces facing the
  // transducer are bright.
  const Phantom s = make_phantom(runtime(), params(PhantomShape::Spine, 48));
  EXPECT_GT(s.fluid_median, 40);
  const std::vector<double> surface = samples(s.volume, [&](std::size_t x, std::size_t y, std::size_t z) {
    const float d = s.truth_sdf.at(x, y, z);
    return std::fabs(d) < 1 && z > 0 && s.truth_sdf.at(x, y, z - 1) > d + 0.5f;  // facing -z
  });
  ASSERT_GT(surface.size(), 50u);
  EXPECT_GT(mean_of(surface), s.fluid_median + 40);
}

// Autocorrelation of the grey levels deep inside tissue at lag 1 along an axis.
double lag1_correlation(const Phantom& p, int axis) {
  const auto& v = p.volume;
  double sum = 0, sum2 = 0, cross = 0;
  std::size_t n = 0;
  for (std::size_t z = 0; z + 1 < v.dims[2]; ++z)
    for (std::size_t y = 0; y + 1 < v.dims[1]; ++y)
      for (std::size_t x = 0; x + 1 < v.dims[0]; ++x) {
        const std::size_t X = x + (axis == 0), Y = y + (axis == 1), Z = z + (axis == 2);
        if (p.truth_sdf.at(x, y, z) > -4 || p.truth_sdf.at(X, Y, Z) > -4) continue;
        const double a = v.at(x, y, z), b = v.at(X, Y, Z);
        sum += a + b;
        sum2 += a * a + b * b;
        cross += a * b;
        ++n;
      }
  const double mean = sum / (2 * n), var = sum2 / (2 * n) - mean * mean;
  return (cross / n - mean * mean) / var;
}

TEST(PhantomImage, SpeckleIsShorterAxiallyThanLaterally) {
  PhantomParams par = params(PhantomShape::Sphere, 56);
  par.attenuation = 0;  // stationary speckle
  const Phantom p = make_phantom(runtime(), par);
  const double cx = lag1_correlation(p, 0), cy = lag1_correlation(p, 1), cz = lag1_correlation(p, 2);
  EXPECT_GT(cx, 0.5);
  EXPECT_NEAR(cx, cy, 0.1) << "lateral directions alike";
  EXPECT_LT(cz, cx - 0.25) << "axial (z) correlation " << cz << " vs lateral " << cx;
  // And a wider lateral PSF lengthens the lateral correlation, a wider axial
  // one the axial (the options of CliPhantom.OptionsReachTheJson: one build).
  par.psf_axial = 0.8;
  par.psf_lateral = 2.0;
  const Phantom q = make_phantom(runtime(), par);
  EXPECT_GT(lag1_correlation(q, 0), cx + 0.03);
  EXPECT_GT(lag1_correlation(q, 2), cz + 0.1);
}

TEST(PhantomImage, BoundaryEchoIsBrightestWhereTheSurfaceFacesTheBeam) {
  const int n = 64;
  PhantomParams par = params(PhantomShape::Sphere, n);
  par.attenuation = 0;  // compare the top and the side at their own depths
  auto top_and_side = [&](const Phantom& p) {
    std::vector<double> top, side;
    for (std::size_t z = 0; z < std::size_t(n); ++z)
      for (std::size_t y = 0; y < std::size_t(n); ++y)
        for (std::size_t x = 0; x < std::size_t(n); ++x) {
          if (std::fabs(p.truth_sdf.at(x, y, z)) > 1) continue;
          const double dx = design(x, n), dy = design(y, n), dz = design(z, n);
          const double cos_beam = -dz / std::sqrt(dx * dx + dy * dy + dz * dz);  // outward normal . (-beam)
          if (cos_beam > 0.9) top.push_back(p.volume.at(x, y, z));
          if (std::fabs(cos_beam) < 0.2) side.push_back(p.volume.at(x, y, z));
        }
    return std::make_pair(mean_of(top), mean_of(side));
  };
  const auto [top, side] = top_and_side(make_phantom(runtime(), par));
  EXPECT_GT(top, side + 25) << "top " << top << " side " << side;
  par.specular = 0;  // and it is the specular term that makes it
  const auto [top0, side0] = top_and_side(make_phantom(runtime(), par));
  EXPECT_GT(top - top0, side - side0 + 20) << "without it: top " << top0 << " side " << side0;
}

TEST(PhantomImage, TissueDarkensWithDepth) {
  const int n = 48;
  auto thirds = [&](double attenuation) {
    PhantomParams par = params(PhantomShape::Sphere, n);
    par.attenuation = attenuation;
    const Phantom p = make_phantom(runtime(), par);
    auto in_slab = [&](double z0, double z1) {
      return mean_of(samples(p.volume, [&](std::size_t x, std::size_t y, std::size_t z) {
        const double dz = design(z, n);
        return p.truth_sdf.at(x, y, z) < -3 && dz >= z0 && dz < z1;
      }));
    };
    return std::make_pair(in_slab(-30, -10), in_slab(10, 30));
  };
  const auto [upper, lower] = thirds(1.0);
  EXPECT_GT(upper, lower + 12) << "upper third " << upper << ", lower third " << lower;
  const auto [upper0, lower0] = thirds(0.0);
  EXPECT_LT(std::fabs(upper0 - lower0), 5) << "without attenuation: " << upper0 << " vs " << lower0;
}

TEST(PhantomImage, BonesCastShadows) {
  const int n = 56;
  const Phantom p = make_phantom(runtime(), params(PhantomShape::Spine, n));
  // Columns (x, y) that cross bone, and columns that stay 3 voxels from it.
  std::vector<int> column(n * n, 0);  // 1: crosses bone, 2: clear
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      float lo = 1e9f;
      for (int z = 0; z < n; ++z) lo = std::min(lo, p.truth_sdf.at(x, y, z));
      column[y * n + x] = lo < -1 ? 1 : (lo > 3 ? 2 : 0);
    }
  // Compare them at the same depths, below every vertebra.
  int deepest = 0;
  for (int z = 0; z < n; ++z)
    for (int i = 0; i < n * n; ++i)
      if (p.truth_sdf.data[std::size_t(z) * n * n + i] < 0) deepest = std::max(deepest, z);
  ASSERT_LT(deepest + 4, n - 4);
  std::vector<double> under, beside;
  for (int z = deepest + 4; z < n; ++z)
    for (int i = 0; i < n * n; ++i) {
      const double v = p.volume.data[std::size_t(z) * n * n + i];
      if (column[i] == 1) under.push_back(v);
      if (column[i] == 2) beside.push_back(v);
    }
  ASSERT_GT(under.size(), 200u);
  ASSERT_GT(beside.size(), 200u);
  EXPECT_LT(mean_of(under), mean_of(beside) - 20) << "under " << mean_of(under) << " beside " << mean_of(beside);
}

TEST(PhantomImage, LogCompressionSpansTheRangeAndDynamicRangeSetsContrast) {
  PhantomParams par = params(PhantomShape::Face, 48);
  const Phantom p = make_phantom(runtime(), par);
  const auto [lo, hi] = std::minmax_element(p.volume.data.begin(), p.volume.data.end());
  EXPECT_EQ(*lo, 0.0f);
  EXPECT_EQ(*hi, 255.0f);
  for (float v : p.volume.data) ASSERT_EQ(v, std::round(v));
  // Tissue is ~26 dB above fluid: 255 * 26 / range grey levels apart while
  // neither end clips, so a wider range lowers the contrast...
  par.dynamic_range_db = 80;
  const Phantom wide = make_phantom(runtime(), par);
  const double c50 = p.tissue_median - p.fluid_median, c80 = wide.tissue_median - wide.fluid_median;
  EXPECT_GT(c50, c80 + 30) << "50 dB: " << c50 << ", 80 dB: " << c80;
  EXPECT_GT(wide.fluid_median, p.fluid_median + 30) << "and lifts the noise floor into view";
  // ... and a narrow one clips more of the fluid to black.
  par.dynamic_range_db = 30;
  const Phantom narrow = make_phantom(runtime(), par);
  auto zeros = [](const Phantom& q) { return std::count(q.volume.data.begin(), q.volume.data.end(), 0.0f); };
  EXPECT_GT(zeros(narrow), 3 * zeros(p));
}

TEST(PhantomSlices, TwoRowsWithTheTrueBoundaryInColour) {
  const Phantom p = make_phantom(runtime(), params(PhantomShape::Sphere, 32));
  const Image img = phantom_slices(p);
  EXPECT_EQ(img.width, 3 * 256 + 2 * 4);
  EXPECT_EQ(img.height, 2 * 256 + 4);
  std::size_t orange_top = 0, orange_bottom = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::uint8_t* q = img.pixel(x, y);
      if (q[0] == 255 && q[1] == 150 && q[2] == 0) (y < 256 ? orange_top : orange_bottom)++;
    }
  EXPECT_EQ(orange_top, 0u);
  EXPECT_GT(orange_bottom, 3u * 256u) << "the sphere's outline in each of the three panels";
}

// ---- the command -----------------------------------------------------------------------

class CliPhantom : public CliTest {};

TEST_F(CliPhantom, WritesVolumeTruthAndJson) {
  const std::string dir = file("out/sphere");  // created, parents too
  const RunResult r = run({"phantom", "--shape", "sphere", "--size", "32", "--seed", "5", "-o", dir});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("32x32x32"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("medians"), std::string::npos) << r.out;
  const Volume v = read_volume(dir + "/volume.nrrd");
  EXPECT_EQ(v.source_type, ScalarType::UInt8);
  EXPECT_EQ(v.dims, (Dims3{32, 32, 32}));
  EXPECT_NEAR(v.spacing[0], 80.0 / 32, 1e-9);
  EXPECT_NEAR(v.spacing[2], 80.0 / 32, 1e-9);
  const Volume s = read_volume(dir + "/truth_sdf.nrrd");
  EXPECT_EQ(s.source_type, ScalarType::Float32);
  EXPECT_LT(s.at(16, 16, 16), -5);
  const std::string json = slurp(dir + "/phantom.json");
  for (const char* field : {"\"shape\": \"sphere\"", "\"size\": 32", "\"seed\": 5", "\"spacing_mm\"",
                            "\"beam\": [0, 0, 1]", "\"fluid_median\"", "\"tissue_median\"", "\"generation_seconds\"",
                            "\"dynamic_range_db\": 50", "\"psf_sigma_voxels\""})
    EXPECT_NE(json.find(field), std::string::npos) << field << " not in " << json;
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"phantom.json", "truth_sdf.nrrd", "volume.nrrd"}))
      << "no temporary files left";
}

TEST_F(CliPhantom, OptionsReachTheJson) {
  const RunResult r = run({"phantom", "--shape", "sphere", "--size", "24", "--speckle", "0.8,2", "--dynamic-range",
                           "40", "--noise", "0.05", "--fov", "30", "-q", "-o", file("s")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_TRUE(r.out.empty()) << r.out;
  const std::string json = slurp(file("s/phantom.json"));
  for (const char* field : {"\"axial\": 0.8", "\"lateral\": 2", "\"dynamic_range_db\": 40", "\"noise\": 0.05",
                            "\"fov_mm\": 30", "\"spacing_mm\": [1.25, 1.25, 1.25]"})
    EXPECT_NE(json.find(field), std::string::npos) << field << " not in " << json;
}

TEST_F(CliPhantom, BadOptionsAreOneLineErrors) {
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--shape", "cube"}, "--shape"},
      {{"--size", "8"}, "--size"},
      {{"--size", "600"}, "--size"},
      {{"--noise", "-1"}, "--noise"},
      {{"--dynamic-range", "5"}, "--dynamic-range"},
      {{"--dynamic-range", "120"}, "--dynamic-range"},
      {{"--speckle", "1"}, "--speckle"},
      {{"--speckle", "a,b"}, "--speckle"},
      {{"--speckle", "0.6,1.5,2"}, "--speckle"},
      {{"--speckle", "0.05,1"}, "--speckle"},
      {{"--fov", "-5"}, "--fov"},
      {{"--seed", "-3"}, "--seed"},
  };
  for (const auto& [extra, option] : cases) {
    std::vector<std::string> args{"phantom", "--size", "16", "-o", file("bad")};
    args.insert(args.end(), extra.begin(), extra.end());
    SCOPED_TRACE(extra[0] + " " + extra[1]);
    expect_one_line_error(run(args), {option});
    EXPECT_FALSE(fs::exists(file("bad"))) << "nothing written for bad options";
  }
  write("plain", "x");
  expect_one_line_error(run({"phantom", "--size", "16", "-o", file("plain")}), {"not a directory"});
}

TEST_F(CliPhantom, NonCubicDims) {
  const RunResult r = run({"phantom", "--dims", "40,24,20", "-o", file("p"), "-q"});
  ASSERT_EQ(r.status, 0) << r.err;
  const Volume v = read_volume(file("p/volume.nrrd")), t = read_volume(file("p/truth_sdf.nrrd"));
  EXPECT_EQ(v.dims, (Dims3{40, 24, 20}));
  EXPECT_EQ(t.dims, (Dims3{40, 24, 20}));
  EXPECT_DOUBLE_EQ(v.spacing[0], v.spacing[2]) << "isotropic voxels";
  EXPECT_NEAR(v.spacing[0], 100.0 / 40, 1e-9) << "the longest axis spans the face's 100 mm";
  for (const auto& [bad, option] : std::vector<std::pair<std::vector<std::string>, std::string>>{
           {{"--dims", "8,20,20"}, "--dims"},
           {{"--dims", "20,20"}, "--dims"},
           {{"--dims", "20,20,600"}, "--dims"},
           {{"--dims", "20,20,20", "--size", "20"}, "--dims"}}) {
    std::vector<std::string> args{"phantom", "-o", file("bad")};
    args.insert(args.end(), bad.begin(), bad.end());
    SCOPED_TRACE(bad[1]);
    expect_one_line_error(run(args), {option});
    EXPECT_FALSE(fs::exists(file("bad")));
  }
}

TEST_F(CliPhantom, SlicesPngHasTheExpectedSize) {
  const RunResult r =
      run({"phantom", "--shape", "face", "--size", "24", "-q", "-o", file("f"), "--slices", file("f.png")});
  ASSERT_EQ(r.status, 0) << r.err;
  const Image img = read_png(file("f.png"));
  EXPECT_EQ(img.width, 3 * 256 + 2 * 4);
  EXPECT_EQ(img.height, 2 * 256 + 4);
}

TEST_F(CliPhantom, HelpDescribesTheCommand) {
  const RunResult r = run({"phantom", "--help"});
  ASSERT_EQ(r.status, 0) << r.err;
  for (const char* s : {"--shape", "--size", "--seed", "--speckle", "--dynamic-range", "--noise", "--fov", "--slices",
                        "--device", "truth_sdf.nrrd", "z = 0", "--physics", "--physics-set", "labels.nrrd", "random"})
    EXPECT_NE(r.out.find(s), std::string::npos) << s << " not in help:\n" << r.out;
}

}  // namespace
}  // namespace softshell
