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
 * work-group. Measurements behind these choices: docs/architecture.md.
 */
#include "grid.h"

#ifndef RADIUS
#error "filter.cl needs -D RADIUS=<taps on each side>"
#endif

#define FILTER_PASS(NAME, COORD, EXTENT, STRIDE)                                   \
  __kernel void NAME(__global const float* restrict in,                           \
                     __global float* restrict out,                                 \
                     __constant const float* restrict w, const GridDesc g) {       \
    /* Weights first, unconditionally: loads inside the branch below cannot be    \
       hoisted out of PoCL's work-item loop and cost 2x on CPUs. */               \
    float wk[2 * RADIUS + 1];                                                      \
    _Pragma("unroll")                                                              \
    for (int k = 0; k <= 2 * RADIUS; ++k) wk[k] = w[k];                            \
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
      for (int k = 0; k <= 2 * RADIUS; ++k) acc = fma(wk[k], p[(size_t)k * stride], acc); \
    } else {                                                                       \
      const size_t base = idx - (size_t)c * stride;                                \
      _Pragma("unroll")                                                            \
      for (int k = -RADIUS; k <= RADIUS; ++k) {                                    \
        const int cc = clamp(c + k, 0, n - 1);                                     \
        acc = fma(wk[k + RADIUS], in[base + (size_t)cc * stride], acc);            \
      }                                                                            \
    }                                                                              \
    out[idx] = acc;                                                                \
  }

FILTER_PASS(filter_gauss_x, x, g.nx, 1)
FILTER_PASS(filter_gauss_y, y, g.ny, (size_t)g.nx)
FILTER_PASS(filter_gauss_z, z, g.nz, (size_t)g.nx * (size_t)g.ny)
