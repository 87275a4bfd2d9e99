// Structure-tensor splat orientation (kernels/orientation.h): the device
// against the float64 host reference, and the reference against geometry.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "error.hpp"
#include "orientation.hpp"
#include "reference.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

double angle_deg(const std::array<double, 3>& a, const std::array<float, 3>& b) {
  const double na = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  const double nb = std::sqrt(double(b[0]) * b[0] + double(b[1]) * b[1] + double(b[2]) * b[2]);
  const double c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (na * nb);
  return std::acos(std::min(1.0, std::abs(c))) * 180.0 / 3.14159265358979323846;
}

// A smooth shell u = m(x) exp(-d^2 / (2 2.5^2)), d the distance in mm from
// the plane n . x = 0 (wide enough for central differences to be accurate on
// the coarsest axis), with a 10 % modulation m along the plane: the
// tangential variation every real shell has (speckle, uneven echo).
Volume plane_shell(const Dims3& dims, const Vec3d& h, const std::array<double, 3>& n) {
  Volume u(dims, h);
  const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x) {
        const double p[3] = {(x - 0.5 * dims[0]) * h[0], (y - 0.5 * dims[1]) * h[1], (z - 0.5 * dims[2]) * h[2]};
        const double d = (p[0] * n[0] + p[1] * n[1] + p[2] * n[2]) / len;
        const double m = 1.0 + 0.1 * std::sin(0.9 * p[0]) * std::cos(0.7 * p[1]);
        u.at(x, y, z) = float(m * std::exp(-d * d / (2 * 2.5 * 2.5)));
      }
  return u;
}

TEST(Orientation, DeviceMatchesTheFloat64Reference) {
  // Odd sizes, anisotropic spacing, a smoothish random field (so the tensor
  // has distinct eigenvalues), points at voxel centres, between voxels, and
  // on the borders.
  Volume u = test::random_volume({23, 17, 19}, {0.7, 1.1, 1.6}, test::seed());
  std::vector<std::array<float, 3>> points;
  std::mt19937_64 rng(test::seed() + 1);
  std::uniform_real_distribution<float> fx(0, 22), fy(0, 16), fz(0, 18);
  for (int i = 0; i < 200; ++i) {
    std::array<float, 3> p{fx(rng), fy(rng), fz(rng)};
    if (i % 2 == 0) p = {std::round(p[0]), std::round(p[1]), std::round(p[2])};
    points.push_back(p);
  }
  points.push_back({0, 0, 0});
  points.push_back({22, 16, 18});
  for (double sigma : {0.8, 1.5, 8.0}) {  // 8: the largest window the kernel holds
    const auto dev = tensor_orientation_device(test::runtime(), u, points, sigma);
    ASSERT_EQ(dev.size(), points.size());
    int compared = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const auto ref = tensor_orientation_reference(u, {points[i][0], points[i][1], points[i][2]}, sigma);
      const double nr = std::sqrt(ref[0] * ref[0] + ref[1] * ref[1] + ref[2] * ref[2]);
      const double nd = std::sqrt(double(dev[i][0]) * dev[i][0] + double(dev[i][1]) * dev[i][1] +
                                  double(dev[i][2]) * dev[i][2]);
      ASSERT_GT(nr, 0);
      EXPECT_NEAR(nd, nr, 1e-3 * nr) << "point " << i;
      EXPECT_LT(angle_deg(ref, dev[i]), 0.5) << "point " << i << " sigma " << sigma;
      // Same side: power iteration keeps the start vector's side on both.
      EXPECT_GT(ref[0] * dev[i][0] + ref[1] * dev[i][1] + ref[2] * dev[i][2], 0) << "point " << i;
      ++compared;
    }
    EXPECT_EQ(compared, int(points.size()));
  }
}

TEST(Orientation, FindsTheNormalOfAShellOnItsRidge) {
  // On the middle sheet of the shell (|d| < 0.5 mm) grad u across the shell
  // vanishes and the central difference points along the sheet, following
  // the modulation; the tensor takes both flanks and gives the plane's
  // normal (per mm: the anisotropic spacing must not tilt it).
  const std::array<double, 3> n{0.3, -0.5, 0.8};
  const Dims3 dims{31, 29, 27};
  const Vec3d h{0.8, 1.0, 1.3};
  const Volume u = plane_shell(dims, h, n);
  const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  const std::array<float, 3> nf{float(n[0] / len), float(n[1] / len), float(n[2] / len)};
  int ridge = 0;
  double tensor_sum = 0, gradient_sum = 0;
  for (std::size_t z = 8; z < 19; ++z)
    for (std::size_t y = 8; y < 21; ++y)
      for (std::size_t x = 8; x < 23; ++x) {
        const double p[3] = {(x - 0.5 * dims[0]) * h[0], (y - 0.5 * dims[1]) * h[1], (z - 0.5 * dims[2]) * h[2]};
        if (std::abs(p[0] * nf[0] + p[1] * nf[1] + p[2] * nf[2]) > 0.5) continue;
        ++ridge;
        const auto t = tensor_orientation_reference(u, {double(x), double(y), double(z)}, 1.5);
        const double a = angle_deg(t, nf);
        EXPECT_LT(a, 6.0) << x << "," << y << "," << z;
        tensor_sum += a;
        // The central-difference gradient at the same voxel, for comparison.
        const std::array<double, 3> g{(u.at(x + 1, y, z) - u.at(x - 1, y, z)) / (2 * h[0]),
                                      (u.at(x, y + 1, z) - u.at(x, y - 1, z)) / (2 * h[1]),
                                      (u.at(x, y, z + 1) - u.at(x, y, z - 1)) / (2 * h[2])};
        gradient_sum += angle_deg(g, nf);
      }
  ASSERT_GT(ridge, 30);
  EXPECT_LT(tensor_sum / ridge, 3.0);
  EXPECT_GT(gradient_sum, 5 * tensor_sum) << "mean angle, grad u " << gradient_sum / ridge << " vs tensor "
                                          << tensor_sum / ridge;
}

TEST(Orientation, SigmaOutsideTheKernelsWindowIsAnInputError) {
  const Volume u = test::random_volume({9, 9, 9}, {1, 1, 1}, test::seed());
  EXPECT_THROW(tensor_orientation_device(test::runtime(), u, {{4, 4, 4}}, 8.5), InputError);
  EXPECT_THROW(tensor_orientation_device(test::runtime(), u, {{4, 4, 4}}, 0.0), InputError);
}

TEST(Orientation, FlatOpacityHasNoOrientation) {
  Volume u({9, 9, 9}, {1, 1, 1});
  std::fill(u.data.begin(), u.data.end(), 0.5f);
  const auto r = tensor_orientation_reference(u, {4, 4, 4}, 1.5);
  EXPECT_EQ(r[0], 0.0);
  EXPECT_EQ(r[1], 0.0);
  EXPECT_EQ(r[2], 0.0);
  const auto d = tensor_orientation_device(test::runtime(), u, {{4, 4, 4}}, 1.5);
  EXPECT_EQ(d[0][0], 0.0f);
  EXPECT_EQ(d[0][1], 0.0f);
  EXPECT_EQ(d[0][2], 0.0f);
}

TEST(Orientation, DataFieldIsAVoxelsLowpassOfTheBmode) {
  // One voxel of the finest axis, isotropic in mm: sigma 0.5 mm on a
  // 0.5 x 0.8 x 1.1 mm grid, against the independent 3-D tap sum; the same
  // bits for any thread count; geometry kept.
  Volume v = test::random_volume({13, 10, 7}, {0.5, 0.8, 1.1}, test::seed() + 3, 0.0f, 255.0f);
  v.origin = {2.0, -1.0, 3.5};
  v.source_type = ScalarType::UInt8;
  const Volume f = data_orientation_field(v, 1);
  EXPECT_EQ(f.dims, v.dims);
  EXPECT_EQ(f.spacing, v.spacing);
  EXPECT_EQ(f.origin, v.origin);
  EXPECT_EQ(f.source_type, ScalarType::Float32);
  const std::vector<double> want = test::reference_lowpass(v, 0.5, 3.0);
  ASSERT_EQ(want.size(), f.data.size());
  double worst = 0;
  for (std::size_t i = 0; i < want.size(); ++i) worst = std::max(worst, std::abs(f.data[i] - want[i]));
  EXPECT_LT(worst, 1e-3) << "of samples up to 255";
  EXPECT_EQ(data_orientation_field(v, 2).data, f.data);
  EXPECT_THROW(data_orientation_field(Volume()), InputError);
}

// The mean angle (degrees) between the structure tensor of `field` and n at
// the voxels within half a voxel of the plane n . (x - c) = 0 (mm), c the
// volume's centre.
double plane_error_deg(const Volume& field, const std::array<double, 3>& n, double sigma) {
  double sum = 0;
  std::size_t count = 0;
  const Dims3& d = field.dims;
  for (std::size_t z = 4; z + 4 < d[2]; ++z)
    for (std::size_t y = 4; y + 4 < d[1]; ++y)
      for (std::size_t x = 4; x + 4 < d[0]; ++x) {
        const double p[3] = {(x - 0.5 * d[0]) * field.spacing[0], (y - 0.5 * d[1]) * field.spacing[1],
                             (z - 0.5 * d[2]) * field.spacing[2]};
        if (std::abs(p[0] * n[0] + p[1] * n[1] + p[2] * n[2]) > 0.5) continue;
        const auto t = tensor_orientation_reference(field, {double(x), double(y), double(z)}, sigma);
        sum += angle_deg(n, {float(t[0]), float(t[1]), float(t[2])});
        ++count;
      }
  EXPECT_GT(count, 100u);
  return count ? sum / double(count) : 90.0;
}

TEST(Orientation, DataFieldFindsATiltedBoundaryUnderSpeckle) {
  // A B-mode boundary (dark above a tilted plane, bright below, blurred by a
  // millimetre) under multiplicative speckle (exponential intensity, as fully
  // developed speckle): the tensor of the field finds its normal to a few
  // degrees; the tensor of the raw samples, whose speckle gradients are as
  // strong as the boundary's, does not.
  const double len = std::sqrt(0.3 * 0.3 + 0.2 * 0.2 + 1.0);
  const std::array<double, 3> n{0.3 / len, -0.2 / len, 1.0 / len};
  Volume v({32, 32, 32}, {0.6, 0.6, 0.6});
  std::mt19937_64 rng(test::seed() + 5);
  std::exponential_distribution<double> speckle(1.0);
  for (std::size_t z = 0; z < 32; ++z)
    for (std::size_t y = 0; y < 32; ++y)
      for (std::size_t x = 0; x < 32; ++x) {
        const double p[3] = {(x - 16.0) * 0.6, (y - 16.0) * 0.6, (z - 16.0) * 0.6};
        const double s = p[0] * n[0] + p[1] * n[1] + p[2] * n[2];
        const double mean = 30.0 + 120.0 / (1.0 + std::exp(-s / 0.6));
        v.at(x, y, z) = float(mean * speckle(rng));
      }
  const double by_field = plane_error_deg(data_orientation_field(v), n, 1.5);
  const double raw = plane_error_deg(v, n, 1.5);
  EXPECT_LT(by_field, 13.0) << "raw samples: " << raw;
  EXPECT_GT(raw, by_field + 15.0) << "the lowpass: " << by_field;
}

}  // namespace
}  // namespace softshell
