/* Grid transfers of the multigrid solver (docs/numerics.md, "Multigrid").
 *
 * Coarse voxel I sits on fine voxel 2I; n_c = floor(n_f / 2) + 1 per axis.
 * P is trilinear interpolation (1-D weights 1 at j = 2I, 1/2 at 2I +- 1),
 * R = P^T. Densities are restricted by P^T-weighted averages.
 */
#include "grid.h"
#include "stencil.h"

inline float hat_weight(const int d) { return d == 0 ? 1.0f : 0.5f; }

/* The P^T-weighted sums over the fine voxels around 2I = (2X, 2Y, 2Z) that
 * lie in the volume: runs BODY with the fine index j and the weight w for
 * each, in a fixed order, and sums the weights into wsum (declared by the
 * caller). One loop for all the fields a kernel restricts, and the same loop
 * in every kernel, so a field restricted by two kernels gets the same bits. */
#define FOR_EACH_RESTRICTION_TAP(gf, X, Y, Z, wsum, BODY)                                             \
  for (int dz = -1; dz <= 1; ++dz)                                                                     \
    for (int dy = -1; dy <= 1; ++dy)                                                                   \
      for (int dx = -1; dx <= 1; ++dx) {                                                               \
        const int fx = 2 * (X) + dx, fy = 2 * (Y) + dy, fz = 2 * (Z) + dz;                             \
        if (fx < 0 || fy < 0 || fz < 0 || fx >= (gf).nx || fy >= (gf).ny || fz >= (gf).nz) continue;   \
        const float w = hat_weight(abs(dx)) * hat_weight(abs(dy)) * hat_weight(abs(dz));              \
        const size_t j = grid_index((gf), fx, fy, fz);                                                 \
        BODY                                                                                           \
        wsum += w;                                                                                     \
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
  float m = 0.0f, r = 0.0f, xx = 0.0f, yy = 0.0f, zz = 0.0f, xy = 0.0f, xz = 0.0f, yz = 0.0f, wsum = 0.0f;
  FOR_EACH_RESTRICTION_TAP(gf, X, Y, Z, wsum, {
    m += w * mu_f[j];
    r += w * rho_f[j];
    xx += w * txx_f[j];
    yy += w * tyy_f[j];
    zz += w * tzz_f[j];
    xy += w * txy_f[j];
    xz += w * txz_f[j];
    yz += w * tyz_f[j];
  })
  const float inv = 1.0f / wsum;
  mu_c[I] = m * inv;
  rho_c[I] = r * inv;
  txx_c[I] = xx * inv;
  tyy_c[I] = yy * inv;
  tzz_c[I] = zz * inv;
  txy_c[I] = xy * inv;
  txz_c[I] = xz * inv;
  tyz_c[I] = yz * inv;
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
  float m = 0.0f, r = 0.0f, wsum = 0.0f;
  FOR_EACH_RESTRICTION_TAP(gf, X, Y, Z, wsum, {
    m += w * mu_f[j];
    r += w * rho_f[j];
  })
  const float inv = 1.0f / wsum;
  store_point(mu_c, rho_c, coef_c, b_c, fixed_c, dT_c, grid_index(gc, X, Y, Z), gc.hx * gc.hy * gc.hz, m * inv,
              r * inv);
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

/* u_f += P e_c at free fine voxels. Along an axis an even fine coordinate
 * takes its coarse voxel with weight 1, an odd one its two neighbours with
 * 1/2 each; written branch-free (for an even coordinate the second coarse
 * voxel is the first with weight 0) so PoCL vectorises the work-group loop. */
__kernel void mg_prolong_add(__global const float* restrict e_c, __global const uchar* restrict fixed_f,
                             __global float* restrict u_f, const GridDesc gf, const GridDesc gc) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(gf, x, y, z)) return;
  const size_t j = grid_index(gf, x, y, z);
  const int x0 = x >> 1, y0 = y >> 1, z0 = z >> 1;
  const int x1 = x0 + (x & 1), y1 = y0 + (y & 1), z1 = z0 + (z & 1);
  const float wx0 = (x & 1) ? 0.5f : 1.0f, wy0 = (y & 1) ? 0.5f : 1.0f, wz0 = (z & 1) ? 0.5f : 1.0f;
  const float wx1 = (x & 1) ? 0.5f : 0.0f, wy1 = (y & 1) ? 0.5f : 0.0f, wz1 = (z & 1) ? 0.5f : 0.0f;
  const size_t sy = (size_t)gc.nx, sz = (size_t)gc.nx * gc.ny;
  const size_t r00 = (size_t)y0 * sy + (size_t)z0 * sz, r10 = (size_t)y1 * sy + (size_t)z0 * sz;
  const size_t r01 = (size_t)y0 * sy + (size_t)z1 * sz, r11 = (size_t)y1 * sy + (size_t)z1 * sz;
  const float e0 = wy0 * (wx0 * e_c[r00 + x0] + wx1 * e_c[r00 + x1]) + wy1 * (wx0 * e_c[r10 + x0] + wx1 * e_c[r10 + x1]);
  const float e1 = wy0 * (wx0 * e_c[r01 + x0] + wx1 * e_c[r01 + x1]) + wy1 * (wx0 * e_c[r11 + x0] + wx1 * e_c[r11 + x1]);
  const float e = wz0 * e0 + wz1 * e1;
  u_f[j] = fixed_f[j] ? u_f[j] : u_f[j] + e;
}
