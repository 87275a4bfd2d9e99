// The solver's kernels one by one, against the device's copy and the host's
// STREAM copy, in one run: the Gauss-Seidel sweep (forward and reverse, and
// forward once more in plain C++ on the host's threads), the operator apply
// and residual, the grid transfers and the vector kernels on the face
// phantom's system (the grid transfers' results are checked by the
// Transfers test instead); then one cold solve and one PCG iteration
// (the difference of two solves one iteration apart). Every kernel result is
// checked against the host reference (bench.hpp) before it is timed.
//
//   softshell_bench_solver [--size N] [--reps R] [--device D] [--slab P] [--sweeps S] [--compact 0|1] [--ab ROUNDS] [--resolve-tol T] [--ab-resolve ROUNDS] [--ab-sweeps ROUNDS] [--resolve-sweeps N] [--barrier B] [--sharpen N] [--trace]
//
// Byte model: docs/benchmarks.md ("Byte model"). Times are the minimum of R.
#include <algorithm>
#include <chrono>
#include <memory>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "bench.hpp"
#include "stencil.h"
#include "parallel.hpp"
#include "error.hpp"
#include "phantom.hpp"
#include "progress.hpp"
#include "stream.hpp"
#include "variational.hpp"

using namespace softshell;

namespace {

int usage() {
  std::cerr << "usage: softshell_bench_solver [--size N] [--reps R] [--device I|NAME] [--slab P] [--sweeps S] [--compact 0|1] [--ab ROUNDS] [--resolve-tol T] [--ab-resolve ROUNDS] [--ab-sweeps ROUNDS] [--resolve-sweeps N] [--barrier B] [--sharpen N] [--trace]\n";
  return 2;
}

template <class F>
double best_of(int reps, F&& f) {
  f();  // warm-up
  double best = 1e30;
  for (int r = 0; r < reps; ++r) best = std::min(best, f());
  return best;
}

double max_relative(const std::vector<float>& a, const std::vector<double>& ref) {
  double dev = 0, scale = 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    dev = std::max(dev, std::abs(double(a[i]) - ref[i])), scale = std::max(scale, std::abs(ref[i]));
  return scale > 0 ? dev / scale : dev;
}

}  // namespace

// The forward slab sweep in plain C++ on the host's threads, the kernel's
// algorithm (kernels/system.cl, relax_gs_slabs: rows in chunks, the chunk's
// row sums in a loop the compiler vectorises, then the recurrence along x,
// here one voxel at a time) on the same coefficients in the same padded
// layout: whether the OpenCL compiler or the memory system sets the sweep's
// speed. Not used by the solver.
struct NativeSweep {
  GridDesc g{};
  std::size_t N = 0, slice = 0;
  std::vector<float> coef, b;  // coef: STENCIL_COEFS slices of `slice` floats
  explicit NativeSweep(const HostStencil& hs) : g(hs.grid), N(hs.voxels()), slice(STENCIL_SLICE(hs.voxels())) {
    coef.assign(STENCIL_COEFS * slice, 0.0f);
    for (int k = 0; k < STENCIL_COEFS; ++k)
      std::copy(hs.coef.begin() + long(k * N), hs.coef.begin() + long((k + 1) * N), coef.begin() + long(k * slice));
    b = hs.b;
  }
  // x-row (y, z), as gs_any_row does it.
  static __attribute__((target_clones("arch=x86-64-v3", "default"))) void native_row(const float* c, const float* b,
                                                                                 std::size_t slice, GridDesc g,
                                                                                 float* x, int y, int z) {
    constexpr int kChunk = 128;
    const long sy = g.nx, sz = long(g.nx) * g.ny;
    const long offs[STENCIL_COEFS] = {
#define OFF(K, DX, DY, DZ) long(DX) + long(DY) * sy + long(DZ) * sz,
        STENCIL_OFFSETS(OFF)
#undef OFF
    };
    const std::size_t row = std::size_t(g.nx) * (std::size_t(y) + std::size_t(g.ny) * std::size_t(z));
    if (y == 0 || z == 0 || y == g.ny - 1 || z == g.nz - 1) {
      for (int i = 0; i < g.nx; ++i) x[row + i] = b[row + i] / c[row + i];
      return;
    }
    x[row] = b[row] / c[row];
    x[row + g.nx - 1] = b[row + g.nx - 1] / c[row + g.nx - 1];
    const int n = g.nx - 2;
    float r[kChunk], l[kChunk];
    for (int done = 0; done < n; done += kChunk) {
      const int m = std::min(kChunk, n - done);
      const std::size_t p0 = row + 1 + std::size_t(done);
      for (int i = 0; i < m; ++i) {
        const std::size_t p = p0 + std::size_t(i);
        float acc = -c[slice + p] * x[p + 1];
#pragma GCC unroll 10
        for (int k = 2; k < STENCIL_COEFS; ++k) {
          acc = std::fma(-c[std::size_t(k) * slice + p], x[p + offs[k]], acc);
          acc = std::fma(-c[std::size_t(k) * slice + p - offs[k]], x[p - offs[k]], acc);
        }
        const float inv = 1.0f / c[p];
        r[i] = (b[p] + acc) * inv;
        l[i] = c[slice + p - 1] * inv;
      }
      float u = x[p0 - 1];
      for (int i = 0; i < m; ++i) x[p0 + std::size_t(i)] = u = std::fma(-l[i], u, r[i]);
    }
  }
  // One forward sweep: colour 0's slabs, then colour 1's, each colour's
  // slabs split into `threads` contiguous ranges.
  void sweep(std::vector<float>& x, int slab, int threads) const {
    const int slabs = (g.nz + 2 * slab - 1) / (2 * slab);
    for (int colour = 0; colour < 2; ++colour) {
      parallel_ranges(std::size_t(slabs), threads, [&](std::size_t lo, std::size_t hi) {
        for (std::size_t k = lo; k < hi; ++k) {
          const int z0 = (2 * int(k) + colour) * slab;
          for (int z = z0; z < std::min(z0 + slab, g.nz); ++z)
            for (int y = 0; y < g.ny; ++y) native_row(coef.data(), b.data(), slice, g, x.data(), y, z);
        }
      });
    }
  }
};

int main(int argc, char** argv) {
  int size = 128, reps = 10;
  std::string device;
  bool trace = false;
  int slab = 0, sweeps = 0, compact = 1, ab = 0, ab_resolve = 0, ab_sweeps = 0;
  double resolve_tol = SolverParams{}.resolve_tol;  // --resolve-tol: the warm re-solves' last step
  int resolve_sweeps = SolverParams{}.resolve_sweeps;  // --resolve-sweeps: a re-solve's sweeps before its iterations
  double barrier = VariationalParams{}.sharpen_barrier;  // --barrier: the sharpening barrier of every classification
  int sharpen = VariationalParams{}.sharpen_iterations;  // --sharpen: its steps
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") return usage(), 0;
    if (a != "--trace" && i + 1 >= argc) return usage();
    if (a == "--size") size = std::atoi(argv[++i]);
    else if (a == "--reps") reps = std::atoi(argv[++i]);
    else if (a == "--device") device = argv[++i];
    else if (a == "--trace") trace = true;
    else if (a == "--slab") slab = std::atoi(argv[++i]);
    else if (a == "--sweeps") sweeps = std::atoi(argv[++i]);
    else if (a == "--compact") compact = std::atoi(argv[++i]);
    else if (a == "--ab") ab = std::atoi(argv[++i]);
    else if (a == "--resolve-tol") resolve_tol = std::atof(argv[++i]);
    else if (a == "--ab-resolve") ab_resolve = std::atoi(argv[++i]);
    else if (a == "--ab-sweeps") ab_sweeps = std::atoi(argv[++i]);
    else if (a == "--resolve-sweeps") resolve_sweeps = std::atoi(argv[++i]);
    else if (a == "--barrier") barrier = std::atof(argv[++i]);
    else if (a == "--sharpen") sharpen = std::atoi(argv[++i]);
    else {
      std::cerr << "softshell_bench_solver: unknown option " << a << "\n";
      return usage();
    }
  }
  if (size < 16 || size > 512) {
    std::cerr << "softshell_bench_solver: --size must be in [16, 512]\n";
    return 2;
  }
  if (reps < 1 || reps > 1000) {
    std::cerr << "softshell_bench_solver: --reps must be in [1, 1000]\n";
    return 2;
  }
  try {
    Runtime rt(device);
    PhantomParams pp;
    pp.shape = PhantomShape::Face;
    pp.size = size;
    const Phantom ph = make_phantom(rt, pp);
    const Volume vn = normalised(ph.volume);
    VariationalParams vp;
    vp.v_iso = phantom_iso(ph);
    vp.sharpen_barrier = barrier;
    vp.sharpen_iterations = sharpen;
    DeviceSystem sys(rt, vn, vp);
    if (slab > 0) sys.set_gs_slab(slab);
    rt.queue().finish();

    const HostStencil hs = host_stencil(sys);
    const std::size_t N = sys.voxels(), bytes = N * sizeof(float);

    // Yardsticks: the device's copy kernel and the host's own STREAM.
    const std::size_t sn = std::size_t(1) << 24;
    cl::Buffer sa = rt.buffer(sn * 4), sb = rt.buffer(sn * 4);
    rt.queue().enqueueFillBuffer(sa, 1.0f, 0, sn * 4);
    Stream stream(rt);
    const double copy_s = best_of(reps, [&] {
      cl::Event e = stream.copy(sa, sb, sn);
      e.wait();
      return event_seconds(e);
    });
    const double dev_copy = 8.0 * double(sn) / copy_s * 1e-9;
    sa = cl::Buffer(), sb = cl::Buffer();
    const HostStream hstream = host_stream(sn, reps);
    std::printf("%s, %dx%dx%d = %zu voxels\n", rt.info().device_name.c_str(), hs.grid.nx, hs.grid.ny, hs.grid.nz, N);
    std::printf("device copy %.1f GB/s, host copy %.1f GB/s (%d threads)\n\n", dev_copy, hstream.copy_gbps,
                hstream.threads);

    cl::Buffer x = rt.buffer(bytes), y = rt.buffer(bytes);
    std::vector<float> u0(N);
    for (std::size_t i = 0; i < N; ++i) u0[i] = hs.fixed[i] ? 0.0f : float((i * 2654435761u) % 1000) / 1000.0f;
    rt.queue().enqueueWriteBuffer(x, CL_TRUE, 0, bytes, u0.data());

    std::printf("%-26s %9s %8s %8s %8s %s\n", "kernel", "ms", "GB/s", "of dev", "of host", "check");
    auto row = [&](const char* name, double s, double bpv, double check) {
      const double gbps = bpv * double(N) / s * 1e-9;
      std::printf("%-26s %9.3f %8.1f %8.2f %8.2f ", name, s * 1e3, gbps, gbps / dev_copy, gbps / hstream.copy_gbps);
      if (check >= 0)
        std::printf("%.1e\n", check);
      else
        std::printf("(tests)\n");
    };

    // A sweep each way, checked against the host's sweep of `h` (the matrix
    // it relaxes on), then timed.
    auto sweep_rows = [&](const HostStencil& h, auto relax, double bpv, const char* fwd, const char* bwd) {
      for (int rev = 0; rev < 2; ++rev) {
        rt.queue().enqueueWriteBuffer(x, CL_TRUE, 0, bytes, u0.data());
        relax(rev).second.wait();
        std::vector<float> got(N), want = u0;
        rt.queue().enqueueReadBuffer(x, CL_TRUE, 0, bytes, got.data());
        host_gs_slab_sweep(h, want, sys.gs_slab(), rev);
        const double check = max_relative(got, std::vector<double>(want.begin(), want.end()));
        const double s = best_of(reps, [&] {
          const auto span = relax(rev);
          span.second.wait();
          return event_span_seconds(span.first, span.second);
        });
        row(rev ? bwd : fwd, s, bpv, check);
      }
    };
    // r = b - A x from u0 into y, checked against the host's residual of `h`, then timed.
    auto residual_row = [&](const char* name, const HostStencil& h, auto residual, double bpv) {
      rt.queue().enqueueWriteBuffer(x, CL_TRUE, 0, bytes, u0.data());
      std::vector<double> ref = host_apply(h, u0);
      for (std::size_t i = 0; i < N; ++i) ref[i] = double(h.b[i]) - ref[i];
      residual().wait();
      std::vector<float> got(N);
      rt.queue().enqueueReadBuffer(y, CL_TRUE, 0, bytes, got.data());
      row(name, best_of(reps, [&] {
            cl::Event e = residual();
            e.wait();
            return event_seconds(e);
          }),
          bpv, max_relative(got, ref));
    };
    sweep_rows(hs, [&](int rev) { return sys.relax_gs(sys.b(), x, 1, rev); }, 52, "sweep (forward)", "sweep (reverse)");
    if (sys.gs_order() == GsOrder::Slabs) {
      // The preconditioner's sweeps and residual on the compact stencil
      // (DeviceSystem::build_compact), checked against the host's on the
      // compact matrix as downloaded.
      sys.build_compact();
      const HostStencil hc = compact_host_stencil(sys);
      sweep_rows(hc, [&](int rev) { return sys.relax_gs_compact(sys.b(), x, 1, rev); }, 38, "sweep compact (forward)",
             "sweep compact (reverse)");
      residual_row("residual compact", hc, [&] { return sys.residual_compact(sys.b(), x, y); }, 38);
    }
    {
      // The same forward sweep in native C++ (NativeSweep), checked the same way.
      const NativeSweep ns(hs);
      const int nslab = std::max(1, sys.gs_slab());  // the CPU order's slabs, whichever device runs the kernels
      std::vector<float> got = u0, want = u0;
      ns.sweep(got, nslab, hstream.threads);
      host_gs_slab_sweep(hs, want, nslab, false);
      const double check = max_relative(got, std::vector<double>(want.begin(), want.end()));
      const double s = best_of(reps, [&] {
        const auto t0 = std::chrono::steady_clock::now();
        ns.sweep(got, nslab, hstream.threads);
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      });
      row("sweep (native C++, fwd)", s, 52, check);
    }
    {
      rt.queue().enqueueWriteBuffer(x, CL_TRUE, 0, bytes, u0.data());
      sys.apply(x, y).wait();
      std::vector<float> got(N);
      rt.queue().enqueueReadBuffer(y, CL_TRUE, 0, bytes, got.data());
      const double check = max_relative(got, host_apply(hs, u0));
      row("apply", best_of(reps, [&] {
            cl::Event e = sys.apply(x, y);
            e.wait();
            return event_seconds(e);
          }),
          48, check);
      residual_row("residual", hs, [&] { return sys.residual(sys.b(), x, y); }, 52);
    }

    // The grid transfers between the fine level and the next: the CPU's row
    // kernels and the GPU's per-voxel ones (both checked in
    // Transfers.RowAndVoxelKernelsAreTheHostInterpolationAndItsTranspose).
    {
      const std::unique_ptr<DeviceSystem> coarse = DeviceSystem::coarsen(sys);
      const GridDesc gf = sys.grid(), gc = coarse->grid();
      const std::size_t nc = coarse->voxels();
      cl::Buffer ec = rt.buffer(nc * 4), rc = rt.buffer(nc * 4);
      rt.queue().enqueueFillBuffer(ec, 0.5f, 0, nc * 4);
      for (const bool rows : {true, false}) {
        cl::Kernel pk = rt.kernel("multigrid.cl", rows ? "mg_prolong_add_rows" : "mg_prolong_add");
        cl::Kernel rk = rt.kernel("multigrid.cl", rows ? "mg_restrict_residual_rows" : "mg_restrict_residual");
        Runtime::set_args(pk, ec, sys.fixed(), y, gf, gc);
        Runtime::set_args(rk, x, coarse->fixed(), rc, gf, gc);
        auto launch = [&](cl::Kernel& k, const GridDesc& g) {
          cl::Event e = rows ? rt.enqueue_rows(k, g) : rt.enqueue_3d(k, g);
          e.wait();
          return event_seconds(e);
        };
        // Byte model (docs/benchmarks.md): prolongation 4 per coarse + 9 per
        // fine voxel, restriction 4 per fine + 5 per coarse.
        const double bpv_p = 9.0 + 4.0 * double(nc) / double(N), bpv_r = 4.0 + 5.0 * double(nc) / double(N);
        row(rows ? "prolongation (rows)" : "prolongation (voxels)", best_of(reps, [&] { return launch(pk, gf); }),
            bpv_p, -1.0);
        row(rows ? "restriction (rows)" : "restriction (voxels)", best_of(reps, [&] { return launch(rk, gc); }),
            bpv_r, -1.0);
      }
    }

    // Every level's sweep, wall clock with launches (small levels: launch-bound).
    {
      std::unique_ptr<DeviceSystem> coarse;
      const DeviceSystem* level = &sys;
      std::printf("\n%-26s %12s %14s\n", "level", "sweep ms", "us per voxel*1e3");
      while (true) {
        const GridDesc& g = level->grid();
        const std::size_t n = level->voxels();
        cl::Buffer u = rt.buffer(n * 4);
        rt.queue().enqueueFillBuffer(u, 0.0f, 0, n * 4);
        const int k = 20;
        const double s = best_of(3, [&] {
          rt.queue().finish();
          const auto t0 = std::chrono::steady_clock::now();
          level->relax_gs(level->b(), u, k, false);
          rt.queue().finish();
          return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / k;
        });
        char name[64];
        std::snprintf(name, sizeof name, "%dx%dx%d", g.nx, g.ny, g.nz);
        std::printf("%-26s %12.3f %14.2f\n", name, s * 1e3, s / double(n) * 1e9);
        if (std::min({g.nx, g.ny, g.nz}) <= 5) break;
        coarse = DeviceSystem::coarsen(*level);
        level = coarse.get();
      }
    }

    // The whole solve and one PCG iteration.
    SolverParams sp;
    if (sweeps > 0) sp.pre_sweeps = sp.post_sweeps = sweeps;
    sp.compact_smoother = compact != 0;
    sp.resolve_tol = resolve_tol;
    sp.resolve_sweeps = resolve_sweeps;
    MultigridSolver mg(sys, sp);
    SolveReport rep;
    mg.solve(&rep);
    const int its = rep.cycles;
    double best = 1e30, bytes_moved = 0;
    for (int r = 0; r < std::max(3, reps / 2); ++r) {
      mg.solve(&rep);
      best = std::min(best, rep.seconds);
      bytes_moved = rep.bytes;
    }
    std::printf("\nsolve: %d levels, %d PCG iterations, %.1f ms, %.0f B/voxel, %.1f GB/s (%.2f of host copy: bound "
                "ratio %.2f)\n",
                mg.levels(), its, best * 1e3, bytes_moved / double(N), bytes_moved / best * 1e-9,
                bytes_moved / best * 1e-9 / hstream.copy_gbps, best / (bytes_moved / (hstream.copy_gbps * 1e9)));
    std::printf("residuals:");
    for (double r : rep.residuals) std::printf(" %.2e", r);
    std::printf("\n");
    SolverParams sp1 = sp;
    sp1.tol = 1e-4;  // below it the solve refines in float64
    auto timed = [&](int cycles) {
      SolverParams s = sp1;
      s.max_cycles = cycles;
      MultigridSolver m(sys, s);
      SolveReport r;
      m.solve(&r);
      double t = 1e30;
      for (int k = 0; k < std::max(3, reps / 2); ++k) m.solve(&r), t = std::min(t, r.seconds);
      return t;
    };
    const double t1 = timed(2), t3 = timed(4);
    std::printf("one PCG iteration: %.1f ms (solves of 2 and 4 iterations: %.1f, %.1f ms)\n", (t3 - t1) / 2 * 1e3,
                t1 * 1e3, t3 * 1e3);

    // The pointwise updates of a re-classification, wall clock.
    auto wall = [&](auto&& f) {
      return best_of(reps, [&] {
        rt.queue().finish();
        const auto t0 = std::chrono::steady_clock::now();
        f();
        rt.queue().finish();
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      });
    };
    const double t_point = wall([&] { sys.update_point(vp); });
    const double t_sharpen = wall([&] { sys.update_sharpen(vp, mg.solution(), 1.0, 1.0); });
    const double t_down = wall([&] { mg.update_point(); });
    std::printf("update: pointwise %.2f ms, with sharpening %.2f ms, down the levels %.2f ms\n", t_point * 1e3,
                t_sharpen * 1e3, t_down * 1e3);

    // A re-classification as the viewer makes it (bench.cpp's bench_warm):
    // one classifier solved at v_iso, then v_iso x 1.05 re-targeted and
    // re-solved warm; beside a cold classification at v_iso x 1.05. With
    // --trace the stages of the last re-solve go to stderr as JSON lines.
    const Volume& v = ph.volume;
    VariationalParams p0 = vp;
    VariationalParams p1 = p0;
    p1.v_iso = 1.05 * p0.v_iso;
    // A classifier solved at p0 that keeps its stages for re-solves.
    auto resolving = [&](const SolverParams& s) {
      auto c = std::make_unique<VariationalClassifier>(rt, v, p0, s);
      c->keep_resolve_start(true);
      SolveReport r;
      c->solve(&r);
      return c;
    };
    // One round: a cold classification at p1 with `s`, then `c` re-targeted
    // to p1 and re-solved warm (timed whole and its update alone), and back
    // to p0 for the next round.
    struct Round {
      double cold = 0, update = 0, warm = 0;
      int cold_cycles = 0, warm_cycles = 0;
    };
    auto reclassify = [&](VariationalClassifier& c, const SolverParams& s, bool json) {
      Round out;
      SolveReport r;
      ClassifyTiming t;
      classify_variational(rt, v, p1, s, &r, nullptr, nullptr, &t);
      out.cold = t.setup + t.solve, out.cold_cycles = r.cycles;
      if (json) progress::set_mode(progress::Mode::Json);
      const auto t0 = std::chrono::steady_clock::now();
      c.update(p1);
      out.update = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      c.solve(&r, nullptr, true);
      out.warm = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      progress::set_mode(progress::Mode::Off);
      out.warm_cycles = r.cycles;
      c.update(p0);
      c.solve(&r, nullptr, true);
      return out;
    };
    {
      const auto c = resolving(sp);
      double cold = 1e30, warm = 1e30, upd = 1e30;
      int cold_cycles = 0, warm_cycles = 0;
      const int rounds = std::max(3, reps / 2);
      for (int k = 0; k < rounds; ++k) {
        const Round t = reclassify(*c, sp, trace && k + 1 == rounds);
        cold = std::min(cold, t.cold), cold_cycles = t.cold_cycles;
        upd = std::min(upd, t.update), warm = std::min(warm, t.warm), warm_cycles = t.warm_cycles;
      }
      std::printf("re-classification: %.1f ms (update %.1f ms, %d cycles) vs cold %.1f ms (%d cycles): %.2f of cold\n",
                  warm * 1e3, upd * 1e3, warm_cycles, cold * 1e3, cold_cycles, warm / cold);
    }
    if (ab > 0) {
      // --ab ROUNDS: the float32 and the compact smoother (SolverParams::
      // compact_smoother) interleaved in one process, round by round: a
      // re-classification (v_iso x 1.05, warm, as above) and a cold
      // classification each (a one-shot classification never relaxes on the
      // compact stencil: the two cold columns are the same code, a measure of
      // the noise); min and median per setting. On a shared machine whose
      // bandwidth drifts from minute to minute this is the fair A/B.
      SolverParams spc[2] = {sp, sp};
      spc[0].compact_smoother = false, spc[1].compact_smoother = true;
      std::unique_ptr<VariationalClassifier> cls[2] = {resolving(spc[0]), resolving(spc[1])};
      std::vector<double> tw[2], tc[2];
      for (int round = 0; round < ab; ++round)
        for (int k = 0; k < 2; ++k) {
          const Round t = reclassify(*cls[k], spc[k], false);
          tc[k].push_back(t.cold);
          tw[k].push_back(t.warm);
        }
      for (int k = 0; k < 2; ++k) {
        const Timing w = summarise(tw[k]), c = summarise(tc[k]);
        std::printf("A/B %-8s re-classification min %.1f median %.1f ms, cold min %.1f median %.1f ms (%d rounds)\n",
                    k ? "compact" : "float32", w.min * 1e3, w.median * 1e3, c.min * 1e3, c.median * 1e3, ab);
      }
    }
    // The A/B re-solves (--ab-sweeps, --ab-resolve): a re-solve at p1 from
    // `c`'s kept stages, timed from its update, with its iterations and its
    // distance from `ref` logged; and the way back to p0 (polished) for the
    // next round.
    struct ResolveLog {
      std::vector<double> time, mean, share;
      int cycles = 0;
    };
    auto timed_resolve = [&](VariationalClassifier& c, const Volume& ref, ResolveLog& log) {
      SolveReport r;
      const auto t0 = std::chrono::steady_clock::now();
      c.update(p1);
      Volume u = c.solve(&r, nullptr, true);
      log.time.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      log.cycles = r.cycles;
      const Deviation d = deviation(u, ref);
      log.mean.push_back(d.mean), log.share.push_back(d.share);
      return u;
    };
    auto back_to_p0 = [&](VariationalClassifier& c) {
      SolveReport r;
      c.update(p0);
      c.solve(&r, nullptr, true);
      c.polish(&r);
    };
    auto worst = [](const std::vector<double>& x) { return *std::max_element(x.begin(), x.end()); };
    if (ab_sweeps > 0) {
      // --ab-sweeps ROUNDS: re-solves whose stages sweep first
      // (SolverParams::resolve_sweeps, the default) against re-solves
      // without (0), interleaved round by round with a cold classification;
      // each re-solve's distance from the reference at v_iso x 1.05
      // (sharpening from converged solves) beside the cold one's.
      SolverParams sps[2] = {sp, sp};
      sps[0].resolve_sweeps = 0;
      SolverParams sp_ref = sp;
      sp_ref.sharpen_tol = 0, sp_ref.resolve_tol = 0;
      SolveReport r;
      const Volume ref = classify_variational(rt, v, p1, sp_ref, &r);
      const Volume cold = classify_variational(rt, v, p1, sp, &r);
      std::unique_ptr<VariationalClassifier> cls[2] = {resolving(sps[0]), resolving(sps[1])};
      ResolveLog log[2];
      std::vector<double> tc;
      for (int round = 0; round < ab_sweeps; ++round) {
        ClassifyTiming t;
        classify_variational(rt, v, p1, sp, &r, nullptr, nullptr, &t);
        tc.push_back(t.setup + t.solve);
        for (int k = 0; k < 2; ++k) {
          timed_resolve(*cls[k], ref, log[k]);
          cls[k]->polish(&r);
          back_to_p0(*cls[k]);
        }
      }
      const Deviation dc = deviation(cold, ref);
      const Timing ct = summarise(tc);
      std::printf("cold classification: min %.1f median %.1f ms; distance from the reference mean %.2e, %.2f %% beyond 5e-3\n",
                  ct.min * 1e3, ct.median * 1e3, dc.mean, 100 * dc.share);
      for (int k = 0; k < 2; ++k) {
        const Timing w = summarise(log[k].time);
        std::printf("A/B re-solve, %d sweeps first: min %.1f median %.1f ms (median %.2f of cold), %d iterations; distance mean %.2e (worst), %.2f %% beyond 5e-3 (worst) (%d rounds)\n",
                    sps[k].resolve_sweeps, w.min * 1e3, w.median * 1e3, w.median / ct.median, log[k].cycles,
                    worst(log[k].mean), 100 * worst(log[k].share), ab_sweeps);
      }
    }
    if (ab_resolve > 0) {
      // --ab-resolve ROUNDS: re-solves to the solver's tol against re-solves
      // stopped at --resolve-tol (or 1e-3) and then polished, interleaved;
      // each result's distance from the reference at v_iso x 1.05
      // (sharpening from converged solves, as bench.cpp's bench_warm) beside
      // a cold classification's.
      SolverParams spr[2] = {sp, sp};
      spr[0].resolve_tol = 0, spr[1].resolve_tol = resolve_tol > 0 ? resolve_tol : 1e-3;
      SolverParams sp_ref = sp;
      sp_ref.sharpen_tol = 0;
      SolveReport r;
      const Volume ref = classify_variational(rt, v, p1, sp_ref, &r);
      const Volume cold = classify_variational(rt, v, p1, sp, &r);
      std::unique_ptr<VariationalClassifier> cls[2] = {resolving(spr[0]), resolving(spr[1])};
      ResolveLog log[2];
      std::vector<double> tp, pmean, pshare;
      for (int round = 0; round < ab_resolve; ++round)
        for (int k = 0; k < 2; ++k) {
          VariationalClassifier& c = *cls[k];
          const Volume u = timed_resolve(c, ref, log[k]);
          if (k == 1) {
            const auto t1 = std::chrono::steady_clock::now();
            const Volume up = c.polish(&r);
            tp.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count());
            const Deviation dp = deviation(up.data.empty() ? u : up, ref);
            pmean.push_back(dp.mean), pshare.push_back(dp.share);
          }
          back_to_p0(c);
        }
      const Deviation dc = deviation(cold, ref);
      std::printf("cold classification: distance from the reference mean %.2e, %.2f %% beyond 5e-3\n", dc.mean,
                  100 * dc.share);
      char loose[32];
      std::snprintf(loose, sizeof loose, "%.0e", spr[1].resolve_tol);
      for (int k = 0; k < 2; ++k) {
        const Timing w = summarise(log[k].time);
        std::printf("A/B re-solve to %-7s min %.1f median %.1f ms, %d cycles; distance mean %.2e (worst), %.2f %% beyond 5e-3 (worst) (%d rounds)\n",
                    k ? loose : "tol", w.min * 1e3, w.median * 1e3, log[k].cycles, worst(log[k].mean),
                    100 * worst(log[k].share), ab_resolve);
      }
      const Timing pt = summarise(tp);
      std::printf("    then polished: min %.1f median %.1f ms more; distance mean %.2e, %.2f %% beyond 5e-3 (worst)\n",
                  pt.min * 1e3, pt.median * 1e3, worst(pmean), 100 * worst(pshare));
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "softshell_bench_solver: " << e.what() << "\n";
    return 1;
  }
}
