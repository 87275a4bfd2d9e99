// Memory a classification needs, known before the volume is read, so a
// volume too large for this machine or its device is refused up front with
// the numbers instead of failing (or PoCL aborting) minutes into the run.
//
// The per-voxel figures are the classifiers' buffers as allocated today
// (host/variational.cpp, host/multigrid.cpp, host/levoy.cpp): 127 bytes per
// voxel for the variational classifier with a mask (118 on the device),
// 37 for Levoy's, checked against the peak resident memory measured at
// 128^3 and 256^3 (docs/benchmarks.md, "Memory": 119.4 and 31 bytes per
// voxel). A solve refined in float64 (--tol below 1e-4) holds 68 bytes per
// voxel more on the host while it refines. Change them with the buffers.
#pragma once

#include <cstdint>
#include <string>

#include "volume.hpp"

namespace softshell {

class Runtime;

struct MemoryNeed {
  std::uint64_t host = 0;            // host memory: the volume, mask and result
  std::uint64_t device = 0;          // device buffers at their peak
  std::uint64_t largest_buffer = 0;  // the largest single device buffer
  double host_per_voxel = 0, device_per_voxel = 0;
};

enum class Classifier { Variational, Levoy };

// What classifying a volume of `dims` needs; `mask`: a scanned-region mask
// is in use (its bytes and the filled copy of the volume); `refine`: the
// solve is refined in float64 (SolverParams::tol below 1e-4).
MemoryNeed classify_memory_need(const Dims3& dims, Classifier method, bool mask, bool refine = false);

// Whether the solver's compact stencil for the smoother (22 bytes per voxel
// more during the solve, DeviceSystem::build_compact) fits beside the rest of
// a classification of `voxels` on this device, under the rule of
// check_classify_memory: where it does not, the solver relaxes on the
// float32 stencil (slower, the same answer) and a volume that fits without
// it is still classified.
struct DeviceInfo;
bool compact_smoother_fits(const DeviceInfo& device, std::size_t voxels);

// Throws InputError (exit 2) naming `path`, the need and the limit, when the
// need does not fit: host memory (75 % of usable_memory_bytes(); on a CPU
// device its buffers are host memory too), the device's global memory, or
// its largest allocation.
void check_classify_memory(const Runtime& rt, const std::string& path, const Dims3& dims, Classifier method,
                           bool mask, bool refine = false);
// The same against a device's description (for tests: any device).
struct DeviceInfo;
void check_classify_memory(const DeviceInfo& device, const std::string& path, const Dims3& dims, Classifier method,
                           bool mask, bool refine = false);

}  // namespace softshell
