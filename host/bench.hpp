// The benchmark behind `softshell bench` (docs/benchmarks.md): on every
// chosen OpenCL device, the paper's Table 1 on phantoms of the paper's
// dimensions, the device's copy/triad bandwidth and the effective bandwidth of
// the solver's two memory-bound kernels under a stated byte model, the CPU
// peers (Eigen's conjugate gradients, a single-threaded two-level
// Gauss-Seidel) on the same system to the same relative residual, the
// growth of the classification time with the volume size, and the cost of a
// warm-started re-solve. Every timed result is also checked; a device that
// cannot run a part is skipped with the reason, never aborting the run.
//
// Speed claims are ratios measured in the same run (against the device's own
// copy bandwidth, or against a peer), never absolute numbers of another day.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "cl_runtime.hpp"
#include "image.hpp"
#include "stencil.h"
#include "stream.hpp"
#include "volume.hpp"

namespace softshell {

class DeviceSystem;
struct Phantom;

// Hook for the renderers (Table 1's last columns): the seconds one 400x400
// image of `opacity` takes with `method` ("shearwarp" or "splat"), or
// nullopt when that renderer is not available. Unset: the columns read
// "n/a (renderer issue)".
using RenderTimer = std::function<std::optional<double>(Runtime& rt, const Volume& opacity,
                                                        const std::string& method, int width, int height)>;

struct BenchOptions {
  bool quick = false;                // smaller sizes, fewer repeats: under a minute on 2 cores
  std::vector<std::string> devices;  // requests as for --device; empty: every device found
  int reps = 0;                      // repeats of the cheap timings; 0: by mode (quick 3, full 5)
  std::ostream* progress = nullptr;  // one line per step (stderr in the CLI); null: silent
  RenderTimer render_timer;          // see above
};

// Minimum and median of repeated timings, in seconds.
struct Timing {
  double min = 0, median = 0;
  int reps = 0;
};
Timing summarise(std::vector<double> seconds);

// One row of the paper's Table 1, reproduced on a phantom.
struct Table1Row {
  std::string dataset, shape;        // "Fetal face I", "face"
  std::array<int, 3> paper_dims{};   // 77x97x56 ...
  std::array<int, 3> dims{};         // what was run (paper dims, a cube of as many voxels, or halved in quick mode)
  std::string dims_note;             // why dims differ from the paper's, empty when they do not
  double filter = 0, gradients = 0;  // device time of the lowpasses and of the gradients (profiling events)
  double setup = 0;                  // rest of the setup: normalise, upload, densities, assembly (wall)
  double solve = 0, total = 0;       // wall; total = whole classification (min over repeats)
  double total_median = 0;
  int reps = 0, iterations = 0, levels = 0;
  double residual = 0;               // final relative residual
  bool converged = false;
  double opaque_percent = 0;         // u > kOpaqueLevel (0.05, host/metrics.hpp)
  std::size_t splats = 0;            // u > 0.2
  std::optional<double> render_shearwarp, render_splat;  // seconds, 400x400
  std::string render_note;           // "n/a (renderer issue)" when not measured
  // The paper's numbers (600 MHz Pentium III, GeForce2 GTS).
  double paper_seconds = 0, paper_opaque_percent = 0, paper_shearwarp = 0, paper_splat = 0;
  std::size_t paper_splats = 0;
};

struct ScalingRow {
  int size = 0;                 // face phantom size^3
  std::size_t voxels = 0;
  Timing total;                 // classification (setup + solve), wall
  double setup = 0, solve = 0;  // of the fastest repeat
  int iterations = 0;
  double residual = 0;
  bool converged = false;
};

// A solver run to the common relative residual.
struct PeerResult {
  std::string name;       // "softshell", "eigen-cg-f64", "eigen-cg-f32", "gauss-seidel-2level"
  std::string detail;     // threads, precision, preconditioner, cycles
  Timing time;
  long iterations = 0;
  double residual = 0;    // ||b - A u|| / ||b|| of its solution, evaluated in float64 on the host
  bool ok = false;        // reached the common tolerance (float64 evaluation, 10 % slack for float32 rounding)
  std::string error;      // when it did not run
};

struct DeviceBench {
  std::string name, type, platform, label;
  bool skipped = false;
  std::string skip_reason;          // the first part that could not run, and why
  std::vector<std::string> notes;   // parts skipped or failed, with reasons
  std::vector<std::string> failed_checks;

  // Bandwidth: STREAM copy (8 B/element) and triad (12 B/element).
  std::size_t stream_elements = 0;
  Timing copy, triad;
  double copy_gbps = 0, triad_gbps = 0;
  // One Gauss-Seidel sweep (the solver's ordering on the device) and one operator apply on the
  // bandwidth system, with the byte models of bench_byte_model().
  int bw_size = 0;
  std::size_t bw_voxels = 0;
  Timing sweep, apply;
  double sweep_gbps = 0, sweep_fraction = 0, apply_gbps = 0, apply_fraction = 0;
  double sweep_check = 0, apply_check = 0;  // max relative deviation from the host reference
  std::string sweep_order;                   // the sweep's Gauss-Seidel ordering, in words
  // The host's own STREAM (host_stream(): std::thread on every core, no
  // OpenCL), run right before the device's: what the machine can move, the
  // yardstick of the *_host fractions (GB/s by the byte model / host copy).
  HostStream host;
  double sweep_fraction_host = 0, apply_fraction_host = 0;
  // The same forward sweep on the compact stencil, where the solver uses it
  // (the slab ordering): its time, GB/s by ByteModel::sweep_compact, that
  // against the host's copy, and its check against the host's sweep of the
  // compact matrix (0 and an empty time where it is not used).
  Timing sweep_compact;
  double sweep_compact_gbps = 0, sweep_compact_fraction_host = 0, sweep_compact_check = 0;
  // The solve against its bandwidth bound, on the peers' system: a built
  // MultigridSolver's cold solve (FMG + PCG, no hierarchy build; min over
  // repeats) against SolveReport::bytes / host copy bandwidth (the bound), and
  // against the device's copy bandwidth.
  double solve_seconds = 0, solve_bytes_per_voxel = 0, solve_bound_s = 0;
  double solve_bound_ratio = 0, solve_bound_ratio_device = 0;
  int solve_iterations = 0;

  // Peers on one system (face phantom of peer_size^3) at the default
  // parameters; the stable keys describe this case.
  int peer_size = 0;
  std::size_t peer_voxels = 0;
  double tol = 1e-4;
  std::vector<PeerResult> peers;
  double speedup_vs_eigen_cg = 0;  // fastest Eigen CG / softshell solve (min times)
  // HYPRE PFMG-PCG (setup + solve) / softshell's solve (hierarchy + solve),
  // min times, as for Eigen; 0: not run (the peer was not built).
  double speedup_vs_pfmg = 0;
  double pfmg_solve_seconds = 0;   // its solve alone (min)
  // The same volume with a strongly anisotropic system (beta = 1000, where
  // point smoothers and diagonal preconditioning struggle; docs/solver.md).
  // Full mode only.
  double aniso_beta = 0;  // 0: not run
  std::vector<PeerResult> peers_aniso;
  double speedup_vs_eigen_cg_aniso = 0;

  // Warm start after a 5 % change of v_iso, same volume as the peers.
  // Warm start: a cold classification at v_iso' = 1.05 v_iso (setup +
  // solve) against a re-solve of a VariationalClassifier set up at v_iso:
  // update() to v_iso' + a solve from the last linear solution
  // (keep_resolve_start; mins over repeats), its last step stopped at
  // SolverParams::resolve_tol as the viewer shows it; warm_polish: the
  // viewer's polish() after it, to the solver's tol (min over repeats).
  // warm_start_fraction = warm_total / cold_total, what a user waits for;
  // warm_solve_fraction = warm solve / cold solve (FMG start, same hierarchy).
  double warm_cold_solve = 0, warm_warm_solve = 0, warm_start_fraction = 0, warm_solve_fraction = 0;
  double warm_cold_total = 0, warm_warm_total = 0, warm_update = 0;
  int warm_cold_iterations = 0, warm_warm_iterations = 0;
  // Distance of the cold classification and of the re-solve (its worst
  // repeat) from the reference (sharpening from converged solves): mean and
  // largest |du|, share of voxels beyond 5e-3.
  double warm_ref_cold_mean = 0, warm_ref_cold_max = 0, warm_ref_cold_share = 0;
  double warm_ref_warm_mean = 0, warm_ref_warm_max = 0, warm_ref_warm_share = 0;
  double warm_polish = 0, warm_ref_polish_mean = 0, warm_ref_polish_share = 0, warm_resolve_tol = 0;
  double warm_loose_vs_polished_max = 0;  // largest |du| between the re-solve shown and its polish (worst repeat)

  std::vector<Table1Row> table1;
  std::vector<ScalingRow> scaling;
  double scaling_exponent = 0;  // least-squares slope of log time vs log voxels
  double seconds = 0;           // wall time of this device's bench
};

struct BenchReport {
  bool quick = false;
  std::string host_cpu;  // the host CPU's model name (for the peers)
  int host_threads = 0;  // threads Eigen used
  std::string load_before, load_after;  // /proc/loadavg: the machine may be shared
  std::vector<DeviceBench> devices;
  double seconds = 0;
  bool all_checks_passed() const;
};

// Bytes per voxel the byte models assume (docs/benchmarks.md, "Byte model").
struct ByteModel {
  static constexpr double sweep = STENCIL_COEFS * 4 + 4 + 4 + 4;  // coefficients, b, u read, u write = 52
  static constexpr double apply = STENCIL_COEFS * 4 + 4 + 4;      // coefficients, x read, y write = 48
  // The preconditioner's sweep on the compact stencil (DeviceSystem::build_compact):
  // diagonal, its correction, 9 bfloat16 couplings, b, u read, u write = 38
  static constexpr double sweep_compact = 4 + STENCIL_COMPACT_BYTES + 4 + 4 + 4;
};

// Runs the benchmark. Throws DeviceError only when a requested device does
// not exist (or none does); every per-device problem is recorded instead.
BenchReport run_bench(const BenchOptions& options);

std::string bench_json(const BenchReport& report);   // one object, keys documented in docs/benchmarks.md
std::string bench_table(const BenchReport& report);  // the terminal tables
// Classification time against voxels (log-log), one colour per device,
// scaling points joined and Table 1 rows as hollow marks.
Image bench_plot(const BenchReport& report);

// ---- The peers' pieces, exposed for tests --------------------------------

// The 19-point system as the device stores it (kernels/stencil.h):
// STENCIL_COEFS coefficients per voxel, structure of arrays, identity rows at
// fixed voxels.
struct HostStencil {
  GridDesc grid{};
  std::vector<float> coef;  // STENCIL_COEFS * N
  std::vector<float> b;     // N
  std::vector<std::uint8_t> fixed;  // N (1: u held at 0)
  std::size_t voxels() const { return grid_voxels(grid); }
};

// A device system's stencil, right-hand side and fixed flags, downloaded.
HostStencil host_stencil(const DeviceSystem& sys);
// The same with the compact stencil the preconditioner relaxes on
// (DeviceSystem::build_compact, built): couplings as their bfloat16 values,
// the diagonal plus its correction.
HostStencil compact_host_stencil(const DeviceSystem& sys);
// The volume in normalised units (IntensityMap::to_unit), as DeviceSystem takes it.
Volume normalised(const Volume& v);
// Largest and mean |a - b| over the voxels of two volumes of the same dims,
// and the share of voxels differing by more than 5e-3 (1.3 grey levels of
// an 8-bit display): a re-solve's distance from a reference.
struct Deviation {
  double max = 0, mean = 0, share = 0;
};
Deviation deviation(const Volume& a, const Volume& b);
// v_iso half-way between a phantom's fluid and tissue medians, normalised.
double phantom_iso(const Phantom& ph);

// ||b - A u|| / ||b|| in float64.
double host_relative_residual(const HostStencil& s, const std::vector<float>& u);
// y = A x in float64 (the apply reference).
std::vector<double> host_apply(const HostStencil& s, const std::vector<float>& x);
// One 8-colour Gauss-Seidel sweep, colour by colour as the device does (the sweep reference).
void host_gs_colour_sweep(const HostStencil& s, std::vector<float>& u);
// One slab Gauss-Seidel sweep as the device's GsOrder::Slabs does it (the
// sweep reference there): 2 colours of z-slabs of `slab` planes, each slab
// plane by plane, rows ascending, x ascending; `reverse`: exactly backwards.
// slab = 1 is zebra-plane Gauss-Seidel (even planes, then odd), lexicographic
// in each plane.
void host_gs_slab_sweep(const HostStencil& s, std::vector<float>& u, int slab, bool reverse);

struct PeerSolve {
  double seconds = 0;
  long iterations = 0;
  double residual = 0;  // float64 evaluation
  std::vector<float> u;
};
// Eigen::ConjugateGradient (Lower|Upper, diagonal preconditioner, row-major
// so the products run on every OpenMP thread) in float64 or float32 on the
// system assembled from the stencil, exact zeros dropped; stops at `tol`
// relative residual (re-checked in float64; continued if it is not met).
PeerSolve eigen_cg_peer(const HostStencil& s, double tol, bool float64, int max_iterations = 20000);
// The paper's two-level scheme, single-threaded: lexicographic Gauss-Seidel
// V(2,2) cycles on the fine level and `coarse_sweeps` symmetric sweeps on the
// one coarse level (`coarse`: the rediscretised next level), from u = 0 until
// `tol`.
PeerSolve gauss_seidel_two_level_peer(const HostStencil& fine, const HostStencil& coarse, double tol,
                                      int max_cycles = 200, int coarse_sweeps = 8);
// Threads Eigen's sparse products use (1 without OpenMP).
int eigen_threads();

}  // namespace softshell
