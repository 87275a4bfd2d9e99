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

/* A coarse voxel is fixed on the coarse boundary, beyond the fine grid, or
 * where its fine voxel 2I is fixed (both coarsening kernels). */
__attribute__((always_inline)) inline uchar coarse_fixed(__global const uchar* restrict fixed_f, const GridDesc gf,
                                                         const GridDesc gc, const int X, const int Y, const int Z) {
  const bool boundary = X == 0 || Y == 0 || Z == 0 || X == gc.nx - 1 || Y == gc.ny - 1 || Z == gc.nz - 1;
  const bool fine_inside = 2 * X < gf.nx && 2 * Y < gf.ny && 2 * Z < gf.nz;
  return (boundary || !fine_inside || fixed_f[grid_index(gf, 2 * X, 2 * Y, 2 * Z)]) ? 1 : 0;
}

/* Weighted averages of the densities over the fine voxels around 2I; which
 * coarse voxels are fixed: coarse_fixed. */
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
  fixed_c[I] = coarse_fixed(fixed_f, gf, gc, X, Y, Z);
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

/* The same P^T-weighted averages for CPUs: a work-item per coarse x-row
 * (global size ny_c x nz_c, as the *_rows transfers below), the 9 fine rows
 * around it (2Y + dy, 2Z + dz) in the volume summed one after another, each
 * along x with the weights 1/2, 1, 1/2 (taps outside the volume left out).
 * Every fine row is read in memory order instead of PoCL's work-group loop
 * gathering 27 strided taps per coarse voxel for each field (105^3, all the
 * levels after an update: 0.7-1.1 ms against 2.9-3.0; docs/benchmarks.md,
 * "Re-solving: the costs around the iterations"). The terms are added in
 * another order than FOR_EACH_RESTRICTION_TAP's: the same averages up to
 * rounding, and one function for both row kernels, so a field restricted by
 * the two gets the same bits, as the voxel kernels' fields do. */
/* Along x: 1/2 f[2X - 1] + f[2X] + 1/2 f[2X + 1] over the taps inside the
 * fine row (restrict_x_weight: the sum of their weights). */
__attribute__((always_inline)) inline float restrict_x_taps(__global const float* restrict f, const int X,
                                                            const int nfx) {
  float s = 0.0f;
  if (2 * X - 1 >= 0 && 2 * X - 1 < nfx) s += 0.5f * f[2 * X - 1];
  if (2 * X < nfx) s += f[2 * X];
  if (2 * X + 1 < nfx) s += 0.5f * f[2 * X + 1];
  return s;
}

__attribute__((always_inline)) inline float restrict_x_weight(const int X, const int nfx) {
  return (2 * X - 1 >= 0 && 2 * X - 1 < nfx ? 0.5f : 0.0f) + (2 * X < nfx ? 1.0f : 0.0f) +
         (2 * X + 1 < nfx ? 0.5f : 0.0f);
}

__attribute__((always_inline)) inline void restrict_field_row(__global const float* restrict f,
                                                              __global float* restrict out, const GridDesc gf,
                                                              const GridDesc gc, const int Y, const int Z) {
  const size_t row_c = (size_t)gc.nx * ((size_t)Y + (size_t)gc.ny * Z);
  /* Coarse X in [1, x_end) has all three x-taps inside the fine row. */
  const int x_end = min(gc.nx, gf.nx / 2);
  for (int X = 0; X < gc.nx; ++X) out[row_c + X] = 0.0f;
  float wyz = 0.0f;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy) {
      const int fy = 2 * Y + dy, fz = 2 * Z + dz;
      if (fy < 0 || fz < 0 || fy >= gf.ny || fz >= gf.nz) continue;
      const float w = hat_weight(abs(dy)) * hat_weight(abs(dz));
      wyz += w;
      __global const float* r = f + (size_t)gf.nx * ((size_t)fy + (size_t)gf.ny * fz);
      out[row_c] = fma(w, restrict_x_taps(r, 0, gf.nx), out[row_c]);
      for (int X = 1; X < x_end; ++X)
        out[row_c + X] = fma(w, fma(0.5f, r[2 * X - 1] + r[2 * X + 1], r[2 * X]), out[row_c + X]);
      for (int X = max(x_end, 1); X < gc.nx; ++X)
        out[row_c + X] = fma(w, restrict_x_taps(r, X, gf.nx), out[row_c + X]);
    }
  for (int X = 0; X < gc.nx; ++X) out[row_c + X] *= 1.0f / (restrict_x_weight(X, gf.nx) * wyz);
}

/* mg_restrict_densities by rows (the CPU's coarsening). */
__kernel void mg_restrict_densities_rows(__global const float* restrict mu_f, __global const float* restrict rho_f,
                                         __global const float* restrict txx_f, __global const float* restrict tyy_f,
                                         __global const float* restrict tzz_f, __global const float* restrict txy_f,
                                         __global const float* restrict txz_f, __global const float* restrict tyz_f,
                                         __global const uchar* restrict fixed_f, __global float* restrict mu_c,
                                         __global float* restrict rho_c, __global float* restrict txx_c,
                                         __global float* restrict tyy_c, __global float* restrict tzz_c,
                                         __global float* restrict txy_c, __global float* restrict txz_c,
                                         __global float* restrict tyz_c, __global uchar* restrict fixed_c,
                                         const GridDesc gf, const GridDesc gc) {
  const int Y = get_global_id(0), Z = get_global_id(1);
  if (Y >= gc.ny || Z >= gc.nz) return;
  restrict_field_row(mu_f, mu_c, gf, gc, Y, Z);
  restrict_field_row(rho_f, rho_c, gf, gc, Y, Z);
  restrict_field_row(txx_f, txx_c, gf, gc, Y, Z);
  restrict_field_row(tyy_f, tyy_c, gf, gc, Y, Z);
  restrict_field_row(tzz_f, tzz_c, gf, gc, Y, Z);
  restrict_field_row(txy_f, txy_c, gf, gc, Y, Z);
  restrict_field_row(txz_f, txz_c, gf, gc, Y, Z);
  restrict_field_row(tyz_f, tyz_c, gf, gc, Y, Z);
  const size_t row_c = (size_t)gc.nx * ((size_t)Y + (size_t)gc.ny * Z);
  for (int X = 0; X < gc.nx; ++X) fixed_c[row_c + X] = coarse_fixed(fixed_f, gf, gc, X, Y, Z);
}

/* mg_restrict_point by rows. */
__kernel void mg_restrict_point_rows(__global const float* restrict mu_f, __global const float* restrict rho_f,
                                     __global const uchar* restrict fixed_c, __global const float* restrict dT_c,
                                     __global float* restrict mu_c, __global float* restrict rho_c,
                                     __global float* restrict coef_c, __global float* restrict b_c,
                                     const GridDesc gf, const GridDesc gc) {
  const int Y = get_global_id(0), Z = get_global_id(1);
  if (Y >= gc.ny || Z >= gc.nz) return;
  restrict_field_row(mu_f, mu_c, gf, gc, Y, Z);
  restrict_field_row(rho_f, rho_c, gf, gc, Y, Z);
  const size_t row_c = (size_t)gc.nx * ((size_t)Y + (size_t)gc.ny * Z);
  const float V = gc.hx * gc.hy * gc.hz;
  for (int X = 0; X < gc.nx; ++X) {
    const size_t p = row_c + X;
    store_point(mu_c, rho_c, coef_c, b_c, fixed_c, dT_c, p, V, mu_c[p], rho_c[p]);
  }
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

/* The same r_c = P^T r_f for CPUs: a work-item per coarse x-row (global size
 * ny_c x nz_c), summing the 9 fine rows around it (2Y + dy, 2Z + dz) one after
 * another, each along x with the weights 1/2, 1, 1/2. Every fine row is then
 * read in memory order, and each fine voxel once per coarse row that takes it,
 * instead of PoCL's work-group loop gathering 27 strided taps per coarse voxel
 * (105^3 to 53^3: 0.28 ms against 1.28, docs/benchmarks.md). The terms are added
 * in another order than mg_restrict_residual's: the same sums up to rounding. */
__kernel void mg_restrict_residual_rows(__global const float* restrict r_f, __global const uchar* restrict fixed_c,
                                        __global float* restrict r_c, const GridDesc gf, const GridDesc gc) {
  const int Y = get_global_id(0), Z = get_global_id(1);
  if (Y >= gc.ny || Z >= gc.nz) return;
  const size_t row_c = (size_t)gc.nx * ((size_t)Y + (size_t)gc.ny * Z);
  for (int X = 0; X < gc.nx; ++X) r_c[row_c + X] = 0.0f;
  if (Y == 0 || Z == 0 || Y == gc.ny - 1 || Z == gc.nz - 1) return; /* coarse boundary: fixed */
  /* A free coarse voxel is interior, so 2X +- 1, 2Y +- 1 and 2Z +- 1 lie in the fine grid. */
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy) {
      const float w = hat_weight(abs(dy)) * hat_weight(abs(dz));
      __global const float* f = r_f + (size_t)gf.nx * ((size_t)(2 * Y + dy) + (size_t)gf.ny * (2 * Z + dz));
      for (int X = 1; X < gc.nx - 1; ++X)
        r_c[row_c + X] = fma(w, fma(0.5f, f[2 * X - 1] + f[2 * X + 1], f[2 * X]), r_c[row_c + X]);
    }
  for (int X = 1; X < gc.nx - 1; ++X)
    if (fixed_c[row_c + X]) r_c[row_c + X] = 0.0f;
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

/* The same u_f += P e_c for CPUs: a work-item per fine x-row (global size
 * ny_f x nz_f). The coarse rows around it are first interpolated in y and z
 * (weights as above) into c, then along x: an even x takes c[x / 2], an odd
 * one the mean of its two neighbours. Coarse and fine rows are read in memory
 * order instead of gathered per voxel (53^3 to 105^3: 0.97 ms against 2.43).
 * The same values up to rounding (the weights are applied in another order
 * than mg_prolong_add's). */
#define PROLONG_ROW_MAX 256
__kernel void mg_prolong_add_rows(__global const float* restrict e_c, __global const uchar* restrict fixed_f,
                                  __global float* restrict u_f, const GridDesc gf, const GridDesc gc) {
  const int y = get_global_id(0), z = get_global_id(1);
  if (y >= gf.ny || z >= gf.nz) return;
  const int y0 = y >> 1, z0 = z >> 1;
  const int y1 = y0 + (y & 1), z1 = z0 + (z & 1);
  const float wy0 = (y & 1) ? 0.5f : 1.0f, wz0 = (z & 1) ? 0.5f : 1.0f;
  const float wy1 = (y & 1) ? 0.5f : 0.0f, wz1 = (z & 1) ? 0.5f : 0.0f;
  const size_t sy = (size_t)gc.nx, sz = (size_t)gc.nx * gc.ny;
  __global const float* c00 = e_c + (size_t)y0 * sy + (size_t)z0 * sz;
  __global const float* c10 = e_c + (size_t)y1 * sy + (size_t)z0 * sz;
  __global const float* c01 = e_c + (size_t)y0 * sy + (size_t)z1 * sz;
  __global const float* c11 = e_c + (size_t)y1 * sy + (size_t)z1 * sz;
  const size_t row = (size_t)gf.nx * ((size_t)y + (size_t)gf.ny * z);
  const float w00 = wy0 * wz0, w10 = wy1 * wz0, w01 = wy0 * wz1, w11 = wy1 * wz1;
  /* Coarse rows longer than the buffer go in pieces (PROLONG_ROW_MAX coarse voxels each). */
  for (int X0 = 0; X0 < gc.nx; X0 += PROLONG_ROW_MAX - 1) {
    const int n = min(PROLONG_ROW_MAX, gc.nx - X0);
    float c[PROLONG_ROW_MAX];
    for (int i = 0; i < n; ++i) {
      const int X = X0 + i;
      c[i] = fma(w11, c11[X], fma(w01, c01[X], fma(w10, c10[X], w00 * c00[X])));
    }
    /* Fine x from 2 X0: even ones c[i], odd ones (c[i] + c[i + 1]) / 2; the
     * piece's last even x, 2 (X0 + n - 1), is the next piece's first. */
    const int x_end = X0 + n >= gc.nx ? gf.nx : 2 * (X0 + n - 1);
    for (int x = 2 * X0; x < x_end; ++x) {
      const int i = (x >> 1) - X0;
      const float e = (x & 1) ? 0.5f * (c[i] + c[i + 1]) : c[i];
      if (!fixed_f[row + x]) u_f[row + x] += e;
    }
  }
}
