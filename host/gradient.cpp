// Host wrapper of kernels/gradient.cl.
#include "gradient.hpp"

#include <stdexcept>

namespace softshell {

Gradient::Gradient(Runtime& rt, const GridDesc& grid)
    : rt_(rt),
      grid_(grid),
      central_(rt.kernel("gradient.cl", "gradient_central")),
      magnitude_(rt.kernel("gradient.cl", "gradient_magnitude")) {}

cl::Event Gradient::apply(const cl::Buffer& f, const cl::Buffer& gx, const cl::Buffer& gy, const cl::Buffer& gz,
                          const std::vector<cl::Event>* wait) const {
  if (f() == gx() || f() == gy() || f() == gz())
    throw std::invalid_argument("Gradient::apply: input must not alias an output");
  central_.setArg(0, f);
  central_.setArg(1, gx);
  central_.setArg(2, gy);
  central_.setArg(3, gz);
  central_.setArg(4, grid_);
  cl::Event e;
  rt_.queue().enqueueNDRangeKernel(central_, cl::NullRange, rt_.global_3d(grid_), rt_.local_3d(), wait, &e);
  return e;
}

cl::Event Gradient::magnitude(const cl::Buffer& gx, const cl::Buffer& gy, const cl::Buffer& gz,
                              const cl::Buffer& mag, const std::vector<cl::Event>* wait) const {
  const std::size_t n = grid_voxels(grid_);
  magnitude_.setArg(0, gx);
  magnitude_.setArg(1, gy);
  magnitude_.setArg(2, gz);
  magnitude_.setArg(3, mag);
  magnitude_.setArg(4, static_cast<cl_ulong>(n));
  cl::Event e;
  rt_.queue().enqueueNDRangeKernel(magnitude_, cl::NullRange, rt_.global_1d(n), rt_.local_1d(), wait, &e);
  return e;
}

}  // namespace softshell
