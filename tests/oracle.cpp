// The float64 CPU oracle of the discrete system (see oracle.hpp). Everything
// here follows docs/numerics.md's definitions directly: no stencil formulas,
// no shortcuts shared with the kernels.
#include "oracle.hpp"

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

#include "reference.hpp"

namespace softshell::test {
namespace {

// T_q as a symmetric 3x3 matrix from the stored (xx, yy, zz, xy, xz, yz).
std::array<std::array<double, 3>, 3> tensor(const Densities& d, std::size_t q) {
  const double xx = d.T[0][q], yy = d.T[1][q], zz = d.T[2][q], xy = d.T[3][q], xz = d.T[4][q], yz = d.T[5][q];
  return {{{xx, xy, xz}, {xy, yy, yz}, {xz, yz, zz}}};
}

// One row of J: d_a = s_a (u(q + s_a e_a) - u(q)) / h_a, two nonzeros.
struct JRow {
  std::size_t i[2];
  double c[2];
};

// Calls f(q, J) for every voxel q and each of its octants s whose cell lies
// inside the volume (the 8 corners of every cell, each once).
template <class F>
void for_each_corner(const Densities& d, F&& f) {
  const long n[3] = {long(d.dims[0]), long(d.dims[1]), long(d.dims[2])};
  auto index = [&](long x, long y, long z) { return std::size_t(x + n[0] * (y + n[1] * z)); };
  for (long z = 0; z < n[2]; ++z)
    for (long y = 0; y < n[1]; ++y)
      for (long x = 0; x < n[0]; ++x)
        for (int o = 0; o < 8; ++o) {
          const long s[3] = {(o & 1) ? 1 : -1, (o & 2) ? 1 : -1, (o & 4) ? 1 : -1};
          const long p[3] = {x, y, z};
          bool inside = true;
          for (int a = 0; a < 3; ++a) inside = inside && p[a] + s[a] >= 0 && p[a] + s[a] < n[a];
          if (!inside) continue;
          const std::size_t q = index(x, y, z);
          std::array<JRow, 3> J;
          for (int a = 0; a < 3; ++a) {
            long r[3] = {x, y, z};
            r[a] += s[a];
            const double w = double(s[a]) / d.spacing[a];
            J[a] = JRow{{q, index(r[0], r[1], r[2])}, {-w, w}};
          }
          f(q, J);
        }
}

void check(const Densities& d) {
  const std::size_t n = d.voxels();
  bool ok = n > 0 && d.mu.size() == n && d.rho.size() == n && d.fixed.size() == n;
  for (const auto& t : d.T) ok = ok && t.size() == n;
  if (!ok) throw std::invalid_argument("oracle: densities of inconsistent size");
}

}  // namespace

double oracle_energy(const Densities& d, const std::vector<double>& u) {
  check(d);
  if (u.size() != d.voxels()) throw std::invalid_argument("oracle_energy: u has the wrong size");
  const double V = d.spacing[0] * d.spacing[1] * d.spacing[2];
  double mass = 0, tan = 0;
  for (std::size_t p = 0; p < u.size(); ++p) mass += V * (double(d.mu[p]) * u[p] * u[p] - 2.0 * double(d.rho[p]) * u[p]);
  for_each_corner(d, [&](std::size_t q, const std::array<JRow, 3>& J) {
    double g[3];
    for (int a = 0; a < 3; ++a) g[a] = J[a].c[0] * u[J[a].i[0]] + J[a].c[1] * u[J[a].i[1]];
    const auto T = tensor(d, q);
    double e = 0;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) e += g[a] * T[a][b] * g[b];
    tan += V / 8.0 * e;
  });
  return mass + tan;
}

OracleSystem assemble_oracle(const Densities& d, Eigen::SparseMatrix<double>* raw) {
  check(d);
  const std::size_t n = d.voxels();
  const double V = d.spacing[0] * d.spacing[1] * d.spacing[2];
  Eigen::SparseMatrix<double> A(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  A.reserve(Eigen::VectorXi::Constant(long(n), 27));
  for (std::size_t p = 0; p < n; ++p) A.coeffRef(long(p), long(p)) += V * double(d.mu[p]);
  // (V/8) J^T T_q J, entry by entry.
  for_each_corner(d, [&](std::size_t q, const std::array<JRow, 3>& J) {
    const auto T = tensor(d, q);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        for (int i = 0; i < 2; ++i)
          for (int j = 0; j < 2; ++j)
            A.coeffRef(long(J[a].i[i]), long(J[b].i[j])) += V / 8.0 * T[a][b] * J[a].c[i] * J[b].c[j];
  });
  A.makeCompressed();
  if (raw) *raw = A;

  OracleSystem s;
  s.dims = d.dims;
  s.b.resize(long(n));
  for (std::size_t p = 0; p < n; ++p) {
    s.b[long(p)] = d.fixed[p] ? 0.0 : V * double(d.rho[p]);
    if (!d.fixed[p]) s.free.push_back(p);
  }
  // Fixed rule: rows and columns of fixed voxels become the identity's.
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(std::size_t(A.nonZeros()));
  for (long c = 0; c < A.outerSize(); ++c)
    for (Eigen::SparseMatrix<double>::InnerIterator it(A, c); it; ++it)
      if (!d.fixed[std::size_t(it.row())] && !d.fixed[std::size_t(it.col())]) t.emplace_back(it.row(), it.col(), it.value());
  for (std::size_t p = 0; p < n; ++p)
    if (d.fixed[p]) t.emplace_back(long(p), long(p), 1.0);
  s.A.resize(long(n), long(n));
  s.A.setFromTriplets(t.begin(), t.end());
  return s;
}

std::vector<double> oracle_solve(const OracleSystem& s, OracleMethod method, OracleSolveInfo* info) {
  using SpMat = Eigen::SparseMatrix<double>;
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t n = s.voxels(), m = s.free.size();
  std::vector<long> compact(n, -1);
  for (std::size_t k = 0; k < m; ++k) compact[s.free[k]] = long(k);
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(std::size_t(s.A.nonZeros()));
  for (long c = 0; c < s.A.outerSize(); ++c)
    for (SpMat::InnerIterator it(s.A, c); it; ++it) {
      const long i = compact[std::size_t(it.row())], j = compact[std::size_t(it.col())];
      if (i >= 0 && j >= 0) t.emplace_back(i, j, it.value());
    }
  const auto mi = static_cast<Eigen::Index>(m);
  SpMat Af(mi, mi);
  Af.setFromTriplets(t.begin(), t.end());
  Eigen::VectorXd bf(mi);
  for (std::size_t k = 0; k < m; ++k) bf[long(k)] = s.b[long(s.free[k])];

  if (method == OracleMethod::Auto) method = m <= kLdltMaxFree ? OracleMethod::Ldlt : OracleMethod::Cg;
  Eigen::VectorXd uf;
  long iterations = 0;
  if (method == OracleMethod::Ldlt) {
    Eigen::SimplicialLDLT<SpMat> ldlt(Af);
    if (ldlt.info() != Eigen::Success) throw std::runtime_error("oracle_solve: LDLT factorisation failed (not SPD?)");
    uf = ldlt.solve(bf);
    if (ldlt.info() != Eigen::Success) throw std::runtime_error("oracle_solve: LDLT solve failed");
  } else {
    Eigen::ConjugateGradient<SpMat, Eigen::Lower | Eigen::Upper, Eigen::IncompleteCholesky<double>> cg;
    cg.setTolerance(1e-13);
    cg.setMaxIterations(20000);
    cg.compute(Af);
    if (cg.info() != Eigen::Success) throw std::runtime_error("oracle_solve: incomplete Cholesky failed");
    uf = cg.solve(bf);
    iterations = long(cg.iterations());
  }
  const double bnorm = bf.norm();
  const double rel = bnorm > 0 ? (bf - Af * uf).norm() / bnorm : (Af * uf).norm();
  if (!(rel <= 1e-11)) throw std::runtime_error("oracle_solve: relative residual " + std::to_string(rel));

  std::vector<double> u(n, 0.0);
  for (std::size_t k = 0; k < m; ++k) u[s.free[k]] = uf[long(k)];
  if (info) {
    info->method = method;
    info->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    info->relative_residual = rel;
    info->iterations = iterations;
  }
  return u;
}

Densities random_densities(Dims3 dims, Vec3d spacing, std::uint64_t seed, double beta, double gamma_delta) {
  Densities d;
  d.dims = dims;
  d.spacing = spacing;
  const std::size_t n = d.voxels();
  d.mu.resize(n);
  d.rho.resize(n);
  for (auto& t : d.T) t.resize(n);
  d.fixed.assign(n, 0);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0), S(-1.0, 1.0);
  for (std::size_t z = 0, p = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x, ++p) {
        const double w = U(rng);
        d.mu[p] = float(gamma_delta + 2.0 * w * w);
        d.rho[p] = float(U(rng) * d.mu[p]);
        const double g[3] = {S(rng), S(rng), S(rng)};
        const double g2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
        d.T[0][p] = float(beta * (g2 - g[0] * g[0]));
        d.T[1][p] = float(beta * (g2 - g[1] * g[1]));
        d.T[2][p] = float(beta * (g2 - g[2] * g[2]));
        d.T[3][p] = float(-beta * g[0] * g[1]);
        d.T[4][p] = float(-beta * g[0] * g[2]);
        d.T[5][p] = float(-beta * g[1] * g[2]);
        const bool boundary = x == 0 || y == 0 || z == 0 || x + 1 == dims[0] || y + 1 == dims[1] || z + 1 == dims[2];
        d.fixed[p] = boundary || U(rng) < 0.03;
      }
  return d;
}

Densities reference_densities(const Volume& v, const VariationalParams& p, const std::vector<std::uint8_t>* mask,
                              const SharpenTerm* sharpen) {
  const std::size_t n = v.voxels();
  if (mask && mask->size() != n) throw std::invalid_argument("reference_densities: mask has the wrong size");
  const std::vector<double> smooth = reference_lowpass(v, p.sigma_mm, 3.0);
  Volume vs(v.dims, v.spacing);
  for (std::size_t i = 0; i < n; ++i) vs.data[i] = float(smooth[i]);
  // |grad v| of F_iso and F_ind from v lowpassed by grad_sigma when set.
  Volume vg = v;
  if (p.grad_sigma_mm > 0) {
    const std::vector<double> g_smooth = reference_lowpass(v, p.grad_sigma_mm, 3.0);
    for (std::size_t i = 0; i < vg.data.size(); ++i) vg.data[i] = float(g_smooth[i]);
  }
  const auto gv = reference_gradient(vg), gs = reference_gradient(vs);

  Densities d;
  d.dims = v.dims;
  d.spacing = v.spacing;
  d.mu.resize(n);
  d.rho.resize(n);
  for (auto& t : d.T) t.resize(n);
  d.fixed.assign(n, 0);
  auto boundary_at = [&](std::size_t x, std::size_t y, std::size_t z) {
    return x == 0 || y == 0 || z == 0 || x + 1 == v.dims[0] || y + 1 == v.dims[1] || z + 1 == v.dims[2];
  };
  // The shell functional (docs/numerics.md): the reference edge gradient is
  // the median |grad v| of the top edge_share of the free voxels (unless
  // given), the thickness at least 2 voxels of the coarsest axis.
  double g_ref = p.g_ref;
  if (p.edge_share > 0 && !(g_ref > 0)) {
    std::vector<double> mags;
    for (std::size_t z = 0, i = 0; z < v.dims[2]; ++z)
      for (std::size_t y = 0; y < v.dims[1]; ++y)
        for (std::size_t x = 0; x < v.dims[0]; ++x, ++i)
          if (!boundary_at(x, y, z) && !(mask && (*mask)[i] == 0))
            mags.push_back(std::sqrt(gv[0][i] * gv[0][i] + gv[1][i] * gv[1][i] + gv[2][i] * gv[2][i]));
    std::sort(mags.begin(), mags.end());
    const std::size_t top = std::max<std::size_t>(1, std::size_t(double(mags.size()) * p.edge_share));
    g_ref = mags.empty() ? 1.0 : mags[mags.size() - top / 2 - 1];
    // A small object's walls (VariationalParams::edge_split): the top
    // edge_share_fine's median when it stands edge_split x above.
    if (!mags.empty() && p.edge_split > 0 && p.edge_share_fine > 0 && p.edge_share_fine < p.edge_share && g_ref > 0) {
      const std::size_t fine_top = std::max<std::size_t>(1, std::size_t(double(mags.size()) * p.edge_share_fine));
      const double fine = mags[mags.size() - fine_top / 2 - 1];
      // Blended between edge_split_from and edge_split: g_ref ratio^w.
      const double ratio = fine / g_ref;
      double w = 0;
      if (ratio >= p.edge_split) w = 1;
      else if (p.edge_split_from > 0 && p.edge_split_from < p.edge_split && ratio > p.edge_split_from)
        w = (ratio - p.edge_split_from) / (p.edge_split - p.edge_split_from);
      if (w >= 1) g_ref = fine;
      else if (w > 0) g_ref *= std::pow(ratio, w);
    }
    if (!(g_ref > 0)) g_ref = 1.0;
  }
  const bool shell = p.thickness_mm > 0;
  const double thickness =
      shell ? std::max(p.thickness_mm, 2.0 * std::max({v.spacing[0], v.spacing[1], v.spacing[2]})) : 0.0;
  const double h2 = 0.25 * thickness * thickness;
  const bool relative = p.edge_share > 0;
  const double eps = relative ? p.epsilon * g_ref * g_ref : p.epsilon;
  const double tscale = relative ? 1.0 / (g_ref * g_ref) : 1.0;
  for (std::size_t z = 0, i = 0; z < v.dims[2]; ++z)
    for (std::size_t y = 0; y < v.dims[1]; ++y)
      for (std::size_t x = 0; x < v.dims[0]; ++x, ++i) {
        const double gv2 = gv[0][i] * gv[0][i] + gv[1][i] * gv[1][i] + gv[2][i] * gv[2][i];
        // The shell's centre moved shell_shift_mm toward the bright side: a
        // local isovalue v_iso + shift |grad v| (kernels/system.cl).
        const double lift = shell ? p.shell_shift_mm * std::sqrt(gv2) : 0.0;
        const double a = double(v.data[i]) - p.v_iso - lift, b = smooth[i] - p.v_iso - lift;
        double W = (p.omega * a * a + (1.0 - p.omega) * b * b) / (gv2 + eps);
        if (shell) W = std::min(std::pow(W / h2, p.profile_power), p.weight_cap);
        const double c = relative ? p.delta + (1.0 - p.delta) * std::pow(std::min(1.0, std::sqrt(gv2) / g_ref), p.edge_power)
                                  : p.delta + (1.0 - p.delta) * std::sqrt(gv2);
        double mu = p.alpha * W + p.gamma * c, rho = p.gamma * c * p.u_ind;
        if (sharpen) {
          const double a = std::clamp(double(sharpen->u0[i]) / p.u_ind, 0.0, 1.0);
          const double e = relative ? std::min(1.0, std::sqrt(gv2) / g_ref) : 1.0;
          const double ra2 = sharpen->ratio * a * a * e * e;
          mu += sharpen->lambda * ((1 - a) * (1 - a) + ra2);
          rho += sharpen->lambda * ra2 * p.u_ind;
        }
        d.mu[i] = float(mu);
        d.rho[i] = float(rho);
        const double g[3] = {gs[0][i], gs[1][i], gs[2][i]};
        const double g2 = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]) * tscale;
        d.T[0][i] = float(p.beta * (g2 - g[0] * g[0] * tscale) + p.kappa);
        d.T[1][i] = float(p.beta * (g2 - g[1] * g[1] * tscale) + p.kappa);
        d.T[2][i] = float(p.beta * (g2 - g[2] * g[2] * tscale) + p.kappa);
        d.T[3][i] = float(-p.beta * g[0] * g[1] * tscale);
        d.T[4][i] = float(-p.beta * g[0] * g[2] * tscale);
        d.T[5][i] = float(-p.beta * g[1] * g[2] * tscale);
        d.fixed[i] = boundary_at(x, y, z) || (mask && (*mask)[i] == 0);
      }
  return d;
}

StencilOffset stencil_offset(int k) {
  static const StencilOffset table[STENCIL_COEFS] = {
#define SOFTSHELL_OFFSET(k, dx, dy, dz) {dx, dy, dz},
      STENCIL_OFFSETS(SOFTSHELL_OFFSET)
#undef SOFTSHELL_OFFSET
  };
  if (k < 0 || k >= STENCIL_COEFS) throw std::out_of_range("stencil_offset");
  return table[k];
}

}  // namespace softshell::test
