/* Grid descriptor shared by the host and the OpenCL kernels.
 *
 * A volume of nx*ny*nz samples, x fastest: index = x + nx*(y + ny*z), with
 * voxel spacing hx, hy, hz in millimetres. Passed to kernels by value; the
 * layout is four 32-bit ints then four 32-bit floats on both sides, so no
 * padding differences can creep in. Host-only helpers sit behind
 * #ifndef __OPENCL_VERSION__.
 */
#ifndef SOFTSHELL_GRID_H
#define SOFTSHELL_GRID_H

#ifdef __OPENCL_VERSION__
typedef int grid_int;
typedef float grid_float;
#else
#include <CL/cl_platform.h>
typedef cl_int grid_int;
typedef cl_float grid_float;
#endif

typedef struct GridDesc {
  grid_int nx, ny, nz, pad_i;
  grid_float hx, hy, hz, pad_f;
} GridDesc;

#ifdef __OPENCL_VERSION__

inline size_t grid_index(const GridDesc g, int x, int y, int z) {
  return (size_t)x + (size_t)g.nx * ((size_t)y + (size_t)g.ny * (size_t)z);
}

inline size_t grid_voxels(const GridDesc g) { return (size_t)g.nx * (size_t)g.ny * (size_t)g.nz; }

inline bool grid_contains(const GridDesc g, int x, int y, int z) {
  return x < g.nx && y < g.ny && z < g.nz;
}

#else  /* host */

#include <array>
#include <cstddef>
#include <stdexcept>

namespace softshell {

inline GridDesc make_grid(const std::array<std::size_t, 3>& dims, const std::array<double, 3>& spacing) {
  for (std::size_t d : dims)
    if (d == 0 || d > 0x7fffffff) throw std::invalid_argument("grid dimension out of range");
  GridDesc g{};
  g.nx = static_cast<grid_int>(dims[0]);
  g.ny = static_cast<grid_int>(dims[1]);
  g.nz = static_cast<grid_int>(dims[2]);
  g.hx = static_cast<grid_float>(spacing[0]);
  g.hy = static_cast<grid_float>(spacing[1]);
  g.hz = static_cast<grid_float>(spacing[2]);
  return g;
}

inline std::size_t grid_voxels(const GridDesc& g) {
  return static_cast<std::size_t>(g.nx) * static_cast<std::size_t>(g.ny) * static_cast<std::size_t>(g.nz);
}

}  // namespace softshell

#endif
#endif /* SOFTSHELL_GRID_H */
