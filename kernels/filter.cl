/* Separable Gaussian lowpass: one 1-D pass per axis, clamp-to-edge boundary.
 *
 * The host computes normalised weights w[0..2r] for the axis (sigma in mm
 * divided by that axis' spacing) and runs filter_gauss_x, _y, _z in turn. Each
 * pass has its own kernel so the stride is a compile-time constant, and the
 * radius is a build option (-D RADIUS=r) so the tap loop unrolls. Work-items
 * map to voxels with x fastest, so neighbouring work-items read neighbouring
 * addresses on every axis (coalesced on GPUs, vectorised across work-items by
 * PoCL on CPUs). Samples whose taps all lie inside the volume take a branch
 * without clamps; for the y and z passes that branch is uniform across a
 * work-group, so it costs nothing on either kind of device.
 */
#include "grid.h"

#ifndef RADIUS
#error "filter.cl needs -D RADIUS=<taps on each side>"
#endif

#define FILTER_PASS(NAME, COORD, EXTENT, STRIDE)                                   \
  __kernel void NAME(__global const float* restrict in,                           \
                     __global float* restrict out,                                 \
                     __constant const float* restrict w, const GridDesc g) {       \
    const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);  \
    if (!grid_contains(g, x, y, z)) return;                                        \
    const size_t idx = grid_index(g, x, y, z);                                     \
    const int c = COORD;                                                           \
    const int n = EXTENT;                                                          \
    const size_t stride = STRIDE;                                                  \
    float acc = 0.0f;                                                              \
    if (c >= RADIUS && c + RADIUS < n) {                                           \
      __global const float* p = in + idx - (size_t)RADIUS * stride;               \
      _Pragma("unroll")                                                            \
      for (int k = 0; k <= 2 * RADIUS; ++k) acc = fma(w[k], p[(size_t)k * stride], acc); \
    } else {                                                                       \
      const size_t base = idx - (size_t)c * stride;                                \
      for (int k = -RADIUS; k <= RADIUS; ++k) {                                    \
        const int cc = clamp(c + k, 0, n - 1);                                     \
        acc = fma(w[k + RADIUS], in[base + (size_t)cc * stride], acc);             \
      }                                                                            \
    }                                                                              \
    out[idx] = acc;                                                                \
  }

FILTER_PASS(filter_gauss_x, x, g.nx, 1)
FILTER_PASS(filter_gauss_y, y, g.ny, (size_t)g.nx)
FILTER_PASS(filter_gauss_z_direct, z, g.nz, (size_t)g.nx * (size_t)g.ny)

/* z pass as a sliding window: work-item (x, y, chunk) walks z through
 * [chunk * ZCHUNK, (chunk + 1) * ZCHUNK), keeping the 2R+1 samples under the
 * kernel in registers, so every input sample is read once per chunk instead
 * of 2R+1 times from planes a whole slice apart. */
#ifndef ZCHUNK
#define ZCHUNK 32
#endif
__kernel void filter_gauss_z(__global const float* restrict in, __global float* restrict out,
                             __constant const float* restrict w, const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1);
  const int z0 = get_global_id(2) * ZCHUNK;
  if (x >= g.nx || y >= g.ny || z0 >= g.nz) return;
  const int z1 = min(z0 + ZCHUNK, g.nz);
  const size_t plane = (size_t)g.nx * (size_t)g.ny;
  __global const float* col = in + (size_t)x + (size_t)g.nx * (size_t)y;
  __global float* dst = out + (size_t)x + (size_t)g.nx * (size_t)y;
  float win[2 * RADIUS + 1];
  _Pragma("unroll")
  for (int k = 0; k < 2 * RADIUS; ++k) win[k + 1] = col[(size_t)clamp(z0 - RADIUS + k, 0, g.nz - 1) * plane];
  for (int z = z0; z < z1; ++z) {
    _Pragma("unroll")
    for (int k = 0; k < 2 * RADIUS; ++k) win[k] = win[k + 1];
    win[2 * RADIUS] = col[(size_t)min(z + RADIUS, g.nz - 1) * plane];
    float acc = 0.0f;
    _Pragma("unroll")
    for (int k = 0; k <= 2 * RADIUS; ++k) acc = fma(w[k], win[k], acc);
    dst[(size_t)z * plane] = acc;
  }
}
