// Levoy's classifier on the device against a float64 CPU reference (on the raw
// and the lowpassed volume, odd sizes, anisotropic spacing), an exact answer
// on a linear ramp, and the classify command end to end.
#include <cmath>

#include "cli_fixture.hpp"
#include "error.hpp"
#include "io.hpp"
#include "levoy.hpp"
#include "variational.hpp"
#include "reference.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

// Levoy's formula in double, written from the 1988 paper.
std::vector<double> reference_levoy(const Volume& v, const LevoyParams& p) {
  Volume f = v;
  if (p.sigma_mm > 0) {
    const auto smooth = test::reference_lowpass(v, p.sigma_mm, 3.0);
    for (std::size_t i = 0; i < f.data.size(); ++i) f.data[i] = float(smooth[i]);
  }
  const auto g = test::reference_gradient(f);
  const double r = p.thickness * std::cbrt(v.spacing[0] * v.spacing[1] * v.spacing[2]);
  std::vector<double> a(v.voxels());
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double mag = std::sqrt(g[0][i] * g[0][i] + g[1][i] * g[1][i] + g[2][i] * g[2][i]);
    const double d = std::abs(p.iso - f.data[i]);
    a[i] = mag > 0 ? (d <= r * mag ? p.alpha * (1 - d / (r * mag)) : 0.0) : (d == 0 ? p.alpha : 0.0);
  }
  return a;
}

struct LevoyCase {
  Dims3 dims;
  Vec3d spacing;
  double sigma_mm, thickness;
  friend void PrintTo(const LevoyCase& c, std::ostream* os) {
    *os << c.dims[0] << "x" << c.dims[1] << "x" << c.dims[2] << " sigma " << c.sigma_mm << " mm, r " << c.thickness;
  }
};

class LevoyVsReference : public ::testing::TestWithParam<LevoyCase> {};

TEST_P(LevoyVsReference, MatchesCpuReference) {
  const LevoyCase c = GetParam();
  // A smooth field plus noise, so the isosurface crosses many voxels.
  Volume v = test::random_volume(c.dims, c.spacing, test::seed() + 20, -10.0f, 10.0f);
  for (std::size_t z = 0; z < c.dims[2]; ++z)
    for (std::size_t y = 0; y < c.dims[1]; ++y)
      for (std::size_t x = 0; x < c.dims[0]; ++x) v.at(x, y, z) += float(8.0 * x * c.spacing[0]);
  LevoyParams p;
  p.iso = 0.5 * 8.0 * (c.dims[0] - 1) * c.spacing[0];  // mid-ramp
  p.thickness = c.thickness;
  p.sigma_mm = c.sigma_mm;
  const Volume got = classify_levoy(test::runtime(), v, p);
  EXPECT_EQ(got.dims, v.dims);
  EXPECT_EQ(got.source_type, ScalarType::Float32);
  const auto want = reference_levoy(v, p);
  EXPECT_TRUE(test::all_near(got.data, want, v.dims, 2e-3, 1e-4));
  std::size_t nonzero = 0;
  for (double w : want) nonzero += w > 0.05;
  EXPECT_GT(nonzero, v.voxels() / 50) << "the test field must actually cross the isovalue";
}

INSTANTIATE_TEST_SUITE_P(OddSizesAnisotropic, LevoyVsReference,
                         ::testing::Values(LevoyCase{{17, 23, 9}, {0.5, 0.8, 1.3}, 0.0, 1.0},
                                           LevoyCase{{17, 23, 9}, {0.5, 0.8, 1.3}, 1.0, 1.5},
                                           LevoyCase{{33, 12, 15}, {1.0, 1.0, 1.0}, 1.5, 2.0},
                                           LevoyCase{{9, 31, 5}, {0.7, 0.4, 1.0}, 0.8, 0.5}));

TEST(Levoy, TentOnALinearRamp) {
  // f = 2 x (mm), iso 20 -> surface at x = 10 mm; opacity 1 - |x - 10| / r.
  Volume v({41, 5, 4}, {0.5, 0.5, 0.5});
  for (std::size_t z = 0; z < 4; ++z)
    for (std::size_t y = 0; y < 5; ++y)
      for (std::size_t x = 0; x < 41; ++x) v.at(x, y, z) = float(2.0 * 0.5 * x);
  LevoyParams p;
  p.iso = 20.0;
  p.thickness = 4.0;  // voxels of 0.5 mm: r = 2 mm
  const Volume u = classify_levoy(test::runtime(), v, p);
  for (std::size_t x = 0; x < 41; ++x) {
    const double want = std::max(0.0, 1.0 - std::abs(0.5 * x - 10.0) / 2.0);
    EXPECT_NEAR(u.at(x, 2, 1), want, 1e-5) << "x = " << x;
  }
}

// Float samples at the ends of float's range: the lowpass and gradients
// overflow, and the classifiers answer instead of writing NaN (fuzzing).
TEST(Levoy, SamplesThatOverflowFloatArithmeticAreAnInputErrorNotNaN) {
  Volume v({8, 8, 8}, {1, 1, 1}, ScalarType::Float32);
  for (std::size_t i = 0; i < v.data.size(); ++i) v.data[i] = (i % 3 == 0) ? 3.0e38f : -3.0e38f;
  LevoyParams p;
  p.iso = 0;
  p.sigma_mm = 1;
  try {
    const Volume u = classify_levoy(test::runtime(), v, p);
    for (float x : u.data) ASSERT_TRUE(std::isfinite(x));
  } catch (const InputError&) {
  }
  // The variational classifier: not converged (the CLI's exit 3), never a
  // converged opacity holding NaN.
  VariationalParams vp;
  vp.v_iso = v.intensity_map().to_unit(0.0);
  SolverParams sp;
  sp.max_cycles = 20;
  SolveReport rep;
  try {
    const Volume u = classify_variational(test::runtime(), v, vp, sp, &rep);
    if (rep.converged)
      for (float x : u.data) ASSERT_TRUE(std::isfinite(x));
  } catch (const InputError&) {
  }
}

TEST(Levoy, RejectsBadParameters) {
  Volume v({8, 8, 8});
  LevoyParams p;
  p.thickness = 0;
  EXPECT_THROW(classify_levoy(test::runtime(), v, p), InputError);
  p = {};
  p.sigma_mm = -1;
  EXPECT_THROW(classify_levoy(test::runtime(), v, p), InputError);
  p = {};
  p.iso = std::nan("");
  EXPECT_THROW(classify_levoy(test::runtime(), v, p), InputError);
}

class CliClassify : public test::CliTest {};

TEST_F(CliClassify, LevoyWritesFloatOpacityWithTheInputGeometry) {
  Volume v({24, 20, 16}, {0.5, 0.6, 0.7}, ScalarType::UInt8);
  v.origin = {1.0, -2.0, 3.0};
  for (std::size_t z = 0; z < 16; ++z)
    for (std::size_t y = 0; y < 20; ++y)
      for (std::size_t x = 0; x < 24; ++x) v.at(x, y, z) = float(10 * x);  // 0..230
  write_volume(file("in.nrrd"), v);
  const test::RunResult r =
      run({"classify", file("in.nrrd"), "--method", "levoy", "--iso", "115", "--thickness", "2", "-o", file("u.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  const Volume u = read_volume(file("u.nrrd"));
  EXPECT_EQ(u.dims, v.dims);
  EXPECT_EQ(u.source_type, ScalarType::Float32);
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(u.spacing[a], v.spacing[a], 1e-9);
    EXPECT_NEAR(u.origin[a], v.origin[a], 1e-9);
  }
  LevoyParams p;
  p.iso = 115;
  p.thickness = 2;
  EXPECT_TRUE(test::all_near(u.data, reference_levoy(v, p), v.dims, 2e-3, 1e-4));
}

TEST_F(CliClassify, BadArgumentsAreOneLineErrors) {
  Volume v({8, 8, 8}, {1, 1, 1}, ScalarType::UInt8);
  write_volume(file("in.nrrd"), v);
  expect_one_line_error(run({"classify", file("in.nrrd"), "--method", "levoy", "-o", file("u.nrrd")}), {"--iso"});
  expect_one_line_error(run({"classify", file("in.nrrd"), "--method", "levoy", "--iso", "abc", "-o", file("u.nrrd")}),
                        {"--iso"});
  expect_one_line_error(
      run({"classify", file("in.nrrd"), "--method", "levoy", "--iso", "5", "--thickness", "-1", "-o", file("u.nrrd")}),
      {"--thickness"});
  expect_one_line_error(run({"classify", file("in.nrrd"), "--method", "magic", "--iso", "5", "-o", file("u.nrrd")}),
                        {"--method"});
  expect_one_line_error(run({"classify", file("missing.nrrd"), "--method", "levoy", "--iso", "5", "-o", file("u.nrrd")}),
                        {"missing.nrrd"});
  EXPECT_FALSE(test::fs::exists(file("u.nrrd")));
}

}  // namespace
}  // namespace softshell
