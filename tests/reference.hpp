// Independent float64 CPU references for the device kernels, shared by the
// kernel tests and the end-to-end CLI tests.
#pragma once

#include <array>
#include <vector>

#include "volume.hpp"

namespace softshell::test {

// Gaussian lowpass of v (sigma in mm, radius ceil(truncate * sigma / h) per
// axis, clamp-to-edge), as the full 3-D tap sum in double.
std::vector<double> reference_lowpass(const Volume& v, double sigma_mm, double truncate);

// d/d(axis) of v at (x, y, z) per mm: central differences inside, one-sided at
// the first and last sample, 0 along an axis of one sample.
double reference_derivative(const Volume& v, long x, long y, long z, int axis);

// All three components of the gradient, per voxel.
std::array<std::vector<double>, 3> reference_gradient(const Volume& v);

}  // namespace softshell::test
