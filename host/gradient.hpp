// Finite-difference gradients on the device (kernels/gradient.cl): central
// differences inside, one-sided at the border, per millimetre.
#pragma once

#include <vector>

#include "cl_runtime.hpp"

namespace softshell {

class Gradient {
 public:
  Gradient(Runtime& rt, const GridDesc& grid);

  // (gx, gy, gz) = grad f; all buffers hold grid voxels floats, f distinct
  // from the outputs.
  cl::Event apply(const cl::Buffer& f, const cl::Buffer& gx, const cl::Buffer& gy, const cl::Buffer& gz,
                  const std::vector<cl::Event>* wait = nullptr) const;
  // mag = |(gx, gy, gz)|.
  cl::Event magnitude(const cl::Buffer& gx, const cl::Buffer& gy, const cl::Buffer& gz, const cl::Buffer& mag,
                      const std::vector<cl::Event>* wait = nullptr) const;

 private:
  Runtime& rt_;
  GridDesc grid_;
  mutable cl::Kernel central_, magnitude_;
};

}  // namespace softshell
