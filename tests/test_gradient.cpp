// Gradient kernels against a float64 CPU reference (central inside,
// one-sided at borders, per mm), guard bands, and determinism.
#include <cstring>

#include "filter.hpp"
#include "gradient.hpp"
#include "reference.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

using test::reference_derivative;
using test::runtime;

struct GradResult {
  std::vector<float> gx, gy, gz, mag;
};

GradResult device_gradient(const Volume& v) {
  Runtime& rt = runtime();
  Gradient grad(rt, make_grid(v.dims, v.spacing));
  const std::size_t n = v.voxels();
  cl::Buffer f = test::upload(rt, v.data);
  cl::Buffer gx = rt.buffer(n * 4), gy = rt.buffer(n * 4), gz = rt.buffer(n * 4), mag = rt.buffer(n * 4);
  grad.apply(f, gx, gy, gz);
  grad.magnitude(gx, gy, gz, mag);
  return {test::download(rt, gx, n), test::download(rt, gy, n), test::download(rt, gz, n),
          test::download(rt, mag, n)};
}

class GradientVsReference : public ::testing::TestWithParam<std::pair<Dims3, Vec3d>> {};

TEST_P(GradientVsReference, MatchesCpuReference) {
  const auto [dims, spacing] = GetParam();
  const Volume v = test::random_volume(dims, spacing, test::seed() + 7, -3.0f, 5.0f);
  const GradResult got = device_gradient(v);
  std::vector<double> want[3], want_mag(v.voxels());
  for (auto& w : want) w.resize(v.voxels());
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x) {
        const std::size_t i = v.index(x, y, z);
        double m2 = 0;
        for (int a = 0; a < 3; ++a) {
          want[a][i] = reference_derivative(v, x, y, z, a);
          m2 += want[a][i] * want[a][i];
        }
        want_mag[i] = std::sqrt(m2);
      }
  EXPECT_TRUE(test::all_near(got.gx, want[0], dims, 1e-5, 1e-5)) << "d/dx";
  EXPECT_TRUE(test::all_near(got.gy, want[1], dims, 1e-5, 1e-5)) << "d/dy";
  EXPECT_TRUE(test::all_near(got.gz, want[2], dims, 1e-5, 1e-5)) << "d/dz";
  EXPECT_TRUE(test::all_near(got.mag, want_mag, dims, 1e-5, 1e-5)) << "|grad|";
}

INSTANTIATE_TEST_SUITE_P(OddSizesAnisotropic, GradientVsReference,
                         ::testing::Values(std::make_pair(Dims3{17, 23, 9}, Vec3d{0.5, 0.8, 1.3}),
                                           std::make_pair(Dims3{2, 5, 3}, Vec3d{1.0, 0.25, 3.0}),
                                           std::make_pair(Dims3{1, 7, 66}, Vec3d{1.0, 1.0, 0.6}),
                                           std::make_pair(Dims3{67, 3, 1}, Vec3d{0.4, 1.0, 1.0})));

TEST(Gradient, OfTheLowpassedVolume) {
  // The classifier needs grad v~: lowpass then gradient on the device, against
  // the reference gradient of the reference lowpass.
  Runtime& rt = runtime();
  const Volume v = test::random_volume({21, 14, 11}, {0.6, 0.9, 1.4}, test::seed() + 10, 0.0f, 255.0f);
  const auto smooth = test::reference_lowpass(v, 1.1, 3.0);
  Volume vs(v.dims, v.spacing);
  for (std::size_t i = 0; i < vs.data.size(); ++i) vs.data[i] = float(smooth[i]);
  const GridDesc g = make_grid(v.dims, v.spacing);
  const std::size_t n = v.voxels();
  cl::Buffer f = test::upload(rt, v.data), fs = rt.buffer(n * 4);
  cl::Buffer gx = rt.buffer(n * 4), gy = rt.buffer(n * 4), gz = rt.buffer(n * 4);
  Lowpass(rt, g, {1.1, 3.0}).apply(f, fs);
  Gradient(rt, g).apply(fs, gx, gy, gz);
  const std::vector<float> got[3] = {test::download(rt, gx, n), test::download(rt, gy, n), test::download(rt, gz, n)};
  for (int a = 0; a < 3; ++a) {
    std::vector<double> want(n);
    for (std::size_t z = 0; z < v.dims[2]; ++z)
      for (std::size_t y = 0; y < v.dims[1]; ++y)
        for (std::size_t x = 0; x < v.dims[0]; ++x) want[v.index(x, y, z)] = reference_derivative(vs, x, y, z, a);
    EXPECT_TRUE(test::all_near(got[a], want, v.dims, 2e-3, 1e-4)) << "axis " << a;
  }
}

TEST(Gradient, ExactOnLinearRamp) {
  // Central and one-sided differences are exact for a linear function.
  Volume v({11, 6, 8}, {0.5, 2.0, 0.75});
  for (std::size_t z = 0; z < 8; ++z)
    for (std::size_t y = 0; y < 6; ++y)
      for (std::size_t x = 0; x < 11; ++x) v.at(x, y, z) = float(3.0 * x * 0.5 - 1.0 * y * 2.0 + 0.5 * z * 0.75);
  const GradResult got = device_gradient(v);
  for (std::size_t i = 0; i < v.voxels(); ++i) {
    ASSERT_NEAR(got.gx[i], 3.0f, 1e-4);
    ASSERT_NEAR(got.gy[i], -1.0f, 1e-4);
    ASSERT_NEAR(got.gz[i], 0.5f, 1e-4);
  }
}

TEST(Gradient, GuardBandsUntouched) {
  Runtime& rt = runtime();
  const Dims3 dims{9, 13, 5};
  const Volume v = test::random_volume(dims, {1.0, 1.0, 1.0}, test::seed() + 8);
  const std::size_t n = v.voxels();
  const std::size_t align = std::max<std::size_t>(rt.info().mem_base_addr_align_bits / 8, 4) / sizeof(float);
  const std::size_t guard = ((512 + align - 1) / align) * align;
  const std::size_t slot = ((n + align - 1) / align) * align;
  const std::size_t total = guard + 3 * slot + guard;
  const float sentinel = 7777.0f;
  cl::Buffer big = test::upload(rt, std::vector<float>(total, sentinel));
  cl::Buffer f = test::upload(rt, v.data);
  cl::Buffer comp[3];
  for (int a = 0; a < 3; ++a) {
    cl_buffer_region r{(guard + a * slot) * sizeof(float), n * sizeof(float)};
    comp[a] = big.createSubBuffer(CL_MEM_READ_WRITE, CL_BUFFER_CREATE_TYPE_REGION, &r);
  }
  Gradient(rt, make_grid(dims, v.spacing)).apply(f, comp[0], comp[1], comp[2]);
  const auto all = test::download(rt, big, total);
  for (std::size_t i = 0; i < total; ++i) {
    const bool written = i >= guard && i < guard + 3 * slot && (i - guard) % slot < n;
    if (!written) ASSERT_EQ(all[i], sentinel) << "guard overwritten at " << i;
  }
}

TEST(Gradient, BitIdenticalAcrossRuns) {
  const Volume v = test::random_volume({29, 17, 23}, {0.5, 0.9, 1.1}, test::seed() + 9);
  const auto a = device_gradient(v), b = device_gradient(v);
  EXPECT_EQ(0, std::memcmp(a.gx.data(), b.gx.data(), a.gx.size() * 4));
  EXPECT_EQ(0, std::memcmp(a.gy.data(), b.gy.data(), a.gy.size() * 4));
  EXPECT_EQ(0, std::memcmp(a.gz.data(), b.gz.data(), a.gz.size() * 4));
}

}  // namespace
}  // namespace softshell
