/* Gradient of a scalar volume by finite differences, per unit length (mm).
 *
 * Central differences (f[i+1] - f[i-1]) / 2h inside, one-sided differences
 * (f[1] - f[0]) / h and (f[n-1] - f[n-2]) / h on the first and last sample of
 * each axis, and 0 along an axis with a single sample. Components go to three
 * separate buffers (structure of arrays) so later stencils read them coalesced.
 */
#include "grid.h"

__kernel void gradient_central(__global const float* restrict f, __global float* restrict gx,
                               __global float* restrict gy, __global float* restrict gz,
                               const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t idx = grid_index(g, x, y, z);
  const size_t sy = (size_t)g.nx, sz = (size_t)g.nx * (size_t)g.ny;
  gx[idx] = grid_diff(f, idx, x, g.nx, 1, g.hx);
  gy[idx] = grid_diff(f, idx, y, g.ny, sy, g.hy);
  gz[idx] = grid_diff(f, idx, z, g.nz, sz, g.hz);
}

/* |grad f| from the three component buffers. */
__kernel void gradient_magnitude(__global const float* restrict gx, __global const float* restrict gy,
                                 __global const float* restrict gz, __global float* restrict mag,
                                 const ulong n) {
  const size_t i = get_global_id(0);
  if (i >= n) return;
  const float a = gx[i], b = gy[i], c = gz[i];
  mag[i] = sqrt(a * a + b * b + c * c);
}
