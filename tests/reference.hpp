// Independent float64 CPU references for the device kernels, shared by the
// kernel tests and the end-to-end CLI tests.
#pragma once

#include <vector>

#include "volume.hpp"

namespace softshell::test {

// Gaussian lowpass of v (sigma in mm, radius ceil(truncate * sigma / h) per
// axis, clamp-to-edge), as the full 3-D tap sum in double.
std::vector<double> reference_lowpass(const Volume& v, double sigma_mm, double truncate);

}  // namespace softshell::test
