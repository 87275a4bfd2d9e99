// The float64 CPU oracle of the variational classifier's discrete system
// (docs/numerics.md), written from the energy's definition and independent of
// the kernels: the energy E(u), the matrix A and b assembled by brute force
// from the per-corner gradient blocks J, a direct sparse solve, and the
// densities computed from a volume with the CPU references of lowpass and
// gradient. Tests hold the device code to it.
#pragma once

#include <Eigen/SparseCore>

#include <cstdint>
#include <vector>

#include "variational.hpp"
#include "volume.hpp"

namespace softshell::test {

// E(u) = sum_p V (mu_p u_p^2 - 2 rho_p u_p)
//      + sum_cells (V/8) sum_{corners q} d_q^T T_q d_q   (one-sided d into the cell).
// u has one value per voxel; fixed voxels are taken as given (callers pass 0).
double oracle_energy(const Densities& d, const std::vector<double>& u);

struct OracleSystem {
  Dims3 dims{0, 0, 0};
  Eigen::SparseMatrix<double> A;  // N x N, symmetric; fixed rows/columns are the identity's
  Eigen::VectorXd b;              // V rho, 0 at fixed voxels
  std::vector<std::size_t> free;  // indices of the free voxels, ascending
  std::size_t voxels() const { return std::size_t(b.size()); }
};

// A = V diag(mu) + (V/8) sum_{q, octant} J^T T_q J and b = V rho, then the
// fixed rule. `raw` (optional) receives A before the fixed rule (the Hessian/2
// of E over all voxels).
OracleSystem assemble_oracle(const Densities& d, Eigen::SparseMatrix<double>* raw = nullptr);

// Solves A u = b over the free voxels; fixed voxels get 0. Direct
// (SimplicialLDLT) up to kLdltMaxFree free voxels: its fill makes it slow
// beyond (measured on 2 cores: 1.6 s at 24^3, 23 s at 32^3, 139 s at 40^3);
// above, conjugate gradients with an incomplete-Cholesky preconditioner to a
// relative residual of 1e-13 (15-50 iterations, 0.2 s at 40^3; agrees with
// LDLT to 1e-13, checked by a test). Throws if the result's relative residual
// exceeds 1e-11.
enum class OracleMethod { Auto, Ldlt, Cg };
constexpr std::size_t kLdltMaxFree = 12000;
struct OracleSolveInfo {
  OracleMethod method = OracleMethod::Auto;  // the one used
  double seconds = 0, relative_residual = 0;
  long iterations = 0;  // CG only
};
std::vector<double> oracle_solve(const OracleSystem& s, OracleMethod method = OracleMethod::Auto,
                                 OracleSolveInfo* info = nullptr);

// Random densities that satisfy the spec's assumptions: mu >= gamma_delta > 0,
// rho >= 0, T = beta (|g|^2 I - g g^T) for a random g (per mm, components in
// [-1, 1]); boundary voxels fixed plus ~3 % random interior ones.
Densities random_densities(Dims3 dims, Vec3d spacing, std::uint64_t seed, double beta, double gamma_delta);

// The densities of a normalised volume, computed on the CPU in double from
// reference_lowpass (truncate 3, as the device's Lowpass) and
// reference_gradient: W, c, mu, rho and T exactly as docs/numerics.md defines
// them; fixed = boundary, or mask byte 0 (unscanned) when a mask is given.
// With `sharpen` (docs/numerics.md, "Sharpening"): the sharpening term
// linearised about u0 added, lambda ((1 - a)^2 + ratio a^2 e^2) to mu and
// lambda ratio a^2 e^2 u_ind to rho, a = clamp(u0 / u_ind, 0, 1),
// e = min(1, |grad v| / g_ref).
struct SharpenTerm {
  std::vector<float> u0;
  double lambda = 0, ratio = 1;
};
Densities reference_densities(const Volume& v, const VariationalParams& p,
                              const std::vector<std::uint8_t>* mask = nullptr, const SharpenTerm* sharpen = nullptr);

// Offset (dx, dy, dz) of stencil coefficient k (kernels/stencil.h).
struct StencilOffset {
  int dx, dy, dz;
};
StencilOffset stencil_offset(int k);

}  // namespace softshell::test
