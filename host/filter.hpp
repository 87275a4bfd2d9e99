// Separable Gaussian lowpass on the device (kernels/filter.cl).
//
// sigma is in millimetres; along each axis it becomes sigma / spacing voxels,
// so anisotropic volumes are smoothed equally in physical space. The kernel
// radius is ceil(truncate * sigma_voxels) per axis; weights are normalised to
// sum to 1; samples beyond the border repeat the edge sample (clamp-to-edge).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "cl_runtime.hpp"
#include "volume.hpp"

namespace softshell {

// Normalised 1-D Gaussian weights w[0..2r], r = ceil(truncate * sigma_voxels);
// sigma_voxels <= 0 gives the identity {1}. Throws std::invalid_argument
// for a radius above kMaxWeightsRadius (callers refuse such sigmas first).
inline constexpr double kMaxWeightsRadius = 1e6;
std::vector<float> gaussian_weights(double sigma_voxels, double truncate);

// The device lowpass compiles its radius into the kernel and unrolls its tap
// loops: at most 100 voxels, sigma up to 33.3 voxels per axis at the default
// truncate of 3, which covers any lowpass that still leaves a surface to find.
inline constexpr int kMaxLowpassRadius = 100;
// Throws InputError when a lowpass of `sigma_mm` on `spacing` needs a radius
// above kMaxLowpassRadius along some axis (or sigma is negative or not
// finite), e.g. "--sigma 1 mm is 10000 voxels along x (spacing 0.0001 mm)
// ...". `what` names the parameter (an option, "lowpass sigma").
void check_lowpass_sigma(double sigma_mm, const Vec3d& spacing, const std::string& what, double truncate = 3.0);

class Lowpass {
 public:
  struct Params {
    double sigma_mm = 1.0;  // standard deviation in mm (0: identity)
    double truncate = 3.0;  // radius in standard deviations
  };

  // Uploads the three weight tables and allocates one scratch volume.
  Lowpass(Runtime& rt, const GridDesc& grid, const Params& params);

  // out = G_sigma * in. `in` and `out` are distinct buffers of grid voxels
  // floats. Returns the events of the x, y and z passes (enqueued in order).
  std::vector<cl::Event> apply(const cl::Buffer& in, const cl::Buffer& out,
                               const std::vector<cl::Event>* wait = nullptr) const;

  const std::array<int, 3>& radius() const { return radius_; }
  const std::array<double, 3>& sigma_voxels() const { return sigma_vox_; }
  std::size_t memory_bytes() const;  // device memory held (scratch + weights)

 private:
  Runtime& rt_;
  GridDesc grid_;
  Params params_;
  std::array<double, 3> sigma_vox_{};
  std::array<int, 3> radius_{};
  std::array<cl::Buffer, 3> weights_;
  cl::Buffer scratch_;
  mutable std::array<cl::Kernel, 3> kernels_;
};

// Host convenience for the CLI: upload, filter, download. The report gives
// the kernel geometry used and times (seconds) from profiling events.
struct LowpassReport {
  std::array<double, 3> sigma_voxels{};
  std::array<int, 3> radius{};
  double upload = 0, filter = 0, download = 0;
};
Volume lowpass_volume(Runtime& rt, const Volume& in, const Lowpass::Params& params,
                      LowpassReport* report = nullptr);

}  // namespace softshell
