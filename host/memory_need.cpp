// Memory a classification needs (host/memory_need.hpp).
#include "memory_need.hpp"

#include <algorithm>
#include <sstream>

#include "cl_runtime.hpp"
#include "error.hpp"
#include "io.hpp"
#include "stencil.h"
#include "text.hpp"

namespace softshell {
namespace {

// Bytes per fine-level voxel of the variational classifier's device buffers
// at their peak, the end of the hierarchy build: the system (mu, rho, b, dT:
// 4 floats; the tangential tensor T: 6 floats, freed right after; the
// stencil: STENCIL_COEFS floats; the fixed flags: 1 byte), the sources kept
// for re-solving (v, v~, |grad v|^2: 3 floats) and the multigrid's fine-level
// u, rhs, r (3 floats); the coarse levels add at most 1/7 of a level's
// system and buffers (each has 1/8 of the voxels of the one above). In the
// solve T is gone and the conjugate gradients' x, r, z, p, q (5 floats) are
// there: 8 bytes less (the sharpening step linearises at the solution in
// place, MultigridSolver::solution(), so it adds nothing). Measured: 119.4
// bytes per voxel in all between 128^3 and 256^3 (docs/benchmarks.md,
// "Memory").
constexpr double kVariationalSystem = (4 + 6 + STENCIL_COEFS) * 4.0 + 1.0;
constexpr double kVariationalFine = kVariationalSystem + 3 * 4.0 + 3 * 4.0;
// The smoother's compact stencil (9 bfloat16 and a float per voxel,
// DeviceSystem::build_compact) is built at the first solve, where the
// conjugate gradients' 5 floats have replaced T's 6: the solve's buffers then
// exceed the setup's peak by this much. It is optional (the solve runs
// without it, slower): built only where it fits (compact_smoother_fits).
constexpr double kCompactOverPeak = STENCIL_COMPACT_BYTES + 5 * 4.0 - 6 * 4.0;
constexpr double kVariationalCoarse = (kVariationalSystem + 3 * 4.0) / 7.0;
// Levoy: the input, its lowpass and the filter's scratch, three gradient
// components and the opacity, one float each.
constexpr double kLevoyDevice = 7 * 4.0;
// Host: the volume (float) and the result downloaded (float); with a mask,
// its bytes (the unscanned fill works in place).
constexpr double kHostVolume = 4.0;
// Float64 refinement (host/multigrid.cpp, refine): the stencil and b
// downloaded (STENCIL_COEFS + 1 floats), the float32 and float64 solutions,
// the float64 residual and the float32 right-hand side.
constexpr double kRefineHost = (STENCIL_COEFS + 1) * 4.0 + 4.0 + 8.0 + 8.0 + 4.0;

std::string per_voxel(double bytes) {
  std::ostringstream s;
  s.precision(3);
  s << bytes << " B per voxel";
  return s.str();
}

}  // namespace

MemoryNeed classify_memory_need(const Dims3& dims, Classifier method, bool mask, bool refine) {
  const double n = double(dims[0]) * double(dims[1]) * double(dims[2]);
  MemoryNeed m;
  if (method == Classifier::Variational) {
    m.device_per_voxel = kVariationalFine + kVariationalCoarse;
    m.host_per_voxel = 2 * kHostVolume + (mask ? 1.0 : 0.0) + (refine ? kRefineHost : 0.0);
    m.largest_buffer = std::uint64_t(STENCIL_SLICE(std::uint64_t(n))) * STENCIL_COEFS * sizeof(float);
  } else {
    m.device_per_voxel = kLevoyDevice;
    m.host_per_voxel = 2 * kHostVolume + (mask ? 1.0 : 0.0);
    m.largest_buffer = std::uint64_t(n) * sizeof(float);
  }
  m.device = std::uint64_t(n * m.device_per_voxel);
  m.host = std::uint64_t(n * m.host_per_voxel);
  return m;
}

bool compact_smoother_fits(const DeviceInfo& d, std::size_t voxels) {
  const double n = double(voxels);
  const double device = n * (kVariationalFine + kVariationalCoarse + kCompactOverPeak);
  // On a CPU device the buffers are host memory, beside the host's volume and result.
  if (d.type == "CPU") return device + n * 2 * kHostVolume <= 0.75 * double(usable_memory_bytes());
  return device <= double(d.global_mem);
}

void check_classify_memory(const Runtime& rt, const std::string& path, const Dims3& dims, Classifier method,
                           bool mask, bool refine) {
  check_classify_memory(rt.info(), path, dims, method, mask, refine);
}

void check_classify_memory(const DeviceInfo& d, const std::string& path, const Dims3& dims, Classifier method,
                           bool mask, bool refine) {
  const MemoryNeed m = classify_memory_need(dims, method, mask, refine);
  const std::string what = "classifying " + dims_text(dims) + " voxels";
  // PoCL and other CPU devices allocate their buffers in host memory.
  const bool shared = d.type == "CPU";
  const double host_need = double(m.host) + (shared ? double(m.device) : 0.0);
  const double host_have = 0.75 * double(usable_memory_bytes());
  if (host_need > host_have) {
    throw input_error(path, what + " needs about " + human_bytes(host_need) + " of host memory (" +
                                per_voxel(m.host_per_voxel + (shared ? m.device_per_voxel : 0.0)) +
                                "), more than the " + human_bytes(host_have) +
                                " usable here (75 % of the memory, cgroup or ulimit); use a smaller volume");
  }
  if (double(m.device) > double(d.global_mem)) {
    throw input_error(path, what + " needs about " + human_bytes(double(m.device)) + " of device memory (" +
                                per_voxel(m.device_per_voxel) + "), more than the " +
                                human_bytes(double(d.global_mem)) + " of " + d.device_name +
                                "; choose another --device or a smaller volume");
  }
  if (m.largest_buffer > d.max_alloc) {
    throw input_error(path, what + " needs a " + human_bytes(double(m.largest_buffer)) + " buffer, but " +
                                d.device_name + " allows at most " + human_bytes(double(d.max_alloc)) +
                                " per allocation; choose another --device or a smaller volume");
  }
}

}  // namespace softshell
