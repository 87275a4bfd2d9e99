// Shared test fixtures: the OpenCL runtime chosen from $SOFTSHELL_DEVICE (the
// suite runs on PoCL's CPU device in CI), a printed random seed, and helpers
// to compare device results with CPU references.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "cl_runtime.hpp"
#include "volume.hpp"

namespace softshell::test {

// One runtime per test process, created on first use; prints the device.
Runtime& runtime();

// Seed for random inputs: $SOFTSHELL_TEST_SEED or a fixed default; printed.
std::uint64_t seed();

// A volume of uniform random samples in [lo, hi).
Volume random_volume(Dims3 dims, Vec3d spacing, std::uint64_t seed, float lo = 0.0f, float hi = 1.0f);

// Upload / download helpers.
cl::Buffer upload(Runtime& rt, const std::vector<float>& host);
std::vector<float> download(Runtime& rt, const cl::Buffer& buf, std::size_t n);

// Asserts |got - want| <= abs_tol + rel_tol * |want| everywhere; on failure,
// reports the first failing index as (x, y, z) and the worst error.
::testing::AssertionResult all_near(const std::vector<float>& got, const std::vector<double>& want, Dims3 dims,
                                    double abs_tol, double rel_tol);

}  // namespace softshell::test
