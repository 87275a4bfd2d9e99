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
  Runtime::set_args(central_, f, gx, gy, gz, grid_);
  return rt_.enqueue_3d(central_, grid_, wait);
}

cl::Event Gradient::magnitude(const cl::Buffer& gx, const cl::Buffer& gy, const cl::Buffer& gz,
                              const cl::Buffer& mag, const std::vector<cl::Event>* wait) const {
  const std::size_t n = grid_voxels(grid_);
  Runtime::set_args(magnitude_, gx, gy, gz, mag, static_cast<cl_ulong>(n));
  return rt_.enqueue_1d(magnitude_, n, wait);
}

}  // namespace softshell
