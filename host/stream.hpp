// Bandwidth probes: copy and triad, the yardstick for every memory-bound
// kernel, measured in the same run as what they judge. Stream runs them on an
// OpenCL device (kernels/stream.cl); host_stream() runs them on the host's own
// cores (std::thread, no OpenCL), what the machine can move at all.
#pragma once

#include <cstddef>

#include "cl_runtime.hpp"

namespace softshell {

class Stream {
 public:
  explicit Stream(Runtime& rt);
  cl::Event copy(const cl::Buffer& a, const cl::Buffer& b, std::size_t n) const;  // b = a
  cl::Event triad(const cl::Buffer& a, const cl::Buffer& b, const cl::Buffer& c, float s,
                  std::size_t n) const;  // c = a + s b
 private:
  Runtime& rt_;
  mutable cl::Kernel copy_, triad_;
};

// The host's STREAM: b = a (copy, 8 B per float element) and c = a + s b
// (triad, 12 B), float32 arrays of `elements` each, split in contiguous
// chunks over `threads` threads (0: std::thread::hardware_concurrency()) that
// also first-touch their chunk. One warm-up of each, then `reps` timed
// repeats between barriers; GB/s from the fastest. The results are checked
// (copy exactly, triad at 1 in 97 elements): `ok` false means a wrong result.
struct HostStream {
  std::size_t elements = 0;
  int threads = 0, reps = 0;
  double copy_min_s = 0, copy_median_s = 0, triad_min_s = 0, triad_median_s = 0;
  double copy_gbps = 0, triad_gbps = 0;
  bool ok = false;
};
HostStream host_stream(std::size_t elements, int reps, int threads = 0);

}  // namespace softshell
