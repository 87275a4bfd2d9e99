// The benchmark behind `softshell bench` (see bench.hpp, docs/benchmarks.md).
#include "bench.hpp"

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCore>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <limits>
#include <memory>
#include <random>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <unistd.h>

#include "error.hpp"
#include "filter.hpp"
#include "gradient.hpp"
#include "metrics.hpp"
#include "phantom.hpp"
#include "stencil.h"
#include "stream.hpp"
#include "variational.hpp"

namespace softshell {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::string fmt(const char* f, double v);

// ------------------------------------------------------------ host stencil

struct Offsets {
  long off[STENCIL_COEFS];
  explicit Offsets(const GridDesc& g) {
    const long sy = g.nx, sz = long(g.nx) * g.ny;
    const int table[STENCIL_COEFS][3] = {
#define SOFTSHELL_OFF(K, DX, DY, DZ) {DX, DY, DZ},
        STENCIL_OFFSETS(SOFTSHELL_OFF)
#undef SOFTSHELL_OFF
    };
    for (int k = 0; k < STENCIL_COEFS; ++k) off[k] = table[k][0] + table[k][1] * sy + table[k][2] * sz;
  }
};

inline bool boundary(const GridDesc& g, int x, int y, int z) {
  return x == 0 || y == 0 || z == 0 || x == g.nx - 1 || y == g.ny - 1 || z == g.nz - 1;
}

// (A u)_p for an interior voxel p, accumulated in T.
template <class T, class U>
inline T row(const HostStencil& s, const Offsets& o, std::size_t N, std::size_t p, const U* u) {
  const float* c = s.coef.data();
  T acc = T(c[p]) * T(u[p]);
  for (int k = 1; k < STENCIL_COEFS; ++k) {
    acc += T(c[k * N + p]) * T(u[p + o.off[k]]);
    acc += T(c[k * N + p - o.off[k]]) * T(u[p - o.off[k]]);
  }
  return acc;
}

void check_stencil(const HostStencil& s) {
  const std::size_t n = s.voxels();
  if (s.coef.size() != n * STENCIL_COEFS || s.b.size() != n || s.fixed.size() != n)
    throw std::invalid_argument("HostStencil: arrays of the wrong size");
}

// One lexicographic Gauss-Seidel sweep (forward or backward) for A u = rhs.
void gs_lex_sweep(const HostStencil& s, const Offsets& o, const std::vector<float>& rhs, std::vector<float>& u,
                  bool backward) {
  const GridDesc& g = s.grid;
  const std::size_t N = s.voxels();
  auto visit = [&](int x, int y, int z) {
    const std::size_t p = std::size_t(x) + std::size_t(g.nx) * (std::size_t(y) + std::size_t(g.ny) * z);
    if (boundary(g, x, y, z)) {
      u[p] = rhs[p] / s.coef[p];
      return;
    }
    u[p] += (rhs[p] - row<float>(s, o, N, p, u.data())) / s.coef[p];
  };
  if (!backward) {
    for (int z = 0; z < g.nz; ++z)
      for (int y = 0; y < g.ny; ++y)
        for (int x = 0; x < g.nx; ++x) visit(x, y, z);
  } else {
    for (int z = g.nz - 1; z >= 0; --z)
      for (int y = g.ny - 1; y >= 0; --y)
        for (int x = g.nx - 1; x >= 0; --x) visit(x, y, z);
  }
}

std::vector<float> host_residual_f(const HostStencil& s, const Offsets& o, const std::vector<float>& rhs,
                                   const std::vector<float>& u) {
  const GridDesc& g = s.grid;
  const std::size_t N = s.voxels();
  std::vector<float> r(N);
  for (int z = 0, p = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x, ++p)
        r[p] = rhs[p] - (boundary(g, x, y, z) ? s.coef[p] * u[p] : row<float>(s, o, N, std::size_t(p), u.data()));
  return r;
}

double norm2(const std::vector<float>& v) {
  double a = 0;
  for (float f : v) a += double(f) * f;
  return std::sqrt(a);
}

// ------------------------------------------------------------ Eigen peer

template <class S>
Eigen::SparseMatrix<S, Eigen::RowMajor> to_eigen(const HostStencil& s) {
  const GridDesc& g = s.grid;
  const std::size_t N = s.voxels();
  const Offsets o(g);
  // The 27 entries of a row in ascending column order: (signed offset, k, sign).
  struct Entry {
    long off;
    int k, sign;
  };
  std::vector<Entry> entries{{0, 0, 0}};
  for (int k = 1; k < STENCIL_COEFS; ++k) entries.push_back({o.off[k], k, 1}), entries.push_back({-o.off[k], k, -1});
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return a.off < b.off; });
  std::vector<int> outer(N + 1, 0), inner;
  std::vector<S> values;
  inner.reserve(N * 19);
  values.reserve(N * 19);
  for (int z = 0, p = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x, ++p) {
        if (boundary(g, x, y, z)) {
          inner.push_back(p), values.push_back(S(s.coef[std::size_t(p)]));
        } else {
          for (const Entry& e : entries) {
            const float v = e.k == 0   ? s.coef[std::size_t(p)]
                            : e.sign > 0 ? s.coef[e.k * N + std::size_t(p)]
                                         : s.coef[e.k * N + std::size_t(p + e.off)];
            if (v == 0.0f && e.k != 0) continue;  // structural zeros (fixed neighbours, corner offsets)
            inner.push_back(int(p + e.off)), values.push_back(S(v));
          }
        }
        outer[std::size_t(p) + 1] = int(inner.size());
      }
  Eigen::SparseMatrix<S, Eigen::RowMajor> A(static_cast<Eigen::Index>(N), static_cast<Eigen::Index>(N));
  A.resizeNonZeros(long(inner.size()));
  std::copy(outer.begin(), outer.end(), A.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), A.innerIndexPtr());
  std::copy(values.begin(), values.end(), A.valuePtr());
  return A;
}

template <class S>
PeerSolve eigen_cg_typed(const HostStencil& s, double tol, int max_iterations) {
  using Mat = Eigen::SparseMatrix<S, Eigen::RowMajor>;
  using Vec = Eigen::Matrix<S, Eigen::Dynamic, 1>;
  const Mat A = to_eigen<S>(s);
  Vec b(long(s.voxels()));
  for (std::size_t i = 0; i < s.voxels(); ++i) b[long(i)] = S(s.b[i]);
  PeerSolve r;
  const auto t0 = Clock::now();
  Eigen::ConjugateGradient<Mat, Eigen::Lower | Eigen::Upper> cg;
  cg.setMaxIterations(max_iterations);
  double t = tol;
  cg.setTolerance(S(t));
  cg.compute(A);
  Vec x = cg.solve(b);
  r.iterations = long(cg.iterations());
  r.seconds = since(t0);
  r.u.assign(x.data(), x.data() + x.size());
  r.residual = host_relative_residual(s, r.u);
  // Eigen judges its recursive residual; in float32 the true one can lag:
  // continue from x with a tighter tolerance until the true one is met.
  for (int extra = 0; extra < 4 && r.residual > tol && r.iterations < max_iterations; ++extra) {
    const auto t1 = Clock::now();
    t *= 0.5;
    cg.setTolerance(S(t));
    x = cg.solveWithGuess(b, x);
    r.iterations += long(cg.iterations());
    r.seconds += since(t1);
    r.u.assign(x.data(), x.data() + x.size());
    r.residual = host_relative_residual(s, r.u);
  }
  return r;
}

// ------------------------------------------------------------ device parts

}  // namespace

HostStencil host_stencil(const DeviceSystem& sys) {
  HostStencil h;
  h.grid = sys.grid();
  h.coef = sys.download_coefficients();
  h.b = sys.download_b();
  h.fixed = sys.download_densities().fixed;
  return h;
}

HostStencil compact_host_stencil(const DeviceSystem& sys) {
  HostStencil h = host_stencil(sys);
  const std::size_t n = h.voxels();
  const std::vector<std::uint16_t> c = sys.download_compact();
  const std::vector<float> delta = sys.download_compact_delta();
  for (std::size_t p = 0; p < n; ++p) h.coef[p] += delta[p];
  for (std::size_t i = 0; i < c.size(); ++i) {
    const std::uint32_t bits = std::uint32_t(c[i]) << 16;
    std::memcpy(&h.coef[n + i], &bits, sizeof bits);
  }
  return h;
}

Volume normalised(const Volume& v) {
  Volume vn = v;
  const IntensityMap map = v.intensity_map();
  for (float& f : vn.data) f = static_cast<float>(map.to_unit(f));
  return vn;
}

Deviation deviation(const Volume& a, const Volume& b) {
  Deviation d;
  std::size_t beyond = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    const double e = std::abs(double(a.data[i]) - double(b.data[i]));
    d.max = std::max(d.max, e), d.mean += e, beyond += e > 5e-3;
  }
  const double n = double(std::max<std::size_t>(1, a.data.size()));
  d.mean /= n, d.share = double(beyond) / n;
  return d;
}

double phantom_iso(const Phantom& ph) {
  return ph.volume.intensity_map().to_unit(ph.fluid_median + 0.5 * (ph.tissue_median - ph.fluid_median));
}

namespace {

// >>> Table 1 shapes: PhantomParams::dims <<<
// Non-cubic phantoms come with PhantomParams::dims (std::array<int, 3>,
// {0, 0, 0} meaning size^3). These overloads use that field when the
// phantom has it and report false otherwise, so the bench builds either way;
// without it, Table 1 runs cubes of as many voxels as the paper's volumes.
template <class P>
auto set_phantom_dims(P& p, const std::array<int, 3>& d, int) -> decltype(p.dims = d, true) {
  p.dims = d;
  return true;
}
template <class P>
bool set_phantom_dims(P&, const std::array<int, 3>&, long) {
  return false;
}

std::string dims_string(const std::array<int, 3>& d) {
  return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

Phantom phantom_of(Runtime& rt, PhantomShape shape, const std::array<int, 3>& want, std::array<int, 3>* got,
                   std::string* note) {
  PhantomParams pp;
  pp.shape = shape;
  pp.seed = 1;
  const bool cube = want[0] == want[1] && want[1] == want[2];
  if (cube || !set_phantom_dims(pp, want, 0)) {
    const double n = double(want[0]) * want[1] * want[2];
    pp.size = cube ? want[0] : int(std::lround(std::cbrt(n)));
    if (!cube && note) *note = "cube of as many voxels (phantom has no --dims yet)";
  } else {
    pp.size = std::max({want[0], want[1], want[2]});
  }
  Phantom ph = make_phantom(rt, pp);
  if (got) *got = {int(ph.volume.dims[0]), int(ph.volume.dims[1]), int(ph.volume.dims[2])};
  return ph;
}

struct Progress {
  std::ostream* out;
  std::string prefix;
  Clock::time_point t0 = Clock::now();
  void operator()(const std::string& line) const {
    if (out) *out << "bench: " << fmt("%6.1f s ", since(t0)) << prefix << line << std::endl;
  }
};

std::string describe(const std::exception& e) {
  if (const auto* ce = dynamic_cast<const cl::Error*>(&e))
    return std::string(ce->what()) + " failed: " + cl_error_name(ce->err());
  return e.what();
}

// Runs one part of a device's bench; an exception becomes a note (the part
// is skipped with its reason) instead of aborting the run.
template <class F>
bool part(DeviceBench& db, const Progress& progress, const std::string& name, F&& f) {
  try {
    progress(name);
    f();
    return true;
  } catch (const std::bad_alloc&) {
    db.notes.push_back(name + ": skipped: out of host memory");
  } catch (const std::exception& e) {
    db.notes.push_back(name + ": skipped: " + describe(e));
  }
  progress(db.notes.back());
  return false;
}

void check(DeviceBench& db, bool ok, const std::string& what) {
  if (!ok) db.failed_checks.push_back(what);
}

// ---- bandwidth

void bench_stream(Runtime& rt, DeviceBench& db, int reps, std::mt19937& rng) {
  const std::size_t n = std::size_t(1) << 24;  // 64 MiB per array: twice the largest cache here
  const std::size_t bytes = n * sizeof(float);
  db.stream_elements = n;
  // The host's own bandwidth first, same array sizes, same repeats.
  db.host = host_stream(n, reps);
  check(db, db.host.ok, "host stream: copy or triad gave a wrong result");
  std::vector<float> a(n), b(n), c(n);
  std::uniform_real_distribution<float> U(-1.0f, 1.0f);
  for (std::size_t i = 0; i < n; ++i) a[i] = U(rng), b[i] = U(rng);
  cl::Buffer da = rt.buffer(bytes), dbuf = rt.buffer(bytes), dc = rt.buffer(bytes);
  rt.queue().enqueueWriteBuffer(da, CL_TRUE, 0, bytes, a.data());
  rt.queue().enqueueWriteBuffer(dbuf, CL_TRUE, 0, bytes, b.data());
  Stream stream(rt);
  stream.copy(da, dc, n).wait();  // warm-up
  stream.triad(da, dbuf, dc, 0.5f, n).wait();
  std::vector<double> tc, tt;
  bool copy_ok = true, triad_ok = true;
  for (int r = 0; r < reps; ++r) {
    cl::Event e = stream.copy(da, dc, n);
    e.wait();
    tc.push_back(event_seconds(e));
    if (r == 0) {
      rt.queue().enqueueReadBuffer(dc, CL_TRUE, 0, bytes, c.data());
      copy_ok = std::memcmp(c.data(), a.data(), bytes) == 0;
    }
    const float s = 0.5f + 0.25f * float(r);
    e = stream.triad(da, dbuf, dc, s, n);
    e.wait();
    tt.push_back(event_seconds(e));
    if (r == 0) {
      rt.queue().enqueueReadBuffer(dc, CL_TRUE, 0, bytes, c.data());
      for (std::size_t i = 0; i < n; i += 97)
        triad_ok = triad_ok && std::abs(c[i] - (a[i] + s * b[i])) <= 1e-6f * (1.0f + std::abs(a[i]) + std::abs(b[i]));
    }
  }
  db.copy = summarise(tc);
  db.triad = summarise(tt);
  db.copy_gbps = 8.0 * double(n) / db.copy.min * 1e-9;
  db.triad_gbps = 12.0 * double(n) / db.triad.min * 1e-9;
  check(db, copy_ok, "stream copy: output differs from input");
  check(db, triad_ok, "stream triad: c != a + s b");
}

void bench_sweep_apply(Runtime& rt, DeviceBench& db, int size, int reps) {
  std::array<int, 3> got{};
  const Phantom ph = phantom_of(rt, PhantomShape::Face, {size, size, size}, &got, nullptr);
  VariationalParams vp;
  vp.v_iso = phantom_iso(ph);
  // The constructor uploads from vn without waiting: keep it alive until the queue is done.
  const Volume vn = normalised(ph.volume);
  DeviceSystem sys(rt, vn, vp);
  rt.queue().finish();
  const HostStencil hs = host_stencil(sys);
  const std::size_t N = hs.voxels(), bytes = N * sizeof(float);
  db.bw_size = size;
  db.bw_voxels = N;
  cl::Buffer x = rt.buffer(bytes), y = rt.buffer(bytes);
  rt.queue().enqueueFillBuffer(x, 0.0f, 0, bytes);
  // One forward sweep in the order the solver uses on this device (DeviceSystem::gs_order()).
  const bool slabs = sys.gs_order() == GsOrder::Slabs;
  db.sweep_order =
      !slabs ? "8 colours" : sys.gs_slab() == 1 ? "row order" : "slabs of " + std::to_string(sys.gs_slab());
  // Forward sweeps of x by `relax` (a function of x returning the event
  // span): `reps` times, x read before and after the first (for the checks).
  std::vector<float> before(N), after(N);
  auto timed_sweeps = [&](auto relax) {
    std::vector<double> t;
    for (int r = 0; r < reps; ++r) {
      if (r == 0) rt.queue().enqueueReadBuffer(x, CL_TRUE, 0, bytes, before.data());
      const auto span = relax();
      span.second.wait();
      t.push_back(event_span_seconds(span.first, span.second));
      if (r == 0) rt.queue().enqueueReadBuffer(x, CL_TRUE, 0, bytes, after.data());
    }
    return t;
  };
  // The largest deviation of the device's first sweep (`after`) from the
  // host's (`before`, swept on the host), relative to the host's largest value.
  double dev = 0, scale = 0;
  auto sweep_deviation = [&] {
    dev = 0, scale = 0;
    for (std::size_t i = 0; i < N; ++i) dev = std::max(dev, double(std::abs(before[i] - after[i]))), scale = std::max(scale, double(std::abs(before[i])));
    return scale > 0 ? dev / scale : dev;
  };
  auto sweep = [&] { return sys.relax_gs(sys.b(), x, 1, false); };
  sweep().second.wait();  // warm-up (and a non-trivial u for the checks)
  std::vector<double> ts = timed_sweeps(sweep), ta;
  if (slabs)
    host_gs_slab_sweep(hs, before, sys.gs_slab(), false);
  else
    host_gs_colour_sweep(hs, before);
  db.sweep_check = sweep_deviation();
  check(db, scale > 0 && db.sweep_check <= 1e-4,
        std::string("sweep: device differs from the host ") + (slabs ? "row/slab" : "8-colour") +
            " Gauss-Seidel by " + std::to_string(db.sweep_check) + " (relative)");
  rt.queue().enqueueReadBuffer(x, CL_TRUE, 0, bytes, after.data());
  sys.apply(x, y).wait();  // warm-up
  for (int r = 0; r < reps; ++r) {
    cl::Event e = sys.apply(x, y);
    e.wait();
    ta.push_back(event_seconds(e));
  }
  std::vector<float> ydev(N);
  rt.queue().enqueueReadBuffer(y, CL_TRUE, 0, bytes, ydev.data());
  const std::vector<double> yref = host_apply(hs, after);
  dev = 0, scale = 0;
  for (std::size_t i = 0; i < N; ++i) dev = std::max(dev, std::abs(ydev[i] - yref[i])), scale = std::max(scale, std::abs(yref[i]));
  db.apply_check = scale > 0 ? dev / scale : dev;
  check(db, scale > 0 && db.apply_check <= 1e-4,
        "apply: device differs from the float64 host apply by " + std::to_string(db.apply_check) + " (relative)");
  db.sweep = summarise(ts);
  db.apply = summarise(ta);
  db.sweep_gbps = ByteModel::sweep * double(N) / db.sweep.min * 1e-9;
  db.apply_gbps = ByteModel::apply * double(N) / db.apply.min * 1e-9;
  if (db.copy_gbps > 0) db.sweep_fraction = db.sweep_gbps / db.copy_gbps, db.apply_fraction = db.apply_gbps / db.copy_gbps;
  if (db.host.copy_gbps > 0)
    db.sweep_fraction_host = db.sweep_gbps / db.host.copy_gbps, db.apply_fraction_host = db.apply_gbps / db.host.copy_gbps;
  if (!slabs) return;
  // The preconditioner's sweep on the compact stencil, from the same u.
  sys.build_compact();
  const HostStencil hc = compact_host_stencil(sys);
  const std::vector<double> tc = timed_sweeps([&] { return sys.relax_gs_compact(sys.b(), x, 1, false); });
  host_gs_slab_sweep(hc, before, sys.gs_slab(), false);
  db.sweep_compact_check = sweep_deviation();
  check(db, scale > 0 && db.sweep_compact_check <= 1e-4,
        "compact sweep: device differs from the host's sweep of the compact matrix by " +
            std::to_string(db.sweep_compact_check) + " (relative)");
  db.sweep_compact = summarise(tc);
  db.sweep_compact_gbps = ByteModel::sweep_compact * double(N) / db.sweep_compact.min * 1e-9;
  if (db.host.copy_gbps > 0) db.sweep_compact_fraction_host = db.sweep_compact_gbps / db.host.copy_gbps;
}

// The solve against its bandwidth bound: a built hierarchy's cold solves
// (FMG + PCG), timed by the solver (no hierarchy build), with the bytes the
// solver counted under the byte model.
void bench_solve_bound(DeviceBench& db, DeviceSystem& sys, const SolverParams& sp, int reps) {
  MultigridSolver mg(sys, sp);
  SolveReport rep;
  mg.solve(&rep);  // warm-up
  std::vector<double> t;
  for (int r = 0; r < reps; ++r) {
    mg.solve(&rep);
    check(db, rep.converged, "solve bound: the solve did not converge");
    t.push_back(rep.seconds);
  }
  db.solve_seconds = summarise(t).min;
  db.solve_iterations = rep.cycles;
  db.solve_bytes_per_voxel = rep.bytes / double(sys.voxels());
  if (db.host.copy_gbps > 0) {
    db.solve_bound_s = rep.bytes / (db.host.copy_gbps * 1e9);
    db.solve_bound_ratio = db.solve_seconds / db.solve_bound_s;
  }
  if (db.copy_gbps > 0) db.solve_bound_ratio_device = db.solve_seconds / (rep.bytes / (db.copy_gbps * 1e9));
}

// ---- HYPRE PFMG-PCG (bench/pfmg_peer.cpp, a separate MPI program)

// The peer program: $SOFTSHELL_PFMG_PEER, else next to this executable,
// else in ../bench/ from it (the build tree: build/host/softshell,
// build/bench/softshell_pfmg_peer); "" when none exists.
std::string pfmg_peer_path() {
  auto exists = [](const std::string& p) { return !p.empty() && ::access(p.c_str(), X_OK) == 0; };
  if (const char* env = std::getenv("SOFTSHELL_PFMG_PEER")) return exists(env) ? env : "";
  char self[4096];
  const ssize_t len = ::readlink("/proc/self/exe", self, sizeof self - 1);
  if (len > 0) {
    std::string dir(self, std::size_t(len));
    dir = dir.substr(0, dir.rfind('/'));
    for (const std::string& p : {dir + "/softshell_pfmg_peer", dir + "/../bench/softshell_pfmg_peer"})
      if (exists(p)) return p;
  }
  return "";
}

// ||b - A u|| / ||b|| in float64 of a float64 u.
double relative_residual64(const HostStencil& s, const std::vector<double>& u) {
  const GridDesc& g = s.grid;
  const std::size_t N = s.voxels();
  const Offsets o(g);
  double rr = 0, bb = 0;
  for (int z = 0, p = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x, ++p) {
        const double au = boundary(g, x, y, z) ? double(s.coef[p]) * u[p] : row<double>(s, o, N, std::size_t(p), u.data());
        rr += (s.b[p] - au) * (s.b[p] - au), bb += double(s.b[p]) * s.b[p];
      }
  return bb > 0 ? std::sqrt(rr / bb) : std::sqrt(rr);
}

struct PfmgRun {
  double setup = 0, solve = 0, hypre_residual = 0, residual = 0;
  long iterations = 0;
  int ranks = 0;
};

// Exports the system, runs the peer on `ranks` MPI ranks to `tol`, reads
// its solution back and evaluates its residual here (float64).
PfmgRun run_pfmg(const std::string& peer, const HostStencil& hs, double tol, int ranks) {
  char dir_template[] = "/tmp/softshell-pfmg-XXXXXX";
  const char* dir = ::mkdtemp(dir_template);
  if (!dir) throw std::runtime_error("cannot make a temporary directory for the PFMG peer");
  const std::string sys_path = std::string(dir) + "/system.bin", out_path = std::string(dir) + "/result.bin",
                    log_path = std::string(dir) + "/log.txt";
  struct Cleanup {
    std::string a, b, c, d;
    ~Cleanup() { std::remove(a.c_str()), std::remove(b.c_str()), std::remove(c.c_str()), ::rmdir(d.c_str()); }
  } cleanup{sys_path, out_path, log_path, dir};
  {
    std::ofstream f(sys_path, std::ios::binary);
    const std::int32_t dims[3] = {hs.grid.nx, hs.grid.ny, hs.grid.nz};
    f.write("SSPFMG1", 8);
    f.write(reinterpret_cast<const char*>(dims), sizeof dims);
    f.write(reinterpret_cast<const char*>(hs.coef.data()), std::streamsize(hs.coef.size() * sizeof(float)));
    f.write(reinterpret_cast<const char*>(hs.b.data()), std::streamsize(hs.b.size() * sizeof(float)));
    if (!f) throw std::runtime_error("cannot write the system for the PFMG peer");
  }
  std::ostringstream cmd;
  cmd << "mpirun -n " << ranks << " --bind-to none --oversubscribe" << (::geteuid() == 0 ? " --allow-run-as-root" : "")
      << " '" << peer << "' '" << sys_path << "' '" << out_path << "' " << fmt("%.17g", tol) << " > '" << log_path
      << "' 2>&1";
  const int rc = std::system(cmd.str().c_str());
  std::ifstream in(out_path, std::ios::binary);
  char magic[8];
  double head[3];
  std::int64_t it = 0;
  PfmgRun r;
  std::vector<double> u(hs.voxels());
  if (rc != 0 || !in.read(magic, 8) || std::memcmp(magic, "SSPFMGR", 8) != 0 ||
      !in.read(reinterpret_cast<char*>(head), sizeof head) || !in.read(reinterpret_cast<char*>(&it), sizeof it) ||
      !in.read(reinterpret_cast<char*>(u.data()), std::streamsize(u.size() * sizeof(double)))) {
    // The first line of the log that says something (mpirun frames its
    // messages with lines of dashes).
    std::ifstream log(log_path);
    std::string line, first;
    while (first.empty() && std::getline(log, line))
      if (line.find_first_not_of("- \t") != std::string::npos) first = line;
    throw std::runtime_error("mpirun " + peer + " failed (status " + std::to_string(rc) + ")" +
                             (first.empty() ? "" : ": " + first));
  }
  r.setup = head[0], r.solve = head[1], r.hypre_residual = head[2], r.iterations = long(it), r.ranks = ranks;
  r.residual = relative_residual64(hs, u);
  return r;
}

// ---- peers

// The peers on one system: softshell's solve (warm-up + `reps`), Eigen CG in
// float64 and float32, the two-level Gauss-Seidel; all to db.tol. Returns
// the fastest Eigen CG over softshell's time (0 when either failed).
double bench_peers(Runtime& rt, DeviceBench& db, const Phantom& ph, double beta, int reps, const Progress& progress,
                   std::vector<PeerResult>& out) {
  VariationalParams vp;
  vp.v_iso = phantom_iso(ph);
  vp.beta = beta;
  const std::string tag = beta == VariationalParams{}.beta ? "" : " (beta " + fmt("%g", beta) + ")";
  // The constructor uploads from vn without waiting: keep it alive until the queue is done.
  const Volume vn = normalised(ph.volume);
  DeviceSystem sys(rt, vn, vp);
  rt.queue().finish();
  const HostStencil hs = host_stencil(sys);
  SolverParams sp;
  sp.tol = db.tol;
  const double ok_tol = db.tol * 1.1;  // float32 rounding between the device's and the float64 evaluation

  PeerResult soft;
  soft.name = "softshell";
  std::vector<double> ts;
  SolveReport rep;
  std::vector<float> u;
  for (int r = 0; r < reps + 1; ++r) {  // the first is a warm-up
    u = solve(sys, sp, &rep);
    if (r > 0) ts.push_back(rep.seconds);
  }
  soft.time = summarise(ts);
  soft.iterations = rep.cycles;
  soft.residual = host_relative_residual(hs, u);
  soft.ok = rep.converged && soft.residual <= ok_tol;
  soft.detail = std::to_string(rep.levels) + "-level V-cycle-preconditioned CG, " + rt.info().device_name;
  if (beta == VariationalParams{}.beta) bench_solve_bound(db, sys, sp, std::max(reps, 3));
  check(db, soft.ok, "softshell solve" + tag + ": residual " + std::to_string(soft.residual) + " above " +
                        std::to_string(db.tol));
  out.push_back(soft);

  const int threads = eigen_threads();
  for (bool f64 : {true, false}) {
    PeerResult pr;
    pr.name = f64 ? "eigen-cg-f64" : "eigen-cg-f32";
    pr.detail = std::string(f64 ? "float64" : "float32") + ", diagonal preconditioner, " + std::to_string(threads) +
                " thread" + (threads > 1 ? "s" : "");
    progress("peers: " + pr.name + tag);
    try {
      const PeerSolve s = eigen_cg_peer(hs, db.tol, f64);
      pr.time = summarise({s.seconds});
      pr.iterations = s.iterations;
      pr.residual = s.residual;
      pr.ok = s.residual <= ok_tol;
    } catch (const std::exception& e) {
      pr.error = describe(e);
    }
    check(db, pr.ok, pr.name + tag + ": did not reach the residual (" + std::to_string(pr.residual) + ")" + pr.error);
    out.push_back(pr);
  }
  {
    PeerResult pr;
    pr.name = "gauss-seidel-2level";
    progress("peers: " + pr.name + tag);
    try {
      auto coarse = DeviceSystem::coarsen(sys);
      const HostStencil hc = host_stencil(*coarse);
      const PeerSolve s = gauss_seidel_two_level_peer(hs, hc, db.tol);
      pr.time = summarise({s.seconds});
      pr.iterations = s.iterations;
      pr.residual = s.residual;
      pr.ok = s.residual <= ok_tol;
      pr.detail = "float32, 1 thread, lexicographic GS V(2,2), coarse " + dims_string({hc.grid.nx, hc.grid.ny, hc.grid.nz}) +
                  " 8 sweeps";
      if (!pr.ok) pr.error = "not converged in " + std::to_string(s.iterations) + " cycles";
    } catch (const std::exception& e) {
      pr.error = describe(e);
    }
    check(db, pr.ok, pr.name + tag + ": did not reach the residual (" + std::to_string(pr.residual) + ") " + pr.error);
    out.push_back(pr);
  }
  const std::string peer = pfmg_peer_path();
  if (!peer.empty() && std::system("command -v mpirun > /dev/null 2>&1") != 0) {
    db.notes.push_back("hypre-pfmg-pcg" + tag + ": skipped: " + peer + " is built but mpirun is not on the PATH");
  } else if (!peer.empty()) {
    PeerResult pr;
    pr.name = "hypre-pfmg-pcg";
    progress("peers: " + pr.name + tag);
    const int ranks = int(std::max(1u, std::thread::hardware_concurrency()));
    try {
      // The same repeats as softshell's solve, after one warm-up run.
      std::vector<double> totals, solves;
      PfmgRun run;
      for (int r = 0; r < reps + 1; ++r) {
        run = run_pfmg(peer, hs, db.tol, ranks);
        if (r > 0) totals.push_back(run.setup + run.solve), solves.push_back(run.solve);
      }
      pr.time = summarise(totals);
      pr.iterations = run.iterations;
      pr.residual = run.residual;
      pr.ok = run.residual <= ok_tol;
      pr.detail = "float64, HYPRE " + std::string("PFMG-PCG (Struct), ") + std::to_string(ranks) + " MPI rank" +
                  (ranks > 1 ? "s" : "") + ", V(1,1) weighted Jacobi, Galerkin; setup " +
                  fmt("%.3f", run.setup) + " s + solve " + fmt("%.3f", summarise(solves).min) + " s";
      if (beta == VariationalParams{}.beta && pr.ok && soft.ok) {
        db.speedup_vs_pfmg = pr.time.min / soft.time.min;
        db.pfmg_solve_seconds = summarise(solves).min;
      }
      check(db, pr.ok, pr.name + tag + ": did not reach the residual (" + std::to_string(pr.residual) + ")");
      out.push_back(pr);
    } catch (const std::exception& e) {
      // The peer could not run here (no mpirun, MPI refusing to start): a
      // note, not a failed check; the other peers stand.
      db.notes.push_back(pr.name + tag + ": skipped: " + describe(e));
      progress(db.notes.back());
    }
  }
  double best = 0;
  for (const PeerResult& p : out)
    if (p.name.rfind("eigen-cg", 0) == 0 && p.ok && (best == 0 || p.time.min < best)) best = p.time.min;
  return best > 0 && soft.ok && soft.time.min > 0 ? best / soft.time.min : 0.0;
}

// ---- warm start

void bench_warm(Runtime& rt, DeviceBench& db, int size, int reps) {
  const Phantom ph = phantom_of(rt, PhantomShape::Face, {size, size, size}, nullptr, nullptr);
  VariationalParams p0;
  p0.v_iso = phantom_iso(ph);
  VariationalParams p1 = p0;
  p1.v_iso = 1.05 * p0.v_iso;
  SolverParams sp;
  sp.tol = db.tol;
  SolveReport rep;
  // The reference at v_iso': sharpening from converged solves (every stage
  // to the solver's tol). A cold classification stops its linear solve and
  // first sharpening step at SolverParams::sharpen_tol, and its result
  // depends on where: the re-solve must come as close to the reference.
  SolverParams sp_ref = sp;
  sp_ref.sharpen_tol = 0;
  const Volume ref = classify_variational(rt, ph.volume, p1, sp_ref, &rep);
  check(db, rep.converged, "warm start: the reference classification did not converge");
  // The viewer's path: one classifier, set up and solved at v_iso, keeping
  // its linear solution for the re-solve.
  VariationalClassifier c(rt, ph.volume, p0, sp);
  c.keep_resolve_start(true);
  c.solve(&rep);
  check(db, rep.converged, "warm start: the first solve did not converge");
  std::vector<double> cold, warm, cold_total, warm_total, update, polish;
  Deviation dev_cold, dev_warm, dev_polish;
  db.warm_resolve_tol = sp.resolve_tol;
  for (int r = 0; r < reps; ++r) {
    ClassifyTiming t;
    const Volume uc = classify_variational(rt, ph.volume, p1, sp, &rep, nullptr, nullptr, &t);
    check(db, rep.converged, "warm start: cold classification did not converge");
    cold.push_back(t.solve), cold_total.push_back(t.setup + t.solve), db.warm_cold_iterations = rep.cycles;
    const auto t0 = Clock::now();
    c.update(p1);
    const double tu = since(t0);
    const Volume uw = c.solve(&rep, nullptr, true);
    const double tw = since(t0);
    check(db, rep.converged, "warm start: the re-solve did not converge");
    update.push_back(tu), warm.push_back(tw - tu), warm_total.push_back(tw), db.warm_warm_iterations = rep.cycles;
    const Deviation dc = deviation(uc, ref), dw = deviation(uw, ref);
    if (r == 0 || dw.mean > dev_warm.mean) dev_warm = dw;  // the worst repeat
    dev_cold = dc;
    // The viewer's polish once the slider rests (nothing to do when the
    // re-solve already reached tol).
    const auto t1 = Clock::now();
    const Volume up = c.polish(&rep);
    polish.push_back(since(t1));
    check(db, up.data.empty() || rep.converged, "warm start: the polish did not converge");
    const Deviation dp = deviation(up.data.empty() ? uw : up, ref);
    if (r == 0 || dp.mean > dev_polish.mean) dev_polish = dp;
    if (!up.data.empty()) db.warm_loose_vs_polished_max = std::max(db.warm_loose_vs_polished_max, deviation(uw, up).max);
    c.update(p0);  // back to v_iso for the next repeat (untimed), as the viewer: re-solve, polish
    c.solve(&rep, nullptr, true);
    c.polish(&rep);
  }
  db.warm_polish = summarise(polish).min;
  db.warm_ref_polish_mean = dev_polish.mean, db.warm_ref_polish_share = dev_polish.share;
  db.warm_ref_cold_mean = dev_cold.mean, db.warm_ref_cold_max = dev_cold.max, db.warm_ref_cold_share = dev_cold.share;
  db.warm_ref_warm_mean = dev_warm.mean, db.warm_ref_warm_max = dev_warm.max, db.warm_ref_warm_share = dev_warm.share;
  // As close to the reference as the cold classification: mean |du| and
  // the share beyond 5e-3 within a factor of 2 (measured on the 105^3
  // face: 0.7-1.1 and 0.5-1.3, docs/numerics.md "Re-solving"); a broken
  // start lands far outside.
  check(db, dev_warm.mean <= 2 * dev_cold.mean + 1e-6 && dev_warm.share <= 2 * dev_cold.share + 1e-3,
        "warm start: the re-solve is further from the reference than the cold classification (mean |du| " +
            fmt("%.2e", dev_warm.mean) + " vs " + fmt("%.2e", dev_cold.mean) + ")");
  db.warm_cold_solve = summarise(cold).min;
  db.warm_warm_solve = summarise(warm).min;
  db.warm_cold_total = summarise(cold_total).min;
  db.warm_warm_total = summarise(warm_total).min;
  db.warm_update = summarise(update).min;
  db.warm_start_fraction = db.warm_warm_total / db.warm_cold_total;
  db.warm_solve_fraction = db.warm_warm_solve / db.warm_cold_solve;
}

// ---- classification rows

struct Classified {
  double filter = 0, gradients = 0, setup = 0, solve = 0, total = 0;
  SolveReport report;
  Volume u;
};

// One classification, and the device time of its lowpasses and gradients
// (the same kernels on the same volume, run on their own with events).
Classified classify_timed(Runtime& rt, const Volume& v, const VariationalParams& vp, const SolverParams& sp,
                          bool stages) {
  Classified c;
  if (stages) {
    const Volume vn = normalised(v);
    const GridDesc g = make_grid(vn.dims, vn.spacing);
    const std::size_t bytes = vn.voxels() * sizeof(float);
    cl::Buffer dv = rt.buffer(bytes), s1 = rt.buffer(bytes), s2 = rt.buffer(bytes);
    std::array<cl::Buffer, 3> gr{rt.buffer(bytes), rt.buffer(bytes), rt.buffer(bytes)};
    rt.queue().enqueueWriteBuffer(dv, CL_TRUE, 0, bytes, vn.data.data());
    const Lowpass lp(rt, g, {vp.sigma_mm, 3.0});
    auto ev = lp.apply(dv, s1);
    ev.back().wait();
    c.filter = event_span_seconds(ev.front(), ev.back());
    const Gradient grad(rt, g);
    const cl::Buffer* gsrc = &dv;
    if (vp.grad_sigma_mm > 0) {
      const Lowpass lg(rt, g, {vp.grad_sigma_mm, 3.0});
      ev = lg.apply(dv, s2);
      ev.back().wait();
      c.filter += event_span_seconds(ev.front(), ev.back());
      gsrc = &s2;
    }
    cl::Event e1 = grad.apply(*gsrc, gr[0], gr[1], gr[2]);
    cl::Event e2 = grad.apply(s1, gr[0], gr[1], gr[2]);
    e2.wait();
    c.gradients = event_seconds(e1) + event_seconds(e2);
  }
  ClassifyTiming t;
  const auto t0 = Clock::now();
  c.u = classify_variational(rt, v, vp, sp, &c.report, nullptr, nullptr, &t);
  c.total = since(t0);
  c.setup = std::max(0.0, t.setup - c.filter - c.gradients);
  c.solve = t.solve;
  return c;
}

struct PaperRow {
  const char* dataset;
  PhantomShape shape;
  std::array<int, 3> dims;
  double seconds, opaque;
  std::size_t splats;
  double shearwarp, splat;
};
// The paper's Table 1 (600 MHz Pentium III, GeForce2 GTS; 400x400 renderings).
const PaperRow kPaperTable1[] = {
    {"Fetal face I", PhantomShape::Face, {77, 97, 56}, 5.7, 16, 32188, 0.13, 0.1},
    {"Fetal face II", PhantomShape::Face, {77, 60, 83}, 4.0, 17.5, 30428, 0.12, 0.11},
    {"Whole fetus", PhantomShape::Face, {123, 71, 85}, 10.5, 12.5, 44908, 0.2, 0.12},
    {"Spine", PhantomShape::Spine, {314, 85, 43}, 5.7, 16, 96349, 0.21, 0.26},
};

void bench_table1(Runtime& rt, DeviceBench& db, bool quick, int reps, const RenderTimer& render,
                  const Progress& progress) {
  for (const PaperRow& pr : kPaperTable1) {
    Table1Row row;
    row.dataset = pr.dataset;
    row.shape = phantom_shape_name(pr.shape);
    row.paper_dims = pr.dims;
    row.paper_seconds = pr.seconds, row.paper_opaque_percent = pr.opaque, row.paper_splats = pr.splats;
    row.paper_shearwarp = pr.shearwarp, row.paper_splat = pr.splat;
    std::array<int, 3> want = pr.dims;
    if (quick)
      for (int& d : want) d = std::max(16, (d + 1) / 2);
    progress("table 1: " + row.dataset + " (" + dims_string(want) + ")");
    const Phantom ph = phantom_of(rt, pr.shape, want, &row.dims, &row.dims_note);
    if (quick) row.dims_note = "halved (--quick)" + (row.dims_note.empty() ? "" : "; " + row.dims_note);
    VariationalParams vp;
    vp.v_iso = phantom_iso(ph);
    SolverParams sp;
    sp.tol = db.tol;
    std::vector<double> totals;
    Classified best;
    // Warm-up: a new shape or spacing builds new lowpass specialisations, and
    // PoCL compiles a kernel for a new work-group layout at its first launch.
    classify_timed(rt, ph.volume, vp, sp, true);
    for (int r = 0; r < reps; ++r) {
      Classified c = classify_timed(rt, ph.volume, vp, sp, true);
      totals.push_back(c.total);
      if (r == 0 || c.total < best.total) best = std::move(c);
    }
    const Timing tt = summarise(totals);
    row.filter = best.filter, row.gradients = best.gradients, row.setup = best.setup, row.solve = best.solve;
    row.total = tt.min, row.total_median = tt.median, row.reps = tt.reps;
    row.iterations = best.report.cycles, row.levels = best.report.levels;
    row.residual = best.report.residuals.empty() ? 0 : best.report.residuals.back();
    row.converged = best.report.converged;
    std::size_t opaque = 0;
    for (float a : best.u.data) opaque += a > kOpaqueLevel, row.splats += a > 0.2f;
    row.opaque_percent = 100.0 * double(opaque) / double(best.u.voxels());
    check(db, row.converged, "table 1 " + row.dataset + ": solve did not converge");
    if (render) {
      row.render_shearwarp = render(rt, best.u, "shearwarp", 400, 400);
      row.render_splat = render(rt, best.u, "splat", 400, 400);
    }
    if (!row.render_shearwarp || !row.render_splat) row.render_note = "n/a (renderer issue)";
    db.table1.push_back(row);
  }
}

void bench_scaling(Runtime& rt, DeviceBench& db, const std::vector<int>& sizes, int reps_small,
                   const Progress& progress) {
  for (int size : sizes) {
    const int reps = size <= 128 ? reps_small : 1;
    progress("scaling: " + std::to_string(size) + "^3 (" + std::to_string(reps) + (reps > 1 ? " runs)" : " run)"));
    try {
      const Phantom ph = phantom_of(rt, PhantomShape::Face, {size, size, size}, nullptr, nullptr);
      VariationalParams vp;
      vp.v_iso = phantom_iso(ph);
      SolverParams sp;
      sp.tol = db.tol;
      ScalingRow row;
      row.size = size;
      row.voxels = ph.volume.voxels();
      std::vector<double> totals;
      double best = std::numeric_limits<double>::infinity();
      for (int r = 0; r < reps; ++r) {
        Classified c = classify_timed(rt, ph.volume, vp, sp, false);
        totals.push_back(c.total);
        if (c.total < best) {
          best = c.total;
          row.setup = c.setup, row.solve = c.solve, row.iterations = c.report.cycles;
          row.residual = c.report.residuals.back(), row.converged = c.report.converged;
        }
      }
      row.total = summarise(totals);
      check(db, row.converged, "scaling " + std::to_string(size) + "^3: solve did not converge");
      db.scaling.push_back(row);
    } catch (const std::bad_alloc&) {
      db.notes.push_back("scaling " + std::to_string(size) + "^3: skipped: out of host memory");
    } catch (const std::exception& e) {
      db.notes.push_back("scaling " + std::to_string(size) + "^3: skipped: " + describe(e));
    }
  }
  // Least-squares slope of log(time) against log(voxels).
  if (db.scaling.size() >= 2) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    const double n = double(db.scaling.size());
    for (const ScalingRow& r : db.scaling) {
      const double x = std::log(double(r.voxels)), y = std::log(r.total.min);
      sx += x, sy += y, sxx += x * x, sxy += x * y;
    }
    db.scaling_exponent = (n * sxy - sx * sy) / (n * sxx - sx * sx);
  }
}

std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  if (!(in >> a >> b >> c)) return "unknown";
  return a + " " + b + " " + c;
}

std::string host_cpu_name() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0 && line.find(':') != std::string::npos) {
      std::string s = line.substr(line.find(':') + 1);
      return s.substr(s.find_first_not_of(' '));
    }
  return "unknown CPU";
}

// ------------------------------------------------------------ output helpers

std::string json_string(const std::string& s) {
  std::string o = "\"";
  for (char ch : s) {
    if (ch == '"' || ch == '\\') o += '\\', o += ch;
    else if (ch == '\n') o += "\\n";
    else if (static_cast<unsigned char>(ch) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", ch);
      o += buf;
    } else o += ch;
  }
  return o + "\"";
}

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

std::string json_timing(const Timing& t) {
  return "{\"min_s\": " + json_number(t.min) + ", \"median_s\": " + json_number(t.median) +
         ", \"reps\": " + std::to_string(t.reps) + "}";
}

std::string json_dims(const std::array<int, 3>& d) {
  return "[" + std::to_string(d[0]) + ", " + std::to_string(d[1]) + ", " + std::to_string(d[2]) + "]";
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

}  // namespace

// ------------------------------------------------------------ public

Timing summarise(std::vector<double> t) {
  Timing s;
  if (t.empty()) return s;
  std::sort(t.begin(), t.end());
  s.min = t.front();
  s.median = t.size() % 2 ? t[t.size() / 2] : 0.5 * (t[t.size() / 2 - 1] + t[t.size() / 2]);
  s.reps = int(t.size());
  return s;
}

bool BenchReport::all_checks_passed() const {
  for (const DeviceBench& d : devices)
    if (!d.failed_checks.empty()) return false;
  return true;
}

int eigen_threads() { return Eigen::nbThreads(); }

double host_relative_residual(const HostStencil& s, const std::vector<float>& u) {
  check_stencil(s);
  if (u.size() != s.voxels()) throw std::invalid_argument("host_relative_residual: u has the wrong size");
  const std::vector<double> au = host_apply(s, u);
  double rr = 0, bb = 0;
  for (std::size_t i = 0; i < au.size(); ++i) {
    const double r = double(s.b[i]) - au[i];
    rr += r * r, bb += double(s.b[i]) * s.b[i];
  }
  return bb > 0 ? std::sqrt(rr / bb) : std::sqrt(rr);
}

std::vector<double> host_apply(const HostStencil& s, const std::vector<float>& x) {
  check_stencil(s);
  const GridDesc& g = s.grid;
  const std::size_t N = s.voxels();
  const Offsets o(g);
  std::vector<double> y(N);
  for (int z = 0, p = 0; z < g.nz; ++z)
    for (int y_ = 0; y_ < g.ny; ++y_)
      for (int x_ = 0; x_ < g.nx; ++x_, ++p)
        y[p] = boundary(g, x_, y_, z) ? double(s.coef[p]) * x[p] : row<double>(s, o, N, std::size_t(p), x.data());
  return y;
}

void host_gs_slab_sweep(const HostStencil& s, std::vector<float>& u, int slab, bool reverse) {
  check_stencil(s);
  if (slab < 1) throw std::invalid_argument("host_gs_slab_sweep: slab < 1");
  const GridDesc& g = s.grid;
  const std::size_t N = s.voxels();
  const Offsets o(g);
  auto relax_row = [&](int y, int z) {
    for (int j = 0; j < g.nx; ++j) {
      const int x = reverse ? g.nx - 1 - j : j;
      const std::size_t p = std::size_t(x) + std::size_t(g.nx) * (std::size_t(y) + std::size_t(g.ny) * z);
      if (boundary(g, x, y, z))
        u[p] = s.b[p] / s.coef[p];
      else  // u_p = (b_p - sum_{q != p} A_pq u_q) / A_pp, with the latest u
        u[p] = float((double(s.b[p]) - (row<double>(s, o, N, p, u.data()) - double(s.coef[p]) * u[p])) / s.coef[p]);
    }
  };
  // Colour c: the slabs [k slab, (k + 1) slab) with k = c mod 2; every voxel
  // in order, forward: plane, row, x ascending (lexicographic in each slab);
  // reverse: all of it backwards. Slabs of one colour are not coupled, so
  // their order is free.
  for (int i = 0; i < 2; ++i) {
    const int c = reverse ? 1 - i : i;
    for (int z0 = c * slab; z0 < g.nz; z0 += 2 * slab)
      for (int j = 0; j < slab && z0 + j < g.nz; ++j) {
        const int z = reverse ? std::min(z0 + slab, g.nz) - 1 - j : z0 + j;
        for (int k = 0; k < g.ny; ++k) relax_row(reverse ? g.ny - 1 - k : k, z);
      }
  }
}

void host_gs_colour_sweep(const HostStencil& s, std::vector<float>& u) {
  check_stencil(s);
  const GridDesc& g = s.grid;
  const std::size_t N = s.voxels();
  const Offsets o(g);
  for (int c = 0; c < 8; ++c)
    for (int z = (c >> 2) & 1; z < g.nz; z += 2)
      for (int y = (c >> 1) & 1; y < g.ny; y += 2)
        for (int x = c & 1; x < g.nx; x += 2) {
          const std::size_t p = std::size_t(x) + std::size_t(g.nx) * (std::size_t(y) + std::size_t(g.ny) * z);
          if (boundary(g, x, y, z))
            u[p] = s.b[p] / s.coef[p];
          else
            u[p] = float(u[p] + (double(s.b[p]) - row<double>(s, o, N, p, u.data())) / s.coef[p]);
        }
}

PeerSolve eigen_cg_peer(const HostStencil& s, double tol, bool float64, int max_iterations) {
  check_stencil(s);
  return float64 ? eigen_cg_typed<double>(s, tol, max_iterations) : eigen_cg_typed<float>(s, tol, max_iterations);
}

PeerSolve gauss_seidel_two_level_peer(const HostStencil& fine, const HostStencil& coarse, double tol, int max_cycles,
                                      int coarse_sweeps) {
  check_stencil(fine);
  check_stencil(coarse);
  const GridDesc gf = fine.grid, gc = coarse.grid;
  if (gc.nx != gf.nx / 2 + 1 || gc.ny != gf.ny / 2 + 1 || gc.nz != gf.nz / 2 + 1)
    throw std::invalid_argument("gauss_seidel_two_level_peer: coarse grid is not the next level of the fine one");
  const Offsets of(gf), oc(gc);
  const std::size_t Nf = fine.voxels(), Nc = coarse.voxels();
  PeerSolve r;
  const auto t0 = Clock::now();
  std::vector<float> u(Nf, 0.0f), rc(Nc), ec(Nc);
  const double bnorm = norm2(fine.b);
  auto fidx = [&](int x, int y, int z) { return std::size_t(x) + std::size_t(gf.nx) * (std::size_t(y) + std::size_t(gf.ny) * z); };
  auto cidx = [&](int x, int y, int z) { return std::size_t(x) + std::size_t(gc.nx) * (std::size_t(y) + std::size_t(gc.ny) * z); };
  double rel = 1.0;
  while (rel > tol && r.iterations < max_cycles) {
    gs_lex_sweep(fine, of, fine.b, u, false);
    gs_lex_sweep(fine, of, fine.b, u, false);
    const std::vector<float> rf = host_residual_f(fine, of, fine.b, u);
    // r_c = P^T r_f at free coarse voxels (free coarse voxels are interior).
    for (int Z = 0; Z < gc.nz; ++Z)
      for (int Y = 0; Y < gc.ny; ++Y)
        for (int X = 0; X < gc.nx; ++X) {
          const std::size_t I = cidx(X, Y, Z);
          float acc = 0.0f;
          if (!coarse.fixed[I])
            for (int dz = -1; dz <= 1; ++dz)
              for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx)
                  acc += (dx ? 0.5f : 1.0f) * (dy ? 0.5f : 1.0f) * (dz ? 0.5f : 1.0f) *
                         rf[fidx(2 * X + dx, 2 * Y + dy, 2 * Z + dz)];
          rc[I] = acc;
        }
    std::fill(ec.begin(), ec.end(), 0.0f);
    for (int s = 0; s < coarse_sweeps; ++s) gs_lex_sweep(coarse, oc, rc, ec, s >= (coarse_sweeps + 1) / 2);
    // u_f += P e_c at free fine voxels (trilinear).
    for (int z = 0; z < gf.nz; ++z)
      for (int y = 0; y < gf.ny; ++y)
        for (int x = 0; x < gf.nx; ++x) {
          const std::size_t j = fidx(x, y, z);
          if (fine.fixed[j]) continue;
          float e = 0.0f;
          for (int cz = z >> 1; cz <= (z + 1) >> 1; ++cz)
            for (int cy = y >> 1; cy <= (y + 1) >> 1; ++cy)
              for (int cx = x >> 1; cx <= (x + 1) >> 1; ++cx)
                e += ((x & 1) ? 0.5f : 1.0f) * ((y & 1) ? 0.5f : 1.0f) * ((z & 1) ? 0.5f : 1.0f) * ec[cidx(cx, cy, cz)];
          u[j] += e;
        }
    gs_lex_sweep(fine, of, fine.b, u, true);
    gs_lex_sweep(fine, of, fine.b, u, true);
    ++r.iterations;
    const std::vector<float> res = host_residual_f(fine, of, fine.b, u);
    rel = bnorm > 0 ? norm2(res) / bnorm : norm2(res);
  }
  r.seconds = since(t0);
  r.residual = host_relative_residual(fine, u);
  r.u = std::move(u);
  return r;
}

BenchReport run_bench(const BenchOptions& o) {
  const auto t0 = Clock::now();
  BenchReport report;
  report.quick = o.quick;
  report.host_cpu = host_cpu_name();
  report.host_threads = eigen_threads();
  report.load_before = load_average();
  const int reps = o.reps > 0 ? o.reps : (o.quick ? 3 : 5);
  const int solve_reps = o.quick ? 2 : 3;
  // Bandwidth system: coefficients of 50 MB (quick) / 117 MB, beyond the
  // 32 MB last-level cache of this machine's CPU.
  const int bw_size = o.quick ? 96 : 128;
  const int peer_size = o.quick ? 48 : 105;  // 105^3 = 1.16 M voxels, the paper's largest volume
  const std::vector<int> sizes = o.quick ? std::vector<int>{32, 48, 64} : std::vector<int>{64, 128, 192, 256};

  std::vector<DeviceInfo> chosen;
  const std::vector<DeviceInfo> all = enumerate_devices();
  if (o.devices.empty()) {
    chosen = all;
  } else {
    for (const std::string& req : o.devices) {
      const DeviceInfo d = select_device(req);
      if (std::none_of(chosen.begin(), chosen.end(), [&](const DeviceInfo& c) { return c.index == d.index; }))
        chosen.push_back(d);
    }
  }
  for (const DeviceInfo& info : chosen) {
    const auto td = Clock::now();
    DeviceBench db;
    db.name = info.device_name, db.type = info.type, db.platform = info.platform_name, db.label = info.label();
    const Progress progress{o.progress, "[" + std::to_string(info.index) + " " + info.device_name + "] "};
    std::unique_ptr<Runtime> rt;
    std::mt19937 rng(1);
    try {
      progress("device setup and kernel builds (" + info.label() + ")");
      rt = std::make_unique<Runtime>(std::to_string(info.index));
      // Warm-up: builds every kernel the classifier uses (cached by PoCL on disk).
      const Phantom ph = phantom_of(*rt, PhantomShape::Face, {32, 32, 32}, nullptr, nullptr);
      VariationalParams vp;
      vp.v_iso = phantom_iso(ph);
      classify_timed(*rt, ph.volume, vp, SolverParams{}, true);
    } catch (const std::exception& e) {
      db.skipped = true;
      db.skip_reason = describe(e);
      progress("skipped: " + db.skip_reason);
      report.devices.push_back(db);
      continue;
    }
    Runtime& r = *rt;
    part(db, progress, "bandwidth: stream copy/triad", [&] { bench_stream(r, db, reps, rng); });
    part(db, progress, "bandwidth: sweep and apply on " + std::to_string(bw_size) + "^3",
         [&] { bench_sweep_apply(r, db, bw_size, reps); });
    std::optional<Phantom> peer_phantom;
    part(db, progress, "peers on " + std::to_string(peer_size) + "^3: softshell solve", [&] {
      peer_phantom = phantom_of(r, PhantomShape::Face, {peer_size, peer_size, peer_size}, nullptr, nullptr);
      db.peer_size = peer_size;
      db.peer_voxels = peer_phantom->volume.voxels();
      db.speedup_vs_eigen_cg = bench_peers(r, db, *peer_phantom, VariationalParams{}.beta, solve_reps, progress, db.peers);
    });
    if (!o.quick && peer_phantom)
      part(db, progress, "peers, anisotropic (beta 1000): softshell solve", [&] {
        db.aniso_beta = 1000;
        db.speedup_vs_eigen_cg_aniso = bench_peers(r, db, *peer_phantom, db.aniso_beta, solve_reps, progress, db.peers_aniso);
      });
    part(db, progress, "warm start on " + std::to_string(peer_size) + "^3",
         [&] { bench_warm(r, db, peer_size, solve_reps); });
    part(db, progress, "table 1", [&] { bench_table1(r, db, o.quick, o.quick ? 1 : 3, o.render_timer, progress); });
    part(db, progress, "scaling", [&] { bench_scaling(r, db, sizes, o.quick ? 1 : 2, progress); });
    db.seconds = since(td);
    progress("done in " + fmt("%.1f", db.seconds) + " s");
    report.devices.push_back(std::move(db));
  }
  report.seconds = since(t0);
  report.load_after = load_average();
  return report;
}

std::string bench_json(const BenchReport& rep) {
  std::ostringstream s;
  s << "{\n  \"quick\": " << (rep.quick ? "true" : "false") << ",\n  \"seconds\": " << json_number(rep.seconds)
    << ",\n  \"host_cpu\": " << json_string(rep.host_cpu) << ",\n  \"host_threads\": " << rep.host_threads << ",\n  \"load_average_before\": " << json_string(rep.load_before)
    << ",\n  \"load_average_after\": " << json_string(rep.load_after);
  {
    // The host's bandwidth: the fastest of the per-device measurements.
    double copy = 0, triad = 0;
    for (const DeviceBench& d : rep.devices) copy = std::max(copy, d.host.copy_gbps), triad = std::max(triad, d.host.triad_gbps);
    s << ",\n  \"host_stream_gbps\": {\"copy\": " << (copy > 0 ? json_number(copy) : "null")
      << ", \"triad\": " << (triad > 0 ? json_number(triad) : "null") << "}";
  }
  s
    << ",\n  \"byte_model\": {\"sweep_bytes_per_voxel\": " << json_number(ByteModel::sweep)
    << ", \"apply_bytes_per_voxel\": " << json_number(ByteModel::apply)
    << ", \"copy_bytes_per_element\": 8, \"triad_bytes_per_element\": 12},\n  \"all_checks_passed\": "
    << (rep.all_checks_passed() ? "true" : "false") << ",\n  \"devices\": [";
  for (std::size_t i = 0; i < rep.devices.size(); ++i) {
    const DeviceBench& d = rep.devices[i];
    auto num = [&](double v) { return d.skipped ? std::string("null") : json_number(v); };
    s << (i ? "," : "") << "\n    {\n      \"name\": " << json_string(d.name) << ",\n      \"type\": "
      << json_string(d.type) << ",\n      \"platform\": " << json_string(d.platform)
      << ",\n      \"skipped\": " << (d.skipped ? "true" : "false")
      << ",\n      \"skip_reason\": " << (d.skipped ? json_string(d.skip_reason) : "null") << ",\n      \"notes\": [";
    for (std::size_t k = 0; k < d.notes.size(); ++k) s << (k ? ", " : "") << json_string(d.notes[k]);
    s << "],\n      \"failed_checks\": [";
    for (std::size_t k = 0; k < d.failed_checks.size(); ++k) s << (k ? ", " : "") << json_string(d.failed_checks[k]);
    s << "],\n      \"stream_gbps\": {\"copy\": " << num(d.copy_gbps) << ", \"triad\": " << num(d.triad_gbps)
      << ", \"elements\": " << d.stream_elements << ", \"copy_time\": " << json_timing(d.copy)
      << ", \"triad_time\": " << json_timing(d.triad) << "},\n      \"host_stream_gbps\": {\"copy\": "
      << num(d.host.copy_gbps) << ", \"triad\": " << num(d.host.triad_gbps) << ", \"threads\": " << d.host.threads
      << ", \"elements\": " << d.host.elements << ", \"copy_time\": "
      << json_timing({d.host.copy_min_s, d.host.copy_median_s, d.host.reps}) << ", \"triad_time\": "
      << json_timing({d.host.triad_min_s, d.host.triad_median_s, d.host.reps}) << "},\n      \"bandwidth_voxels\": " << d.bw_voxels
      << ",\n      \"sweep_gbps\": " << num(d.sweep_gbps) << ",\n      \"sweep_fraction\": " << num(d.sweep_fraction)
      << ",\n      \"sweep_time\": " << json_timing(d.sweep) << ",\n      \"apply_gbps\": " << num(d.apply_gbps)
      << ",\n      \"apply_fraction\": " << num(d.apply_fraction) << ",\n      \"apply_time\": " << json_timing(d.apply)
      << ",\n      \"sweep_fraction_host\": " << num(d.sweep_fraction_host)
      << ",\n      \"apply_fraction_host\": " << num(d.apply_fraction_host)
      << ",\n      \"sweep_compact_gbps\": " << num(d.sweep_compact_gbps)
      << ",\n      \"sweep_compact_fraction_host\": " << num(d.sweep_compact_fraction_host)
      << ",\n      \"sweep_compact_time\": " << json_timing(d.sweep_compact)
      << ",\n      \"sweep_compact_check\": " << num(d.sweep_compact_check)
      << ",\n      \"solve_bound_ratio\": " << num(d.solve_bound_ratio) << ",\n      \"solve_bound\": {\"solve_s\": "
      << num(d.solve_seconds) << ", \"iterations\": " << d.solve_iterations << ", \"bytes_per_voxel\": "
      << num(d.solve_bytes_per_voxel) << ", \"bound_s\": " << num(d.solve_bound_s)
      << ", \"ratio_vs_device_copy\": " << num(d.solve_bound_ratio_device) << "}"
      << ",\n      \"speedup_vs_pfmg\": " << (d.speedup_vs_pfmg > 0 ? num(d.speedup_vs_pfmg) : "null")
      << ",\n      \"pfmg_solve_s\": " << (d.pfmg_solve_seconds > 0 ? num(d.pfmg_solve_seconds) : "null")
      << ",\n      \"sweep_check\": " << num(d.sweep_check) << ",\n      \"apply_check\": " << num(d.apply_check)
      << ",\n      \"peer_voxels\": " << d.peer_voxels << ",\n      \"tolerance\": " << json_number(d.tol)
      << ",\n      \"peers\": [";
    for (std::size_t k = 0; k < d.peers.size(); ++k) {
      const PeerResult& p = d.peers[k];
      s << (k ? "," : "") << "\n        {\"name\": " << json_string(p.name) << ", \"detail\": " << json_string(p.detail)
        << ", \"time\": " << json_timing(p.time) << ", \"iterations\": " << p.iterations
        << ", \"residual\": " << json_number(p.residual) << ", \"ok\": " << (p.ok ? "true" : "false")
        << ", \"error\": " << (p.error.empty() ? "null" : json_string(p.error)) << "}";
    }
    s << "],\n      \"anisotropic_beta\": " << (d.aniso_beta > 0 ? json_number(d.aniso_beta) : "null")
      << ",\n      \"peers_anisotropic\": [";
    for (std::size_t k = 0; k < d.peers_aniso.size(); ++k) {
      const PeerResult& p = d.peers_aniso[k];
      s << (k ? "," : "") << "\n        {\"name\": " << json_string(p.name) << ", \"detail\": " << json_string(p.detail)
        << ", \"time\": " << json_timing(p.time) << ", \"iterations\": " << p.iterations
        << ", \"residual\": " << json_number(p.residual) << ", \"ok\": " << (p.ok ? "true" : "false")
        << ", \"error\": " << (p.error.empty() ? "null" : json_string(p.error)) << "}";
    }
    s << "],\n      \"speedup_vs_eigen_cg_anisotropic\": "
      << (d.aniso_beta > 0 ? num(d.speedup_vs_eigen_cg_aniso) : "null")
      << ",\n      \"speedup_vs_eigen_cg\": " << num(d.speedup_vs_eigen_cg)
      << ",\n      \"warm_start_fraction\": " << num(d.warm_start_fraction) << ",\n      \"warm_start\": {\"cold_solve_s\": "
      << num(d.warm_cold_solve) << ", \"warm_solve_s\": " << num(d.warm_warm_solve) << ", \"cold_total_s\": "
      << num(d.warm_cold_total) << ", \"warm_total_s\": " << num(d.warm_warm_total) << ", \"update_s\": "
      << num(d.warm_update) << ", \"solve_fraction\": " << num(d.warm_solve_fraction)
      << ", \"resolve_tol\": " << num(d.warm_resolve_tol) << ", \"polish_s\": " << num(d.warm_polish)
      << ", \"cold_iterations\": " << d.warm_cold_iterations << ", \"warm_iterations\": " << d.warm_warm_iterations
      << ", \"reference_distance\": {\"cold_mean\": " << num(d.warm_ref_cold_mean) << ", \"cold_max\": "
      << num(d.warm_ref_cold_max) << ", \"cold_share\": " << num(d.warm_ref_cold_share) << ", \"warm_mean\": "
      << num(d.warm_ref_warm_mean) << ", \"warm_max\": " << num(d.warm_ref_warm_max) << ", \"warm_share\": "
      << num(d.warm_ref_warm_share) << ", \"polished_mean\": " << num(d.warm_ref_polish_mean)
      << ", \"polished_share\": " << num(d.warm_ref_polish_share) << ", \"shown_vs_polished_max\": "
      << num(d.warm_loose_vs_polished_max) << "}},\n      \"table1\": [";
    for (std::size_t k = 0; k < d.table1.size(); ++k) {
      const Table1Row& t = d.table1[k];
      auto opt = [](const std::optional<double>& v) { return v ? json_number(*v) : std::string("null"); };
      s << (k ? "," : "") << "\n        {\"dataset\": " << json_string(t.dataset) << ", \"shape\": "
        << json_string(t.shape) << ", \"dims\": " << json_dims(t.dims) << ", \"paper_dims\": " << json_dims(t.paper_dims)
        << ", \"dims_note\": " << json_string(t.dims_note) << ", \"filter_s\": " << json_number(t.filter)
        << ", \"gradients_s\": " << json_number(t.gradients) << ", \"setup_s\": " << json_number(t.setup)
        << ", \"solve_s\": " << json_number(t.solve) << ", \"total_s\": " << json_number(t.total)
        << ", \"total_median_s\": " << json_number(t.total_median) << ", \"reps\": " << t.reps
        << ", \"iterations\": " << t.iterations << ", \"levels\": " << t.levels
        << ", \"residual\": " << json_number(t.residual) << ", \"converged\": " << (t.converged ? "true" : "false")
        << ", \"opaque_percent\": " << json_number(t.opaque_percent) << ", \"splats\": " << t.splats
        << ", \"render_shearwarp_s\": " << opt(t.render_shearwarp) << ", \"render_splat_s\": " << opt(t.render_splat)
        << ", \"render_note\": " << json_string(t.render_note) << ", \"paper\": {\"total_s\": "
        << json_number(t.paper_seconds) << ", \"opaque_percent\": " << json_number(t.paper_opaque_percent)
        << ", \"splats\": " << t.paper_splats << ", \"render_shearwarp_s\": " << json_number(t.paper_shearwarp)
        << ", \"render_splat_s\": " << json_number(t.paper_splat) << "}}";
    }
    s << "],\n      \"scaling\": [";
    for (std::size_t k = 0; k < d.scaling.size(); ++k) {
      const ScalingRow& r = d.scaling[k];
      s << (k ? "," : "") << "\n        {\"size\": " << r.size << ", \"voxels\": " << r.voxels
        << ", \"total_s\": " << json_number(r.total.min) << ", \"total_median_s\": " << json_number(r.total.median)
        << ", \"reps\": " << r.total.reps << ", \"setup_s\": " << json_number(r.setup)
        << ", \"solve_s\": " << json_number(r.solve) << ", \"iterations\": " << r.iterations
        << ", \"residual\": " << json_number(r.residual) << ", \"converged\": " << (r.converged ? "true" : "false")
        << "}";
    }
    s << "],\n      \"scaling_exponent\": " << num(d.scaling_exponent) << ",\n      \"seconds\": " << json_number(d.seconds)
      << "\n    }";
  }
  s << "\n  ]\n}\n";
  return s.str();
}

std::string bench_table(const BenchReport& rep) {
  std::ostringstream s;
  s << "softshell bench" << (rep.quick ? " --quick" : "") << "  (host " << rep.host_cpu << ", Eigen threads "
    << rep.host_threads << ", " << fmt("%.1f", rep.seconds) << " s; load average " << rep.load_before << " before, "
    << rep.load_after << " after)\n";
  for (const DeviceBench& d : rep.devices) {
    s << "\n== " << d.label << "\n";
    if (d.skipped) {
      s << "   skipped: " << d.skip_reason << "\n";
      continue;
    }
    s << "\nbandwidth (min of " << d.copy.reps << "; GB/s by the byte model; fraction of the device's copy and of the"
      << " host's copy)\n";
    s << "  " << std::left << std::setw(34) << "kernel" << std::right << std::setw(10) << "min ms" << std::setw(11)
      << "median ms" << std::setw(9) << "GB/s" << std::setw(9) << "of copy" << std::setw(9) << "of host" << "\n";
    auto bw = [&](const std::string& name, const Timing& t, double gbps) {
      s << "  " << std::left << std::setw(34) << name << std::right << std::setw(10) << fmt("%.2f", t.min * 1e3)
        << std::setw(11) << fmt("%.2f", t.median * 1e3) << std::setw(9) << fmt("%.2f", gbps) << std::setw(8)
        << fmt("%.0f", d.copy_gbps > 0 ? 100 * gbps / d.copy_gbps : 0) << "%" << std::setw(8)
        << fmt("%.0f", d.host.copy_gbps > 0 ? 100 * gbps / d.host.copy_gbps : 0) << "%\n";
    };
    const std::string m = std::to_string(d.stream_elements >> 20) + "M";
    const std::string th = std::to_string(d.host.threads) + " thr";
    bw("host copy (" + m + " floats, " + th + ")", {d.host.copy_min_s, d.host.copy_median_s, d.host.reps}, d.host.copy_gbps);
    bw("host triad (" + m + " floats, " + th + ")", {d.host.triad_min_s, d.host.triad_median_s, d.host.reps},
       d.host.triad_gbps);
    bw("copy (" + m + " floats, 8 B)", d.copy, d.copy_gbps);
    bw("triad (" + m + " floats, 12 B)", d.triad, d.triad_gbps);
    const std::string v = std::to_string(d.bw_size) + "^3";
    bw("GS sweep, " + d.sweep_order + " (" + v + ", " + fmt("%g", ByteModel::sweep) + " B)", d.sweep, d.sweep_gbps);
    if (d.sweep_compact_gbps > 0)
      bw("GS sweep, compact stencil (" + v + ", " + fmt("%g", ByteModel::sweep_compact) + " B)", d.sweep_compact,
         d.sweep_compact_gbps);
    bw("operator apply (" + v + ", " + fmt("%g", ByteModel::apply) + " B)", d.apply, d.apply_gbps);
    s << "  checks: sweep vs host " << fmt("%.1e", d.sweep_check) << ", apply vs host " << fmt("%.1e", d.apply_check)
      << " (relative)\n";

    auto peers = [&](const std::string& title, const std::vector<PeerResult>& list, double speedup) {
      s << "\npeers: face phantom " << d.peer_size << "^3 (" << d.peer_voxels << " voxels), " << title
        << ", to relative residual " << fmt("%.0e", d.tol) << "\n";
      s << "  " << std::left << std::setw(22) << "solver" << std::right << std::setw(10) << "min s" << std::setw(10)
        << "median s" << std::setw(7) << "iters" << std::setw(11) << "residual" << std::setw(9) << "vs soft"
        << "  detail\n";
      double soft = 0;
      for (const PeerResult& p : list)
        if (p.name == "softshell") soft = p.time.min;
      for (const PeerResult& p : list) {
        s << "  " << std::left << std::setw(22) << p.name << std::right << std::setw(10) << fmt("%.3f", p.time.min)
          << std::setw(10) << fmt("%.3f", p.time.median) << std::setw(7) << p.iterations << std::setw(11)
          << fmt("%.2e", p.residual) << std::setw(8) << fmt("%.1f", soft > 0 ? p.time.min / soft : 0) << "x  "
          << p.detail << (p.ok ? "" : "  NOT OK " + p.error) << "\n";
      }
      s << "  speedup of softshell vs the fastest Eigen CG: " << fmt("%.2f", speedup) << "x\n";
    };
    peers("default parameters", d.peers, d.speedup_vs_eigen_cg);
    if (d.speedup_vs_pfmg > 0) s << "  speedup of softshell vs HYPRE PFMG-PCG: " << fmt("%.2f", d.speedup_vs_pfmg) << "x\n";
    s << "  solve vs its bandwidth bound: " << fmt("%.3f", d.solve_seconds) << " s (FMG + " << d.solve_iterations
      << " it, " << fmt("%.0f", d.solve_bytes_per_voxel) << " B/voxel) vs " << fmt("%.3f", d.solve_bound_s)
      << " s at the host's copy bandwidth = " << fmt("%.2f", d.solve_bound_ratio) << "x (" << fmt("%.2f", d.solve_bound_ratio_device)
      << "x at the device's)\n";
    if (d.aniso_beta > 0) peers("beta " + fmt("%g", d.aniso_beta), d.peers_aniso, d.speedup_vs_eigen_cg_aniso);
    s << "\nwarm start (v_iso +5 %): re-solve " << fmt("%.3f", d.warm_warm_total) << " s (update "
      << fmt("%.3f", d.warm_update) << " + solve from the previous u " << fmt("%.3f", d.warm_warm_solve) << ", "
      << d.warm_warm_iterations << " it) vs cold classification " << fmt("%.3f", d.warm_cold_total) << " s (setup "
      << fmt("%.3f", d.warm_cold_total - d.warm_cold_solve) << " + solve " << fmt("%.3f", d.warm_cold_solve) << ", FMG + "
      << d.warm_cold_iterations << " it) = " << fmt("%.2f", d.warm_start_fraction) << "; solves alone "
      << fmt("%.2f", d.warm_solve_fraction) << "; distance from the converged reference: re-solve mean |du| "
      << fmt("%.1e", d.warm_ref_warm_mean) << " (" << fmt("%.2f", 100 * d.warm_ref_warm_share)
      << " % of voxels beyond 5e-3), cold " << fmt("%.1e", d.warm_ref_cold_mean) << " ("
      << fmt("%.2f", 100 * d.warm_ref_cold_share) << " %); the re-solve stops at " << fmt("%.0e", d.warm_resolve_tol)
      << ", its polish to the solver's tol " << fmt("%.3f", d.warm_polish) << " s more (then mean |du| "
      << fmt("%.1e", d.warm_ref_polish_mean) << "; largest change " << fmt("%.1e", d.warm_loose_vs_polished_max)
      << ")\n";

    s << "\nTable 1 (seconds; paper: 600 MHz Pentium III)\n";
    s << "  " << std::left << std::setw(14) << "dataset" << std::setw(11) << "dims" << std::right << std::setw(7)
      << "filter" << std::setw(7) << "grad" << std::setw(7) << "setup" << std::setw(7) << "solve" << std::setw(7)
      << "total" << std::setw(7) << "paper" << std::setw(8) << "%opq" << std::setw(6) << "paper" << std::setw(8)
      << "splats" << std::setw(7) << "paper" << "  render sw/splat (paper)\n";
    for (const Table1Row& t : d.table1) {
      const std::string render = t.render_note.empty()
                                     ? fmt("%.2f", *t.render_shearwarp) + "/" + fmt("%.2f", *t.render_splat)
                                     : t.render_note;
      s << "  " << std::left << std::setw(14) << t.dataset << std::setw(11) << dims_string(t.dims) << std::right
        << std::setw(7) << fmt("%.3f", t.filter) << std::setw(7) << fmt("%.3f", t.gradients) << std::setw(7)
        << fmt("%.3f", t.setup) << std::setw(7) << fmt("%.3f", t.solve) << std::setw(7) << fmt("%.2f", t.total)
        << std::setw(7) << fmt("%.1f", t.paper_seconds) << std::setw(8) << fmt("%.1f", t.opaque_percent)
        << std::setw(6) << fmt("%.1f", t.paper_opaque_percent) << std::setw(8) << t.splats << std::setw(7)
        << t.paper_splats << "  " << render << " (" << fmt("%.2f", t.paper_shearwarp) << "/"
        << fmt("%.2f", t.paper_splat) << ")" << (t.dims_note.empty() ? "" : "  [" + t.dims_note + "]") << "\n";
    }

    s << "\nscaling (face phantom, classification = setup + solve, wall)\n";
    s << "  " << std::right << std::setw(6) << "size" << std::setw(11) << "voxels" << std::setw(9) << "total s"
      << std::setw(9) << "setup s" << std::setw(9) << "solve s" << std::setw(7) << "iters" << std::setw(12)
      << "ns/voxel\n";
    for (const ScalingRow& r : d.scaling)
      s << "  " << std::setw(6) << r.size << std::setw(11) << r.voxels << std::setw(9) << fmt("%.3f", r.total.min)
        << std::setw(9) << fmt("%.3f", r.setup) << std::setw(9) << fmt("%.3f", r.solve) << std::setw(7) << r.iterations
        << std::setw(11) << fmt("%.0f", 1e9 * r.total.min / double(r.voxels)) << "\n";
    s << "  time grows as voxels^" << fmt("%.2f", d.scaling_exponent) << " (least-squares fit)\n";
    for (const std::string& n : d.notes) s << "  note: " << n << "\n";
    for (const std::string& f : d.failed_checks) s << "  CHECK FAILED: " << f << "\n";
    s << "  (" << fmt("%.1f", d.seconds) << " s on this device)\n";
  }
  return s.str();
}

Image bench_plot(const BenchReport& rep) {
  const int W = 720, H = 480, left = 80, right = 20, top = 40, bottom = 60;
  Image img(W, H, 255);
  const Rgb black{0, 0, 0}, grey{200, 200, 200};
  const Rgb palette[] = {{31, 119, 180}, {214, 39, 40}, {44, 160, 44}, {148, 103, 189}, {255, 127, 14}};
  double xmin = 1e300, xmax = 0, ymin = 1e300, ymax = 0;
  for (const DeviceBench& d : rep.devices) {
    for (const ScalingRow& r : d.scaling)
      xmin = std::min(xmin, double(r.voxels)), xmax = std::max(xmax, double(r.voxels)),
      ymin = std::min(ymin, r.total.min), ymax = std::max(ymax, r.total.min);
    for (const Table1Row& t : d.table1) {
      const double v = double(t.dims[0]) * t.dims[1] * t.dims[2];
      xmin = std::min(xmin, v), xmax = std::max(xmax, v), ymin = std::min(ymin, t.total), ymax = std::max(ymax, t.total);
    }
  }
  if (!(xmax > 0) || !(ymax > 0)) xmin = 1e4, xmax = 1e7, ymin = 0.01, ymax = 10;
  // Decades around the data.
  const double lx0 = std::floor(std::log10(xmin)), lx1 = std::ceil(std::log10(xmax) + 1e-9);
  const double ly0 = std::floor(std::log10(ymin)), ly1 = std::ceil(std::log10(ymax) + 1e-9);
  const int pw = W - left - right, ph = H - top - bottom;
  auto px = [&](double v) { return left + int(std::lround((std::log10(v) - lx0) / std::max(lx1 - lx0, 1.0) * pw)); };
  auto py = [&](double v) { return top + ph - int(std::lround((std::log10(v) - ly0) / std::max(ly1 - ly0, 1.0) * ph)); };
  auto line = [&](int x0, int y0, int x1, int y1, Rgb c) {
    const int n = std::max(std::abs(x1 - x0), std::abs(y1 - y0));
    for (int i = 0; i <= n; ++i) {
      const double t = n ? double(i) / n : 0;
      fill_rect(img, int(std::lround(x0 + t * (x1 - x0))), int(std::lround(y0 + t * (y1 - y0))), 2, 2, c);
    }
  };
  // Grid, axes and tick labels at every decade (and 2, 5 in between).
  for (double e = lx0; e <= lx1 + 1e-9; ++e)
    for (double m : {1.0, 2.0, 5.0}) {
      const double v = m * std::pow(10.0, e);
      if (std::log10(v) > lx1 + 1e-9) break;
      const int x = px(v);
      fill_rect(img, x, top, 1, ph, grey);
      if (m == 1.0) {
        const std::string lab = "1e" + std::to_string(int(e));
        draw_text(img, x - text_width(lab, 1) / 2, top + ph + 6, lab, black, 1);
      }
    }
  for (double e = ly0; e <= ly1 + 1e-9; ++e)
    for (double m : {1.0, 2.0, 5.0}) {
      const double v = m * std::pow(10.0, e);
      if (std::log10(v) > ly1 + 1e-9) break;
      const int y = py(v);
      fill_rect(img, left, y, pw, 1, grey);
      std::ostringstream lab;
      lab << v;
      draw_text(img, left - 6 - text_width(lab.str(), 1), y - 3, lab.str(), black, 1);
    }
  fill_rect(img, left, top, 1, ph + 1, black);
  fill_rect(img, left, top + ph, pw + 1, 1, black);
  draw_text(img, left, 12, std::string("softshell classification time vs voxels") + (rep.quick ? " (--quick)" : ""),
            black, 2);
  draw_text(img, left + pw / 2 - text_width("voxels", 1) / 2, H - 34, "voxels", black, 1);
  draw_text(img, 8, top - 14, "seconds", black, 1);
  draw_text(img, left + 10, top + ph - 14, "filled: face phantom cubes (joined); hollow: Table 1 phantoms", black, 1);
  int legend_y = top + 8;
  for (std::size_t i = 0; i < rep.devices.size(); ++i) {
    const DeviceBench& d = rep.devices[i];
    if (d.skipped) continue;
    const Rgb c = palette[i % 5];
    for (std::size_t k = 0; k < d.scaling.size(); ++k) {
      const int x = px(double(d.scaling[k].voxels)), y = py(d.scaling[k].total.min);
      fill_rect(img, x - 3, y - 3, 7, 7, c);
      if (k) line(px(double(d.scaling[k - 1].voxels)), py(d.scaling[k - 1].total.min), x, y, c);
    }
    for (const Table1Row& t : d.table1) {
      const int x = px(double(t.dims[0]) * t.dims[1] * t.dims[2]), y = py(t.total);
      fill_rect(img, x - 4, y - 4, 9, 1, c), fill_rect(img, x - 4, y + 4, 9, 1, c);
      fill_rect(img, x - 4, y - 4, 1, 9, c), fill_rect(img, x + 4, y - 4, 1, 9, c);
    }
    const std::string lab = d.name + " (" + d.type + "): time ~ voxels^" + fmt("%.2f", d.scaling_exponent);
    fill_rect(img, left + 10, legend_y, 7, 7, c);
    draw_text(img, left + 22, legend_y, lab, black, 1);
    legend_y += 14;
  }
  return img;
}

}  // namespace softshell
