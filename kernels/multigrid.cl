/* Grid transfers of the multigrid solver (docs/numerics.md, "Multigrid").
 *
 * Coarse voxel I sits on fine voxel 2I; n_c = floor(n_f / 2) + 1 per axis.
 * P is trilinear interpolation (1-D weights 1 at j = 2I, 1/2 at 2I +- 1),
 * R = P^T. Densities are restricted by P^T-weighted averages.
 */
#include "grid.h"
#include "stencil.h"

inline float hat_weight(const int d) { return d == 0 ? 1.0f : 0.5f; }

/* The P^T-weighted average of a fine density around fine voxel 2I. */
inline float restricted_average(__global const float* restrict f, const GridDesc gf, const int X, const int Y,
                                const int Z) {
  float acc = 0.0f, wsum = 0.0f;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int x = 2 * X + dx, y = 2 * Y + dy, z = 2 * Z + dz;
        if (x < 0 || y < 0 || z < 0 || x >= gf.nx || y >= gf.ny || z >= gf.nz) continue;
        const float w = hat_weight(abs(dx)) * hat_weight(abs(dy)) * hat_weight(abs(dz));
        acc += w * f[grid_index(gf, x, y, z)];
        wsum += w;
      }
  return acc * (1.0f / wsum);
}

/* Weighted averages of the densities over the fine voxels around 2I; a coarse
 * voxel is fixed on the coarse boundary or where its fine voxel is fixed. */
__kernel void mg_restrict_densities(__global const float* restrict mu_f, __global const float* restrict rho_f,
                                    __global const float* restrict txx_f, __global const float* restrict tyy_f,
                                    __global const float* restrict tzz_f, __global const float* restrict txy_f,
                                    __global const float* restrict txz_f, __global const float* restrict tyz_f,
                                    __global const uchar* restrict fixed_f, __global float* restrict mu_c,
                                    __global float* restrict rho_c, __global float* restrict txx_c,
                                    __global float* restrict tyy_c, __global float* restrict tzz_c,
                                    __global float* restrict txy_c, __global float* restrict txz_c,
                                    __global float* restrict tyz_c, __global uchar* restrict fixed_c,
                                    const GridDesc gf, const GridDesc gc) {
  const int X = get_global_id(0), Y = get_global_id(1), Z = get_global_id(2);
  if (!grid_contains(gc, X, Y, Z)) return;
  const size_t I = grid_index(gc, X, Y, Z);
  mu_c[I] = restricted_average(mu_f, gf, X, Y, Z);
  rho_c[I] = restricted_average(rho_f, gf, X, Y, Z);
  txx_c[I] = restricted_average(txx_f, gf, X, Y, Z);
  tyy_c[I] = restricted_average(tyy_f, gf, X, Y, Z);
  tzz_c[I] = restricted_average(tzz_f, gf, X, Y, Z);
  txy_c[I] = restricted_average(txy_f, gf, X, Y, Z);
  txz_c[I] = restricted_average(txz_f, gf, X, Y, Z);
  tyz_c[I] = restricted_average(tyz_f, gf, X, Y, Z);
  const bool boundary = X == 0 || Y == 0 || Z == 0 || X == gc.nx - 1 || Y == gc.ny - 1 || Z == gc.nz - 1;
  const bool fine_inside = 2 * X < gf.nx && 2 * Y < gf.ny && 2 * Z < gf.nz;
  fixed_c[I] = (boundary || !fine_inside || fixed_f[grid_index(gf, 2 * X, 2 * Y, 2 * Z)]) ? 1 : 0;
}

/* After a pointwise update of the finer level (system_update_point): the
 * coarse mu and rho re-restricted, and the diagonal and b of every free
 * coarse voxel, as mg_restrict_densities + system_assemble would give them. */
__kernel void mg_restrict_point(__global const float* restrict mu_f, __global const float* restrict rho_f,
                                __global const uchar* restrict fixed_c, __global const float* restrict dT_c,
                                __global float* restrict mu_c, __global float* restrict rho_c,
                                __global float* restrict coef_c, __global float* restrict b_c, const GridDesc gf,
                                const GridDesc gc) {
  const int X = get_global_id(0), Y = get_global_id(1), Z = get_global_id(2);
  if (!grid_contains(gc, X, Y, Z)) return;
  store_point(mu_c, rho_c, coef_c, b_c, fixed_c, dT_c, grid_index(gc, X, Y, Z), gc.hx * gc.hy * gc.hz,
              restricted_average(mu_f, gf, X, Y, Z), restricted_average(rho_f, gf, X, Y, Z));
}

/* r_c = P^T r_f (zero at fixed coarse voxels). */
__kernel void mg_restrict_residual(__global const float* restrict r_f, __global const uchar* restrict fixed_c,
                                   __global float* restrict r_c, const GridDesc gf, const GridDesc gc) {
  const int X = get_global_id(0), Y = get_global_id(1), Z = get_global_id(2);
  if (!grid_contains(gc, X, Y, Z)) return;
  const size_t I = grid_index(gc, X, Y, Z);
  if (fixed_c[I]) {
    r_c[I] = 0.0f;
    return;
  }
  /* A free coarse voxel is interior, so 2I +- 1 lies inside the fine grid. */
  float acc = 0.0f;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const float w = hat_weight(abs(dx)) * hat_weight(abs(dy)) * hat_weight(abs(dz));
        acc = fma(w, r_f[grid_index(gf, 2 * X + dx, 2 * Y + dy, 2 * Z + dz)], acc);
      }
  r_c[I] = acc;
}

/* u_f += P e_c at free fine voxels. */
__kernel void mg_prolong_add(__global const float* restrict e_c, __global const uchar* restrict fixed_f,
                             __global float* restrict u_f, const GridDesc gf, const GridDesc gc) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(gf, x, y, z)) return;
  const size_t j = grid_index(gf, x, y, z);
  if (fixed_f[j]) return;
  const int x0 = x >> 1, y0 = y >> 1, z0 = z >> 1;
  const int x1 = x0 + (x & 1), y1 = y0 + (y & 1), z1 = z0 + (z & 1);
  const float wx = (x & 1) ? 0.5f : 1.0f, wy = (y & 1) ? 0.5f : 1.0f, wz = (z & 1) ? 0.5f : 1.0f;
  /* Along an axis: an even fine coordinate takes its coarse voxel with weight
   * 1, an odd one the two neighbours with 1/2 each. */
  float e = 0.0f;
  for (int c = 0; c < 8; ++c) {
    const int cx = (c & 1) ? x1 : x0, cy = (c & 2) ? y1 : y0, cz = (c & 4) ? z1 : z0;
    if (((c & 1) && !(x & 1)) || ((c & 2) && !(y & 1)) || ((c & 4) && !(z & 1))) continue;
    e = fma(wx * wy * wz, e_c[grid_index(gc, cx, cy, cz)], e);
  }
  u_f[j] += e;
}
