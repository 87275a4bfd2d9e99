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
  const float3 d = grid_gradient(f, g, idx, x, y, z);
  gx[idx] = d.x;
  gy[idx] = d.y;
  gz[idx] = d.z;
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
