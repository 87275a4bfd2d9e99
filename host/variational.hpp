// The variational opacity classifier (paper Section 3; docs/numerics.md): the
// per-voxel densities, the assembled 19-point system on the device, and the
// multigrid solver.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "cl_runtime.hpp"
#include "stencil.h"
#include "crest.hpp"
#include "volume.hpp"

namespace softshell {

// The paper's parameters, named as in the paper, on normalised data
// (intensities in [0, 1], gradients per mm). v_iso is normalised too.
struct VariationalParams {
  // Defaults: the shell functional (docs/numerics.md, "The shell
  // functional"; docs/parameters.md has the study behind each value). With
  // literal_defaults() the paper's functional and the weights the earlier
  // study chose for it.
  double alpha = 1.0, beta = 2.0, gamma = 1.0, omega = 0.0, delta = 0.01, epsilon = 0.01, u_ind = 1.0;
  double v_iso = 0.5;
  double sigma_mm = 1.0;  // lowpass giving v~
  // The |grad v| in F_iso's denominator and in F_ind taken from v lowpassed
  // with this sigma (mm) instead of from the raw v: speckle then no longer
  // reads as edges everywhere in tissue. 0: the paper's literal functional.
  double grad_sigma_mm = 1.5;
  // Weight of an isotropic smoothness term kappa |grad u|^2 added to the
  // paper's functional (T -> T + kappa I). 0: the paper's literal functional.
  double kappa = 0.1;
  // The shell functional (all three 0: the paper's terms):
  //  - thickness_mm: the shell's full width at half maximum across the
  //    surface, in mm (at least 2 voxels, resolved_for()); F_iso's weight is
  //    (W / h^2)^profile_power with h half the thickness, W the paper's
  //    squared distance to the isosurface, so u falls off as a power
  //    2 profile_power of the distance instead of as 1 / (1 + d^2);
  //  - edge_share: the reference edge gradient g_ref is the median |grad v|
  //    of the top edge_share of the scanned voxels; F_ind's edge weight is
  //    min(1, |grad v| / g_ref)^edge_power, and T and epsilon are in units of
  //    g_ref^2, so gain, type and voxel size drop out (beta and kappa are then
  //    squared lengths in mm^2, times F_ind's scale).
  double thickness_mm = 2.0, profile_power = 2.0;
  // Upper bound of the shell F_iso weight (W / h^2)^profile_power: beyond
  // it u < 1 / (1 + weight_cap) anyway, and the bound keeps the coefficient
  // contrast, hence the multigrid convergence, in check.
  double weight_cap = 100.0;
  // The shell's centre moved this far (mm) from the isosurface toward its
  // bright side, onto the boundary echo's crest (docs/numerics.md, "The shell
  // on the echo"). 0: centred on the isosurface.
  double shell_shift_mm = 0.5;
  double edge_share = 0.03, edge_power = 3.5;
  // A small object's walls (docs/parameters.md, "A small object's walls"):
  // where the median |grad v| of the top edge_share_fine stands at least
  // edge_split times that of the top edge_share, the strongest edges are a
  // population of their own, fewer than edge_share of the voxels (a small
  // cyst's walls among speckle: the top edge_share is then mostly speckle,
  // and F_ind gives speckle edges an object's weight); g_ref is then the top
  // edge_share_fine's median. edge_split 0: off (always edge_share).
  // Between edge_split_from and edge_split the two medians are blended
  // (geometrically, the weight rising linearly with the ratio from 0 to 1),
  // so that g_ref does not jump by the ratio where the ratio crosses one
  // threshold (a small change of resolution or noise); edge_split_from 0
  // (or not below edge_split): a switch at edge_split.
  double edge_share_fine = 0.01, edge_split = 2.0, edge_split_from = 1.6;
  // u_ind from the data (the shell functional): the system is linear in
  // u_ind, so solving with u_ind / crest scales u by 1 / crest exactly; the
  // crest is the median of u on the shell's ridge (voxels where u is a
  // maximum across the shell, crest_of()), so the typical shell peaks at
  // u_ind. The factor is at most max_gain; 0 turns it off.
  double max_gain = 0.0;
  // Sharpening (docs/numerics.md, "Sharpening"): a non-linear term
  // lambda u^2 (1 - u/u_ind)^2 weighted so its barrier sits at
  // sharpen_barrier x the crest of the linear solution (crest_of); it pulls
  // u above the barrier toward u_ind and below it toward 0. Solved by
  // sharpen_iterations fixed-point steps, each a pointwise update and a warm
  // re-solve. 0 iterations: the linear functional.
  int sharpen_iterations = 2;
  double sharpen_lambda = 2.0, sharpen_barrier = 0.3;  // barrier 0.5 until 2026-11-27 (docs/parameters.md, "The sharpening barrier")
  // The resolved reference gradient (per mm of normalised intensity): 0
  // until DeviceSystem takes it from the data (edge_share > 0), or given.
  double g_ref = 0;
  // The top edge_share_fine's median over the top edge_share's, as measured
  // when g_ref was taken from the data (edge_split's test: g_ref is the top
  // edge_share_fine's where it is at least edge_split); 0 when not measured
  // (edge_split 0, the bone cue's reference, or a given g_ref).
  double g_ref_ratio = 0;
  // The bone cue (host/bone_cue.hpp; docs/numerics.md, "The bone cue"): a
  // per-voxel factor w in [0, 1] on the edge strength |grad v| wherever it
  // enters the functional (F_ind's edge weight, F_iso's denominator, the
  // sharpening's edge gate), so edges without an acoustic shadow beneath
  // them pull u toward u_ind less. Null: off (w = 1). One entry per voxel.
  std::shared_ptr<const std::vector<float>> edge_weight;
  // Where the reference edge gradient g_ref comes from when edge_weight is
  // given: Cue, the bone cue's rule (the median weighted |grad v| of the
  // voxels weighted at least 1/2: the cued bone echoes); Weighted, the top
  // edge_share of the weighted |grad v| (the shadow walls' weights: the
  // strongest edges that remain); Data, the data's own (unweighted).
  enum class EdgeReference { Cue, Weighted, Data };
  EdgeReference edge_reference = EdgeReference::Cue;
  // Shells on a bright echo's crest (host/crest.hpp; docs/parameters.md,
  // "The echo's crest"): F_iso re-centred on the crest of ridges along the
  // beam (crest.axis). ridge 0: off (the default; --literal turns it off).
  CrestParams crest{0.0};
  ClassifyCoeffs coeffs() const;
  // The paper's functional exactly (no lowpassed |grad v|, no kappa, no
  // shell terms) with the weights chosen for it by the earlier study.
  static VariationalParams literal_defaults();
  bool literal() const {
    return grad_sigma_mm == 0 && kappa == 0 && thickness_mm == 0 && edge_share == 0 && sharpen_iterations == 0 &&
           max_gain == 0 && !edge_weight;
  }
  // The shell thickness in force on a grid of this spacing: thickness_mm,
  // but at least 2 voxels along the coarsest axis (a thinner shell cannot be
  // sampled, rendered or oriented).
  double effective_thickness_mm(const Vec3d& spacing) const;
};

// Small volumes (docs/parameters.md, "Small volumes"): the default length
// scales -- the lowpasses (sigma_mm, grad_sigma_mm), the shell thickness and
// the isovalue field's spread -- are in mm for anatomy-sized scans; a volume
// whose smallest extent (dims x spacing, over the axes with at least 2
// voxels) is below reference_mm cannot hold them (a 1 mm lowpass is +-3 mm
// wide), so they shrink by this factor: min(1, smallest extent /
// reference_mm); beta and kappa, squared lengths, by its square. 1 when
// reference_mm <= 0, and when the smallest extent is under kSmallVolumeMinMm
// (a spacing in the wrong unit, which the lowpass checks then refuse).
constexpr double kSmallVolumeMinMm = 1.0;
double small_volume_scale(const Dims3& dims, const Vec3d& spacing, double reference_mm);
// The reference extent `softshell classify --small-volume` takes by default
// (chosen on the PLUS IMLiF volume, 4.6 mm thin: not held out).
constexpr double kSmallVolumeMm = 20.0;
// p's length scales times f: sigma_mm, grad_sigma_mm and thickness_mm by f,
// beta and kappa (squared lengths) by f^2. The classify CLI does the same to
// the ones not given on its command line.
void scale_length_scales(VariationalParams& p, double f);

// The median of u over its ridge voxels: u above 5 % of its maximum and not
// below either neighbour along the axis where its second difference is most
// negative (a maximum across a shell). 0 when there is none.
double crest_of(const Volume& u);

// The reference edge gradient of a field of |grad v|^2 (negative entries are
// not scanned): the median |grad v| of its top `share` entries. 0 when no
// entry is usable.
double reference_edge_gradient(const std::vector<float>& grad2, double share);
// The same with VariationalParams::edge_split's rule: the median of the top
// `fine_share` when it is at least `split` times the top `share`'s (split >
// 0 and fine_share < share), else the top `share`'s.
// Between split_from and split the medians are blended: g_ref = (top
// share's) x ratio^w, w = (ratio - split_from) / (split - split_from).
struct ReferenceEdge {
  double g_ref = 0;   // 0: no usable entry
  double share = 0;   // the share taken (fine_share at a weight of 1)
  double ratio = 0;   // the top fine_share's median over the top share's (0: not measured)
  double weight = 0;  // the top fine_share's weight in g_ref, in [0, 1]
};
ReferenceEdge reference_edge_gradient(const std::vector<float>& grad2, double share, double fine_share, double split,
                                      double split_from = 0.0);
// The weight of the top fine share's median at `ratio` (VariationalParams::
// edge_split, edge_split_from): 0 below split_from, 1 from split, linear
// between; a switch at split when split_from is 0 or not below it; 0 when
// split is 0 (off).
double edge_split_weight(double ratio, double split, double split_from);

// Per-voxel densities (docs/numerics.md): mu, rho, the tangential tensor T
// (xx, yy, zz, xy, xz, yz) and the fixed flag, on a grid with spacing h and
// voxel volume V = hx hy hz. Host copies, for tests and the float64 oracle.
struct Densities {
  Dims3 dims{0, 0, 0};
  Vec3d spacing{1, 1, 1};
  std::vector<float> mu, rho;
  std::array<std::vector<float>, 6> T;
  std::vector<std::uint8_t> fixed;  // 1: u held at 0
  std::size_t voxels() const { return dims[0] * dims[1] * dims[2]; }
};

// Orderings of the Gauss-Seidel smoother (DeviceSystem::set_gs_order).
enum class GsOrder { Points, Slabs };

// One level of the system on the device: densities, the assembled stencil
// (10 coefficients per voxel, kernels/stencil.h), b, and the operations the
// solver needs on it.
class DeviceSystem {
 public:
  // Uploads densities and assembles A and b.
  DeviceSystem(Runtime& rt, const Densities& d);
  // Computes the densities from a normalised volume on the device (lowpass,
  // gradients, densities kernel), then assembles. `mask` (optional, one byte
  // per voxel, 0 = unscanned) fixes voxels.
  DeviceSystem(Runtime& rt, const Volume& v_normalised, const VariationalParams& p,
               const std::vector<std::uint8_t>* mask = nullptr);
  // The next coarser level: restricted densities on the grid of floor(n/2)+1
  // voxels per axis, spacing 2h, re-assembled (docs/numerics.md).
  static std::unique_ptr<DeviceSystem> coarsen(const DeviceSystem& fine);

  // Re-targets a system built from a volume to new pointwise parameters
  // (alpha, gamma, omega, delta, epsilon, u_ind, v_iso: they change only mu,
  // rho, the diagonal and b); beta, kappa and the lowpass sigmas must be
  // those it was built with (VariationalClassifier checks). The result equals
  // a fresh build with `p`. Throws std::logic_error unless updatable().
  void update_point(const VariationalParams& p);
  bool updatable() const { return bool(sources_[0]()); }
  // update_point(p) plus the sharpening term linearised about u0 (one
  // fixed-point step of the non-linear functional; docs/numerics.md,
  // "Sharpening"): mu += lambda ((1 - a)^2 + ratio a^2), rho += lambda ratio
  // a^2 u_ind, a = clamp(u0 / u_ind, 0, 1).
  void update_sharpen(const VariationalParams& p, const std::vector<float>& u0, double lambda, double ratio);
  // The same from a device buffer of voxels() floats (read by the kernel
  // only; the caller keeps it), e.g. MultigridSolver::solution().
  void update_sharpen(const VariationalParams& p, const cl::Buffer& u0, double lambda, double ratio);
  // The parameters in force on a volume-built level: g_ref resolved from the
  // data when it was 0, thickness_mm raised to its voxel floor.
  const VariationalParams& resolved() const { return resolved_; }
  const CrestReport& crest() const { return crest_; }
  // On a coarse level made by coarsen(fine): re-restricts mu and rho after
  // fine.update_point() (or the fine level's own restrict_point) and updates
  // the diagonal and b to match.
  void restrict_point(const DeviceSystem& fine);

  const GridDesc& grid() const { return grid_; }
  std::size_t voxels() const { return grid_voxels(grid_); }
  Runtime& runtime() const { return rt_; }

  cl::Event apply(const cl::Buffer& x, const cl::Buffer& y) const;                      // y = A x
  cl::Event residual(const cl::Buffer& rhs, const cl::Buffer& x, const cl::Buffer& r) const;  // r = rhs - A x
  cl::Event residual(const cl::Buffer& x, const cl::Buffer& r) const { return residual(b_, x, r); }
  // Gauss-Seidel sweeps in the system's ordering (gs_order()); `reverse`
  // runs a sweep exactly backwards (colours and rows in reverse order), so a
  // forward and a reverse sweep together are symmetric. Returns the first and
  // the last kernel launched (profiling events).
  std::pair<cl::Event, cl::Event> relax_gs(const cl::Buffer& rhs, const cl::Buffer& x, int sweeps,
                                           bool reverse) const;
  // Gauss-Seidel ordering: GsOrder::Points, 8 colours by the parity of
  // (x, y, z), a work-item per voxel (coalesced: GPUs); GsOrder::Slabs, 2
  // colours of z-slabs of gs_slab() planes, a work-item per slab relaxing its
  // planes, rows and x in order (kernels/system.cl, relax_gs_slabs: whole
  // cache lines, one ascending stream per array: CPUs; a stronger,
  // line-ordered smoother). Default: Points on GPUs, Slabs of 1 plane
  // otherwise (zebra-plane Gauss-Seidel, lexicographic in each plane);
  // coarsen() passes both on.
  GsOrder gs_order() const { return gs_order_; }
  int gs_slab() const;  // planes per slab (GsOrder::Slabs)
  void set_gs_order(GsOrder o) { gs_order_ = o; }
  void set_gs_slab(int planes) { gs_slab_ = planes; }  // 0: the default (1)
  // Weighted Jacobi sweeps; `tmp` is scratch of the same size.
  void relax_jacobi(const cl::Buffer& rhs, const cl::Buffer& x, const cl::Buffer& tmp, double w, int sweeps) const;
  // The smoother's compact copy of the stencil (kernels/system.cl,
  // system_compact; docs/solver.md, "A compact stencil for the smoother"):
  // the off-diagonals in bfloat16 and a diagonal correction that keeps every
  // row sum, 22 bytes per voxel besides the float32 stencil. Built from the
  // stencil as it is (the pointwise updates change only the diagonal, which
  // the compact form reads from the stencil itself); idempotent. The slab
  // sweep (GsOrder::Slabs) and the residual on it:
  void build_compact();
  bool has_compact() const { return bool(compact_h_()); }
  std::pair<cl::Event, cl::Event> relax_gs_compact(const cl::Buffer& rhs, const cl::Buffer& x, int sweeps,
                                                   bool reverse) const;
  cl::Event residual_compact(const cl::Buffer& rhs, const cl::Buffer& x, const cl::Buffer& r) const;
  std::vector<std::uint16_t> download_compact() const;  // 9 * N, SoA (k - 1) * N + p
  std::vector<float> download_compact_delta() const;
  void zero_fixed(const cl::Buffer& x) const;
  double norm(const cl::Buffer& x) const;  // Euclidean, deterministic
  double dot(const cl::Buffer& x, const cl::Buffer& y) const;  // deterministic
  // The dot product's kernel: work-groups striding over the vector (GPUs,
  // the default there) or a contiguous chunk per work-item (CPUs).
  void set_strided_dot(bool strided);
  void axpby(float a, const cl::Buffer& x, float b, const cl::Buffer& y) const;  // y = a x + b y

  // Frees the tangential tensor T (6 floats per voxel): only the assembly
  // and coarsen() read it, so a built hierarchy needs it no more. Then
  // download_densities() and coarsen() throw std::logic_error.
  void release_tensor();
  bool has_tensor() const { return bool(T_[0]()); }

  Densities download_densities() const;
  std::vector<float> download_coefficients() const;  // STENCIL_COEFS * N, SoA
  std::vector<float> download_b() const;
  const cl::Buffer& b() const { return b_; }
  const cl::Buffer& fixed() const { return fixed_; }
  std::size_t memory_bytes() const;

 private:
  DeviceSystem(Runtime& rt, const GridDesc& g);  // allocates
  void assemble();
  // The slab ordering's launches of `k` (relax_gs_slabs or its compact form),
  // whose arguments before rhs are the stencil's, set by the caller: `first`
  // is rhs's index; then x, colour, reverse, slab, grid.
  std::pair<cl::Event, cl::Event> slab_sweeps(cl::Kernel& k, cl_uint first, const cl::Buffer& rhs,
                                              const cl::Buffer& x, int sweeps, bool reverse) const;

  Runtime& rt_;
  GridDesc grid_;
  cl::Buffer mu_, rho_, fixed_, coef_, b_, dT_, partial_;
  cl::Buffer compact_h_, compact_delta_;  // build_compact()
  std::array<cl::Buffer, 6> T_;
  std::array<cl::Buffer, 3> sources_;  // v, v~, |grad v|^2 of a volume-built level (for update_point)
  VariationalParams resolved_;
  CrestReport crest_;  // the crest rule's count (host/crest.hpp)
  // The echo-crest rule as built (ridge 0: off), the isovalue and shell
  // shift it was last applied for, and the voxels it changed with their
  // values before it (update_point re-applies it to those).
  CrestParams crest_params_{0.0};
  double crest_iso_ = 0, crest_shift_ = 0;
  Dims3 dims_{0, 0, 0};
  CrestChanges crest_changes_;  // the voxels the rule replaced, their values before it
  // Applies the rule to v~ and |grad v|^2 (sources_) for this isovalue and
  // shift; false when nothing changed on the device.
  bool apply_crest(double v_iso, double shift_mm);
  Vec3d spacing_{1, 1, 1};  // the volume's spacing, in double (the thickness floor)
  GsOrder gs_order_ = GsOrder::Points;
  bool strided_dot_ = false;
  int gs_slab_ = 0;
  mutable cl::Kernel apply_, residual_, gs_, gs_slabs_, jacobi_, zero_fixed_, dot_, axpby_;
  mutable cl::Kernel gs_slabs_compact_, residual_compact_;
};

// Multigrid solver settings and report (docs/numerics.md, "Multigrid").
struct SolverParams {
  // Stop at ||b - A u|| / ||b|| <= tol. Below 1e-4 the solve iterates in
  // float32 to 1e-4, then refines in float64 (mixed-precision iterative
  // refinement, docs/solver.md): the residuals reported from there on are
  // float64 ones of the float64 solution (MultigridSolver::solution64()).
  double tol = 1e-4;
  int max_cycles = 30;      // V-cycles; more means "not converged"
  int pre_sweeps = 2, post_sweeps = 2;
  bool jacobi = false;      // smoother: weighted Jacobi instead of Gauss-Seidel
  double jacobi_weight = 0.8;
  bool full_multigrid = true;  // FMG initial guess (ignored with an initial u)
  int max_levels = 8;          // 2 reproduces the paper's two-level scheme
  // Outer iteration: conjugate gradients preconditioned by one symmetric
  // V-cycle per iteration (robust for the strongly anisotropic tangential
  // term), or plain V-cycles.
  bool krylov = true;
  // With sharpening: the relative residual the linear solve and every
  // sharpening step but the last stop at (the last one stops at tol). They
  // only give the next linearisation point; 0 takes tol (the reference the
  // bench measures re-solves against: sharpening from converged solves).
  double sharpen_tol = 5e-2;
  // A warm re-solve from kept stages (VariationalClassifier::solve with
  // `warm` after keep_resolve_start: the viewer's sliders) stops its last
  // step at this relative residual (or tol, if looser): one PCG iteration
  // fewer, as close to the converged reference as a cold classification
  // (docs/numerics.md, "Re-solving to the display");
  // VariationalClassifier::polish() then finishes it to tol, as the viewer
  // does once no slider moves. 0 takes tol.
  double resolve_tol = 1e-3;
  // A warm re-solve's stages (as for resolve_tol) first relax this many
  // symmetric Gauss-Seidel sweeps on the fine level from their start and
  // stop there when the stage's tolerance (sharpen_tol, resolve_tol) is met,
  // else go on with the conjugate gradients from there: after a slider's
  // step the change lies near the shell, where the smoother removes it at a
  // fraction of a preconditioned iteration's cost (docs/numerics.md,
  // "Sweeps before the iterations"). Stages to a tolerance under 1e-3 (the
  // polish, a cold classification) never do. 0: the conjugate gradients at once.
  int resolve_sweeps = 8;
  // The conjugate gradients' preconditioner relaxes on a compact copy of the
  // fine level's stencil (bfloat16 couplings; DeviceSystem::build_compact)
  // where the slab Gauss-Seidel runs (CPUs) and the copy fits: fewer bytes
  // per sweep, the float32 system's answer (docs/solver.md). A
  // VariationalClassifier uses it in warm re-solves only.
  bool compact_smoother = true;
};

struct SolveReport {
  std::vector<double> residuals;  // relative residual: initial, after FMG (or a re-solve's sweeps), after each cycle / iteration
  int cycles = 0, levels = 0;
  int refinements = 0;  // float64 refinement steps (tol below 1e-4), each a float32 solve of its own
  bool converged = false;
  double seconds = 0;
  double bytes = 0;  // bytes the solve moved at the least, under the byte model of docs/benchmarks.md
};

// The multigrid hierarchy of a fine level (coarse levels by rediscretisation,
// docs/numerics.md) and the solver on it. Built once; every solve and every
// pointwise update re-uses it.
class MultigridSolver {
 public:
  MultigridSolver(DeviceSystem& fine, const SolverParams& sp);  // `fine` must outlive the solver
  ~MultigridSolver();
  MultigridSolver(const MultigridSolver&) = delete;
  MultigridSolver& operator=(const MultigridSolver&) = delete;

  // Solves A u = b of the fine level: from `init` when given, else from the
  // previous solve's solution (kept on the device) when `warm` and there is
  // one, else from FMG (or 0, per SolverParams). Never throws for
  // non-convergence: the report says so and the caller decides.
  // `tol_override` > 0 replaces SolverParams::tol for this solve. Without
  // `read_back` the solution stays on the device (solution()) and an empty
  // vector is returned.
  std::vector<float> solve(SolveReport* report = nullptr, const std::vector<float>* init = nullptr,
                           bool warm = false, double tol_override = 0, bool read_back = true);
  // Makes `u` (a fine-level vector on the device) the previous solution: the
  // next solve with `warm` starts there (fixed voxels set to 0).
  void load_solution(const cl::Buffer& u);
  // After fine.update_point(): carries the new mu and rho down every level.
  void update_point();
  // Whether the next solves may relax on the compact stencil
  // (SolverParams::compact_smoother still decides; on by default;
  // VariationalClassifier allows it for its warm re-solves only).
  void allow_compact_smoother(bool on);
  bool compact_smoother_in_use() const;  // the last solve relaxed on the compact stencil
  // Whether the next warm solves to a tolerance of 1e-3 or looser first
  // relax SolverParams::resolve_sweeps sweeps (VariationalClassifier allows
  // it for its warm re-solves only, with the compact smoother).
  void allow_resolve_sweeps(bool on);
  // The float64 solution of the last solve when it was refined (tol below
  // 1e-4; its float32 rounding is what solve() returned), else empty.
  const std::vector<double>& solution64() const;
  int levels() const;
  const SolverParams& params() const;
  // The last solve's solution on the device (the fine level's u, fixed
  // voxels 0); valid until the next solve or update.
  const cl::Buffer& solution() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Solves A u = b for the densities' system on the device. `init` (optional)
// warm-starts from a previous u. Never throws for non-convergence: the report
// says so and the caller decides. Builds the hierarchy for this one solve
// (and counts it in the report's seconds).
std::vector<float> solve(Runtime& rt, const Densities& d, const SolverParams& sp, SolveReport* report = nullptr,
                         const std::vector<float>* init = nullptr);
std::vector<float> solve(DeviceSystem& fine, const SolverParams& sp, SolveReport* report = nullptr,
                         const std::vector<float>* init = nullptr);

// The classifier on one volume, ready to re-solve: it keeps on the device
// everything that does not depend on the pointwise parameters (the lowpasses,
// gradients, the tangential tensor and couplings of every level, the
// multigrid hierarchy) so a change of v_iso, alpha, gamma, omega, delta,
// epsilon or u_ind costs one pointwise pass per level and a warm solve
// (docs/numerics.md, "Re-solving"). `v` is in its own intensity units;
// params.v_iso is normalised (IntensityMap::to_unit). With a `mask`, pass the
// volume through fill_unscanned first (see classify_variational).
// A 3D+t warm start (classify over a sequence, docs/formats.md): the linear
// solve starts from `linear_in` (the previous frame's linear solution, one
// float per voxel) instead of full multigrid, with sharpening too (unlike
// `init`), and `linear_out` receives this solve's linear solution for the
// next frame. With sharpening the result then differs from a cold solve by
// what the loose linear tolerance lets through (tested: within the solver's
// tolerance of the cold frame). Either may be null.
struct SequenceStart {
  const std::vector<float>* linear_in = nullptr;
  std::vector<float>* linear_out = nullptr;
};

class VariationalClassifier {
 public:
  VariationalClassifier(Runtime& rt, const Volume& v, const VariationalParams& params, const SolverParams& sp = {},
                        const std::vector<std::uint8_t>* mask = nullptr);
  ~VariationalClassifier();

  const VariationalParams& params() const { return params_; }
  const VariationalParams& resolved() const { return sys_->resolved(); }
  // What the echo-crest rule re-centred (VariationalParams::crest).
  const CrestReport& crest() const { return sys_->crest(); }
  const IntensityMap& intensity_map() const { return map_; }
  // True when `p` keeps beta, kappa and both lowpass sigmas: update() can
  // then re-target this classifier; otherwise build a new one.
  bool can_update(const VariationalParams& p) const;
  // With the echo-crest rule on (either side): the rule's parameters
  // unchanged (a new isovalue or shell shift re-applies it).
  bool same_crest(const VariationalParams& p) const;
  // Throws std::invalid_argument unless can_update(p).
  void update(const VariationalParams& p);
  // The opacity u, clamped to [0, 1], with the volume's geometry: from
  // `init` when given, else from the previous solution when `warm`, else cold.
  // With sharpening (the default) a solve starts cold, `init` applying to
  // the linear functional only (sharpen_iterations 0), unless `warm` and the
  // last solve's stages are kept (keep_resolve_start): the linear solve then
  // starts from the last linear solution and the last sharpening step from
  // the new previous stage plus the last solve's change over that step.
  // `sequence`: a 3D+t warm start (SequenceStart).
  Volume solve(SolveReport* report = nullptr, const Volume* init = nullptr, bool warm = false,
               const SequenceStart* sequence = nullptr);
  // Finishes the last solve to SolverParams::tol when it stopped at
  // resolve_tol (a warm re-solve), from where it stopped, with the same
  // system; returns its u as solve() does, or an empty volume when there is
  // nothing to finish (no loose re-solve since the last update or solve).
  Volume polish(SolveReport* report = nullptr);
  // Whether the last solve stopped at resolve_tol and polish() would finish it.
  bool polishable() const { return polishable_; }
  // The factor the last solve scaled u by (u_ind from the data, max_gain).
  double gain() const { return gain_; }
  double setup_seconds() const { return setup_seconds_; }    // the constructor, hierarchy included
  double update_seconds() const { return update_seconds_; }  // the last update()
  int levels() const { return mg_->levels(); }
  bool compact_smoother_in_use() const { return mg_->compact_smoother_in_use(); }
  // Keeps the solution of every stage of each solve on the device (the
  // linear solve and each sharpening step: sharpen_iterations + 2 floats per
  // voxel with a scratch buffer, less than the tangential tensor freed after
  // the setup) so that solve(..., warm = true) after update() starts the
  // linear solve from the last linear solution instead of from full
  // multigrid, and the last sharpening step from the new step before it plus
  // the last solve's change over the step (docs/numerics.md, "Re-solving").
  // Off by default: one-shot classifications never re-solve.
  // Its warm re-solves also relax on the compact stencil
  // (SolverParams::compact_smoother, where it fits: 22 bytes per voxel).
  // Cold solves do not: over a one-shot classification's few iterations the
  // copy's build and first touch cost about what its fewer bytes save
  // (docs/solver.md), and a cold solve stays the bits of `classify` with the
  // same parameters (the viewer's saved u and `classify --params`).
  void keep_resolve_start(bool on) {
    keep_start_ = on;
    if (!on) kept_.clear(), scratch_ = cl::Buffer(), kept_linear_ = kept_steps_ = false;
  }

 private:
  Runtime& rt_;
  VariationalParams params_;
  IntensityMap map_;
  Volume geometry_;  // the volume's header, no samples
  std::unique_ptr<DeviceSystem> sys_;
  std::unique_ptr<MultigridSolver> mg_;
  double setup_seconds_ = 0, update_seconds_ = 0, gain_ = 1.0;
  // The solution `u` as solve() returns it: scaled by the gain, clamped.
  Volume finish(std::vector<float> u);
  // The solver's solution (the last sharpening step's) kept as kept_.back(),
  // the next re-solve's start (keep_resolve_start).
  void keep_last_step();
  bool sharpened_ = false;  // the system holds the sharpening term of the last solve
  bool polishable_ = false;  // the last solve stopped at resolve_tol (polish())
  // The last solve's stages (keep_resolve_start): kept_[0] its linear
  // solution (valid: kept_linear_), kept_[s] its sharpening step s's
  // (kept_steps_: all of them, from the same solve as kept_[0]).
  std::vector<cl::Buffer> kept_;
  cl::Buffer scratch_;
  bool kept_linear_ = false, kept_steps_ = false, keep_start_ = false;
};

// The whole classifier on a volume in its own intensity units: normalise
// (IntensityMap), densities and system on the device, solve, and return the
// opacity u clamped to [0, 1] with the volume's geometry. `params.v_iso` is
// normalised (IntensityMap::to_unit of the file value). `init` warm-starts.
// Non-convergence is reported in `report`, not thrown. With a `mask`, pass
// the volume through fill_unscanned (host/mask.hpp) first, as the CLI does,
// so the lowpass and gradients see no step at the edge of the sweep.
struct ClassifyTiming {
  double setup = 0, solve = 0;  // seconds: densities, assembly, hierarchy; multigrid iterations
  VariationalParams resolved;   // the parameters in force (g_ref from the data, the thickness floor)
  CrestReport crest;            // what the echo-crest rule re-centred (VariationalParams::crest)
};
Volume classify_variational(Runtime& rt, const Volume& v, const VariationalParams& params, const SolverParams& sp,
                            SolveReport* report = nullptr, const Volume* init = nullptr,
                            const std::vector<std::uint8_t>* mask = nullptr, ClassifyTiming* timing = nullptr,
                            const SequenceStart* sequence = nullptr);

}  // namespace softshell
