// Surface-quality metrics of an opacity volume u against a ground-truth
// signed distance field (`softshell evaluate`). Definitions and the reasons
// for them: docs/metrics.md.
//
// Everything is O(N) on the host: one pass over the voxels for the pointwise
// sums, per-voxel flags and the opacity profiles across the facing surface
// (O(|S| x samples)), an exact separable Euclidean distance transform of the
// drawn set for recall, and flood fills with an explicit stack for the
// 26-connected drawn components and the 6-connected components at the
// relative threshold. Passes run on std::threads over slices (or lines); each
// slice keeps its own partial sums and they are added in slice order, so the
// result does not depend on the number of threads.
#include "metrics.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <limits>
#include <mutex>
#include <sstream>
#include <thread>

#include "error.hpp"
#include "grid.h"
#include "orientation.hpp"
#include "text.hpp"

namespace softshell {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Per-voxel flags of the first pass; kBright (u above the relative blob threshold) is set
// once that is known; kVisited and kVisited6 are used by the flood fills.
enum : std::uint8_t { kDrawn = 1, kNear = 2, kFacing = 4, kVisited = 8, kBright = 16, kVisited6 = 32 };

// The opacity profile across the surface (surface_peak, shell_thickness_mm):
// samples every kProfileStep smallest spacings along the true normal, out to
// R = max(kProfileMinVoxels smallest spacings, kProfileMinMm) on either side
// of the surface point. 6 voxels holds the half-maximum crossings of a shell
// up to 12 voxels wide; 4 mm keeps the same physical reach on fine grids.
constexpr double kProfileStep = 0.1;
constexpr double kProfileMinVoxels = 6.0;
constexpr double kProfileMinMm = 4.0;
// A profile whose peak is below this fraction of u_ind has no shell to measure:
// it counts in surface_peak (as a hole) but not in the thickness median.
constexpr double kPeakFloor = 0.05;

// Below this change of u across one voxel, grad u has no meaningful direction
// (it is 1/4 of an 8-bit opacity step): such voxels stay out of the normal error.
constexpr double kMinOpacityStep = 1e-3;

// Runs body(item) for item in [0, n) on up to hardware_concurrency threads,
// items handed out one by one (slices differ in cost). The first exception
// thrown by any body is rethrown here after all threads have joined.
template <class Body>
void parallel_items(std::size_t n, const Body& body) {
  const std::size_t hw = std::max(1u, std::thread::hardware_concurrency());
  const std::size_t threads = std::min(hw, n);
  if (threads <= 1) {
    for (std::size_t i = 0; i < n; ++i) body(i);
    return;
  }
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  const auto worker = [&] {
    try {
      for (std::size_t i = next++; i < n; i = next++) body(i);
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      next = n;  // stop the others early
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(threads - 1);
  for (std::size_t t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

// Lower envelope of the parabolas (q - p)^2 + f[p] over the sites p with a
// finite f (Felzenszwalb & Huttenlocher 2012, with empty sites skipped rather
// than given a large finite value, so no precision is lost). f holds n values
// `stride` apart, d receives n values `dstride` apart; v and z are scratch of
// n and n + 1 entries.
void edt_line(const float* f, std::size_t stride, float* d, std::size_t dstride, std::size_t n,
              std::vector<std::size_t>& v, std::vector<double>& z) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  std::size_t k = 0;
  bool any = false;
  for (std::size_t q = 0; q < n; ++q) {
    const double fq = f[q * stride];
    if (!std::isfinite(fq)) continue;
    if (!any) {
      any = true;
      k = 0;
      v[0] = q;
      z[0] = -kInf;
      z[1] = kInf;
      continue;
    }
    const double qd = double(q);
    double s = 0;
    for (;;) {
      const double pd = double(v[k]);
      s = ((fq + qd * qd) - (double(f[v[k] * stride]) + pd * pd)) / (2.0 * (qd - pd));
      if (s > z[k]) break;
      --k;  // z[0] = -inf, so k never goes below 0
    }
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = kInf;
  }
  if (!any) {
    for (std::size_t q = 0; q < n; ++q) d[q * dstride] = std::numeric_limits<float>::infinity();
    return;
  }
  k = 0;
  for (std::size_t q = 0; q < n; ++q) {
    while (z[k + 1] < double(q)) ++k;
    const double dq = double(q) - double(v[k]);
    d[q * dstride] = float(dq * dq + double(f[v[k] * stride]));
  }
}


struct Grid {
  std::size_t nx, ny, nz, sy, sz;
  Vec3d h;
  void gradient(const float* f, std::size_t i, std::size_t x, std::size_t y, std::size_t z, double g[3]) const {
    // Central differences per mm, one-sided at the borders (grid.h).
    g[0] = grid_diff(f, i, x, nx, 1, h[0]);
    g[1] = grid_diff(f, i, y, ny, sy, h[1]);
    g[2] = grid_diff(f, i, z, nz, sz, h[2]);
  }
};

// Trilinear interpolation of f at index coordinates q, clamped to the volume
// (outside it the border values continue).
double trilinear(const float* f, const Grid& g, const double q[3]) {
  const std::size_t n[3] = {g.nx, g.ny, g.nz};
  std::size_t i0[3], step[3] = {1, g.sy, g.sz};
  double w[3];
  for (int a = 0; a < 3; ++a) {
    double c = q[a] > 0 ? q[a] : 0.0;  // NaN-safe: a NaN coordinate samples the corner
    c = c < double(n[a] - 1) ? c : double(n[a] - 1);
    std::size_t i = std::size_t(c);
    if (i + 1 >= n[a]) i = n[a] >= 2 ? n[a] - 2 : 0;
    i0[a] = i;
    w[a] = n[a] >= 2 ? c - double(i) : 0.0;
    if (n[a] < 2) step[a] = 0;
  }
  const float* p = f + i0[0] + i0[1] * g.sy + i0[2] * g.sz;
  const double c00 = p[0] + w[0] * (p[step[0]] - p[0]);
  const double c10 = p[step[1]] + w[0] * (p[step[1] + step[0]] - p[step[1]]);
  const double c01 = p[step[2]] + w[0] * (p[step[2] + step[0]] - p[step[2]]);
  const double c11 = p[step[2] + step[1]] + w[0] * (p[step[2] + step[1] + step[0]] - p[step[2] + step[1]]);
  const double c0 = c00 + w[1] * (c10 - c00), c1 = c01 + w[1] * (c11 - c01);
  return c0 + w[2] * (c1 - c0);
}

// The profile of u along the true normal through one facing surface voxel.
struct ProfileGeometry {
  double step_mm = 0, tol_mm = 0;  // sample spacing; the peak is searched within |t| <= tol_mm
  int half = 0;                    // samples t = k step_mm for k in [-half, half]
};

struct ProfileResult {
  double peak = 0;          // max of u for |t| <= tol
  double width_mm = 0;      // full width at half that maximum (a lower bound when censored)
  bool measured = false;    // peak above the floor: width_mm enters the thickness median
  bool censored = false;    // ... but a crossing lies beyond the window, which then stands in for it
  double centre_mm = 0;     // the middle of the half-maximum interval, mm along the outward normal
};

// foot: the surface point in mm; n: the unit outward normal (per mm). Samples
// are taken only as far as needed: the tolerance window, then outward to the
// half-maximum crossings.
ProfileResult profile(const float* u, const Grid& g, const ProfileGeometry& pg, const double foot[3],
                      const double n[3], double floor) {
  const int half = pg.half;
  const double q0[3] = {foot[0] / g.h[0], foot[1] / g.h[1], foot[2] / g.h[2]};
  const double dq[3] = {pg.step_mm * n[0] / g.h[0], pg.step_mm * n[1] / g.h[1], pg.step_mm * n[2] / g.h[2]};
  const auto sample = [&](int k) {  // u at t = k step_mm
    const double q[3] = {q0[0] + k * dq[0], q0[1] + k * dq[1], q0[2] + k * dq[2]};
    return trilinear(u, g, q);
  };
  ProfileResult r;
  // The surface's own peak: the largest sample with |t| <= tol (on ties the
  // one nearest the inside).
  const double steps = std::floor(pg.tol_mm / pg.step_mm + 1e-9);
  const int reach = steps >= double(half) ? half : int(steps);
  int at = -reach;
  r.peak = sample(-reach);
  for (int k = -reach + 1; k <= reach; ++k) {
    const double v = sample(k);
    if (v > r.peak) r.peak = v, at = k;
  }
  if (!(r.peak >= floor) || r.peak <= 0) return r;
  const double level = 0.5 * r.peak;
  // Walk out both ways to the first sample below half the peak; the crossing
  // is interpolated linearly between it and the sample before. Where u stays
  // above half the peak to the end of the window, the window's end stands in
  // for the crossing: the width is then a lower bound, and it still enters
  // the median (leaving the widest shells out would flatter the median).
  double t_hi = half * pg.step_mm, t_lo = -half * pg.step_mm;
  bool hi = false, lo = false;
  double prev = r.peak;
  for (int k = at + 1; k <= half; ++k) {
    const double v = sample(k);
    if (v < level) {
      t_hi = (k - 1 + (prev - level) / (prev - v)) * pg.step_mm;
      hi = true;
      break;
    }
    prev = v;
  }
  prev = r.peak;
  for (int k = at - 1; k >= -half; --k) {
    const double v = sample(k);
    if (v < level) {
      t_lo = (k + 1 - (prev - level) / (prev - v)) * pg.step_mm;
      lo = true;
      break;
    }
    prev = v;
  }
  r.measured = true;
  r.censored = !(hi && lo);
  r.width_mm = t_hi - t_lo;
  r.centre_mm = 0.5 * (t_hi + t_lo);
  return r;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

// Partial sums of one z slice (first pass).
struct SliceSums {
  std::size_t splats = 0, opaque = 0, facing = 0, normal_voxels = 0, non_finite_u = 0, non_finite_sdf = 0;
  std::size_t censored = 0;
  double drawn_u = 0, near_u = 0, normal_w = 0, normal_wangle = 0, mass = 0, near_mass = 0, max_u = 0;
  std::vector<double> peaks, widths;  // facing surface voxels in index order; widths of the measured ones
  std::vector<double> visible_peaks;  // the peaks of the visible ones (with a shadow volume)
  std::vector<double> centres;        // the half-maximum intervals' centres of the measured, uncensored ones
};

void validate(const Volume& opacity, const Volume& truth, const MetricsParams& p) {
  if (opacity.dims != truth.dims)
    throw InputError("dims differ: opacity " + dims_text(opacity.dims) + " vs truth SDF " + dims_text(truth.dims));
  if (opacity.data.size() != opacity.voxels() || truth.data.size() != truth.voxels())
    throw InputError("evaluate: sample count does not match the dims");
  if (!std::isfinite(p.threshold) || p.threshold < 0)
    throw InputError("threshold must be a finite number >= 0, got " + std::to_string(p.threshold));
  if (!std::isfinite(p.tolerance) || p.tolerance < 0)
    throw InputError("tolerance must be a finite number >= 0 (voxels), got " + std::to_string(p.tolerance));
  if (!std::isfinite(p.tolerance_mm) || p.tolerance_mm < 0)
    throw InputError("tolerance_mm must be a finite number >= 0 (0: use tolerance in voxels), got " +
                     std::to_string(p.tolerance_mm));
  if (!std::isfinite(p.opaque) || p.opaque < 0)
    throw InputError("opaque must be a finite number >= 0, got " + std::to_string(p.opaque));
  if (!std::isfinite(p.u_ind) || !(p.u_ind > 0))
    throw InputError("u_ind must be a finite number > 0, got " + std::to_string(p.u_ind));
  if (!(p.blob_rel > 0 && p.blob_rel <= 1))
    throw InputError("blob_rel must be in (0, 1], got " + std::to_string(p.blob_rel));
  if (!(p.tensor_sigma >= 0 && p.tensor_sigma <= 8))
    throw InputError("tensor sigma must be in [0, 8] voxels, got " + std::to_string(p.tensor_sigma));
  if (p.orientation_field) {
    if (p.orientation_field->dims != opacity.dims)
      throw InputError("dims differ: orientation field " + dims_text(p.orientation_field->dims) + " vs opacity " +
                       dims_text(opacity.dims));
    if (p.orientation_field->data.size() != p.orientation_field->voxels())
      throw InputError("evaluate: orientation field sample count does not match the dims");
    if (!(p.tensor_sigma > 0)) throw InputError("orientation by the data needs a tensor sigma > 0");
  }
  if (p.shadow_db) {
    if (p.shadow_db->dims != truth.dims)
      throw InputError("dims differ: shadow " + dims_text(p.shadow_db->dims) + " vs truth SDF " + dims_text(truth.dims));
    if (p.shadow_db->data.size() != p.shadow_db->voxels())
      throw InputError("evaluate: shadow sample count does not match the dims");
    for (float x : p.shadow_db->data)
      if (std::isnan(x)) throw InputError("shadow volume has NaN samples");
    if (!std::isfinite(p.visible_db)) throw InputError("visible_db must be finite");
  }
  if (!(p.facing_cos >= -1 && p.facing_cos <= 1))
    throw InputError("facing_cos must be in [-1, 1], got " + std::to_string(p.facing_cos));
  const double b = std::sqrt(p.beam[0] * p.beam[0] + p.beam[1] * p.beam[1] + p.beam[2] * p.beam[2]);
  if (!std::isfinite(b) || !(b > 0)) throw InputError("beam must be a finite, non-zero direction");
  for (double s : opacity.spacing)
    if (!std::isfinite(s) || !(s > 0)) throw InputError("opacity volume: spacing must be positive");
}

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

}  // namespace

namespace metrics_detail {

std::vector<float> squared_edt(const std::vector<unsigned char>& mask, const Dims3& dims) {
  const std::size_t nx = dims[0], ny = dims[1], nz = dims[2], sy = nx, sz = nx * ny;
  const std::size_t n = nx * ny * nz;
  if (mask.size() != n) throw InputError("squared_edt: mask size does not match the dims");
  constexpr float kInf = std::numeric_limits<float>::infinity();
  std::vector<float> d(n);
  if (n == 0) return d;
  // x: distance to the nearest set voxel in the row, by two scans.
  parallel_items(nz, [&](std::size_t z) {
    for (std::size_t y = 0; y < ny; ++y) {
      const std::size_t row = y * sy + z * sz;
      double dist = std::numeric_limits<double>::infinity();
      for (std::size_t x = 0; x < nx; ++x) {
        dist = mask[row + x] ? 0.0 : dist + 1.0;
        d[row + x] = float(dist);
      }
      dist = std::numeric_limits<double>::infinity();
      for (std::size_t x = nx; x-- > 0;) {
        dist = mask[row + x] ? 0.0 : dist + 1.0;
        const double m = std::min(dist, double(d[row + x]));
        d[row + x] = std::isfinite(m) ? float(m * m) : kInf;
      }
    }
  });
  // y: lines inside each z slice (a slice is contiguous, so this is cache-friendly).
  parallel_items(nz, [&](std::size_t z) {
    std::vector<std::size_t> v(ny);
    std::vector<double> zz(ny + 1);
    std::vector<float> out(ny);
    for (std::size_t x = 0; x < nx; ++x) {
      float* line = d.data() + z * sz + x;
      edt_line(line, sy, out.data(), 1, ny, v, zz);
      for (std::size_t y = 0; y < ny; ++y) line[y * sy] = out[y];
    }
  });
  // z: gather each xz plane row by row, transform its columns, scatter back.
  parallel_items(ny, [&](std::size_t y) {
    std::vector<std::size_t> v(nz);
    std::vector<double> zz(nz + 1);
    std::vector<float> plane(nx * nz), out(nx * nz);
    for (std::size_t z = 0; z < nz; ++z)
      std::copy_n(d.data() + y * sy + z * sz, nx, plane.data() + z * nx);
    for (std::size_t x = 0; x < nx; ++x) edt_line(plane.data() + x, nx, out.data() + x, nx, nz, v, zz);
    for (std::size_t z = 0; z < nz; ++z) std::copy_n(out.data() + z * nx, nx, d.data() + y * sy + z * sz);
  });
  return d;
}

}  // namespace metrics_detail

Metrics evaluate_opacity(const Volume& opacity, const Volume& truth_sdf, const MetricsParams& p) {
  validate(opacity, truth_sdf, p);
  Metrics m;
  const Grid g{opacity.dims[0], opacity.dims[1], opacity.dims[2], opacity.dims[0],
               opacity.dims[0] * opacity.dims[1], opacity.spacing};
  const std::size_t n = opacity.voxels();
  const float* u = opacity.data.data();
  const float* sdf = truth_sdf.data.data();
  const double blen = std::sqrt(p.beam[0] * p.beam[0] + p.beam[1] * p.beam[1] + p.beam[2] * p.beam[2]);
  const double toward[3] = {-p.beam[0] / blen, -p.beam[1] / blen, -p.beam[2] / blen};  // to the transducer
  const double h0 = std::min({g.h[0], g.h[1], g.h[2]});
  const double min_grad_u = kMinOpacityStep / h0;
  // The tolerance in voxels of the smallest spacing (the SDF's unit on an anisotropic grid).
  const double tol = p.tolerance_mm > 0 ? p.tolerance_mm / h0 : p.tolerance;
  m.tolerance = tol;
  m.tolerance_mm = tol * h0;
  ProfileGeometry pg;
  pg.step_mm = kProfileStep * h0;
  m.profile_radius_mm = std::max(kProfileMinVoxels * h0, kProfileMinMm);
  pg.half = int(std::ceil(m.profile_radius_mm / pg.step_mm - 1e-9));
  pg.tol_mm = m.tolerance_mm;
  const double peak_floor = kPeakFloor * p.u_ind;
  if (n == 0) return m;

  // ---- pass 1: pointwise sums and flags ----------------------------------
  std::vector<std::uint8_t> flags(n, 0);
  std::vector<SliceSums> slices(g.nz);
  parallel_items(g.nz, [&](std::size_t z) {
    SliceSums& s = slices[z];
    double gu[3], gs[3];
    for (std::size_t y = 0; y < g.ny; ++y) {
      for (std::size_t x = 0; x < g.nx; ++x) {
        const std::size_t i = x + y * g.sy + z * g.sz;
        const double ui = u[i], si = sdf[i];
        if (!std::isfinite(ui)) ++s.non_finite_u;
        if (!std::isfinite(si)) ++s.non_finite_sdf;
        const bool near = std::abs(si) <= tol;
        std::uint8_t f = near ? kNear : 0;
        bool have_gs = false;
        s.mass += ui;
        if (near) s.near_mass += ui;
        s.max_u = std::max(s.max_u, ui);
        if (ui > p.opaque) ++s.opaque;
        if (ui > p.threshold) {
          f |= kDrawn;
          ++s.splats;
          s.drawn_u += ui;
          if (near) {
            s.near_u += ui;
            g.gradient(u, i, x, y, z, gu);
            double nu = std::sqrt(gu[0] * gu[0] + gu[1] * gu[1] + gu[2] * gu[2]);
            if (p.tensor_sigma > 0) {  // the renderer's default orientation (of u, or of the data)
              const std::array<double, 3> t = tensor_orientation_reference(
                  p.orientation_field ? *p.orientation_field : opacity, {double(x), double(y), double(z)},
                  p.tensor_sigma);
              gu[0] = t[0], gu[1] = t[1], gu[2] = t[2];
              nu = std::sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
            }
            // u's flat spots have no orientation; the data field is in its own units (any non-zero rms gradient).
            if (p.orientation_field ? nu > 0 : nu > min_grad_u) {
              g.gradient(sdf, i, x, y, z, gs);
              have_gs = true;
              const double ns = std::sqrt(gs[0] * gs[0] + gs[1] * gs[1] + gs[2] * gs[2]);
              if (ns > 0) {
                const double c = std::abs(gu[0] * gs[0] + gu[1] * gs[1] + gu[2] * gs[2]) / (nu * ns);
                const double angle = std::acos(std::min(1.0, c)) * (180.0 / kPi);
                s.normal_w += ui;
                s.normal_wangle += ui * angle;
                ++s.normal_voxels;
              }
            }
          }
        }
        // Surface voxel: the sign of sdf (inside = sdf <= 0) differs from a
        // 6-neighbour's, i.e. the zero level set crosses one of its six edges.
        const bool inside = si <= 0;
        const bool surface = (x > 0 && (sdf[i - 1] <= 0) != inside) ||
                             (x + 1 < g.nx && (sdf[i + 1] <= 0) != inside) ||
                             (y > 0 && (sdf[i - g.sy] <= 0) != inside) ||
                             (y + 1 < g.ny && (sdf[i + g.sy] <= 0) != inside) ||
                             (z > 0 && (sdf[i - g.sz] <= 0) != inside) ||
                             (z + 1 < g.nz && (sdf[i + g.sz] <= 0) != inside);
        if (surface) {
          if (!have_gs) g.gradient(sdf, i, x, y, z, gs);
          const double ns = std::sqrt(gs[0] * gs[0] + gs[1] * gs[1] + gs[2] * gs[2]);
          if (ns > 0 && (gs[0] * toward[0] + gs[1] * toward[1] + gs[2] * toward[2]) / ns >= p.facing_cos &&
              std::isfinite(ns) && std::isfinite(si)) {  // (a non-finite SDF is rejected below)
            f |= kFacing;
            ++s.facing;
            // The profile through the surface point nearest x: one Newton step
            // x - sdf grad sdf / |grad sdf|^2 (in mm; exact for a distance field).
            const double nrm[3] = {gs[0] / ns, gs[1] / ns, gs[2] / ns};
            const double d = si / ns;
            const double foot[3] = {double(x) * g.h[0] - d * nrm[0], double(y) * g.h[1] - d * nrm[1],
                                    double(z) * g.h[2] - d * nrm[2]};
            const ProfileResult r = profile(u, g, pg, foot, nrm, peak_floor);
            s.peaks.push_back(r.peak);
            if (p.shadow_db && p.shadow_db->data[i] < float(p.visible_db)) s.visible_peaks.push_back(r.peak);
            if (r.measured) s.widths.push_back(r.width_mm);
            if (r.measured && !r.censored) s.centres.push_back(r.centre_mm);
            if (r.censored) ++s.censored;
          }
        }
        flags[i] = f;
      }
    }
  });
  SliceSums t;
  for (SliceSums& s : slices) {
    t.censored += s.censored;
    t.mass += s.mass;
    t.near_mass += s.near_mass;
    t.max_u = std::max(t.max_u, s.max_u);
    t.peaks.insert(t.peaks.end(), s.peaks.begin(), s.peaks.end());
    t.visible_peaks.insert(t.visible_peaks.end(), s.visible_peaks.begin(), s.visible_peaks.end());
    t.widths.insert(t.widths.end(), s.widths.begin(), s.widths.end());
    t.centres.insert(t.centres.end(), s.centres.begin(), s.centres.end());
    s.peaks = {}, s.widths = {}, s.visible_peaks = {}, s.centres = {};
    t.splats += s.splats;
    t.opaque += s.opaque;
    t.facing += s.facing;
    t.normal_voxels += s.normal_voxels;
    t.non_finite_u += s.non_finite_u;
    t.non_finite_sdf += s.non_finite_sdf;
    t.drawn_u += s.drawn_u;
    t.near_u += s.near_u;
    t.normal_w += s.normal_w;
    t.normal_wangle += s.normal_wangle;
  }
  if (t.non_finite_u)
    throw InputError("opacity volume has " + std::to_string(t.non_finite_u) + " non-finite samples (NaN or inf)");
  if (t.non_finite_sdf)
    throw InputError("truth SDF has " + std::to_string(t.non_finite_sdf) + " non-finite samples (NaN or inf)");
  m.splats = t.splats;
  m.facing_surface_voxels = t.facing;
  if (p.shadow_db) {
    // The visible facing surface voxels: shadow loss below visible_db.
    const std::vector<float>& sh = p.shadow_db->data;
    for (std::size_t i = 0; i < n; ++i)
      if ((flags[i] & kFacing) && sh[i] < float(p.visible_db)) ++m.visible_surface_voxels;
  }
  m.normal_voxels = t.normal_voxels;
  m.percent_opaque = 100.0 * double(t.opaque) / double(n);
  m.precision = t.drawn_u > 0 ? t.near_u / t.drawn_u : 0.0;
  m.normal_error_deg = t.normal_w > 0 ? t.normal_wangle / t.normal_w : 0.0;
  m.mass_precision = t.mass > 0 ? t.near_mass / t.mass : 0.0;
  m.surface_peak = median(std::move(t.peaks)) / p.u_ind;
  if (!t.visible_peaks.empty()) m.surface_peak_visible = median(std::move(t.visible_peaks)) / p.u_ind;
  m.thickness_points = t.widths.size();
  m.thickness_censored = t.censored;
  m.shell_thickness_mm = median(std::move(t.widths));
  m.offset_points = t.centres.size();
  m.shell_offset_mm = t.centres.empty() ? std::numeric_limits<double>::quiet_NaN() : median(std::move(t.centres));

  // ---- recall: distance from each facing surface voxel to the drawn set --
  if (m.splats > 0 && m.facing_surface_voxels > 0) {
    std::vector<unsigned char> drawn(n);
    for (std::size_t i = 0; i < n; ++i) drawn[i] = flags[i] & kDrawn;
    const std::vector<float> d2 = metrics_detail::squared_edt(drawn, opacity.dims);
    drawn = {};
    // Squared distances between voxel centres are integers: compare exactly.
    const double tol2 = std::floor(tol * tol + 1e-9);
    std::vector<std::size_t> hits(g.nz, 0), vis_hits(g.nz, 0);
    const float* sh = p.shadow_db ? p.shadow_db->data.data() : nullptr;
    const float vis_db = float(p.visible_db);
    parallel_items(g.nz, [&](std::size_t z) {
      for (std::size_t i = z * g.sz, e = i + g.sz; i < e; ++i)
        if ((flags[i] & kFacing) && double(d2[i]) <= tol2) {
          ++hits[z];
          if (sh && sh[i] < vis_db) ++vis_hits[z];
        }
    });
    std::size_t hit = 0, vis_hit = 0;
    for (std::size_t h : hits) hit += h;
    for (std::size_t h : vis_hits) vis_hit += h;
    m.recall = double(hit) / double(m.facing_surface_voxels);
    if (sh && m.visible_surface_voxels > 0) m.recall_visible = double(vis_hit) / double(m.visible_surface_voxels);
  }
  if (p.shadow_db && m.visible_surface_voxels > 0 && std::isnan(m.recall_visible)) m.recall_visible = 0.0;

  // ---- 26-connected components of the drawn set ---------------------------
  std::vector<std::size_t> stack;
  for (std::size_t start = 0; start < n; ++start) {
    if ((flags[start] & (kDrawn | kVisited)) != kDrawn) continue;
    flags[start] |= kVisited;
    stack.push_back(start);
    bool near = false;
    std::size_t size = 0;
    while (!stack.empty()) {
      const std::size_t i = stack.back();
      stack.pop_back();
      ++size;
      near = near || (flags[i] & kNear);
      const std::size_t x = i % g.nx, y = (i / g.nx) % g.ny, z = i / g.sz;
      const std::size_t z0 = z > 0 ? z - 1 : 0, z1 = std::min(z + 1, g.nz - 1);
      const std::size_t y0 = y > 0 ? y - 1 : 0, y1 = std::min(y + 1, g.ny - 1);
      const std::size_t x0 = x > 0 ? x - 1 : 0, x1 = std::min(x + 1, g.nx - 1);
      for (std::size_t zz = z0; zz <= z1; ++zz)
        for (std::size_t yy = y0; yy <= y1; ++yy)
          for (std::size_t xx = x0; xx <= x1; ++xx) {
            const std::size_t j = xx + yy * g.sy + zz * g.sz;
            if ((flags[j] & (kDrawn | kVisited)) == kDrawn) {
              flags[j] |= kVisited;
              stack.push_back(j);
            }
          }
    }
    ++m.components;
    if (!near) {
      ++m.spurious_blobs;
      m.spurious_voxels += size;
    }
  }

  // ---- 6-connected components of {u > blob_rel max u} -----------------------
  // Relative, so that a dim u cannot hide its debris below a fixed threshold;
  // 6-connected, so that speckle touching a shell only at an edge or a corner
  // stays a blob of its own.
  m.blob_threshold = p.blob_rel * t.max_u;
  const double t6 = m.blob_threshold;
  parallel_items(g.nz, [&](std::size_t z) {
    for (std::size_t i = z * g.sz, e = i + g.sz; i < e; ++i)
      if (double(u[i]) > t6) flags[i] |= kBright;
  });
  const auto bright = [&](std::size_t j) { return (flags[j] & (kBright | kVisited6)) == kBright; };
  std::size_t bright_voxels = 0, blob_voxels = 0;
  for (std::size_t start = 0; start < n; ++start) {
    if (!bright(start)) continue;
    flags[start] |= kVisited6;
    stack.push_back(start);
    bool near = false;
    std::size_t size = 0;
    while (!stack.empty()) {
      const std::size_t i = stack.back();
      stack.pop_back();
      ++size;
      near = near || (flags[i] & kNear);
      const std::size_t x = i % g.nx, y = (i / g.nx) % g.ny, z = i / g.sz;
      const std::size_t nb[6] = {x > 0 ? i - 1 : i,         x + 1 < g.nx ? i + 1 : i,
                                 y > 0 ? i - g.sy : i,      y + 1 < g.ny ? i + g.sy : i,
                                 z > 0 ? i - g.sz : i,      z + 1 < g.nz ? i + g.sz : i};
      for (std::size_t j : nb)
        if (bright(j)) {
          flags[j] |= kVisited6;
          stack.push_back(j);
        }
    }
    bright_voxels += size;
    ++m.components6;
    if (!near) {
      ++m.blobs6;
      blob_voxels += size;
    }
  }
  m.blob6_voxel_share = bright_voxels > 0 ? double(blob_voxels) / double(bright_voxels) : 0.0;

  const auto f1 = [](double a, double b) { return a + b > 0 ? 2 * a * b / (a + b) : 0.0; };
  m.f1 = f1(m.precision, m.recall);
  m.f1_mass = f1(m.mass_precision, m.recall);
  if (!std::isnan(m.recall_visible)) m.f1_visible = f1(m.precision, m.recall_visible);
  return m;
}

std::string metrics_json(const Metrics& m, const MetricsParams& p) {
  const double blen = std::sqrt(p.beam[0] * p.beam[0] + p.beam[1] * p.beam[1] + p.beam[2] * p.beam[2]);
  const double b[3] = {blen > 0 ? p.beam[0] / blen : 0, blen > 0 ? p.beam[1] / blen : 0,
                       blen > 0 ? p.beam[2] / blen : 0};
  std::ostringstream o;
  o << "{\"precision\": " << json_number(m.precision) << ", \"recall\": " << json_number(m.recall)
    << ", \"spurious_blobs\": " << m.spurious_blobs << ", \"components\": " << m.components
    << ", \"normal_error_deg\": " << json_number(m.normal_error_deg)
    << ", \"percent_opaque\": " << json_number(m.percent_opaque) << ", \"splats\": " << m.splats
    << ", \"facing_surface_voxels\": " << m.facing_surface_voxels
    << ", \"recall_visible\": " << json_number(m.recall_visible)
    << ", \"visible_surface_voxels\": " << m.visible_surface_voxels
    << ", \"visible_db\": " << (p.shadow_db ? json_number(p.visible_db) : std::string("null"))
    << ", \"normal_voxels\": " << m.normal_voxels
    << ", \"spurious_voxels\": " << m.spurious_voxels << ", \"mass_precision\": " << json_number(m.mass_precision)
    << ", \"f1\": " << json_number(m.f1) << ", \"f1_mass\": " << json_number(m.f1_mass)
    << ", \"surface_peak\": " << json_number(m.surface_peak)
    << ", \"surface_peak_visible\": " << json_number(m.surface_peak_visible)
    << ", \"f1_visible\": " << json_number(m.f1_visible)
    << ", \"shell_thickness_mm\": " << json_number(m.shell_thickness_mm)
    << ", \"thickness_points\": " << m.thickness_points << ", \"thickness_censored\": " << m.thickness_censored
    << ", \"shell_offset_mm\": " << json_number(m.shell_offset_mm) << ", \"offset_points\": " << m.offset_points
    << ", \"blobs6\": " << m.blobs6 << ", \"components6\": " << m.components6
    << ", \"blob6_voxel_share\": " << json_number(m.blob6_voxel_share)
    << ", \"threshold\": " << json_number(p.threshold)
    << ", \"tolerance\": " << json_number(m.tolerance) << ", \"tolerance_mm\": " << json_number(m.tolerance_mm)
    << ", \"opaque\": " << json_number(p.opaque) << ", \"u_ind\": " << json_number(p.u_ind)
    << ", \"blob_rel\": " << json_number(p.blob_rel) << ", \"blob_threshold\": " << json_number(m.blob_threshold)
    << ", \"profile_radius_mm\": " << json_number(m.profile_radius_mm)
    << ", \"facing_cos\": " << json_number(p.facing_cos) << ", \"tensor_sigma\": " << json_number(p.tensor_sigma)
    << ", \"orientation\": \"" << (p.tensor_sigma > 0 ? (p.orientation_field ? "data" : "tensor") : "gradient") << "\""
    << ", \"beam\": [" << json_number(b[0] + 0.0) << ", "
    << json_number(b[1] + 0.0) << ", " << json_number(b[2] + 0.0) << "]}";
  return o.str();
}

}  // namespace softshell
