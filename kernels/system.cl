/* The linear system of the variational classifier (docs/numerics.md):
 * per-voxel densities, assembly of the 19-point stencil, operator apply and
 * residual, the smoothers (Gauss-Seidel by 8 point colours or by 2 colours of
 * z-slabs, weighted Jacobi), and a deterministic dot-product reduction.
 *
 * Stencil storage (kernels/stencil.h): coef[k * N + p], k = 0 diagonal,
 * k = 1..9 the face and edge offsets with a positive linear index; A[p][p - off_k] is
 * coef[k * N + (p - off_k)]. Fixed voxels have identity rows and no couplings,
 * and every voxel on the volume boundary is fixed, so interior voxels never
 * look outside the volume.
 *
 * The row helpers and the density helpers are always_inline: left to itself
 * clang keeps stencil_row (or density_mu) a call, and a call in the work-item
 * loop stops PoCL's loop vectoriser (the apply ran scalar at ~1/3 of its
 * vector speed on the CPU device; system_update_point at 14.5 ms instead of
 * 4.5 ms at 105^3, docs/benchmarks.md "Solver kernels one by one").
 */
#include "grid.h"
#include "stencil.h"

__attribute__((always_inline)) inline bool on_boundary(const GridDesc g, int x, int y, int z) {
  return x == 0 || y == 0 || z == 0 || x == g.nx - 1 || y == g.ny - 1 || z == g.nz - 1;
}

/* ------------------------------------------------------------ densities */

/* The pointwise densities, from v, v~ and |grad v|^2 (of the --grad-sigma
 * lowpass): mu = alpha W + gamma c and rho = gamma c u_ind. They are all
 * that depends on v_iso, alpha, gamma, omega, delta, epsilon and u_ind, so
 * a change of those re-targets a system in place (system_update_point). */
/* x^q for x >= 0. Built by default for half-integer q in [0, 8] (the host
 * checks: DeviceSystem picks the program's options): x^n by its binary
 * digits, times sqrt(x) for the half, each factor chosen by a select on the
 * uniform q, so PoCL's work-group loop vectorises the density kernels (a
 * branch per power kept them scalar: the re-targeting kernel took 7.4 ms at
 * 105^3 against 1.8 ms; with exp2(q log2 x), the path for every power other
 * than 1, 2 and 4 before, 30 ms). The products come in the order of the
 * earlier lines for 1, 2, 3.5 and 4, so those give the same bits. Any other
 * q: the program built with -DSHELL_GENERAL_POWERS, exp2(q log2 x). */
__attribute__((always_inline)) inline float shell_power(const float x, const float q) {
#ifdef SHELL_GENERAL_POWERS
  if (q == 1.0f) return x;
  if (q == 2.0f) return x * x;
  if (q == 4.0f) return (x * x) * (x * x);
  return x > 0.0f ? exp2(q * log2(x)) : 0.0f;
#else
  const int q2 = (int)(2.0f * q);
  const float x2 = x * x, x4 = x2 * x2, x8 = x4 * x4;
  float r = (q2 & 2) ? x : 1.0f;
  r = (q2 & 4) ? ((q2 & 2) ? x2 * r : x2) : r;
  r = (q2 & 8) ? ((q2 & 6) ? r * x4 : x4) : r;
  r = (q2 & 16) ? ((q2 & 14) ? r * x8 : x8) : r;
  return (q2 & 1) ? r * sqrt(x) : r;
#endif
}
__attribute__((always_inline)) inline float density_c(const ClassifyCoeffs k, const float grad2) {
  if (k.g_ref > 0.0f) {
    /* The shell functional: the edge strength relative to the data's own
     * strong edges, saturating at 1 (gain and voxel size drop out). */
    const float e = fmin(1.0f, sqrt(grad2) / k.g_ref);
    return k.delta + (1.0f - k.delta) * shell_power(e, k.edge_power);
  }
  return k.delta + (1.0f - k.delta) * sqrt(grad2);
}
__attribute__((always_inline)) inline float density_mu(const ClassifyCoeffs k, const float v, const float vs,
                                                      const float grad2) {
  /* The shell functional's centre moved shell_shift mm toward the bright
   * side: to first order a local isovalue v_iso + shell_shift |grad v|. */
  const float lift = k.shell_h2 > 0.0f ? k.shell_shift * sqrt(grad2) : 0.0f;
  const float dv = v - k.v_iso - lift, dvs = vs - k.v_iso - lift;
  const float eps = k.g_ref > 0.0f ? k.epsilon * k.g_ref * k.g_ref : k.epsilon;
  float W = (k.omega * dv * dv + (1.0f - k.omega) * dvs * dvs) / (grad2 + eps);
  /* The shell functional: W is a squared distance (mm^2) to the isosurface;
   * measured in shell half-widths and raised to a power, its weight rises
   * steeply outside the shell instead of as the distance squared. */
  if (k.shell_h2 > 0.0f) W = fmin(shell_power(W / k.shell_h2, k.profile_power), k.weight_cap);
  return k.alpha * W + k.gamma * density_c(k, grad2);
}
__attribute__((always_inline)) inline float density_rho(const ClassifyCoeffs k, const float grad2) {
  return k.gamma * density_c(k, grad2) * k.u_ind;
}

/* mu, rho, T = beta (|g|^2 I - g g^T) + kappa I with g = grad v~ (kappa: the
 * optional isotropic smoothness term, 0 in the paper's functional); fixed =
 * boundary or unscanned (mask == 0); grad2 = |grad v|^2 with v taken from vg
 * (v itself, or its --grad-sigma lowpass), kept for updates. The gradients
 * are grid_gradient's central differences (gradient.cl's rule), computed here
 * rather than stored: six fewer volumes to write, read and allocate. */
__kernel void system_densities(__global const float* restrict v, __global const float* restrict vs,
                               __global const float* restrict vg, __global const uchar* restrict mask,
                               __global float* restrict mu,
                               __global float* restrict rho, __global float* restrict txx,
                               __global float* restrict tyy, __global float* restrict tzz,
                               __global float* restrict txy, __global float* restrict txz,
                               __global float* restrict tyz, __global uchar* restrict fixed,
                               __global float* restrict grad2_out, const ClassifyCoeffs k, const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t p = grid_index(g, x, y, z);
  const float3 gv = grid_gradient(vg, g, p, x, y, z);
  const float grad2 = gv.x * gv.x + gv.y * gv.y + gv.z * gv.z;
  grad2_out[p] = grad2;
  mu[p] = density_mu(k, v[p], vs[p], grad2);
  rho[p] = density_rho(k, grad2);
  const float3 gs = grid_gradient(vs, g, p, x, y, z);
  /* The shell functional measures grad v~ in units of g_ref: beta is then a
   * squared length (mm^2) times F_ind's scale, whatever the gain. */
  const float gscale = k.g_ref > 0.0f ? 1.0f / k.g_ref : 1.0f;
  const float ax = gs.x * gscale, ay = gs.y * gscale, az = gs.z * gscale;
  const float s2 = ax * ax + ay * ay + az * az;
  txx[p] = k.beta * (s2 - ax * ax) + k.kappa;
  tyy[p] = k.beta * (s2 - ay * ay) + k.kappa;
  tzz[p] = k.beta * (s2 - az * az) + k.kappa;
  txy[p] = -k.beta * ax * ay;
  txz[p] = -k.beta * ax * az;
  tyz[p] = -k.beta * ay * az;
  fixed[p] = (on_boundary(g, x, y, z) || mask[p] == 0) ? 1 : 0;
}

/* |grad v|^2 of v (the --grad-sigma lowpass) on the free voxels, -1 on the
 * fixed ones: the host takes the reference edge gradient g_ref from it before
 * the densities are computed. */
__kernel void system_grad2(__global const float* restrict vg, __global const uchar* restrict mask,
                           __global float* restrict grad2_out, const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t p = grid_index(g, x, y, z);
  if (on_boundary(g, x, y, z) || mask[p] == 0) {
    grad2_out[p] = -1.0f;
    return;
  }
  const float3 gv = grid_gradient(vg, g, p, x, y, z);
  grad2_out[p] = gv.x * gv.x + gv.y * gv.y + gv.z * gv.z;
}

/* New pointwise parameters (k) on an assembled fine level: mu, rho, the
 * diagonal and b of every free voxel; T, the couplings and the fixed rows
 * stay. The same result as densities + assembly with k, bit for bit. */
__kernel void system_update_point(__global const float* restrict v, __global const float* restrict vs,
                                  __global const float* restrict grad2, __global const uchar* restrict fixed,
                                  __global const float* restrict dT, __global float* restrict mu,
                                  __global float* restrict rho, __global float* restrict coef,
                                  __global float* restrict b, const ClassifyCoeffs k, const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t p = grid_index(g, x, y, z);
  store_point(mu, rho, coef, b, fixed, dT, p, g.hx * g.hy * g.hz, density_mu(k, v[p], vs[p], grad2[p]),
              density_rho(k, grad2[p]));
}

/* The pointwise densities plus the sharpening term linearised about the
 * previous solution u0 (docs/numerics.md, "Sharpening"): with a = u0 / u_ind
 * clamped to [0, 1], lambda ((1 - a)^2 u^2 + ratio a^2 (u - u_ind)^2) adds
 * lambda ((1 - a)^2 + ratio a^2) to mu and lambda ratio a^2 u_ind to rho. */
#ifndef SHARPEN_EDGE_POWER
#define SHARPEN_EDGE_POWER 2.0f
#endif
__kernel void system_update_sharpen(__global const float* restrict v, __global const float* restrict vs,
                                    __global const float* restrict grad2, __global const uchar* restrict fixed,
                                    __global const float* restrict dT, __global const float* restrict u0,
                                    __global float* restrict mu, __global float* restrict rho,
                                    __global float* restrict coef, __global float* restrict b, const ClassifyCoeffs k,
                                    const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t p = grid_index(g, x, y, z);
  const float a = clamp(u0[p] / k.u_ind, 0.0f, 1.0f);
  /* The pull toward u_ind only as strong as the edge under it (relative to
   * g_ref): speckle crossings, with weak edges, are not lifted. */
  const float e = k.g_ref > 0.0f ? fmin(1.0f, sqrt(grad2[p]) / k.g_ref) : 1.0f;
  const float lam = k.sharpen_lambda, ra2 = k.sharpen_ratio * a * a * shell_power(e, SHARPEN_EDGE_POWER);
  store_point(mu, rho, coef, b, fixed, dT, p, g.hx * g.hy * g.hz,
              density_mu(k, v[p], vs[p], grad2[p]) + lam * ((1.0f - a) * (1.0f - a) + ra2),
              density_rho(k, grad2[p]) + lam * ra2 * k.u_ind);
}

/* ------------------------------------------------------------- assembly */

/* T component (a, b) of voxel q (T[0..5] = xx, yy, zz, xy, xz, yz). */
__attribute__((always_inline)) inline float tensor_ab(__global const float* txx, __global const float* tyy,
                                                     __global const float* tzz, __global const float* txy,
                                                     __global const float* txz, __global const float* tyz, size_t q,
                                                     int a, int b) {
  if (a == b) return a == 0 ? txx[q] : (a == 1 ? tyy[q] : tzz[q]);
  const int s = a + b; /* 1: xy, 2: xz, 3: yz */
  return s == 1 ? txy[q] : (s == 2 ? txz[q] : tyz[q]);
}

/* Row p of A (docs/numerics.md, "Stencil"), all times V/8, plus V mu on the
 * diagonal. A free voxel is interior and so are its free neighbours, so every
 * cell the sums below visit exists, and the octant sums reduce to closed forms
 * (the cross terms T_ab s_a s_b cancel over the octants):
 *   diagonal    8 sum_a T_aa(p) / h_a^2 + 4 sum_a (T_aa(p - e_a) + T_aa(p + e_a)) / h_a^2
 *               (p's own 8 octants; the 4 octants of each face neighbour that point back at p)
 *   face +e_b   -4 (T_bb(p) + T_bb(p + e_b)) / h_b^2
 *               (the 4 octants of p with s_b = +1 and of p + e_b with s_b = -1)
 *   edge k_a e_a + k_b e_b
 *               -2 k_a k_b (T_ab(p + k_a e_a) + T_ab(p + k_b e_b)) / (h_a h_b)
 *               (the two cells sharing the face diagonal, at its two other corners).
 * Couplings to or from fixed voxels are 0; fixed rows are the identity. */
__kernel void system_assemble(__global const float* restrict mu, __global const float* restrict rho,
                              __global const float* restrict txx, __global const float* restrict tyy,
                              __global const float* restrict tzz, __global const float* restrict txy,
                              __global const float* restrict txz, __global const float* restrict tyz,
                              __global const uchar* restrict fixed, __global float* restrict coef,
                              __global float* restrict b, __global float* restrict dT, const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t N = STENCIL_SLICE(grid_voxels(g));
  const size_t p = grid_index(g, x, y, z);
  const float V = g.hx * g.hy * g.hz;
  if (fixed[p]) {
    coef[p] = 1.0f;
    for (int k = 1; k < STENCIL_COEFS; ++k) coef[k * N + p] = 0.0f;
    b[p] = 0.0f;
    dT[p] = 0.0f;
    return;
  }
  const long sy = g.nx, sz = (long)g.nx * g.ny;
  const float ihx2 = 1.0f / (g.hx * g.hx), ihy2 = 1.0f / (g.hy * g.hy), ihz2 = 1.0f / (g.hz * g.hz);
  const float diag = 8.0f * (txx[p] * ihx2 + tyy[p] * ihy2 + tzz[p] * ihz2) +
                     4.0f * ((txx[p - 1] + txx[p + 1]) * ihx2 + (tyy[p - sy] + tyy[p + sy]) * ihy2 +
                             (tzz[p - sz] + tzz[p + sz]) * ihz2);
  dT[p] = 0.125f * V * diag;
  coef[p] = diagonal_coef(V, mu[p], 0.125f * V * diag);
  b[p] = V * rho[p];
  const float h[3] = {g.hx, g.hy, g.hz};
  const long stride[3] = {1, sy, sz};
#define COUPLING(K, DX, DY, DZ)                                                                            \
  if (K > 0) {                                                                                            \
    const long off = (long)(DX) + (long)(DY) * sy + (long)(DZ) * sz;                                      \
    float value = 0.0f;                                                                                   \
    if (!fixed[p + off]) {                                                                                \
      const int d[3] = {DX, DY, DZ};                                                                      \
      const int nz_axes = (DX != 0) + (DY != 0) + (DZ != 0);                                              \
      if (nz_axes == 1) {                                                                                 \
        const int bax = DX ? 0 : (DY ? 1 : 2);                                                            \
        value = -4.0f * (tensor_ab(txx, tyy, tzz, txy, txz, tyz, p, bax, bax) +                           \
                         tensor_ab(txx, tyy, tzz, txy, txz, tyz, p + off, bax, bax)) / (h[bax] * h[bax]); \
      } else {                                                                                            \
        const int a = DX ? 0 : 1, bb = DZ ? 2 : 1;                                                        \
        value = -2.0f * (float)(d[a] * d[bb]) *                                                           \
                (tensor_ab(txx, tyy, tzz, txy, txz, tyz, p + d[a] * stride[a], a, bb) +                   \
                 tensor_ab(txx, tyy, tzz, txy, txz, tyz, p + d[bb] * stride[bb], a, bb)) /                \
                (h[a] * h[bb]);                                                                           \
      }                                                                                                   \
    }                                                                                                     \
    coef[K * N + p] = 0.125f * V * value;                                                                 \
  }
  STENCIL_OFFSETS(COUPLING)
#undef COUPLING
}

/* ------------------------------------------------------ apply, residual */

/* (A x)_p for an interior voxel p. */
__attribute__((always_inline)) inline float stencil_row(__global const float* restrict coef,
                                                       __global const float* restrict xv, const size_t N, const size_t p,
                                                       const long sy, const long sz) {
  float acc = coef[p] * xv[p];
#define TERM(K, DX, DY, DZ)                                          \
  if (K > 0) {                                                       \
    const long off = (long)(DX) + (long)(DY) * sy + (long)(DZ) * sz; \
    acc = fma(coef[K * N + p], xv[p + off], acc);                    \
    acc = fma(coef[K * N + p - off], xv[p - off], acc);              \
  }
  STENCIL_OFFSETS(TERM)
#undef TERM
  return acc;
}

/* (A x)_p for any voxel: boundary voxels are fixed, their row is the diagonal. */
__attribute__((always_inline)) inline float apply_row(__global const float* restrict coef,
                                                     __global const float* restrict xv, const GridDesc g, const int x,
                                                     const int y, const int z, const size_t p) {
  return on_boundary(g, x, y, z) ? coef[p] * xv[p]
                                 : stencil_row(coef, xv, STENCIL_SLICE(grid_voxels(g)), p, g.nx, (long)g.nx * g.ny);
}

__kernel void system_apply(__global const float* restrict coef, __global const float* restrict xv,
                           __global float* restrict yv, const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t p = grid_index(g, x, y, z);
  yv[p] = apply_row(coef, xv, g, x, y, z, p);
}

__kernel void system_residual(__global const float* restrict coef, __global const float* restrict bv,
                              __global const float* restrict xv, __global float* restrict rv, const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t p = grid_index(g, x, y, z);
  rv[p] = bv[p] - apply_row(coef, xv, g, x, y, z, p);
}

/* ------------------------------------------------------------ smoothers */

/* One Gauss-Seidel update of the voxels of one colour (parity of x, y, z):
 * same-colour voxels differ by even offsets, so no 19-point stencil couples
 * them and the sweep is race-free. Global size: ceil(n / 2) per axis. */
__kernel void relax_gs_colour(__global const float* restrict coef, __global const float* restrict bv,
                              __global float* xv, const int colour, const GridDesc g) {
  const int x = 2 * (int)get_global_id(0) + (colour & 1);
  const int y = 2 * (int)get_global_id(1) + ((colour >> 1) & 1);
  const int z = 2 * (int)get_global_id(2) + ((colour >> 2) & 1);
  if (!grid_contains(g, x, y, z)) return;
  const size_t p = grid_index(g, x, y, z);
  if (on_boundary(g, x, y, z)) {
    xv[p] = bv[p] / coef[p];
    return;
  }
  const size_t N = STENCIL_SLICE(grid_voxels(g));
  const float ax = stencil_row(coef, xv, N, p, g.nx, (long)g.nx * g.ny);
  xv[p] += (bv[p] - ax) / coef[p];
}

/* Slab Gauss-Seidel (the CPU ordering). Two colours of slabs of `slab`
 * consecutive z-planes (colour: the parity of z / slab); slabs of one colour
 * are a slab apart, so no 19-point stencil couples them and a colour is
 * race-free. One work-item relaxes one slab: plane by plane, in each plane the
 * rows in order of y, each x-row in order of x (lexicographic). `reverse` runs
 * all of it backwards (with the colours in reverse order this is exactly the
 * forward sweep backwards, so forward + reverse is a symmetric smoother). A
 * work-item's accesses are then one stream per array, ascending (descending
 * in reverse), which the CPU's prefetchers follow: the earlier order, a
 * plane's even rows and then its odd rows, broke every stream after one row
 * (7 cache lines at 105^3) and ran the sweep 1.3-1.5x slower
 * (docs/benchmarks.md, "Solver kernels one by one"). Every coefficient cache
 * line is used in full, which suits CPUs; on GPUs a work-item per slab is too
 * little parallelism and uncoalesced (relax_gs_colour there).
 * Global size: ceil(nz / (2 slab)).
 *
 * Within a row only the coupling to the previous voxel in walking order sees a
 * value updated in this pass; the rest of each row sum is formed for a chunk
 * of the row at once (a plain loop the compiler vectorises; in reverse it walks
 * the chunk downwards, keeping the stream descending), then the chunk is
 * finished serially: u_p = r_p - l_p u_prev, with r_p = (b_p - the other
 * off-diagonal terms) / A[p][p] and l_p = A[p][prev] / A[p][p]. */
#define GS_ROW_CHUNK 128

/* The sweep on the stencil as assembled (float32). */
#define GS_NAME(f) f
#define GS_COEF_PARAMS __global const float* restrict coef
#define GS_COEF_ARGS coef
#define GS_OFFD(k, q) coef[(k) * N + (q)]
#define GS_DIAG(q) coef[q]
#include "gs_slabs.h"
#undef GS_NAME
#undef GS_COEF_PARAMS
#undef GS_COEF_ARGS
#undef GS_OFFD
#undef GS_DIAG

/* ------------------------------------------- the smoother's compact stencil */

/* The smoother's copy of the stencil (docs/solver.md, "A compact stencil for
 * the smoother"): the nine off-diagonal slices rounded to bfloat16 (the upper
 * 16 bits of a float, to nearest even; 8 significant bits), and per row
 * delta, minus the sum of that row's rounding errors (both directions of each
 * coupling), added to its diagonal so that every row sum, and so A applied to
 * a constant, stays what it was. The sweep reads 26 bytes of coefficients per
 * voxel instead of 40. It serves the conjugate gradients' preconditioner
 * only: the V-cycle there relaxes and takes residuals on this matrix (a
 * symmetric operator of its own), while the conjugate gradients apply the
 * float32 one, so the answer is the float32 system's to the same tolerance.
 * (Storing the float32 couplings as two 16-bit halves instead, the upper one
 * serving as the bfloat16, would have cost no memory, but the float32 kernels
 * reading 19 streams ran 1.3-1.5x slower.) */
__attribute__((always_inline)) inline float bf16_value(const ushort h) { return as_float((uint)h << 16); }

__attribute__((always_inline)) inline ushort bf16_round(const float a) {
  const uint u = as_uint(a);
  if (isnan(a)) return (ushort)((u >> 16) | 0x40u); /* stays a NaN */
  const uint r = (u + 0x7fffu + ((u >> 16) & 1u)) >> 16;
  /* A finite value that rounds past the largest bfloat16: the largest. */
  if ((r & 0x7f80u) == 0x7f80u && !isinf(a)) return (ushort)(((u >> 16) & 0x8000u) | 0x7f7fu);
  return (ushort)r;
}

/* ch[(k - 1) N + p] for k = 1..9 and delta[p], from coef. The rounding errors of
 * row p's couplings stored at its neighbours (p - off) are recomputed there:
 * the same function of the same float, so the two rows of a coupling agree. */
__kernel void system_compact(__global const float* restrict coef, __global ushort* restrict ch,
                             __global float* restrict delta, const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t N = STENCIL_SLICE(grid_voxels(g));
  const size_t p = grid_index(g, x, y, z);
  const long sy = g.nx, sz = (long)g.nx * g.ny;
  const bool inner = !on_boundary(g, x, y, z);
  float d = 0.0f;
#define COMPACT(K, DX, DY, DZ)                                                 \
  if (K > 0) {                                                                 \
    const float a = coef[K * N + p];                                           \
    const ushort h = bf16_round(a);                                            \
    ch[(K - 1) * N + p] = h;                                                   \
    if (inner) {                                                               \
      const long off = (long)(DX) + (long)(DY) * sy + (long)(DZ) * sz;        \
      const float an = coef[K * N + p - off];                                  \
      d += (bf16_value(h) - a) + (bf16_value(bf16_round(an)) - an);           \
    }                                                                          \
  }
  STENCIL_OFFSETS(COMPACT)
#undef COMPACT
  delta[p] = -d;
}

/* The sweep on the compact stencil. */
#define GS_NAME(f) f##_compact
#define GS_COEF_PARAMS                                                       \
  __global const float* restrict coef, __global const float* restrict delta, \
      __global const ushort* restrict ch
#define GS_COEF_ARGS coef, delta, ch
#define GS_OFFD(k, q) bf16_value(ch[((k) - 1) * N + (q)])
#define GS_DIAG(q) (coef[q] + delta[q])
#include "gs_slabs.h"
#undef GS_NAME
#undef GS_COEF_PARAMS
#undef GS_COEF_ARGS
#undef GS_OFFD
#undef GS_DIAG

/* r = rhs - A~ x on the compact stencil (the V-cycle's residual on the fine
 * level, where it relaxes on A~). */
__kernel void system_residual_compact(__global const float* restrict coef, __global const float* restrict delta,
                                      __global const ushort* restrict ch, __global const float* restrict bv,
                                      __global const float* restrict xv, __global float* restrict rv,
                                      const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t p = grid_index(g, x, y, z);
  if (on_boundary(g, x, y, z)) {
    rv[p] = bv[p] - coef[p] * xv[p];
    return;
  }
  const size_t N = STENCIL_SLICE(grid_voxels(g));
  const long sy = g.nx, sz = (long)g.nx * g.ny;
  float acc = (coef[p] + delta[p]) * xv[p];
#define TERM(K, DX, DY, DZ)                                                    \
  if (K > 0) {                                                                 \
    const long off = (long)(DX) + (long)(DY) * sy + (long)(DZ) * sz;           \
    acc = fma(bf16_value(ch[(K - 1) * N + p]), xv[p + off], acc);              \
    acc = fma(bf16_value(ch[(K - 1) * N + p - off]), xv[p - off], acc);        \
  }
  STENCIL_OFFSETS(TERM)
#undef TERM
  rv[p] = bv[p] - acc;
}

/* Weighted Jacobi: x_new = x + w (b - A x) / diag. */
__kernel void relax_jacobi(__global const float* restrict coef, __global const float* restrict bv,
                           __global const float* restrict xv, __global float* restrict xnew, const float w,
                           const GridDesc g) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t p = grid_index(g, x, y, z);
  xnew[p] = xv[p] + w * (bv[p] - apply_row(coef, xv, g, x, y, z, p)) / coef[p];
}

/* u = 0 at fixed voxels (after a warm start from an arbitrary u). */
__kernel void system_zero_fixed(__global const uchar* restrict fixed, __global float* restrict u, const ulong n) {
  const size_t i = get_global_id(0);
  if (i < n && fixed[i]) u[i] = 0.0f;
}

/* y = a x + b y (the vector updates of conjugate gradients). */
__kernel void vec_axpby(const float a, __global const float* restrict xv, const float b, __global float* restrict yv,
                        const ulong n) {
  const size_t i = get_global_id(0);
  if (i < n) yv[i] = a * xv[i] + b * yv[i];
}

/* ------------------------------------------------------------ reduction */

/* Partial sums of x . y per work-group (tree in local memory, fixed order):
 * the host adds the partials in order, so the result is deterministic. */
__kernel void reduce_dot(__global const float* restrict xv, __global const float* restrict yv, const ulong n,
                         __global float* restrict partial, __local float* scratch) {
  const size_t i = get_global_id(0), l = get_local_id(0), ls = get_local_size(0);
  float acc = 0.0f;
  for (size_t j = i; j < n; j += get_global_size(0)) acc = fma(xv[j], yv[j], acc);
  scratch[l] = acc;
  barrier(CLK_LOCAL_MEM_FENCE);
  for (size_t s = ls / 2; s > 0; s >>= 1) {
    if (l < s) scratch[l] += scratch[l + s];
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (l == 0) partial[get_group_id(0)] = scratch[0];
}

/* The same partial sums for CPUs: work-item i sums the contiguous chunk
 * [i c, (i + 1) c) (c a multiple of 8) with 8 lanes of vector loads, lanes
 * added in a fixed order. A work-item walking its own stretch of memory suits
 * a CPU core; the strided kernel above suits a GPU. Deterministic. */
__kernel void reduce_dot_chunks(__global const float* restrict xv, __global const float* restrict yv, const ulong n,
                                const ulong chunk, __global float* restrict partial) {
  const size_t i = get_global_id(0);
  const size_t lo = min((size_t)n, i * (size_t)chunk), hi = min((size_t)n, lo + (size_t)chunk);
  float8 acc8 = (float8)(0.0f);
  size_t j = lo;
  for (; j + 8 <= hi; j += 8) acc8 = fma(vload8(0, xv + j), vload8(0, yv + j), acc8);
  float acc = ((acc8.s0 + acc8.s1) + (acc8.s2 + acc8.s3)) + ((acc8.s4 + acc8.s5) + (acc8.s6 + acc8.s7));
  for (; j < hi; ++j) acc = fma(xv[j], yv[j], acc);
  partial[i] = acc;
}
