// Bandwidth probes (kernels/stream.cl): copy and triad, the yardstick for
// every memory-bound kernel, measured in the same run as what it judges.
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

}  // namespace softshell
