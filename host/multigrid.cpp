// Multigrid solver of the variational classifier's system (docs/numerics.md,
// "Multigrid"): levels by rediscretisation, V(nu1, nu2) cycles with
// Gauss-Seidel (DeviceSystem::gs_order()) or weighted Jacobi, full multigrid
// for the initial guess, stopping on the relative residual; below
// kRefineBelow, mixed-precision iterative refinement (float64 residuals and
// solution on the host, float32 correction solves on the device).
#include <algorithm>
#include <limits>
#include <array>
#include <chrono>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <thread>

#include "memory_need.hpp"
#include "variational.hpp"
#include "progress.hpp"

namespace softshell {
namespace {

// Bytes per voxel each operation moves at the least (float32; the byte model
// of docs/benchmarks.md): they add up to SolveReport::bytes.
namespace bytes_per_voxel {
constexpr double sweep = STENCIL_COEFS * 4 + 4 + 4 + 4;  // coefficients, rhs, u read, u write
constexpr double jacobi = sweep + 8;                     // + the copy back from tmp
constexpr double residual = STENCIL_COEFS * 4 + 4 + 4 + 4;  // coefficients, rhs, x, r write
// The compact stencil (DeviceSystem::build_compact): the diagonal, read from
// the float32 stencil, and the compact copy (its correction, nine bfloat16
// couplings).
constexpr double compact_coefs = 4 + STENCIL_COMPACT_BYTES;
constexpr double sweep_compact = compact_coefs + 4 + 4 + 4;
constexpr double residual_compact = compact_coefs + 4 + 4 + 4;
constexpr double apply = STENCIL_COEFS * 4 + 4 + 4;
constexpr double fill = 4, copy = 8, dot = 8, norm = 4, axpby = 12;
}  // namespace bytes_per_voxel

struct Level {
  std::unique_ptr<DeviceSystem> owned;  // null for the caller's fine level
  DeviceSystem* sys = nullptr;
  cl::Buffer u, rhs, r, tmp;
};

class Multigrid {
 public:
  Multigrid(DeviceSystem& fine, const SolverParams& sp)
      : sp_(sp),
        rt_(fine.runtime()),
        rows_(!rt_.info().is_gpu()),
        restrict_(rt_.kernel("multigrid.cl", rows_ ? "mg_restrict_residual_rows" : "mg_restrict_residual")),
        prolong_(rt_.kernel("multigrid.cl", rows_ ? "mg_prolong_add_rows" : "mg_prolong_add")) {
    add_level(nullptr, &fine);
    while (int(levels_.size()) < std::max(1, sp.max_levels)) {
      const GridDesc& g = levels_.back().sys->grid();
      if (std::min({g.nx, g.ny, g.nz}) <= 5) break;
      auto coarse = DeviceSystem::coarsen(*levels_.back().sys);
      // An owned level's tensor has served its assembly and this coarsening.
      if (levels_.back().owned) levels_.back().sys->release_tensor();
      DeviceSystem* raw = coarse.get();
      add_level(std::move(coarse), raw);
    }
    if (levels_.back().owned) levels_.back().sys->release_tensor();
  }

  int levels() const { return int(levels_.size()); }
  const SolverParams& params() const { return sp_; }
  // The preconditioner's fine level on the compact stencil (SolverParams::
  // compact_smoother): only under the conjugate gradients, which apply the
  // float32 operator (plain V-cycles would converge to the compact system's
  // solution), with the slab Gauss-Seidel, when allowed (allow_compact:
  // VariationalClassifier allows it for warm re-solves) and where its 22
  // bytes per voxel fit (compact_smoother_fits). Built at the first solve
  // that uses it.
  bool compact_in_use() const { return compact_; }
  void allow_compact(bool on) {
    compact_allowed_ = on;
    if (!on) compact_ = false;  // the copy stays built: allowing it again costs nothing
  }
  void use_compact() {
    if (compact_ || !compact_allowed_ || !sp_.compact_smoother || !sp_.krylov || sp_.jacobi ||
        fine().sys->gs_order() != GsOrder::Slabs || !compact_smoother_fits(rt_.info(), fine().sys->voxels()))
      return;
    fine().sys->build_compact();
    compact_ = true;
  }
  // ||b|| of the fine level: set at the start of every solve (b changes with
  // the pointwise parameters).
  double b_norm() const { return b_norm_; }
  void measure_b() { b_norm_ = fine().sys->norm(fine().sys->b()); }
  bool has_solution = false;  // fine().u holds the last solve's solution
  bool resolve_sweeps_allowed = false;  // MultigridSolver::allow_resolve_sweeps

  // After the fine level's update_point(): mu and rho down every level.
  void update_point() {
    for (int l = 1; l < levels(); ++l) levels_[l].sys->restrict_point(*levels_[l - 1].sys);
  }
  Level& fine() { return levels_.front(); }

  // Bytes moved so far under the byte model (SolveReport::bytes).
  double bytes = 0;
  void count(const DeviceSystem& sys, double per_voxel, int times = 1) {
    bytes += per_voxel * double(sys.voxels()) * times;
  }

  void smooth(int l, int sweeps, bool reverse) {
    Level& L = levels_[l];
    if (l == 0 && compact_) {
      count(*L.sys, bytes_per_voxel::sweep_compact, sweeps);
      L.sys->relax_gs_compact(L.rhs, L.u, sweeps, reverse);
      return;
    }
    count(*L.sys, sp_.jacobi ? bytes_per_voxel::jacobi : bytes_per_voxel::sweep, sweeps);
    if (sp_.jacobi)
      L.sys->relax_jacobi(L.rhs, L.u, L.tmp, sp_.jacobi_weight, sweeps);
    else
      L.sys->relax_gs(L.rhs, L.u, sweeps, reverse);
  }

  // Forward then backward sweeps: keeps the V-cycle a symmetric operator,
  // as a conjugate-gradient preconditioner must be.
  void smooth_symmetric(int l, int sweeps) {
    smooth(l, (sweeps + 1) / 2, false);
    smooth(l, sweeps / 2, true);
  }

  void vcycle(int l) {
    Level& L = levels_[l];
    if (l == levels() - 1) {
      smooth_symmetric(l, coarse_sweeps());
      return;
    }
    Level& C = levels_[l + 1];
    smooth(l, sp_.pre_sweeps, false);
    if (l == 0 && compact_) {
      L.sys->residual_compact(L.rhs, L.u, L.r);
      count(*L.sys, bytes_per_voxel::residual_compact);
    } else {
      L.sys->residual(L.rhs, L.u, L.r);
      count(*L.sys, bytes_per_voxel::residual);
    }
    restrict_residual(L, C);
    rt_.queue().enqueueFillBuffer(C.u, 0.0f, 0, C.sys->voxels() * sizeof(float));
    count(*C.sys, bytes_per_voxel::fill);
    vcycle(l + 1);
    prolong_add(C, L);
    smooth(l, sp_.post_sweeps, true);
  }

  // Full multigrid: solve on the coarsest level with its own b, then at each
  // finer level start from the prolonged solution and run one V-cycle.
  void full_multigrid() {
    for (int l = levels() - 1; l >= 0; --l) {
      Level& L = levels_[l];
      rt_.queue().enqueueCopyBuffer(L.sys->b(), L.rhs, 0, 0, L.sys->voxels() * sizeof(float));
      rt_.queue().enqueueFillBuffer(L.u, 0.0f, 0, L.sys->voxels() * sizeof(float));
      count(*L.sys, bytes_per_voxel::copy + bytes_per_voxel::fill);
      if (l == levels() - 1) {
        smooth_symmetric(l, coarse_sweeps());
      } else {
        prolong_add(levels_[l + 1], L);
        vcycle(l);
      }
    }
  }

  // z = M r: one V-cycle from zero with right-hand side r. The fine level
  // works on r and z themselves (the V-cycle only reads its right-hand side).
  void precondition(const cl::Buffer& r, const cl::Buffer& z) {
    Level& F = fine();
    const cl::Buffer rhs = F.rhs, u = F.u;
    F.rhs = r;
    F.u = z;
    rt_.queue().enqueueFillBuffer(z, 0.0f, 0, F.sys->voxels() * sizeof(float));
    count(*F.sys, bytes_per_voxel::fill);
    vcycle(0);
    F.rhs = rhs;
    F.u = u;
  }

  // ||rhs - A u|| / ||rhs|| of the fine level's u (into F.r), `rhs_norm`
  // given; by default against the system's own b (the V-cycle and the
  // preconditioner reuse F.rhs).
  double relative_residual() { return relative_residual(fine().sys->b(), b_norm_); }
  double relative_residual(const cl::Buffer& rhs, double rhs_norm) {
    Level& F = fine();
    F.sys->residual(rhs, F.u, F.r);
    count(*F.sys, bytes_per_voxel::residual + bytes_per_voxel::norm);
    return rhs_norm > 0 ? F.sys->norm(F.r) / rhs_norm : F.sys->norm(F.r);
  }

 private:
  int coarse_sweeps() const {
    // Tiny coarsest grids are relaxed to convergence; a large one (the
    // paper's two-level scheme) gets a fixed budget.
    const GridDesc& g = levels_.back().sys->grid();
    return grid_voxels(g) <= 4096 ? 60 : 8;
  }

  void add_level(std::unique_ptr<DeviceSystem> owned, DeviceSystem* sys) {
    Level L;
    L.owned = std::move(owned);
    L.sys = sys;
    const std::size_t bytes = sys->voxels() * sizeof(float);
    L.u = rt_.buffer(bytes);
    L.rhs = rt_.buffer(bytes);
    L.r = rt_.buffer(bytes);
    if (sp_.jacobi) L.tmp = rt_.buffer(bytes);
    levels_.push_back(std::move(L));
  }

  // On CPUs the transfers run a work-item per x-row (kernels/multigrid.cl,
  // *_rows: rows read in memory order), on GPUs a work-item per voxel.
  void launch(const cl::Kernel& k, const GridDesc& g) {
    if (rows_)
      rt_.enqueue_rows(k, g);
    else
      rt_.enqueue_3d(k, g);
  }

  void restrict_residual(const Level& F, const Level& C) {
    Runtime::set_args(restrict_, F.r, C.sys->fixed(), C.rhs, F.sys->grid(), C.sys->grid());
    launch(restrict_, C.sys->grid());
    count(*F.sys, 4), count(*C.sys, 4 + 1);  // fine r read; coarse rhs written, fixed read
  }

  void prolong_add(const Level& C, const Level& F) {
    Runtime::set_args(prolong_, C.u, F.sys->fixed(), F.u, F.sys->grid(), C.sys->grid());
    launch(prolong_, F.sys->grid());
    count(*C.sys, 4), count(*F.sys, 8 + 1);  // coarse u read; fine u read and written, fixed read
  }

  SolverParams sp_;
  Runtime& rt_;
  bool rows_;                     // CPU device: the transfers' row kernels
  bool compact_ = false;          // use_compact()
  bool compact_allowed_ = true;   // allow_compact()
  cl::Kernel restrict_, prolong_;  // created once: the V-cycle launches them every level
  double b_norm_ = 0;               // ||b|| of the fine level, fixed for the solve
  std::vector<Level> levels_;
};


// Mixed-precision iterative refinement (docs/solver.md, "float64 answers"):
// below this tolerance the float32 iteration is run to kRefineBelow, then
// corrected by float32 solves of A e = r for the float64 residual r of the
// float64 solution, each to kRefineInner relative to its r.
constexpr double kRefineBelow = 1e-4;
constexpr double kRefineInner = 1e-3;
constexpr int kMaxRefinements = 12;
// At or above this tolerance a conjugate-gradient solve stops on its
// recursive residual (Impl::iterate).
constexpr double kLooseTol = 1e-3;

// r = b - A u in float64 on the host (the stencil as the device stores it:
// boundary rows are c_0 x_p, interior rows the 19 points), over z-slabs on
// every core. Returns ||r||^2; the sum is taken in a fixed order (one partial
// per z-plane), so the result does not depend on the thread count.
double host_residual64(const GridDesc& g, const std::vector<float>& coef, const std::vector<float>& b,
                       const std::vector<double>& u, std::vector<double>& r) {
  const std::size_t N = grid_voxels(g), sy = std::size_t(g.nx), sz = sy * std::size_t(g.ny);
  long off[STENCIL_COEFS];
  const int table[STENCIL_COEFS][3] = {
#define SOFTSHELL_OFF(K, DX, DY, DZ) {DX, DY, DZ},
      STENCIL_OFFSETS(SOFTSHELL_OFF)
#undef SOFTSHELL_OFF
  };
  for (int k = 0; k < STENCIL_COEFS; ++k) off[k] = table[k][0] + table[k][1] * long(sy) + table[k][2] * long(sz);
  r.resize(N);
  std::vector<double> plane(std::size_t(g.nz), 0.0);
  auto planes = [&](int z0, int z1) {
    for (int z = z0; z < z1; ++z) {
      double acc2 = 0;
      for (int y = 0; y < g.ny; ++y)
        for (int x = 0; x < g.nx; ++x) {
          const std::size_t p = std::size_t(x) + sy * std::size_t(y) + sz * std::size_t(z);
          double ax = double(coef[p]) * u[p];
          if (!(x == 0 || y == 0 || z == 0 || x == g.nx - 1 || y == g.ny - 1 || z == g.nz - 1))
            for (int k = 1; k < STENCIL_COEFS; ++k)
              ax += double(coef[k * N + p]) * u[p + off[k]] + double(coef[k * N + p - off[k]]) * u[p - off[k]];
          r[p] = double(b[p]) - ax;
          acc2 += r[p] * r[p];
        }
      plane[std::size_t(z)] = acc2;
    }
  };
  const int threads = int(std::clamp<unsigned>(std::thread::hardware_concurrency(), 1u, 64u));
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(planes, g.nz * t / threads, g.nz * (t + 1) / threads);
  planes(0, g.nz / threads);
  for (std::thread& t : pool) t.join();
  double rr = 0;
  for (double v : plane) rr += v;
  return rr;
}

}  // namespace

struct MultigridSolver::Impl : Multigrid {
  Impl(DeviceSystem& fine, const SolverParams& sp) : Multigrid(fine, sp), sys(fine) {}
  DeviceSystem& sys;
  std::array<cl::Buffer, 5> pcg;  // x, r, z, p, q of the conjugate gradients, allocated on first use
  std::vector<double> u64;        // the last refined solve's float64 solution

  // Iterates on A u = rhs from the fine level's u: on entry F.r = rhs - A F.u
  // and rep.residuals.back() its relative norm, and, for plain V-cycles,
  // F.rhs holds rhs (they read it); on exit F.u holds the result and
  // rep.residuals.back() its true relative residual (evaluated on the
  // device, float32), or under a tol of kLooseTol or more the recursive one.
  void iterate(const cl::Buffer& rhs, double rhs_norm, double tol, SolveReport& rep,
               progress::Stage* stage = nullptr) {
    Level& F = fine();
    DeviceSystem& fine_sys = sys;
    Runtime& rt = fine_sys.runtime();
    const std::size_t n = fine_sys.voxels();
    const SolverParams& sp = params();
    // SolverParams::max_cycles bounds the whole solve, refinement included
    // (rep.cycles carries the cycles already spent).
    const int max_cycles = sp.max_cycles;
    if (!sp.krylov) {
      while (rep.residuals.back() > tol && rep.cycles < max_cycles) {
        vcycle(0);
        ++rep.cycles;
        rep.residuals.push_back(relative_residual(rhs, rhs_norm));
        if (stage) stage->residual(rep.residuals.back(), tol, rep.cycles);
      }
      return;
    }
    if (rep.residuals.back() <= tol) return;
    // Preconditioned conjugate gradients on A x = rhs from the current u; the
    // multigrid's fine-level buffers serve the V-cycle, so x, r, z, p, q are
    // separate.
    const std::size_t bytes = n * sizeof(float);
    if (!pcg[0]()) for (auto& buf : pcg) buf = rt.buffer(bytes);  // kept for the next solve
    // x and r start as F.u and F.r (rhs - A u, from the residual just
    // reported): the buffers are swapped in, not copied, and swapped back at
    // the end (F.u then holds x). The V-cycle's own fine-level u and r are
    // scratch meanwhile (precondition() lends it z as u).
    std::swap(F.u, pcg[0]);
    std::swap(F.r, pcg[1]);
    const double nb = rhs_norm;
    precondition(pcg[1], pcg[2]);
    std::swap(pcg[2], pcg[3]);  // p = z
    const cl::Buffer &x = pcg[0], &r = pcg[1], &z = pcg[2], &p = pcg[3], &q = pcg[4];
    double rz = fine_sys.dot(r, p);
    count(fine_sys, bytes_per_voxel::dot);
    // A loose tolerance (the sharpening's linearisation points) is judged by
    // the recursive residual: its float32 drift from the true one after the
    // one or two iterations these take, measured at 1e-10 to 1e-8 of ||rhs||
    // (105^3 and 96^3 faces), cannot move it across such a tol, and the true
    // residual's evaluation (a residual and a norm, the cost of a fifth of an
    // iteration) is saved.
    const bool recursive_ok = tol >= kLooseTol;
    bool true_residual = false;  // is r the true residual of x (not the recursive one)?
    while (rep.cycles < max_cycles) {
      fine_sys.apply(p, q);
      const double pq = fine_sys.dot(p, q);
      count(fine_sys, bytes_per_voxel::apply + bytes_per_voxel::dot);
      if (!(pq > 0)) break;  // breakdown: only at the float floor
      const double a = rz / pq;
      fine_sys.axpby(float(a), p, 1.0f, x);
      fine_sys.axpby(float(-a), q, 1.0f, r);
      ++rep.cycles;
      double rel = nb > 0 ? fine_sys.norm(r) / nb : 0.0;
      count(fine_sys, 2 * bytes_per_voxel::axpby + bytes_per_voxel::norm);
      true_residual = false;
      if (rel <= tol && !recursive_ok) {
        // The recursive residual drifts from the true one in float32: stop
        // only when the true residual agrees, else go on from it (residual
        // replacement) rather than stop just short of tol.
        fine_sys.residual(rhs, x, r);
        rel = nb > 0 ? fine_sys.norm(r) / nb : 0.0;
        count(fine_sys, bytes_per_voxel::residual + bytes_per_voxel::norm);
        true_residual = true;
      }
      rep.residuals.push_back(rel);
      if (stage) stage->residual(rel, tol, rep.cycles);
      if (rel <= tol) break;
      precondition(r, z);
      const double rz_new = fine_sys.dot(r, z);
      fine_sys.axpby(1.0f, z, float(rz_new / rz), p);
      count(fine_sys, bytes_per_voxel::dot + bytes_per_voxel::axpby);
      rz = rz_new;
    }
    // Report and judge the true residual of the final x (already in r when
    // the loop stopped on it; under a loose tol the recursive one).
    std::swap(F.u, pcg[0]);
    std::swap(F.r, pcg[1]);
    if (!true_residual && !(recursive_ok && rep.residuals.back() <= tol))
      rep.residuals.back() = relative_residual(rhs, rhs_norm);
  }

  // Mixed-precision iterative refinement from the float32 solution in F.u
  // (rep.residuals.back() its float32-evaluated residual) to `tol` in
  // float64: x64 = F.u; repeat r = b - A x64 (float64, host), stop at
  // ||r|| / ||b|| <= tol, else solve A e = r / ||r|| in float32 on the
  // device to kRefineInner and add ||r|| e to x64. Leaves float(x64) in F.u
  // and x64 in u64; the residuals reported are the float64 ones.
  void refine(double tol, SolveReport& rep) {
    Level& F = fine();
    Runtime& rt = sys.runtime();
    const std::size_t n = sys.voxels(), bytes = n * sizeof(float);
    const std::vector<float> coef = sys.download_coefficients(), b = sys.download_b();
    std::vector<float> u32(n);
    rt.queue().enqueueReadBuffer(F.u, CL_TRUE, 0, bytes, u32.data());
    u64.assign(u32.begin(), u32.end());
    double bb = 0;
    for (float v : b) bb += double(v) * v;
    const double nb = std::sqrt(bb);
    std::vector<double> r;
    double rel = std::sqrt(host_residual64(sys.grid(), coef, b, u64, r)) / (nb > 0 ? nb : 1.0);
    rep.residuals.back() = rel;  // the float64 evaluation of the float32 solution
    std::vector<float> rhs(n);
    for (int step = 0; step < kMaxRefinements && rel > tol && rep.cycles < params().max_cycles; ++step) {
      double rn = 0;
      for (double v : r) rn += v * v;
      rn = std::sqrt(rn);
      if (!(rn > 0)) break;
      for (std::size_t i = 0; i < n; ++i) rhs[i] = float(r[i] / rn);
      rt.queue().enqueueWriteBuffer(F.rhs, CL_FALSE, 0, bytes, rhs.data());
      rt.queue().enqueueFillBuffer(F.u, 0.0f, 0, bytes);
      rt.queue().enqueueCopyBuffer(F.rhs, F.r, 0, 0, bytes);  // the residual of e = 0
      count(sys, bytes_per_voxel::fill + bytes_per_voxel::copy);
      const double scaled_norm = sys.norm(F.rhs);
      SolveReport inner;
      inner.residuals.push_back(1.0);
      inner.cycles = rep.cycles;
      const cl::Buffer rhs_buf = F.rhs;  // precondition() swaps F.rhs for a while
      iterate(rhs_buf, scaled_norm, kRefineInner, inner);
      rep.cycles = inner.cycles;
      rt.queue().enqueueReadBuffer(F.u, CL_TRUE, 0, bytes, u32.data());
      for (std::size_t i = 0; i < n; ++i) u64[i] += rn * double(u32[i]);
      const double prev = rel;
      rel = std::sqrt(host_residual64(sys.grid(), coef, b, u64, r)) / (nb > 0 ? nb : 1.0);
      rep.residuals.push_back(rel);
      ++rep.refinements;
      if (!(rel < 0.9 * prev)) break;  // stagnation: float64 cannot help further
    }
    for (std::size_t i = 0; i < n; ++i) u32[i] = float(u64[i]);
    rt.queue().enqueueWriteBuffer(F.u, CL_TRUE, 0, bytes, u32.data());
  }
};

MultigridSolver::MultigridSolver(DeviceSystem& fine, const SolverParams& sp)
    : impl_(std::make_unique<Impl>(fine, sp)) {}
MultigridSolver::~MultigridSolver() = default;
const cl::Buffer& MultigridSolver::solution() const { return impl_->fine().u; }

int MultigridSolver::levels() const { return impl_->levels(); }
const SolverParams& MultigridSolver::params() const { return impl_->params(); }
void MultigridSolver::update_point() { impl_->update_point(); }
void MultigridSolver::allow_compact_smoother(bool on) { impl_->allow_compact(on); }
void MultigridSolver::allow_resolve_sweeps(bool on) { impl_->resolve_sweeps_allowed = on; }
bool MultigridSolver::compact_smoother_in_use() const { return impl_->compact_in_use(); }
void MultigridSolver::load_solution(const cl::Buffer& u) {
  Impl& mg = *impl_;
  const std::size_t bytes = mg.sys.voxels() * sizeof(float);
  mg.sys.runtime().queue().enqueueCopyBuffer(u, mg.fine().u, 0, 0, bytes);
  mg.sys.zero_fixed(mg.fine().u);
  mg.has_solution = true;
}
const std::vector<double>& MultigridSolver::solution64() const { return impl_->u64; }

std::vector<float> MultigridSolver::solve(SolveReport* report, const std::vector<float>* init, bool warm,
                                          double tol_override, bool read_back) {
  const auto t0 = std::chrono::steady_clock::now();
  Impl& mg = *impl_;
  DeviceSystem& fine = impl_->sys;
  const SolverParams& sp = mg.params();
  const double tol = tol_override > 0 ? tol_override : sp.tol;
  Runtime& rt = fine.runtime();
  Level& F = mg.fine();
  const std::size_t n = fine.voxels();
  SolveReport rep;
  rep.levels = mg.levels();
  mg.use_compact();
  mg.bytes = 0;
  mg.u64.clear();
  mg.measure_b();
  mg.count(fine, bytes_per_voxel::norm);
  // Plain V-cycles read the fine level's b from F.rhs; the conjugate
  // gradients lend the preconditioner their own residual instead, and the
  // full multigrid start copies b down every level itself.
  if (!sp.krylov) {
    rt.queue().enqueueCopyBuffer(fine.b(), F.rhs, 0, 0, n * sizeof(float));
    mg.count(fine, bytes_per_voxel::copy);
  }
  if (init) {
    if (init->size() != n) throw std::invalid_argument("initial u has the wrong size");
    rt.queue().enqueueWriteBuffer(F.u, CL_FALSE, 0, n * sizeof(float), init->data());
    fine.zero_fixed(F.u);
    rep.residuals.push_back(mg.relative_residual());
    rt.queue().finish();  // `init` may go out of scope after the call
  } else if (warm && mg.has_solution) {
    rep.residuals.push_back(mg.relative_residual());  // F.u: the previous solution, fixed voxels at 0
    // A re-solve's stage (SolverParams::resolve_sweeps): sweeps first, and
    // the conjugate gradients only if they leave the residual above tol.
    // The sweeps relax on F.rhs, which the conjugate gradients do not read.
    if (mg.resolve_sweeps_allowed && sp.resolve_sweeps > 0 && sp.krylov && tol >= kLooseTol &&
        rep.residuals.back() > tol) {
      rt.queue().enqueueCopyBuffer(fine.b(), F.rhs, 0, 0, n * sizeof(float));
      mg.count(fine, bytes_per_voxel::copy);
      mg.smooth_symmetric(0, sp.resolve_sweeps);
      rep.residuals.push_back(mg.relative_residual());
    }
  } else if (sp.full_multigrid) {
    rep.residuals.push_back(1.0);  // u = 0
    const progress::Stage fmg("full multigrid, " + std::to_string(mg.levels()) + " levels");
    mg.full_multigrid();  // leaves b in F.rhs
    rep.residuals.push_back(mg.relative_residual());
  } else {
    rt.queue().enqueueFillBuffer(F.u, 0.0f, 0, n * sizeof(float));
    mg.count(fine, bytes_per_voxel::fill);
    rep.residuals.push_back(mg.relative_residual());
  }
  mg.has_solution = false;  // F.u is scratch until the solve ends
  // Below kRefineBelow, float32 alone would stall at its rounding floor:
  // iterate to kRefineBelow, then refine in float64.
  const bool refine = tol < kRefineBelow;
  {
    progress::Stage stage(sp.krylov ? "solve (PCG)" : "solve (V-cycles)");
    mg.iterate(fine.b(), mg.b_norm(), refine ? kRefineBelow : tol, rep, &stage);
  }
  if (refine && std::isfinite(rep.residuals.back())) {
    const progress::Stage stage("refine (float64 residuals)");
    mg.refine(tol, rep);
  }
  rep.converged = rep.residuals.back() <= tol;
  std::vector<float> u(read_back ? n : 0);
  if (read_back) rt.queue().enqueueReadBuffer(F.u, CL_TRUE, 0, n * sizeof(float), u.data());
  // A relative residual says nothing when ||b|| is not finite (it is then
  // taken as 0): a system whose b or solution overflowed is not converged,
  // whatever the residual read (data at the ends of float's range, found
  // by fuzzing the classify pipeline). Unread, u is checked by whoever
  // reads it (a sharpening step's solution reaches the last step's).
  if (!std::isfinite(mg.b_norm()) ||
      std::any_of(u.begin(), u.end(), [](float x) { return !std::isfinite(x); })) {
    rep.converged = false;
    rep.residuals.back() = std::numeric_limits<double>::quiet_NaN();
  }
  mg.has_solution = true;
  rep.bytes = mg.bytes;
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (report) *report = rep;
  return u;
}

std::vector<float> solve(DeviceSystem& fine, const SolverParams& sp, SolveReport* report,
                         const std::vector<float>* init) {
  const auto t0 = std::chrono::steady_clock::now();
  MultigridSolver mg(fine, sp);
  std::vector<float> u = mg.solve(report, init);
  // This one-shot form counts building the hierarchy as part of the solve.
  if (report) report->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return u;
}

std::vector<float> solve(Runtime& rt, const Densities& d, const SolverParams& sp, SolveReport* report,
                         const std::vector<float>* init) {
  DeviceSystem fine(rt, d);
  return solve(fine, sp, report, init);
}


VariationalClassifier::VariationalClassifier(Runtime& rt, const Volume& v, const VariationalParams& params,
                                             const SolverParams& sp, const std::vector<std::uint8_t>* mask)
    : rt_(rt), params_(params), map_(v.intensity_map()) {
  const auto t0 = std::chrono::steady_clock::now();
  Volume vn = v;
  for (float& f : vn.data) f = static_cast<float>(map_.to_unit(f));
  sys_ = std::make_unique<DeviceSystem>(rt, vn, params, mask);
  // The upload was blocking: the normalised copy is not needed any more.
  vn.data.clear();
  vn.data.shrink_to_fit();
  mg_ = std::make_unique<MultigridSolver>(*sys_, sp);
  // The hierarchy is built: the fine level's tensor is not read again
  // (re-solves update mu, rho, the diagonal and b only).
  sys_->release_tensor();
  rt.queue().finish();
  geometry_ = std::move(vn);
  setup_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

VariationalClassifier::~VariationalClassifier() = default;

bool VariationalClassifier::can_update(const VariationalParams& p) const {
  return p.beta == params_.beta && p.kappa == params_.kappa && p.sigma_mm == params_.sigma_mm &&
         p.grad_sigma_mm == params_.grad_sigma_mm && p.edge_share == params_.edge_share &&
         p.edge_share_fine == params_.edge_share_fine && p.edge_split == params_.edge_split &&
         p.edge_split_from == params_.edge_split_from && p.g_ref == params_.g_ref &&
         p.edge_weight == params_.edge_weight && p.edge_reference == params_.edge_reference && same_crest(p);
}

// The echo-crest rule was built with its parameters; a new isovalue or
// shell shift re-applies it (DeviceSystem::update_point), other parameters
// need a new setup.
bool VariationalClassifier::same_crest(const VariationalParams& p) const {
  const CrestParams &a = p.crest, &b = params_.crest;
  if (!(a.ridge > 0) && !(b.ridge > 0)) return true;
  return a.ridge == b.ridge && a.quantile == b.quantile && a.reach_mm == b.reach_mm && a.above_mm == b.above_mm &&
         a.pad_mm == b.pad_mm && a.min_edge == b.min_edge && a.shadow == b.shadow && a.lift == b.lift &&
         a.axis == b.axis;
}

void VariationalClassifier::update(const VariationalParams& p) {
  if (!can_update(p))
    throw std::invalid_argument("VariationalClassifier::update: beta, kappa, the lowpass sigmas, the edge reference, the edge weight and the echo-crest rule's parameters need a new setup");
  const auto t0 = std::chrono::steady_clock::now();
  sys_->update_point(p);
  mg_->update_point();
  rt_.queue().finish();
  sharpened_ = polishable_ = false;
  params_ = p;
  update_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

Volume VariationalClassifier::solve(SolveReport* report, const Volume* init, bool warm, const SequenceStart* sequence) {
  const std::vector<float>* linear_in = sequence ? sequence->linear_in : nullptr;
  if (linear_in && linear_in->size() != geometry_.voxels())
    throw std::invalid_argument("sequence start has another voxel count than the volume");
  if (init && init->dims != geometry_.dims)
    throw std::invalid_argument("initial opacity has other dims than the volume");
  if (sharpened_) {
    // The last solve left the sharpening term in the system: back to the
    // linear functional first.
    sys_->update_point(params_);
    mg_->update_point();
    sharpened_ = false;
  }
  const int steps = params_.sharpen_iterations;
  // With sharpening, the linear solution and every step but the last only
  // give the next linearisation point: solved to SolverParams::sharpen_tol
  // (or the solver's tol, if looser), the last step to the solver's tol.
  const double loose = std::max(mg_->params().sharpen_tol, mg_->params().tol);
  // With sharpening the result depends on where the loose linear solve
  // stops, so it starts as a cold one does (FMG), not from `init`; a warm
  // re-solve starts it from the last linear solution (kept on the device,
  // keep_resolve_start) instead of FMG, the first sharpening step from the
  // new linear solution, as a cold solve does, and the last step from the
  // new previous stage's solution plus the last solve's change over that
  // step (it moves little with a parameter). Measured against sharpening
  // from converged solves, the result is as close as a cold
  // classification's (docs/numerics.md, "Re-solving").
  SolveReport local;
  if (!report) report = &local;
  const std::size_t bytes = geometry_.voxels() * sizeof(float);
  const bool keep = keep_start_ && steps > 0;
  if (keep && kept_.size() != std::size_t(steps) + 1) kept_.assign(std::size_t(steps) + 1, cl::Buffer()), kept_linear_ = kept_steps_ = false;
  if (keep) {
    for (cl::Buffer& b : kept_)
      if (b() == nullptr) b = rt_.buffer(bytes);
    if (scratch_() == nullptr) scratch_ = rt_.buffer(bytes);
  }
  const bool from_last = warm && !linear_in && keep && kept_linear_;
  const bool extrapolate = from_last && kept_steps_;
  // A warm re-solve's last step stops at resolve_tol (polish() finishes it).
  const double last_tol = from_last && mg_->params().resolve_tol > mg_->params().tol ? mg_->params().resolve_tol : 0.0;
  polishable_ = false;
  // Warm re-solves relax on the compact stencil (keep_resolve_start).
  mg_->allow_compact_smoother(from_last);
  mg_->allow_resolve_sweeps(from_last);
  kept_linear_ = kept_steps_ = false;
  if (from_last) mg_->load_solution(kept_[0]);
  std::vector<float> u = steps > 0 ? mg_->solve(report, linear_in, from_last, loose)
                                   : mg_->solve(report, init ? &init->data : linear_in, warm);
  // The new linear solution waits in scratch_ until the first sharpening
  // step has used the last one (kept_[0]).
  const bool keep_linear = keep && report->converged;
  if (keep_linear) rt_.queue().enqueueCopyBuffer(mg_->solution(), scratch_, 0, 0, bytes);
  if (sequence && sequence->linear_out) *sequence->linear_out = u;
  double crest = 0;
  // A linear solve that did not converge is reported as it is: sharpening
  // would only spend more cycles on it.
  const bool linear_ok = report->converged;
  if (steps > 0 && linear_ok) {
    // The crest of u, lent to a Volume and taken back (no copy).
    Volume lent = geometry_.with_data(std::move(u), ScalarType::Float32);
    crest = crest_of(lent);
    u = std::move(lent.data);
  }
  const bool sharpen = steps > 0 && linear_ok && params_.sharpen_lambda > 0 && crest > 0;
  if (keep_linear && !sharpen) std::swap(scratch_, kept_[0]), kept_linear_ = true;
  if (sharpen) {
    // The barrier relative to the linear solution's own crest, in units of
    // u_ind: ratio = (1 - barrier) / barrier puts the unstable point there.
    const double barrier = std::clamp(params_.sharpen_barrier * crest / params_.u_ind, 0.05, 0.95);
    const double ratio = (1 - barrier) / barrier;
    SolveReport step_report;
    for (int s = 0; s < steps; ++s) {
      const progress::Stage stage("sharpen " + std::to_string(s + 1) + "/" + std::to_string(steps));
      // The linearisation point is the solution still on the device: no
      // host copy is kept through the update and the solve, and no device
      // copy made (8 bytes per voxel of the peak).
      std::vector<float>().swap(u);
      sys_->update_sharpen(params_, mg_->solution(), params_.sharpen_lambda, ratio);
      mg_->update_point();
      sharpened_ = true;
      if (keep_linear) {
        // Stage s's new solution (the linearisation point) kept as kept_[s]
        // for the next re-solve. The last step, solved to the solver's
        // tolerance, starts from it plus the last solve's change over the
        // step (kept_[s + 1] - kept_[s]): its result does not depend on its
        // start. A loose step's does (it stops within sharpen_tol of its
        // answer, and the double well carries that on): started so, the first
        // step was often within its tolerance at once, took no iteration, and
        // landed up to 7x further from the converged reference than a cold
        // classification (the 64^3 face, the isovalue back from +5 %).
        const std::size_t k = std::size_t(s);
        if (s > 0) rt_.queue().enqueueCopyBuffer(mg_->solution(), scratch_, 0, 0, bytes);
        if (extrapolate && s + 1 == steps) {
          sys_->axpby(1.0f, kept_[k + 1], 1.0f, mg_->solution());
          sys_->axpby(-1.0f, kept_[k], 1.0f, mg_->solution());
          sys_->zero_fixed(mg_->solution());
        }
        std::swap(scratch_, kept_[k]);
        if (s == 0) kept_linear_ = true;
      }
      // Only the last step's solution comes back to the host.
      u = mg_->solve(&step_report, nullptr, true, s + 1 < steps ? loose : last_tol, s + 1 == steps);
      if (keep_linear && s + 1 == steps && step_report.converged) keep_last_step();
      report->cycles += step_report.cycles;
      report->seconds += step_report.seconds;
      report->converged = step_report.converged;  // the last step's, to the solver's tol (or resolve_tol)
      report->residuals.push_back(step_report.residuals.back());
    }
    polishable_ = last_tol > 0 && step_report.converged && step_report.residuals.back() > mg_->params().tol;
  }
  if (steps > 0 && !sharpened_ && linear_ok) {
    // No sharpening after all (nothing drawn): finish the loose linear
    // solve to the solver's tol.
    SolveReport tail;
    u = mg_->solve(&tail, nullptr, true);
    report->cycles += tail.cycles;
    report->seconds += tail.seconds;
    report->converged = tail.converged;
    report->residuals.push_back(tail.residuals.back());
  }
  return finish(std::move(u));
}

Volume VariationalClassifier::polish(SolveReport* report) {
  if (!polishable_) return Volume{};
  polishable_ = false;
  const progress::Stage stage("polish");
  // The system still holds the last step's sharpening term and the solver
  // its solution: the same solve, carried on to the solver's tol.
  SolveReport local;
  if (!report) report = &local;
  std::vector<float> u = mg_->solve(report, nullptr, true, 0.0, true);
  // The stages kept by the solve polished (an update in between leaves
  // nothing to polish): its last step now the polished one.
  if (report->converged && kept_steps_) keep_last_step();
  return finish(std::move(u));
}

void VariationalClassifier::keep_last_step() {
  rt_.queue().enqueueCopyBuffer(mg_->solution(), kept_.back(), 0, 0, geometry_.voxels() * sizeof(float));
  kept_steps_ = true;
}

Volume VariationalClassifier::finish(std::vector<float> u) {
  Volume out = geometry_.with_data(std::move(u), ScalarType::Float32);
  gain_ = 1.0;
  if (params_.max_gain > 0) {
    // u_ind from the data (VariationalParams::max_gain): by linearity the
    // solution for u_ind / crest is u / crest.
    const double crest = crest_of(out);
    if (crest > 0) gain_ = std::clamp(params_.u_ind / crest, 1.0, params_.max_gain);
  }
  for (float& f : out.data) f = std::clamp(float(gain_ * f), 0.0f, 1.0f);
  return out;
}

Volume classify_variational(Runtime& rt, const Volume& v, const VariationalParams& params, const SolverParams& sp,
                            SolveReport* report, const Volume* init, const std::vector<std::uint8_t>* mask,
                            ClassifyTiming* timing, const SequenceStart* sequence) {
  if (init && init->dims != v.dims) throw std::invalid_argument("initial opacity has other dims than the volume");
  std::optional<progress::Stage> setup(std::in_place, "setup (lowpass, gradients, system, levels)");
  VariationalClassifier c(rt, v, params, sp, mask);
  setup.reset();
  const auto t1 = std::chrono::steady_clock::now();
  Volume u = c.solve(report, init, false, sequence);
  if (timing) {
    timing->setup = c.setup_seconds();
    timing->solve = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
    timing->resolved = c.resolved();
    timing->crest = c.crest();
  }
  return u;
}

}  // namespace softshell
