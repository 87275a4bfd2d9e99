// Gaussian lowpass kernels against an independent float64 CPU reference, on
// odd sizes and anisotropic spacing; guard bands; run-to-run determinism.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

#include "blur.hpp"
#include "error.hpp"
#include "filter.hpp"
#include "reference.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

using test::reference_lowpass;
using test::runtime;

std::vector<float> device_lowpass(const Volume& v, double sigma_mm) {
  Runtime& rt = runtime();
  const GridDesc g = make_grid(v.dims, v.spacing);
  Lowpass f(rt, g, {sigma_mm, 3.0});
  cl::Buffer in = test::upload(rt, v.data);
  cl::Buffer out = rt.buffer(v.voxels() * sizeof(float));
  f.apply(in, out);
  return test::download(rt, out, v.voxels());
}

struct Case {
  Dims3 dims;
  Vec3d spacing;
  double sigma_mm;
  friend void PrintTo(const Case& c, std::ostream* os) {
    *os << c.dims[0] << "x" << c.dims[1] << "x" << c.dims[2] << " spacing " << c.spacing[0] << "," << c.spacing[1]
        << "," << c.spacing[2] << " sigma " << c.sigma_mm << " mm";
  }
};

class LowpassVsReference : public ::testing::TestWithParam<Case> {};

TEST_P(LowpassVsReference, MatchesCpuReference) {
  const Case c = GetParam();
  const Volume v = test::random_volume(c.dims, c.spacing, test::seed(), 0.0f, 255.0f);
  const auto want = reference_lowpass(v, c.sigma_mm, 3.0);
  // float32 accumulation of <= ~50 taps per pass over values up to 255.
  EXPECT_TRUE(test::all_near(device_lowpass(v, c.sigma_mm), want, v.dims, 2e-3, 1e-5));
}

INSTANTIATE_TEST_SUITE_P(
    OddSizesAnisotropic, LowpassVsReference,
    ::testing::Values(Case{{17, 23, 9}, {0.5, 0.8, 1.3}, 1.0},   // radii 6, 4, 3
                      Case{{17, 23, 9}, {1.0, 1.0, 1.0}, 1.5},   // radius larger than z extent / 2
                      Case{{5, 7, 3}, {0.3, 0.3, 2.0}, 0.9},     // radius far beyond x extent
                      Case{{31, 1, 13}, {1.0, 1.0, 0.7}, 1.2},   // a degenerate axis
                      Case{{64, 33, 19}, {0.5, 0.5, 0.5}, 0.0},  // sigma 0: identity
                      Case{{70, 3, 5}, {1.0, 1.0, 1.0}, 0.6},    // x beyond one work-group
                      Case{{6, 5, 75}, {1.0, 1.0, 0.5}, 1.0}));  // long z axis

TEST(Lowpass, PreservesConstantsAndMean) {
  // Clamp-to-edge with normalised weights: a constant volume stays constant.
  Volume v({19, 11, 7}, {0.7, 1.1, 0.4});
  std::fill(v.data.begin(), v.data.end(), 42.5f);
  const auto got = device_lowpass(v, 2.0);
  for (float f : got) ASSERT_NEAR(f, 42.5f, 1e-4);
}

TEST(Lowpass, WeightsAreNormalisedGaussians) {
  const auto w = gaussian_weights(1.5, 3.0);
  ASSERT_EQ(w.size(), 2u * 5 + 1);
  double sum = 0;
  for (float x : w) sum += x;
  EXPECT_NEAR(sum, 1.0, 1e-6);
  EXPECT_NEAR(w[5 + 1] / w[5], std::exp(-1.0 / (2 * 2.25)), 1e-6);
  EXPECT_EQ(gaussian_weights(0.0, 3.0), std::vector<float>{1.0f});
}

TEST(Lowpass, GuardBandsUntouched) {
  // Input and output live in the middle of larger buffers (sub-buffers); the
  // guard regions around them must keep their sentinel values.
  Runtime& rt = runtime();
  const Dims3 dims{13, 9, 7};
  const Volume v = test::random_volume(dims, {1.0, 0.6, 1.4}, test::seed() + 1, 0.0f, 10.0f);
  const std::size_t n = v.voxels();
  const std::size_t align = std::max<std::size_t>(rt.info().mem_base_addr_align_bits / 8, 4) / sizeof(float);
  const std::size_t guard = ((1024 + align - 1) / align) * align;  // floats, aligned for sub-buffers
  const std::size_t total = guard + ((n + align - 1) / align) * align + guard;
  const float sentinel = -12345.0f;
  std::vector<float> host_in(total, sentinel), host_out(total, sentinel);
  std::copy(v.data.begin(), v.data.end(), host_in.begin() + guard);
  cl::Buffer big_in = test::upload(rt, host_in), big_out = test::upload(rt, host_out);
  cl_buffer_region region{guard * sizeof(float), n * sizeof(float)};
  cl::Buffer in = big_in.createSubBuffer(CL_MEM_READ_WRITE, CL_BUFFER_CREATE_TYPE_REGION, &region);
  cl::Buffer out = big_out.createSubBuffer(CL_MEM_READ_WRITE, CL_BUFFER_CREATE_TYPE_REGION, &region);
  Lowpass f(rt, make_grid(dims, v.spacing), {1.2, 3.0});
  f.apply(in, out);
  const auto result = test::download(rt, big_out, total);
  const auto input_after = test::download(rt, big_in, total);
  for (std::size_t i = 0; i < total; ++i) {
    const bool inside = i >= guard && i < guard + n;
    if (!inside) {
      ASSERT_EQ(result[i], sentinel) << "output guard overwritten at offset " << long(i) - long(guard);
      ASSERT_EQ(input_after[i], sentinel) << "input guard overwritten at offset " << long(i) - long(guard);
    } else {
      ASSERT_EQ(input_after[i], host_in[i]) << "input modified at " << i - guard;
    }
  }
  EXPECT_TRUE(test::all_near(std::vector<float>(result.begin() + guard, result.begin() + guard + n),
                             reference_lowpass(v, 1.2, 3.0), dims, 1e-4, 1e-5));
}

TEST(Lowpass, BitIdenticalAcrossRuns) {
  const Volume v = test::random_volume({37, 21, 15}, {0.5, 0.9, 1.1}, test::seed() + 2, 0.0f, 255.0f);
  const auto a = device_lowpass(v, 1.3);
  const auto b = device_lowpass(v, 1.3);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(float)));
}

TEST(Lowpass, RejectsAliasingAndBadSigma) {
  Runtime& rt = runtime();
  const GridDesc g = make_grid({8, 8, 8}, {1, 1, 1});
  EXPECT_THROW(Lowpass(rt, g, {-1.0, 3.0}), InputError);
  Lowpass f(rt, g, {1.0, 3.0});
  cl::Buffer b = rt.buffer(512 * sizeof(float));
  EXPECT_THROW(f.apply(b, b), std::invalid_argument);
}

// A sigma whose radius exceeds the kernel's limit is refused with the
// numbers (it used to overflow ceil(3 sigma) into a 3-tap filter, or to
// allocate gigabytes of weights first).
TEST(Lowpass, RefusesTooWideASigmaWithTheNumbers) {
  Runtime& rt = runtime();
  const GridDesc g = make_grid({8, 8, 8}, {1e-3, 1, 1});
  for (double sigma : {1.0, 1e8, 1e9, 1e300}) {
    SCOPED_TRACE(sigma);
    try {
      Lowpass(rt, g, {sigma, 3.0});
      ADD_FAILURE() << "accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("voxels along x (spacing 0.001 mm)"), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(Lowpass(rt, g, {0.03, 3.0}));  // 30 voxels along x, radius 90
  EXPECT_THROW(check_lowpass_sigma(std::nan(""), {1, 1, 1}, "--sigma"), InputError);
  EXPECT_THROW(check_lowpass_sigma(HUGE_VAL, {1, 1, 1}, "--sigma"), InputError);
  EXPECT_NO_THROW(check_lowpass_sigma(33.3, {1, 1, 1}, "--sigma"));
  EXPECT_THROW(check_lowpass_sigma(33.4, {1, 1, 1}, "--sigma"), InputError);
}

// Weights of a wide Gaussian (radius 60000: k * k passes INT_MAX) are the
// definition's, and a radius beyond kMaxWeightsRadius is refused.
TEST(Lowpass, WideWeightsAreExactAndHugeOnesRefused) {
  const double sigma = 20000;
  const std::vector<float> w = gaussian_weights(sigma, 3.0);
  ASSERT_EQ(w.size(), 2 * 60000u + 1);
  double sum = 0;
  for (float x : w) sum += x;
  EXPECT_NEAR(sum, 1.0, 1e-4);
  const double centre = w[60000];
  EXPECT_NEAR(w[0] / centre, std::exp(-4.5), 1e-5);      // k = -60000
  EXPECT_NEAR(w[110000] / centre, std::exp(-0.5 * 50000.0 * 50000.0 / (sigma * sigma)), 1e-5);
  EXPECT_THROW(gaussian_weights(1e9, 3.0), std::invalid_argument);
  EXPECT_THROW(gaussian_weights(HUGE_VAL, 3.0), std::invalid_argument);
}

TEST(HostBlur, IsTheClampedSeparableSumPerSample) {
  // blur_3d (auto_iso's v~, the splats' orientation field) sums 32, 16 or
  // fewer outputs at a time in vector registers: against a per-sample
  // reference in the stated order (x, then y, then z; clamp to the edge;
  // float products and sums in tap order), bit for bit, for both fields,
  // rows long enough for every block width and a tail, and a thread count
  // that does not divide the planes.
  std::mt19937 rng(test::seed());
  std::uniform_real_distribution<float> val(-2.0f, 300.0f);
  for (const Dims3 d : {Dims3{61, 23, 9}, Dims3{7, 5, 12}}) {
    const std::size_t n = d[0] * d[1] * d[2];
    std::vector<float> a(n), b(n);
    for (float& x : a) x = val(rng);
    for (float& x : b) x = val(rng);
    const std::vector<float> wx = gaussian_weights(2.2, 3.0), wy = gaussian_weights(1.3, 3.0),
                             wz = gaussian_weights(1.0, 3.0);
    const auto reference = [&](std::vector<float> f) {
      const std::vector<float>* w[3] = {&wx, &wy, &wz};
      const std::size_t stride[3] = {1, d[0], d[0] * d[1]};
      for (int axis = 0; axis < 3; ++axis) {
        std::vector<float> out(n);
        const long r = long(w[axis]->size() / 2), len = long(d[std::size_t(axis)]);
        for (std::size_t i = 0; i < n; ++i) {
          const long at = long((i / stride[axis]) % d[std::size_t(axis)]);
          float s = 0.0f;
          for (long k = 0; k <= 2 * r; ++k) {
            const long q = std::clamp(at + k - r, 0L, len - 1);
            s += (*w[axis])[std::size_t(k)] * f[std::size_t(long(i) + (q - at) * long(stride[axis]))];
          }
          out[i] = s;
        }
        f.swap(out);
      }
      return f;
    };
    const std::vector<float> ra = reference(a), rb = reference(b);
    for (const int threads : {1, 3}) {
      std::vector<float> ga = a, gb = b;
      blur_3d(ga.data(), gb.data(), d, wx, wy, wz, threads, [](std::size_t) {});
      std::size_t differ = 0;
      for (std::size_t i = 0; i < n; ++i) differ += (ga[i] != ra[i]) + (gb[i] != rb[i]);
      EXPECT_EQ(differ, 0u) << d[0] << "x" << d[1] << "x" << d[2] << ", threads " << threads;
    }
  }
}

}  // namespace
}  // namespace softshell
