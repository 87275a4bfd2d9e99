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

/* Derivative of f per unit length along one axis at the sample idx, whose
 * coordinate on that axis is c of n (stride between neighbours, spacing h):
 * central inside, one-sided on the first and last sample, 0 along an axis of
 * one sample. The one rule for every gradient in the kernels (gradient.cl,
 * the classifier's densities, splats, splat orientation, ray casting, Marching
 * Cubes) and the host references. always_inline, as every helper a kernel
 * calls per work-item: a call left in the work-group loop keeps PoCL from
 * vectorising it (system_densities ran 2.5x, system_grad2 10x slower). */
__attribute__((always_inline)) inline float grid_diff(__global const float* restrict f, const size_t idx,
                                                     const int c, const int n, const size_t stride, const float h) {
  if (n < 2) return 0.0f;
  if (c == 0) return (f[idx + stride] - f[idx]) / h;
  if (c == n - 1) return (f[idx] - f[idx - stride]) / h;
  return (f[idx + stride] - f[idx - stride]) / (2.0f * h);
}

/* grad f at voxel (x, y, z) = idx, per mm, by grid_diff along each axis. */
__attribute__((always_inline)) inline float3 grid_gradient(__global const float* restrict f, const GridDesc g,
                                                           const size_t idx, const int x, const int y, const int z) {
  const size_t sy = (size_t)g.nx, sz = (size_t)g.nx * (size_t)g.ny;
  return (float3)(grid_diff(f, idx, x, g.nx, 1, g.hx), grid_diff(f, idx, y, g.ny, sy, g.hy),
                  grid_diff(f, idx, z, g.nz, sz, g.hz));
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

// grid_diff's rule on the host, in double precision (metrics, references).
inline double grid_diff(const float* f, std::size_t idx, std::size_t c, std::size_t n, std::size_t stride, double h) {
  if (n < 2) return 0.0;
  if (c == 0) return (double(f[idx + stride]) - double(f[idx])) / h;
  if (c + 1 == n) return (double(f[idx]) - double(f[idx - stride])) / h;
  return (double(f[idx + stride]) - double(f[idx - stride])) / (2.0 * h);
}

inline std::size_t grid_voxels(const GridDesc& g) {
  return static_cast<std::size_t>(g.nx) * static_cast<std::size_t>(g.ny) * static_cast<std::size_t>(g.nz);
}

}  // namespace softshell

#endif
#endif /* SOFTSHELL_GRID_H */
