// Helpers shared by the two image pipelines of the phantom (host/phantom.cpp,
// the fixed physics; host/phantom_scan.cpp, physics in physical units).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "cl_runtime.hpp"
#include "phantom.hpp"

namespace softshell::phantom_detail {

constexpr double k_median_band = 3.0;  // voxels from the boundary: fluid sdf > 3, tissue sdf < -3

// splitmix64 finaliser: a 32-bit key per (seed, stream), so the counter-based
// RNG streams (scatterers, texture, noise, ...) are independent and seed-specific.
std::uint32_t stream_key(std::uint64_t seed, std::uint64_t stream);

// Median of a 256-bin histogram (NaN when empty).
double median_of_histogram(const std::array<std::size_t, 256>& hist);

// Voxels per work-item of the lane kernels: 8 on CPUs, 1 on GPUs.
int default_lanes(const Runtime& rt);

// The pose's rotation R = Rz(yaw) Ry(roll) Rx(pitch), row-major, and the
// kernels' pose argument (R, then the shift in design units).
std::array<double, 9> pose_rotation(const PhantomPhysics& p);
cl_float16 pose_argument(const PhantomPhysics& p);

}  // namespace softshell::phantom_detail
