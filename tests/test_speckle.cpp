// The speckle's size across the beam and the gradient lowpass taken from it
// (host/speckle.hpp): on white noise blurred by a Gaussian of known width
// along each axis (the estimate is the width, a little low from the 1 mm
// detail filter: about 6 % at 0.3 mm, computed independently with scipy
// when the tolerances were set), only the scanned voxels counted, the same
// bits for any thread count, the clamp of --grad-sigma's default, its gate
// (echoes over darker data only), and classify's report of it.
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "io.hpp"
#include "speckle.hpp"
#include "cli_fixture.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

// White noise blurred along each axis by a Gaussian of sigma_mm[a] (direct
// separable convolution, periodic so that every voxel sees the same blur).
Volume blurred_noise(Dims3 d, double h, const double sigma_mm[3], std::uint64_t seed) {
  Volume v(d, {h, h, h});
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<double> f(v.voxels());
  for (double& x : f) x = n(rng);
  for (int a = 0; a < 3; ++a) {
    const double s = sigma_mm[a] / h;
    const long r = long(std::ceil(4 * s)), len = long(d[std::size_t(a)]);
    std::vector<double> w;
    for (long k = -r; k <= r; ++k) w.push_back(std::exp(-0.5 * double(k * k) / (s * s)));
    std::vector<double> g(f.size(), 0.0);
    for (std::size_t z = 0; z < d[2]; ++z)
      for (std::size_t y = 0; y < d[1]; ++y)
        for (std::size_t x = 0; x < d[0]; ++x) {
          const long c[3] = {long(x), long(y), long(z)};
          double acc = 0;
          for (long k = -r; k <= r; ++k) {
            long q[3] = {c[0], c[1], c[2]};
            q[a] = ((c[a] + k) % len + len) % len;
            acc += w[std::size_t(k + r)] * f[v.index(std::size_t(q[0]), std::size_t(q[1]), std::size_t(q[2]))];
          }
          g[v.index(x, y, z)] = acc;
        }
    f.swap(g);
  }
  for (std::size_t i = 0; i < f.size(); ++i) v.data[i] = float(100.0 + 10.0 * f[i]);
  return v;
}

TEST(Speckle, BlurredNoiseGivesItsWidthAcrossTheBeam) {
  const double sigma[3] = {0.3, 0.5, 0.1};  // x lateral, y elevation, z along the beam
  const Volume v = blurred_noise({56, 56, 40}, 0.2, sigma, test::seed());
  const SpeckleReport r = speckle_size(v, nullptr, 2);
  ASSERT_TRUE(r.measured);
  EXPECT_EQ(r.axis, 0) << "the finer of x and y";
  EXPECT_NEAR(r.sigma_mm, 0.3 * 0.94, 0.3 * 0.1);
  EXPECT_EQ(r.lag1[2], 0.0) << "the beam axis is not measured";
  EXPECT_GT(r.lag1[1], r.lag1[0]);
  // The beam along x (finest there): across it, z's 0.3 mm is finer than y's 0.5.
  const double along_x[3] = {0.1, 0.5, 0.3};
  const SpeckleReport rx = speckle_size(blurred_noise({40, 56, 56}, 0.2, along_x, test::seed() + 3), nullptr, 0);
  ASSERT_TRUE(rx.measured);
  EXPECT_EQ(rx.axis, 2);
  EXPECT_EQ(rx.lag1[0], 0.0);
  EXPECT_NEAR(rx.sigma_mm, 0.3 * 0.94, 0.3 * 0.1);
  // Finer speckle, smaller estimate; coarser, larger.
  const double fine[3] = {0.2, 0.5, 0.1}, coarse[3] = {0.4, 0.5, 0.1};
  const double sf = speckle_size(blurred_noise({56, 56, 40}, 0.2, fine, test::seed() + 1), nullptr, 2).sigma_mm;
  const double sc = speckle_size(blurred_noise({56, 56, 40}, 0.2, coarse, test::seed() + 2), nullptr, 2).sigma_mm;
  EXPECT_LT(sf, r.sigma_mm);
  EXPECT_GT(sc, r.sigma_mm);
  EXPECT_NEAR(sf, 0.2 * 0.96, 0.2 * 0.1);
}

TEST(Speckle, OnlyTheScannedVoxelsCountAndAnyThreadCountGivesTheSameBits) {
  // Fine speckle at x < 28, a coarse-grained field at x >= 28 marked
  // unscanned: the estimate is the fine speckle's, as measured on it alone;
  // without the mask the coarse half pulls it up.
  const double fine[3] = {0.25, 0.5, 0.1}, coarse[3] = {1.2, 1.2, 0.1};
  const Dims3 d{56, 48, 32};
  const Volume a = blurred_noise(d, 0.2, fine, test::seed()), b = blurred_noise(d, 0.2, coarse, test::seed() + 7);
  Volume v = a;
  std::vector<std::uint8_t> mask(v.voxels(), 1);
  for (std::size_t z = 0; z < d[2]; ++z)
    for (std::size_t y = 0; y < d[1]; ++y)
      for (std::size_t x = 28; x < d[0]; ++x) v.at(x, y, z) = b.at(x, y, z), mask[v.index(x, y, z)] = 0;
  const SpeckleReport masked = speckle_size(v, &mask, 2), all = speckle_size(v, nullptr, 2);
  ASSERT_TRUE(masked.measured);
  EXPECT_NEAR(masked.sigma_mm, 0.25 * 0.95, 0.25 * 0.1);
  EXPECT_GT(all.sigma_mm, 1.3 * masked.sigma_mm);
  for (int threads : {1, 2, 3}) {
    const SpeckleReport t = speckle_size(v, &mask, 2, threads);
    EXPECT_EQ(t.sigma_mm, masked.sigma_mm) << threads << " threads";
    for (int k = 0; k < 3; ++k) EXPECT_EQ(t.lag1[k], masked.lag1[k]);
  }
}

TEST(Speckle, NothingToMeasureAndBadArgumentsAreSaid) {
  Volume flat({24, 24, 24}, {0.5, 0.5, 0.5});
  std::fill(flat.data.begin(), flat.data.end(), 7.0f);
  EXPECT_FALSE(speckle_size(flat, nullptr, 2).measured) << "no detail at all";
  const double s[3] = {0.3, 0.3, 0.1};
  const Volume v = blurred_noise({24, 24, 24}, 0.2, s, test::seed());
  std::vector<std::uint8_t> few(v.voxels(), 0);
  for (std::size_t i = 0; i < 300; ++i) few[i] = 1;
  EXPECT_FALSE(speckle_size(v, &few, 2).measured) << "fewer than kSpeckleMinPairs scanned neighbours";
  const std::vector<std::uint8_t> wrong(10, 1);
  EXPECT_THROW(speckle_size(v, &wrong, 2), std::invalid_argument);
  EXPECT_THROW(speckle_size(v, nullptr, 3), std::invalid_argument);
}

TEST(Speckle, TheGradientLowpassIsThreeSpecklesWithinItsBounds) {
  SpeckleReport r;
  EXPECT_EQ(grad_sigma_from_speckle(r), kGradSigmaMaxMm) << "unmeasured: the earlier fixed default";
  r.measured = true;
  r.sigma_mm = 0.1;
  EXPECT_EQ(grad_sigma_from_speckle(r), kGradSigmaMinMm);
  r.sigma_mm = 0.45;
  EXPECT_NEAR(grad_sigma_from_speckle(r), 1.35, 1e-12);
  EXPECT_NEAR(grad_sigma_from_speckle(r, 0.5), 0.675, 1e-12) << "a small volume's scale";
  r.sigma_mm = 2.0;
  EXPECT_EQ(grad_sigma_from_speckle(r), kGradSigmaMaxMm);
}

// Speckle of 0.35 mm across the beam over a boundary at half depth, 21 mm
// across (no small-volume scaling): an echo over darker data (bright above)
// or a step from dark to bright (fluid over tissue).
Volume speckled_boundary(bool bright_above) {
  const double s[3] = {0.35, 0.7, 0.2};
  Volume v = blurred_noise({42, 42, 42}, 0.5, s, test::seed());
  for (std::size_t z = 0; z < 42; ++z)
    for (std::size_t y = 0; y < 42; ++y)
      for (std::size_t x = 0; x < 42; ++x)
        if ((z < 21) == bright_above) v.at(x, y, z) += 60.0f;
  return v;
}

TEST(Speckle, OnlyEchoesOverDarkerDataTakeTheNarrowerLowpass) {
  const GradSigmaChoice echo = auto_grad_sigma(speckled_boundary(true), nullptr, 2);
  EXPECT_TRUE(echo.echoes);
  EXPECT_GT(echo.falling, 0.9);
  EXPECT_TRUE(echo.speckle.measured);
  EXPECT_EQ(echo.sigma_mm, grad_sigma_from_speckle(echo.speckle));
  EXPECT_EQ(echo.sigma_mm, kGradSigmaMinMm) << "3 x about 0.33 mm, below the lower bound";
  const GradSigmaChoice step = auto_grad_sigma(speckled_boundary(false), nullptr, 2);
  EXPECT_FALSE(step.echoes);
  EXPECT_GT(step.rising, 0.9);
  EXPECT_FALSE(step.speckle.measured) << "not measured where it is not used";
  EXPECT_EQ(step.sigma_mm, kGradSigmaMaxMm);
  EXPECT_EQ(auto_grad_sigma(speckled_boundary(false), nullptr, 2, 0.5).sigma_mm, 0.5 * kGradSigmaMaxMm);
}

class CliSpeckle : public test::CliTest {};

TEST_F(CliSpeckle, ClassifySaysHowItChoseTheGradientLowpassAndAGivenOneStays) {
  write_volume(file("echo.nrrd"), speckled_boundary(true));
  write_volume(file("step.nrrd"), speckled_boundary(false));
  const test::RunResult a = run({"classify", file("echo.nrrd"), "--iso", "130", "-o", file("a.nrrd")});
  ASSERT_EQ(a.status, 0) << a.err;
  EXPECT_NE(a.out.find("grad-sigma 1.250 mm (auto: 3.00 x the speckle's 0.3"), std::string::npos) << a.out;
  EXPECT_NE(a.out.find("mm along x, within 1.25-1.50 mm)"), std::string::npos) << a.out;
  const test::RunResult b = run({"classify", file("step.nrrd"), "--iso", "130", "-o", file("b.nrrd")});
  ASSERT_EQ(b.status, 0) << b.err;
  EXPECT_NE(b.out.find("grad-sigma 1.500 mm (auto: the strong edges are no echoes over darker data, 0 % fall and 100 % "
                       "rise along the beam)"),
            std::string::npos)
      << b.out;
  const test::RunResult g = run({"classify", file("echo.nrrd"), "--iso", "130", "--grad-sigma", "1.5", "-o", file("g.nrrd")});
  ASSERT_EQ(g.status, 0) << g.err;
  EXPECT_NE(g.out.find("grad-sigma 1.500 mm\n"), std::string::npos) << g.out;
  EXPECT_EQ(g.out.find("(auto:"), std::string::npos) << g.out;
  EXPECT_NE(read_volume(file("a.nrrd")).data, read_volume(file("g.nrrd")).data) << "the lowpass chosen is the one used";
  // The paper's functional takes no gradient lowpass, and no report of one.
  const test::RunResult l = run({"classify", file("echo.nrrd"), "--iso", "130", "--literal", "-o", file("l.nrrd")});
  ASSERT_EQ(l.status, 0) << l.err;
  EXPECT_NE(l.out.find("grad-sigma 0.000 mm (the paper's functional)"), std::string::npos) << l.out;
}

}  // namespace
}  // namespace softshell
