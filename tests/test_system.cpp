// The device's discrete system (kernels/system.cl, host/variational.cpp)
// against the float64 oracle (tests/oracle.cpp), which follows
// docs/numerics.md from the energy's definition:
//  - the operator is the exact gradient of the discrete energy: 2 (A u - b)
//    equals central differences of E at every free voxel;
//  - the densities computed on the device equal the CPU reference;
//  - every stored coefficient equals the oracle's matrix entry (this pins the
//    stencil down exactly), with the structural zeros exactly zero;
//  - the device operator is symmetric (exactly, by the storage) and positive
//    definite on the free voxels.
// Plus self-checks of the oracle: its assembled matrix is the Hessian of its
// energy, and the stencil table is the positive half of the 19-point
// neighbourhood.
#include <algorithm>
#include <iostream>
#include <cmath>
#include <random>
#include <tuple>
#include <sstream>
#include <string>
#include <vector>

#include "oracle.hpp"
#include "test_support.hpp"
#include "variational.hpp"

namespace softshell {
namespace {

using test::assemble_oracle;
using test::oracle_energy;
using test::OracleSystem;
using test::runtime;
using test::stencil_offset;

std::string xyz(Dims3 dims, std::size_t i) {
  std::ostringstream s;
  s << "(" << i % dims[0] << ", " << (i / dims[0]) % dims[1] << ", " << i / (dims[0] * dims[1]) << ")";
  return s.str();
}

long linear_offset(Dims3 dims, int dx, int dy, int dz) {
  return dx + long(dims[0]) * (dy + long(dims[1]) * dz);
}

// Index of p + (dx, dy, dz), or -1 outside the volume.
long neighbour(Dims3 dims, std::size_t p, int dx, int dy, int dz) {
  const long x = long(p % dims[0]) + dx, y = long((p / dims[0]) % dims[1]) + dy, z = long(p / (dims[0] * dims[1])) + dz;
  if (x < 0 || y < 0 || z < 0 || x >= long(dims[0]) || y >= long(dims[1]) || z >= long(dims[2])) return -1;
  return x + long(dims[0]) * (y + long(dims[1]) * z);
}

// Random values in [-1, 1) on the free voxels, 0 on the fixed ones.
std::vector<double> random_free(const std::vector<std::uint8_t>& fixed, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::vector<double> u(fixed.size());
  for (std::size_t p = 0; p < u.size(); ++p) u[p] = fixed[p] ? 0.0 : U(rng);
  return u;
}

std::vector<float> to_float(const std::vector<double>& v) { return std::vector<float>(v.begin(), v.end()); }
Eigen::VectorXd to_eigen(const std::vector<double>& v) { return Eigen::Map<const Eigen::VectorXd>(v.data(), long(v.size())); }
Eigen::VectorXd to_eigen(const std::vector<float>& v) {
  return Eigen::Map<const Eigen::VectorXf>(v.data(), long(v.size())).cast<double>();
}

// y = A x and r = b - A x on the device, for host vectors.
std::vector<float> device_apply(const DeviceSystem& sys, const std::vector<float>& x) {
  Runtime& rt = runtime();
  cl::Buffer xb = test::upload(rt, x), yb = rt.buffer(x.size() * sizeof(float));
  sys.apply(xb, yb);
  return test::download(rt, yb, x.size());
}
std::vector<float> device_residual(const DeviceSystem& sys, const std::vector<float>& x) {
  Runtime& rt = runtime();
  cl::Buffer xb = test::upload(rt, x), rb = rt.buffer(x.size() * sizeof(float));
  sys.residual(xb, rb);
  return test::download(rt, rb, x.size());
}

// Central differences of the oracle energy at every free voxel (0 at fixed
// ones). E is quadratic in u, so a central difference is exact for any step
// in exact arithmetic; a step of the order of u keeps the rounding error
// (~1e-16 |E| / step) negligible.
std::vector<double> energy_gradient_fd(const Densities& d, const std::vector<double>& u) {
  const double step = 0.5;
  std::vector<double> g(u.size(), 0.0), w = u;
  for (std::size_t p = 0; p < u.size(); ++p) {
    if (d.fixed[p]) continue;
    w[p] = u[p] + step;
    const double ep = oracle_energy(d, w);
    w[p] = u[p] - step;
    const double em = oracle_energy(d, w);
    w[p] = u[p];
    g[p] = (ep - em) / (2 * step);
  }
  return g;
}

// Per-voxel size of the terms of (A u)_p and b_p, for float tolerances:
// sum_q |A_pq u_q| + |b_p| + max_{q near p} A_qq max|u| (the last covers the
// cancellation among the contributions summed into one coefficient).
std::vector<double> term_scale(const OracleSystem& s, const std::vector<double>& u) {
  const std::size_t n = s.voxels();
  double umax = 0;
  for (double x : u) umax = std::max(umax, std::abs(x));
  std::vector<double> scale(n, 0.0), diag(n);
  for (std::size_t p = 0; p < n; ++p) diag[p] = std::abs(s.A.coeff(long(p), long(p)));
  for (long c = 0; c < s.A.outerSize(); ++c)
    for (Eigen::SparseMatrix<double>::InnerIterator it(s.A, c); it; ++it)
      scale[std::size_t(it.row())] += std::abs(it.value() * u[std::size_t(it.col())]);
  for (std::size_t p = 0; p < n; ++p) {
    double dmax = 0;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const long q = neighbour(s.dims, p, dx, dy, dz);
          if (q >= 0) dmax = std::max(dmax, diag[std::size_t(q)]);
        }
    scale[p] += std::abs(s.b[long(p)]) + dmax * umax;
  }
  return scale;
}

// |got - want| <= rel * scale at every voxel; reports the first failure by
// (x, y, z) and the worst error relative to the scale.
::testing::AssertionResult near_scaled(const std::vector<double>& got, const std::vector<double>& want,
                                       const std::vector<double>& scale, double rel, Dims3 dims) {
  std::size_t bad = 0, first = got.size();
  double worst = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const double err = std::abs(got[i] - want[i]);
    const double r = scale[i] > 0 ? err / scale[i] : (err > 0 ? INFINITY : 0.0);
    if (!(r <= rel)) {
      if (first == got.size()) first = i;
      ++bad;
    }
    if (!(r <= worst)) worst = r;
  }
  if (bad == 0) return ::testing::AssertionSuccess() << "worst error / scale " << worst;
  return ::testing::AssertionFailure() << bad << " of " << got.size() << " voxels differ; first at "
                                       << xyz(dims, first) << ": got " << got[first] << ", want " << want[first]
                                       << " (scale " << scale[first] << "); worst error / scale " << worst
                                       << " > " << rel;
}

// The operator test shared by both ways of building the device system: at
// random u (fixed voxels 0), the device's -2 (b - A u) and 2 (A u - V rho)
// against central differences of the energy of the densities the device
// holds.
void expect_operator_is_energy_gradient(const DeviceSystem& sys, const Densities& d, std::uint64_t seed) {
  const OracleSystem s = assemble_oracle(d);
  const std::vector<double> u = random_free(d.fixed, seed);
  const std::vector<double> fd = energy_gradient_fd(d, u);
  std::vector<double> scale = term_scale(s, u);
  for (double& x : scale) x *= 2;  // of 2 (A u - b)
  const std::vector<float> r = device_residual(sys, to_float(u)), y = device_apply(sys, to_float(u));
  const double V = d.spacing[0] * d.spacing[1] * d.spacing[2];
  std::vector<double> from_residual(u.size()), from_apply(u.size()), want(u.size());
  for (std::size_t p = 0; p < u.size(); ++p) {
    // At fixed voxels (u = 0) the gradient is not defined by E; the spec's
    // identity rows and b = 0 give r = 0 and A u = 0 there.
    from_residual[p] = -2.0 * double(r[p]);
    from_apply[p] = d.fixed[p] ? 2.0 * double(y[p]) : 2.0 * (double(y[p]) - V * double(d.rho[p]));
    want[p] = fd[p];
  }
  // float32 assembly and product: a few units of 6e-8 on each term.
  const auto via_residual = near_scaled(from_residual, want, scale, 2e-6, d.dims);
  const auto via_apply = near_scaled(from_apply, want, scale, 2e-6, d.dims);
  EXPECT_TRUE(via_residual) << "-2 r = -2 (b - A u) vs dE/du";
  EXPECT_TRUE(via_apply) << "2 (A u - V rho) vs dE/du";
  if (via_residual && via_apply)
    std::cout << "[ oracle   ] residual: " << via_residual.message() << "; apply: " << via_apply.message() << "\n";
}

const Dims3 kSmall{9, 11, 7};
const Vec3d kSmallSpacing{0.7, 1.1, 1.6};

// A smooth blob plus noise in [0, 1] (v~ and grad v are then non-trivial)
// and a mask that marks an "unscanned" corner region.
Volume test_volume(Dims3 dims, Vec3d spacing, std::uint64_t seed) {
  Volume v(dims, spacing);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-0.15, 0.15);
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x) {
        const double px = (x - 0.5 * (dims[0] - 1)) * spacing[0], py = (y - 0.45 * (dims[1] - 1)) * spacing[1],
                     pz = (z - 0.55 * (dims[2] - 1)) * spacing[2];
        const double r = std::sqrt(px * px + py * py + pz * pz);
        const double blob = 0.2 + 0.6 / (1.0 + std::exp((r - 3.5) / 0.8));
        v.at(x, y, z) = float(std::clamp(blob + U(rng), 0.0, 1.0));
      }
  return v;
}
std::vector<std::uint8_t> corner_mask(Dims3 dims) {
  std::vector<std::uint8_t> m(dims[0] * dims[1] * dims[2], 1);
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x)
        if (x + y + z <= 4) m[x + dims[0] * (y + dims[1] * z)] = 0;
  return m;
}
VariationalParams test_params() {
  VariationalParams p;  // every term active and the tangential one strong
  p.alpha = 1.0;
  p.beta = 0.4;
  p.gamma = 0.2;
  p.omega = 0.6;
  p.delta = 0.1;
  p.epsilon = 0.01;
  p.u_ind = 1.0;
  p.v_iso = 0.45;
  p.sigma_mm = 0.9;
  // The paper's F_iso and F_ind (with the lowpassed |grad v| and kappa of
  // the earlier defaults); shell_test_params() turns the shell terms on.
  p.kappa = 1.0, p.grad_sigma_mm = 1.5;
  p.thickness_mm = 0, p.edge_share = 0, p.sharpen_iterations = 0;
  return p;
}

// The shell functional's terms on top (docs/numerics.md, "The shell
// functional"): a profile power and an edge power that take the general
// power path of the kernel (exp2(q log2 x); shell_power in kernels/system.cl).
VariationalParams shell_test_params() {
  VariationalParams p = test_params();
  p.thickness_mm = 2.5, p.profile_power = 1.5, p.edge_share = 0.05, p.edge_power = 2.7, p.weight_cap = 50;
  return p;
}

// The same with the given edge power: every power with a path of its own
// (1, 2, 2.5, 3, 3.5 and 4 by multiplication and sqrt).
VariationalParams shell_test_params(double edge_power) {
  VariationalParams p = shell_test_params();
  p.edge_power = edge_power;
  return p;
}

// ---------------------------------------------------------------- oracle self-checks

TEST(SystemOracle, StencilTableIsThePositiveHalf) {
  // k = 0 is the diagonal; k = 1..9 are exactly the face and edge offsets
  // of the 3x3x3 neighbourhood (corners excluded: the operator never
  // couples them) with a positive linear index, in increasing order (x fastest).
  const Dims3 big{100, 100, 100};
  EXPECT_EQ(linear_offset(big, stencil_offset(0).dx, stencil_offset(0).dy, stencil_offset(0).dz), 0);
  std::vector<long> want;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx)
        if (linear_offset(big, dx, dy, dz) > 0 && !(dx != 0 && dy != 0 && dz != 0))
          want.push_back(linear_offset(big, dx, dy, dz));
  std::sort(want.begin(), want.end());
  ASSERT_EQ(want.size(), 9u);
  ASSERT_EQ(STENCIL_COEFS, 10);
  for (int k = 1; k < STENCIL_COEFS; ++k) {
    const auto o = stencil_offset(k);
    EXPECT_EQ(linear_offset(big, o.dx, o.dy, o.dz), want[k - 1]) << "k = " << k;
  }
}


TEST(SystemOracle, CoefficientSlicesFallOnDifferentCacheLinesOfAPage) {
  // The sweep reads all ten slices at the same voxel at once: their offsets
  // within a 4 KiB page (which index the L1's sets) must differ by whole
  // cache lines, for every grid, the power-of-two ones above all; and a
  // slice holds the level. kernels/stencil.h, STENCIL_SLICE.
  for (std::size_t n : {std::size_t(16 * 16 * 16), std::size_t(64 * 64 * 64), std::size_t(128 * 128 * 128),
                        std::size_t(256 * 256 * 256), std::size_t(105 * 105 * 105), std::size_t(1), std::size_t(1023)}) {
    const std::size_t s = STENCIL_SLICE(n);
    EXPECT_GE(s, n);
    EXPECT_LT(s, n + 1024 + 128) << "n = " << n;
    std::vector<std::size_t> lines;
    for (std::size_t k = 0; k < STENCIL_COEFS; ++k) lines.push_back((k * s * sizeof(float)) % 4096 / 64);
    std::sort(lines.begin(), lines.end());
    EXPECT_EQ(std::adjacent_find(lines.begin(), lines.end()), lines.end()) << "two slices share a set, n = " << n;
  }
}
TEST(SystemOracle, AssemblyIsTheEnergysGradient) {
  // The oracle's two routes agree in double: 2 (A u - b) from the assembled
  // matrix equals central differences of E; A is symmetric; E(u) = u'Au - 2b'u
  // (no constant) for u = 0 on fixed voxels; the raw Hessian/2 agrees with A
  // on the free block.
  const Densities d = test::random_densities(kSmall, kSmallSpacing, test::seed() + 101, 0.7, 0.01);
  Eigen::SparseMatrix<double> raw;
  const OracleSystem s = assemble_oracle(d, &raw);
  const std::vector<double> u = random_free(d.fixed, test::seed() + 102);
  const Eigen::VectorXd ue = to_eigen(u);
  const Eigen::VectorXd g = 2.0 * (s.A * ue - s.b);
  const std::vector<double> fd = energy_gradient_fd(d, u);
  std::vector<double> got(u.size()), scale = term_scale(s, u);
  for (std::size_t p = 0; p < u.size(); ++p) got[p] = d.fixed[p] ? 0.0 : g[long(p)];
  EXPECT_TRUE(near_scaled(got, fd, scale, 1e-12, d.dims));
  EXPECT_LE((Eigen::SparseMatrix<double>(s.A.transpose()) - s.A).norm(), 1e-14 * s.A.norm());
  EXPECT_LE((Eigen::SparseMatrix<double>(raw.transpose()) - raw).norm(), 1e-14 * raw.norm());
  const double e = oracle_energy(d, u), q = ue.dot(s.A * ue) - 2 * s.b.dot(ue);
  EXPECT_NEAR(e, q, 1e-12 * std::abs(e));
  // A checkerboard has a large tangential energy (the reason for the corner
  // gradients): with mu = 0 the form must still be clearly positive.
  Densities no_mass = d;
  std::fill(no_mass.mu.begin(), no_mass.mu.end(), 0.0f);
  std::fill(no_mass.rho.begin(), no_mass.rho.end(), 0.0f);
  std::vector<double> checker(u.size());
  for (std::size_t p = 0; p < u.size(); ++p) {
    const std::size_t x = p % d.dims[0], y = (p / d.dims[0]) % d.dims[1], z = p / (d.dims[0] * d.dims[1]);
    checker[p] = d.fixed[p] ? 0.0 : ((x + y + z) % 2 ? 1.0 : -1.0);
  }
  EXPECT_GT(oracle_energy(no_mass, checker), 0.1 * oracle_energy(no_mass, u));
}

TEST(System, SharpenedDensitiesMatchReference) {
  // The sharpening term linearised about a u0 (docs/numerics.md,
  // "Sharpening") on top of the shell functional's densities: device against
  // the float64 reference, and the update equals a fresh build's diagonal
  // and b from those densities.
  const Volume v = test_volume(kSmall, kSmallSpacing, test::seed() + 131);
  const VariationalParams p = shell_test_params();
  std::mt19937_64 rng(test::seed() + 132);
  std::uniform_real_distribution<float> U(-0.2f, 1.3f);  // outside [0, u_ind] too: clamped
  test::SharpenTerm sh;
  sh.u0.resize(v.voxels());
  for (float& f : sh.u0) f = U(rng);
  sh.lambda = 1.7, sh.ratio = 2.5;
  DeviceSystem sys(runtime(), v, p);
  sys.update_sharpen(p, sh.u0, sh.lambda, sh.ratio);
  const Densities got = sys.download_densities();
  const Densities want = test::reference_densities(v, p, nullptr, &sh);
  const Densities plain = test::reference_densities(v, p);
  for (const auto& [g, w, name] : {std::tuple{&got.mu, &want.mu, "mu"}, std::tuple{&got.rho, &want.rho, "rho"}}) {
    double wmax = 0;
    for (float x : *w) wmax = std::max(wmax, double(std::abs(x)));
    EXPECT_TRUE(test::all_near(*g, std::vector<double>(w->begin(), w->end()), want.dims, 1e-5 * wmax, 1e-4)) << name;
  }
  EXPECT_GT(test::max_relative_deviation(got.mu, plain.mu), 1e-2) << "the term must change mu";
  // The assembled system equals one built from the sharpened densities.
  const DeviceSystem from(runtime(), got);
  EXPECT_LT(test::max_relative_deviation(sys.download_coefficients(), from.download_coefficients()), 1e-6);
  EXPECT_LT(test::max_relative_deviation(sys.download_b(), from.download_b()), 1e-6);
}

// ---------------------------------------------------------------- (a) operator == energy gradient

TEST(System, OperatorIsEnergyGradientRandomDensities) {
  const Densities d = test::random_densities(kSmall, kSmallSpacing, test::seed() + 111, 0.7, 0.01);
  const DeviceSystem sys(runtime(), d);
  expect_operator_is_energy_gradient(sys, d, test::seed() + 112);
}

TEST(System, DeviceDensitiesMatchReference) {
  const Volume v = test_volume(kSmall, kSmallSpacing, test::seed() + 121);
  const auto mask = corner_mask(kSmall);
  for (const bool masked : {false, true})
  for (const VariationalParams& p : {test_params(), shell_test_params(), shell_test_params(1.0), shell_test_params(2.0),
                                     shell_test_params(2.5), shell_test_params(3.0), shell_test_params(3.5),
                                     shell_test_params(4.0)}) {
    SCOPED_TRACE(masked ? "with mask" : "without mask");
    SCOPED_TRACE(p.thickness_mm > 0 ? "shell functional, edge power " + std::to_string(p.edge_power) : "paper's terms");
    const DeviceSystem sys(runtime(), v, p, masked ? &mask : nullptr);
    const Densities got = sys.download_densities();
    const Densities want = test::reference_densities(v, p, masked ? &mask : nullptr);
    ASSERT_EQ(got.dims, want.dims);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(got.spacing[a], want.spacing[a], 1e-6 * want.spacing[a]);
    std::size_t fixed_bad = 0, first = 0;
    for (std::size_t i = 0; i < want.voxels(); ++i)
      if ((got.fixed[i] != 0) != (want.fixed[i] != 0) && fixed_bad++ == 0) first = i;
    EXPECT_EQ(fixed_bad, 0u) << "fixed flags differ, first at " << xyz(want.dims, first) << ": got "
                             << int(got.fixed[first]) << ", want " << int(want.fixed[first]);
    // Per field: error <= 1e-4 relative + 1e-5 of the field's largest value
    // (float lowpass and gradients against double references).
    auto check = [&](const std::vector<float>& g, const std::vector<float>& w, const char* name) {
      double wmax = 0;
      for (float x : w) wmax = std::max(wmax, double(std::abs(x)));
      EXPECT_TRUE(test::all_near(g, std::vector<double>(w.begin(), w.end()), want.dims, 1e-5 * wmax, 1e-4)) << name;
    };
    check(got.mu, want.mu, "mu");
    check(got.rho, want.rho, "rho");
    const char* tn[6] = {"T_xx", "T_yy", "T_zz", "T_xy", "T_xz", "T_yz"};
    for (int k = 0; k < 6; ++k) check(got.T[k], want.T[k], tn[k]);
  }
}

TEST(System, OperatorIsEnergyGradientVolumeDensities) {
  // Densities computed on the device (with a mask); the operator is checked
  // against the energy of the densities the device holds (their agreement
  // with the CPU reference is DeviceDensitiesMatchReference).
  const Volume v = test_volume(kSmall, kSmallSpacing, test::seed() + 131);
  const auto mask = corner_mask(kSmall);
  const DeviceSystem sys(runtime(), v, test_params(), &mask);
  expect_operator_is_energy_gradient(sys, sys.download_densities(), test::seed() + 132);
}

// ---------------------------------------------------------------- (b) stencil, symmetry, positivity

// Every stored coefficient against the oracle's entry A(p, p + off_k); b
// against V rho. Structural zeros (corner offsets on the fine level,
// couplings to or from fixed voxels, offsets leaving the volume) must be
// exactly 0: the spec's kernels have no special cases, so nothing else is
// acceptable there.
void expect_coefficients_match(const DeviceSystem& sys, const Densities& d) {
  const OracleSystem s = assemble_oracle(d);
  const std::size_t n = d.voxels();
  const std::vector<float> coef = sys.download_coefficients();
  ASSERT_EQ(coef.size(), STENCIL_COEFS * n);
  std::vector<double> diag(n);
  for (std::size_t p = 0; p < n; ++p) diag[p] = s.A.coeff(long(p), long(p));
  std::size_t bad = 0, structural_bad = 0;
  std::ostringstream first, first_structural;
  double worst = 0;
  for (std::size_t p = 0; p < n; ++p)
    for (int k = 0; k < STENCIL_COEFS; ++k) {
      const auto o = stencil_offset(k);
      const long q = neighbour(d.dims, p, o.dx, o.dy, o.dz);
      const double got = coef[std::size_t(k) * n + p];
      const bool corner = o.dx != 0 && o.dy != 0 && o.dz != 0;
      const bool structural_zero =
          k != 0 && (corner || q < 0 || d.fixed[p] || d.fixed[std::size_t(q)]);
      if (structural_zero) {
        if (got != 0.0 && structural_bad++ == 0)
          first_structural << "k " << k << " (" << o.dx << ", " << o.dy << ", " << o.dz << ") at "
                           << xyz(d.dims, p) << (corner ? " [corner]" : q < 0 ? " [outside]" : " [fixed]")
                           << ": got " << got << ", want 0";
        continue;
      }
      const double want = s.A.coeff(long(p), q);
      // float assembly: relative to the entry, plus the rows' diagonals for
      // the cancellation among contributions.
      const double tol = 1e-5 * std::abs(want) + 2e-6 * std::max(diag[p], diag[std::size_t(q)]);
      const double err = std::abs(got - want);
      worst = std::max(worst, err / tol);
      if (!(err <= tol) && bad++ == 0)
        first << "k " << k << " (" << o.dx << ", " << o.dy << ", " << o.dz << ") at " << xyz(d.dims, p)
              << (d.fixed[p] ? " [fixed row]" : "") << ": got " << got << ", want " << want
              << " (diagonal " << diag[p] << ")";
    }
  EXPECT_EQ(bad, 0u) << "coefficients differ from the oracle; first: " << first.str();
  EXPECT_EQ(structural_bad, 0u) << "structural zeros not zero; first: " << first_structural.str();
  std::cout << "[ oracle   ] worst coefficient error / tolerance " << worst << "\n";

  const std::vector<float> b = sys.download_b();
  std::vector<double> want_b(s.b.data(), s.b.data() + n);
  EXPECT_TRUE(test::all_near(b, want_b, d.dims, 0.0, 1e-6)) << "b = V rho (0 at fixed voxels)";
}

TEST(System, CoefficientsMatchOracleRandomDensities) {
  const Densities d = test::random_densities(kSmall, kSmallSpacing, test::seed() + 141, 0.7, 0.01);
  expect_coefficients_match(DeviceSystem(runtime(), d), d);
  // Also where the fixed voxels are only the boundary and the tensor dominates.
  Densities e = test::random_densities({6, 5, 8}, {1.3, 0.6, 0.9}, test::seed() + 142, 5.0, 0.001);
  for (std::size_t z = 0, p = 0; z < e.dims[2]; ++z)
    for (std::size_t y = 0; y < e.dims[1]; ++y)
      for (std::size_t x = 0; x < e.dims[0]; ++x, ++p)
        e.fixed[p] = x == 0 || y == 0 || z == 0 || x + 1 == e.dims[0] || y + 1 == e.dims[1] || z + 1 == e.dims[2];
  expect_coefficients_match(DeviceSystem(runtime(), e), e);
}

TEST(System, CoefficientsMatchOracleVolumeDensities) {
  const Volume v = test_volume(kSmall, kSmallSpacing, test::seed() + 151);
  const auto mask = corner_mask(kSmall);
  const DeviceSystem sys(runtime(), v, test_params(), &mask);
  expect_coefficients_match(sys, sys.download_densities());
}

TEST(System, DeviceOperatorIsExactlySymmetric) {
  // Probing: x_c = 1 on the voxels whose (x, y, z) mod 3 equals colour c, 0
  // elsewhere. Each voxel's 3x3x3 neighbourhood holds exactly one voxel j of
  // colour c, so (A x_c)_i = A_ij is a single product by 1 plus zeros: exact
  // in float. 27 applies read out the operator the device applies, entry by
  // entry, with no rounding; it must be exactly symmetric and exactly what
  // the stored coefficients say (A[p][p + k] = coef_p[k], A[p][p - k] =
  // coef_{p-k}[k]).
  const Densities d = test::random_densities(kSmall, kSmallSpacing, test::seed() + 161, 0.7, 0.01);
  const DeviceSystem sys(runtime(), d);
  const Dims3 dims = d.dims;
  const std::size_t n = d.voxels();
  auto colour = [&](std::size_t p) { return int(p % dims[0] % 3 + 3 * ((p / dims[0]) % dims[1] % 3) + 9 * (p / (dims[0] * dims[1]) % 3)); };
  std::vector<std::vector<float>> probe(27);
  for (int c = 0; c < 27; ++c) {
    std::vector<float> x(n, 0.0f);
    for (std::size_t p = 0; p < n; ++p) x[p] = colour(p) == c ? 1.0f : 0.0f;
    probe[c] = device_apply(sys, x);
  }
  // entry(i, j) for j in i's neighbourhood.
  auto entry = [&](std::size_t i, std::size_t j) { return probe[colour(j)][i]; };
  const std::vector<float> coef = sys.download_coefficients();
  std::size_t asym = 0, stored = 0;
  std::ostringstream first_asym, first_stored;
  for (std::size_t i = 0; i < n; ++i)
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const long jl = neighbour(dims, i, dx, dy, dz);
          if (jl < 0) continue;
          const std::size_t j = std::size_t(jl);
          if (entry(i, j) != entry(j, i) && asym++ == 0)
            first_asym << "A" << xyz(dims, i) << xyz(dims, j) << " = " << entry(i, j) << " but A" << xyz(dims, j)
                       << xyz(dims, i) << " = " << entry(j, i);
        }
  for (std::size_t p = 0; p < n; ++p)
    for (int k = 0; k < STENCIL_COEFS; ++k) {
      const auto o = stencil_offset(k);
      const long q = neighbour(dims, p, o.dx, o.dy, o.dz);
      if (q < 0) continue;
      const float c = coef[std::size_t(k) * n + p];
      const float fwd = entry(p, std::size_t(q)), back = entry(std::size_t(q), p);
      if ((fwd != c || back != c) && stored++ == 0)
        first_stored << "k " << k << " at " << xyz(dims, p) << ": stored " << c << ", applied A[p][p+k] = " << fwd
                     << ", A[p+k][p] = " << back;
    }
  EXPECT_EQ(asym, 0u) << "device operator not symmetric; first: " << first_asym.str();
  EXPECT_EQ(stored, 0u) << "apply does not use the stored stencil; first: " << first_stored.str();
}

TEST(System, SymmetricPositiveOnDevice) {
  const Densities d = test::random_densities(kSmall, kSmallSpacing, test::seed() + 171, 0.7, 0.01);
  const DeviceSystem sys(runtime(), d);
  const OracleSystem s = assemble_oracle(d);
  for (int trial = 0; trial < 4; ++trial) {
    SCOPED_TRACE("trial " + std::to_string(trial));
    std::vector<double> x = random_free(d.fixed, test::seed() + 172 + 2 * trial),
                        y = random_free(d.fixed, test::seed() + 173 + 2 * trial);
    if (trial == 3)  // the checkerboard, the pattern a central-difference F_tan would not see
      for (std::size_t p = 0; p < x.size(); ++p) {
        const std::size_t a = p % d.dims[0], b = (p / d.dims[0]) % d.dims[1], c = p / (d.dims[0] * d.dims[1]);
        x[p] = d.fixed[p] ? 0.0 : ((a + b + c) % 2 ? 1.0 : -1.0);
      }
    const Eigen::VectorXd xe = to_eigen(x), ye = to_eigen(y);
    const Eigen::VectorXd Ax = to_eigen(device_apply(sys, to_float(x))), Ay = to_eigen(device_apply(sys, to_float(y)));
    const double xAy = xe.dot(Ay), yAx = ye.dot(Ax), xAx = xe.dot(Ax);
    const double scale = xe.cwiseAbs().dot(Ay.cwiseAbs()) + ye.cwiseAbs().dot(Ax.cwiseAbs());
    EXPECT_NEAR(xAy, yAx, 1e-5 * scale) << "x.(A y) vs y.(A x)";
    const double want = xe.dot(s.A * xe);
    EXPECT_GT(xAx, 0.0);
    EXPECT_NEAR(xAx, want, 1e-5 * std::abs(want)) << "x.(A x) against the oracle";
  }
}

}  // namespace
}  // namespace softshell

namespace softshell {
namespace {

TEST(System, DotAndNormMatchAHostFloat64SumAndAreDeterministic) {
  // Sizes around the CPU kernel's chunking (8-float blocks, 256 chunks) and
  // the GPU kernel's 64 x 256 work-items: fewer voxels than chunks, a tail
  // that is not a multiple of 8, and many voxels per chunk.
  for (const Dims3 dims : {Dims3{5, 5, 5}, Dims3{13, 11, 7}, Dims3{37, 41, 29}, Dims3{64, 64, 65}}) {
    SCOPED_TRACE(std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]));
    const Densities d = test::random_densities(dims, {1, 1, 1}, test::seed() + 181, 0.7, 0.01);
    DeviceSystem sys(runtime(), d);
    const std::size_t n = d.voxels();
    const Volume xv = test::random_volume(dims, {1, 1, 1}, test::seed() + 182, -1.0f, 1.0f);
    const Volume yv = test::random_volume(dims, {1, 1, 1}, test::seed() + 183, 0.0f, 2.0f);
    const cl::Buffer x = test::upload(runtime(), xv.data), y = test::upload(runtime(), yv.data);
    double want = 0, want_xx = 0, scale = 0;
    for (std::size_t i = 0; i < n; ++i) {
      want += double(xv.data[i]) * yv.data[i];
      want_xx += double(xv.data[i]) * xv.data[i];
      scale += std::abs(double(xv.data[i]) * yv.data[i]);
    }
    for (bool strided : {false, true}) {  // the CPU and the GPU kernel, both on this device
      SCOPED_TRACE(strided ? "strided (GPU) kernel" : "chunked (CPU) kernel");
      sys.set_strided_dot(strided);
      const double got = sys.dot(x, y);
      EXPECT_NEAR(got, want, 1e-6 * scale);
      EXPECT_NEAR(sys.norm(x), std::sqrt(want_xx), 1e-6 * std::sqrt(want_xx));
      EXPECT_EQ(got, sys.dot(x, y)) << "deterministic";
    }
  }
}

TEST(System, RejectsAFreeBoundaryVoxel) {
  // The kernels skip the stencil on the boundary; a free boundary voxel would
  // silently give a non-symmetric operator, so it is refused.
  Densities d = test::random_densities({6, 5, 4}, {1.0, 1.0, 1.0}, test::seed(), 1.0, 0.1);
  EXPECT_NO_THROW(DeviceSystem(test::runtime(), d));
  d.fixed[0 + 6 * (2 + 5 * 1)] = 0;  // x = 0 face
  EXPECT_THROW(DeviceSystem(test::runtime(), d), std::invalid_argument);
}

// The reference edge gradient (VariationalParams::edge_share, edge_split)
// against medians taken from a full sort: speckle alone, speckle with a
// small object's walls (1.2 % of the entries, a gradient 8x the speckle's),
// and speckle whose walls fill more than edge_share.
TEST(ReferenceEdge, ASmallObjectsWallsStandApartFromSpeckle) {
  std::mt19937_64 rng(test::seed());
  std::normal_distribution<double> N(0.0, 1.0);
  const std::size_t n = 100000;
  // |grad| of speckle: the length of a 3-D Gaussian vector.
  auto speckle = [&] {
    const double a = N(rng), b = N(rng), c = N(rng);
    return std::sqrt(a * a + b * b + c * c);
  };
  auto field = [&](double wall_share) {
    std::vector<float> g2(n);
    for (std::size_t i = 0; i < n; ++i) {
      const double g = double(i) < wall_share * double(n) ? 8.0 + 0.5 * N(rng) : speckle();
      g2[i] = float(g * g);
    }
    for (std::size_t i = 0; i < n; i += 97) g2[i] = -1.0f;  // unscanned: ignored
    return g2;
  };
  // The median of the top `share` of the usable entries, from a full sort.
  auto sorted_median = [](const std::vector<float>& g2, double share) {
    std::vector<double> g;
    for (float x : g2)
      if (x >= 0) g.push_back(std::sqrt(double(x)));
    std::sort(g.begin(), g.end());
    const std::size_t top = std::max<std::size_t>(1, std::size_t(double(g.size()) * share));
    return g[g.size() - top / 2 - 1];
  };
  {
    // Speckle alone: the top 1 % is the same tail, not twice as steep.
    const std::vector<float> g2 = field(0.0);
    const ReferenceEdge r = reference_edge_gradient(g2, 0.03, 0.01, 2.0);
    EXPECT_EQ(r.share, 0.03);
    EXPECT_NEAR(r.g_ref, sorted_median(g2, 0.03), 1e-6);
    EXPECT_NEAR(r.ratio, sorted_median(g2, 0.01) / sorted_median(g2, 0.03), 1e-6);
    EXPECT_LT(r.ratio, 1.3);
    EXPECT_NEAR(reference_edge_gradient(g2, 0.03), r.g_ref, 0);
  }
  {
    // Walls on 1.2 %: the top 3 % is more than half speckle, its median
    // speckle's; the top 1 % is walls.
    const std::vector<float> g2 = field(0.012);
    const double coarse = sorted_median(g2, 0.03), fine = sorted_median(g2, 0.01);
    EXPECT_LT(coarse, 5.0);
    EXPECT_GT(fine, 7.0);
    const ReferenceEdge r = reference_edge_gradient(g2, 0.03, 0.01, 2.0);
    EXPECT_EQ(r.share, 0.01);
    EXPECT_NEAR(r.g_ref, fine, 1e-6);
    EXPECT_NEAR(r.ratio, fine / coarse, 1e-6);
    // Off (split 0), or a split the ratio does not reach: the top 3 %'s.
    EXPECT_NEAR(reference_edge_gradient(g2, 0.03, 0.01, 0.0).g_ref, coarse, 1e-6);
    EXPECT_EQ(reference_edge_gradient(g2, 0.03, 0.01, 0.0).share, 0.03);
    const ReferenceEdge high = reference_edge_gradient(g2, 0.03, 0.01, 1.01 * r.ratio);
    EXPECT_EQ(high.share, 0.03);
    EXPECT_NEAR(high.g_ref, coarse, 1e-6);
    // A finer share not below the share: off.
    EXPECT_EQ(reference_edge_gradient(g2, 0.01, 0.03, 2.0).share, 0.01);
  }
  {
    // Walls on 5 %, more than the share: the top 3 % is walls already.
    const std::vector<float> g2 = field(0.05);
    const ReferenceEdge r = reference_edge_gradient(g2, 0.03, 0.01, 2.0);
    EXPECT_EQ(r.share, 0.03);
    EXPECT_GT(r.g_ref, 7.0);
  }
  // Nothing usable.
  EXPECT_EQ(reference_edge_gradient(std::vector<float>(10, -1.0f), 0.03, 0.01, 2.0).g_ref, 0.0);
}

// Between edge_split_from and edge_split the two medians are blended
// (VariationalParams::edge_split_from): the weight rises linearly with the
// ratio, g_ref = (top 3 %'s) x ratio^w, so g_ref does not jump where the
// ratio crosses a threshold; the switch (from 0) does.
TEST(ReferenceEdge, BlendedBetweenTheThresholdsWithoutAJump) {
  EXPECT_EQ(edge_split_weight(1.5, 2.0, 1.6), 0.0);
  EXPECT_EQ(edge_split_weight(1.6, 2.0, 1.6), 0.0);
  EXPECT_NEAR(edge_split_weight(1.8, 2.0, 1.6), 0.5, 1e-12);
  EXPECT_EQ(edge_split_weight(2.0, 2.0, 1.6), 1.0);
  EXPECT_EQ(edge_split_weight(3.0, 2.0, 1.6), 1.0);
  EXPECT_EQ(edge_split_weight(1.8, 2.0, 0.0), 0.0);  // a switch at 2
  EXPECT_EQ(edge_split_weight(2.0, 2.0, 0.0), 1.0);
  EXPECT_EQ(edge_split_weight(1.8, 2.0, 2.5), 0.0);  // from not below split: a switch
  EXPECT_EQ(edge_split_weight(5.0, 0.0, 1.6), 0.0);  // off
  EXPECT_EQ(edge_split_weight(0.0, 2.0, 1.6), 0.0);  // not measured

  // A field whose top 1 % (walls) stands about 2x above its top 3 %.
  std::mt19937_64 rng(test::seed());
  std::normal_distribution<double> N(0.0, 1.0);
  const std::size_t n = 100000;
  std::vector<float> g2(n);
  for (std::size_t i = 0; i < n; ++i) {
    double g = 8.0 + 0.5 * N(rng);
    if (i >= n * 12 / 1000) {
      const double a = N(rng), b = N(rng), c = N(rng);
      g = std::sqrt(a * a + b * b + c * c);
    }
    g2[i] = float(g * g);
  }
  const ReferenceEdge off = reference_edge_gradient(g2, 0.03, 0.01, 0.0);
  const ReferenceEdge full = reference_edge_gradient(g2, 0.03, 0.01, 1.0);
  const double coarse = off.g_ref, fine = full.g_ref, r0 = full.ratio;
  ASSERT_GT(r0, 1.5);
  EXPECT_NEAR(fine, coarse * r0, 1e-6 * fine);
  // Halfway between from and split: the geometric mean, weight 1/2, the
  // top 3 % still the share named.
  const ReferenceEdge half = reference_edge_gradient(g2, 0.03, 0.01, 1.25 * r0, 0.75 * r0);
  EXPECT_NEAR(half.weight, 0.5, 1e-9);
  EXPECT_NEAR(half.g_ref, std::sqrt(coarse * fine), 1e-6 * fine);
  EXPECT_EQ(half.share, 0.03);
  EXPECT_NEAR(half.ratio, r0, 1e-12);
  // Below from: the top 3 %'s, weight 0; from split up: the top 1 %'s.
  const ReferenceEdge below = reference_edge_gradient(g2, 0.03, 0.01, 2.0 * r0, 1.1 * r0);
  EXPECT_EQ(below.weight, 0.0);
  EXPECT_EQ(below.g_ref, coarse);
  const ReferenceEdge above = reference_edge_gradient(g2, 0.03, 0.01, 0.99 * r0, 0.5 * r0);
  EXPECT_EQ(above.weight, 1.0);
  EXPECT_EQ(above.g_ref, fine);
  EXPECT_EQ(above.share, 0.01);
  // The ratio just under the split: blended (w = 0.2 / 0.201), g_ref within
  // 1 % of the top 1 %'s; the switch gives the top 3 %'s there (a jump by
  // the ratio).
  const ReferenceEdge ramp = reference_edge_gradient(g2, 0.03, 0.01, 1.001 * r0, 0.8 * r0);
  EXPECT_NEAR(ramp.weight, 0.2 / 0.201, 1e-9);
  EXPECT_NEAR(ramp.g_ref, coarse * std::pow(r0, ramp.weight), 1e-6 * fine);
  EXPECT_GT(ramp.g_ref, 0.99 * fine);
  EXPECT_LT(ramp.g_ref, fine);
  EXPECT_EQ(reference_edge_gradient(g2, 0.03, 0.01, 1.001 * r0, 0.0).g_ref, coarse);
}

}  // namespace
}  // namespace softshell
