/* Storage of a symmetric 27-point stencil, shared by host and kernels
 * (docs/numerics.md, "Storage").
 *
 * Per voxel 14 coefficients, structure of arrays (coef[k * N + p]): k = 0 is
 * the diagonal, k = 1..13 the offsets with a positive linear index, x fastest.
 * The entry for the opposite offset lives at the neighbour:
 *   A[p][p - off_k] = coef[k * N + (p - off_k)].
 * STENCIL_OFFSETS(X) expands X(k, dx, dy, dz) for k = 0..13.
 */
#ifndef SOFTSHELL_STENCIL_H
#define SOFTSHELL_STENCIL_H

#define STENCIL_COEFS 14

#define STENCIL_OFFSETS(X)                                                              \
  X(0, 0, 0, 0) X(1, 1, 0, 0) X(2, -1, 1, 0) X(3, 0, 1, 0) X(4, 1, 1, 0)              \
  X(5, -1, -1, 1) X(6, 0, -1, 1) X(7, 1, -1, 1) X(8, -1, 0, 1) X(9, 0, 0, 1)          \
  X(10, 1, 0, 1) X(11, -1, 1, 1) X(12, 0, 1, 1) X(13, 1, 1, 1)

/* Parameters of the functional, as the kernels take them (normalised data). */
typedef struct ClassifyCoeffs {
  float alpha, beta, gamma, omega, delta, epsilon, u_ind, v_iso;
  float kappa, pad0, pad1, pad2; /* kappa: isotropic smoothness (0: the paper's functional) */
} ClassifyCoeffs;

#endif /* SOFTSHELL_STENCIL_H */
