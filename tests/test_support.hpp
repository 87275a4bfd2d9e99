// Shared test fixtures: the OpenCL runtime chosen from $SOFTSHELL_DEVICE (the
// suite runs on PoCL's CPU device in CI), a printed random seed, and helpers
// to compare device results with CPU references.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <random>
#include <string>
#include <vector>

#include "cl_runtime.hpp"
#include "error.hpp"
#include "volume.hpp"

namespace softshell::test {

// Runs `fn`, expecting an InputError whose one-line message contains all
// of `parts`.
template <typename Fn>
void expect_input_error(Fn fn, std::initializer_list<std::string> parts) {
  try {
    fn();
    ADD_FAILURE() << "no InputError thrown";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.find('\n'), std::string::npos) << "message is not one line: " << msg;
    for (const std::string& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' not in: " << msg;
  }
}

// One runtime per test process, created on first use; prints the device.
Runtime& runtime();

// Seed for random inputs: $SOFTSHELL_TEST_SEED or a fixed default; printed.
std::uint64_t seed();

// A volume of uniform random samples in [lo, hi).
Volume random_volume(Dims3 dims, Vec3d spacing, std::uint64_t seed, float lo = 0.0f, float hi = 1.0f);

// Speckle-like uint8 samples of a mean given per voxel position in mm,
// mean(x, y, z), on voxels of h mm: each sample is the mean times a uniform
// factor in [lo, hi), one factor per cell of `grain` x `grain` voxels across
// z and one voxel along it (the grain finest along z, the beam, as in
// ultrasound), rounded and clamped to [1, 255].
template <class Mean>
Volume speckled(Dims3 dims, double h, Mean mean, std::uint64_t seed, double lo = 0.6, double hi = 1.4,
                std::size_t grain = 3) {
  Volume v(dims, {h, h, h}, ScalarType::UInt8);
  std::uniform_real_distribution<double> U(lo, hi);
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x) {
        std::mt19937_64 cell(seed ^ (z * 1000003 + (y / grain) * 7919 + (x / grain) * 104729));
        const double m = mean(double(x) * h, double(y) * h, double(z) * h);
        v.at(x, y, z) = float(std::clamp(std::round(m * U(cell)), 1.0, 255.0));
      }
  return v;
}

// A soft spherical shell as a float opacity volume: n^3 voxels of 0.8 mm,
// u = max(0, 1 - |d - 0.3 n| / 1.5) with d the distance in voxels from the
// centre (renderer tests).
Volume shell_volume(int n);

// Directory of the real test data: $SOFTSHELL_SHARED_DATA, else data/ in the
// source tree (data/README.md), else the path baked in at build time
// (../shared/data beside the source tree).
std::string shared_data_dir();
bool in_ci();  // $CI == "true"

// Skips a test locally, or fails it in CI, when a shared data file is absent.
#define REQUIRE_SHARED_FILE(path)                                                          \
  do {                                                                                     \
    if (!std::filesystem::exists(path)) {                                                  \
      if (::softshell::test::in_ci()) FAIL() << "shared data missing in CI: " << (path);  \
      GTEST_SKIP() << "shared data missing: " << (path) << " (set SOFTSHELL_SHARED_DATA)"; \
    }                                                                                      \
  } while (0)

// Upload / download helpers.
cl::Buffer upload(Runtime& rt, const std::vector<float>& host);
std::vector<float> download(Runtime& rt, const cl::Buffer& buf, std::size_t n);

// max |a - b| / max |b| (max |a - b| when b is all 0).
double max_relative_deviation(const std::vector<float>& a, const std::vector<float>& b);
// ||a - b|| / ||b|| (||a - b|| when b is all 0).
double relative_l2(const std::vector<float>& a, const std::vector<float>& b);
// Mean |a - b| and the share of samples with |a - b| > `beyond`.
struct MeanDeviation {
  double mean = 0, share = 0;
};
MeanDeviation mean_deviation(const std::vector<float>& a, const std::vector<float>& b, double beyond);

// Asserts |got - want| <= abs_tol + rel_tol * |want| everywhere; on failure,
// reports the first failing index as (x, y, z) and the worst error.
::testing::AssertionResult all_near(const std::vector<float>& got, const std::vector<double>& want, Dims3 dims,
                                    double abs_tol, double rel_tol);

}  // namespace softshell::test
