/* Storage of the classifier's symmetric 19-point stencil, shared by host and
 * kernels (docs/numerics.md, "Storage").
 *
 * The operator couples a voxel to its 6 face and 12 edge neighbours only
 * (never to the 8 corners of its 3x3x3 neighbourhood), on every multigrid
 * level. Per voxel 10 coefficients, structure of arrays (coef[k * S + p],
 * S = STENCIL_SLICE(N) for a level of N voxels): k = 0 is the diagonal,
 * k = 1..9 the face and edge offsets with a positive linear index, in
 * increasing order (x fastest). The entry for the opposite offset lives at
 * the neighbour:
 *   A[p][p - off_k] = coef[k * S + (p - off_k)].
 * STENCIL_OFFSETS(X) expands X(k, dx, dy, dz) for k = 0..9.
 */
#ifndef SOFTSHELL_STENCIL_H
#define SOFTSHELL_STENCIL_H

#define STENCIL_COEFS 10

/* Floats from one coefficient slice to the next: N rounded up to 4 KiB, plus
 * 7 cache lines. A sweep walks all ten slices (and b and u) at the same voxel
 * at once; with a slice stride of N floats, and N a multiple of 1024 (every
 * power-of-two grid from 16^3 up), all of them share their offset within a
 * 4 KiB page, so they fall into one set of the CPU's L1 (whose set index lies
 * within the page offset) and evict one another: the sweep at 128^3 ran
 * 10-20 % slower per voxel than at 129^3. With the 7-line shift the ten slices
 * land on ten different sets (docs/benchmarks.md, "Solver kernels one by
 * one"). The host's downloads return the slices packed (k * N + p). */
#define STENCIL_SLICE(n) (((n) + 1023) / 1024 * 1024 + 112)

/* Bytes per voxel of the smoother's compact copy of the stencil (kernels/
 * system.cl, system_compact): the nine couplings in bfloat16 and the
 * diagonal's correction, a float. */
#define STENCIL_COMPACT_BYTES ((STENCIL_COEFS - 1) * 2 + 4)

#define STENCIL_OFFSETS(X)                                                    \
  X(0, 0, 0, 0) X(1, 1, 0, 0) X(2, -1, 1, 0) X(3, 0, 1, 0) X(4, 1, 1, 0)    \
  X(5, 0, -1, 1) X(6, -1, 0, 1) X(7, 0, 0, 1) X(8, 1, 0, 1) X(9, 0, 1, 1)

/* Parameters of the functional, as the kernels take them (normalised data). */
typedef struct ClassifyCoeffs {
  float alpha, beta, gamma, omega, delta, epsilon, u_ind, v_iso;
  float kappa; /* isotropic smoothness (0: the paper's functional) */
  /* The shell terms (docs/numerics.md, "The shell functional"; all 0 in the
   * paper's functional): shell_h2, the squared half-width (mm^2) of the shell
   * F_iso's weight is measured in; profile_power, the power of that
   * normalised squared distance; g_ref (per mm), the data's reference edge
   * gradient: F_ind's edge weight min(1, |grad v| / g_ref)^edge_power, and
   * T and epsilon in units of g_ref^2; weight_cap bounds the shell weight
   * (far outside the shell u is 0 either way, and a bounded coefficient
   * contrast keeps multigrid fast). */
  float shell_h2, profile_power, g_ref, edge_power, weight_cap;
  /* The sharpening term (docs/numerics.md, "Sharpening"), linearised about
   * a previous u: sharpen_lambda (0: off) and sharpen_ratio, the weight of
   * the pull toward u_ind against the pull toward 0. */
  float sharpen_lambda, sharpen_ratio;
  /* The shell's centre moved this far (mm) from the isosurface toward its
   * bright side (docs/numerics.md, "The shell on the echo"; 0: on it). */
  float shell_shift;
} ClassifyCoeffs;

#ifdef __OPENCL_VERSION__
/* The diagonal of a free voxel's row: its mass V mu plus the tangential part
 * dT (0.125 V times the sum of its octant terms, stored per voxel by the
 * assembly). One function for the assembly and for the in-place updates
 * (system_update_point, mg_restrict_point), so they give the same bits. */
inline float diagonal_coef(const float V, const float mu, const float dT) { return V * mu + dT; }

/* Stores new pointwise densities m, r of voxel p and, when it is free, its
 * diagonal and right-hand side (V: the level's voxel volume). */
__attribute__((always_inline)) inline void store_point(__global float* mu, __global float* rho,
                                                       __global float* coef, __global float* b,
                                                       __global const uchar* fixed, __global const float* dT,
                                                       const size_t p, const float V, const float m, const float r) {
  mu[p] = m;
  rho[p] = r;
  if (fixed[p]) return;
  coef[p] = diagonal_coef(V, m, dT[p]);
  b[p] = V * r;
}
#endif

#endif /* SOFTSHELL_STENCIL_H */
