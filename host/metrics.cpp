// Surface-quality metrics of an opacity volume u against a ground-truth
// signed distance field (`softshell evaluate`). Definitions and the reasons
// for them: docs/metrics.md.
//
// Everything is O(N) on the host: one pass over the voxels for the pointwise
// sums and per-voxel flags, an exact separable Euclidean distance transform
// of the drawn set for recall, and a flood fill with an explicit stack for
// the 26-connected components. Passes run on std::threads over slices (or
// lines); each slice keeps its own partial sums and they are added in slice
// order, so the result does not depend on the number of threads.
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

// Per-voxel flags of the first pass; kVisited is used by the flood fill.
enum : std::uint8_t { kDrawn = 1, kNear = 2, kFacing = 4, kVisited = 8 };

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

// Partial sums of one z slice (first pass).
struct SliceSums {
  std::size_t splats = 0, opaque = 0, facing = 0, normal_voxels = 0, non_finite_u = 0, non_finite_sdf = 0;
  double drawn_u = 0, near_u = 0, normal_w = 0, normal_wangle = 0;
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
  if (!std::isfinite(p.opaque) || p.opaque < 0)
    throw InputError("opaque must be a finite number >= 0, got " + std::to_string(p.opaque));
  if (!(p.tensor_sigma >= 0 && p.tensor_sigma <= 8))
    throw InputError("tensor sigma must be in [0, 8] voxels, got " + std::to_string(p.tensor_sigma));
  if (!(p.facing_cos >= -1 && p.facing_cos <= 1))
    throw InputError("facing_cos must be in [-1, 1], got " + std::to_string(p.facing_cos));
  const double b = std::sqrt(p.beam[0] * p.beam[0] + p.beam[1] * p.beam[1] + p.beam[2] * p.beam[2]);
  if (!std::isfinite(b) || !(b > 0)) throw InputError("beam must be a finite, non-zero direction");
  for (double s : opacity.spacing)
    if (!std::isfinite(s) || !(s > 0)) throw InputError("opacity volume: spacing must be positive");
}

std::string json_number(double v) {
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
  if (n == 0) return m;
  const float* u = opacity.data.data();
  const float* sdf = truth_sdf.data.data();
  const double blen = std::sqrt(p.beam[0] * p.beam[0] + p.beam[1] * p.beam[1] + p.beam[2] * p.beam[2]);
  const double toward[3] = {-p.beam[0] / blen, -p.beam[1] / blen, -p.beam[2] / blen};  // to the transducer
  const double min_grad_u = kMinOpacityStep / std::min({g.h[0], g.h[1], g.h[2]});

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
        const bool near = std::abs(si) <= p.tolerance;
        std::uint8_t f = near ? kNear : 0;
        bool have_gs = false;
        if (ui > p.opaque) ++s.opaque;
        if (ui > p.threshold) {
          f |= kDrawn;
          ++s.splats;
          s.drawn_u += ui;
          if (near) {
            s.near_u += ui;
            g.gradient(u, i, x, y, z, gu);
            double nu = std::sqrt(gu[0] * gu[0] + gu[1] * gu[1] + gu[2] * gu[2]);
            if (p.tensor_sigma > 0) {  // the renderer's default orientation
              const std::array<double, 3> t =
                  tensor_orientation_reference(opacity, {double(x), double(y), double(z)}, p.tensor_sigma);
              gu[0] = t[0], gu[1] = t[1], gu[2] = t[2];
              nu = std::sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
            }
            if (nu > min_grad_u) {
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
          if (ns > 0 && (gs[0] * toward[0] + gs[1] * toward[1] + gs[2] * toward[2]) / ns >= p.facing_cos) {
            f |= kFacing;
            ++s.facing;
          }
        }
        flags[i] = f;
      }
    }
  });
  SliceSums t;
  for (const SliceSums& s : slices) {
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
  m.normal_voxels = t.normal_voxels;
  m.percent_opaque = 100.0 * double(t.opaque) / double(n);
  m.precision = t.drawn_u > 0 ? t.near_u / t.drawn_u : 0.0;
  m.normal_error_deg = t.normal_w > 0 ? t.normal_wangle / t.normal_w : 0.0;

  // ---- recall: distance from each facing surface voxel to the drawn set --
  if (m.splats > 0 && m.facing_surface_voxels > 0) {
    std::vector<unsigned char> drawn(n);
    for (std::size_t i = 0; i < n; ++i) drawn[i] = flags[i] & kDrawn;
    const std::vector<float> d2 = metrics_detail::squared_edt(drawn, opacity.dims);
    drawn = {};
    // Squared distances between voxel centres are integers: compare exactly.
    const double tol2 = std::floor(p.tolerance * p.tolerance + 1e-9);
    std::vector<std::size_t> hits(g.nz, 0);
    parallel_items(g.nz, [&](std::size_t z) {
      for (std::size_t i = z * g.sz, e = i + g.sz; i < e; ++i)
        if ((flags[i] & kFacing) && double(d2[i]) <= tol2) ++hits[z];
    });
    std::size_t hit = 0;
    for (std::size_t h : hits) hit += h;
    m.recall = double(hit) / double(m.facing_surface_voxels);
  }

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
    << ", \"facing_surface_voxels\": " << m.facing_surface_voxels << ", \"normal_voxels\": " << m.normal_voxels
    << ", \"spurious_voxels\": " << m.spurious_voxels << ", \"threshold\": " << json_number(p.threshold)
    << ", \"tolerance\": " << json_number(p.tolerance) << ", \"opaque\": " << json_number(p.opaque)
    << ", \"facing_cos\": " << json_number(p.facing_cos) << ", \"tensor_sigma\": " << json_number(p.tensor_sigma)
    << ", \"beam\": [" << json_number(b[0] + 0.0) << ", "
    << json_number(b[1] + 0.0) << ", " << json_number(b[2] + 0.0) << "]}";
  return o.str();
}

}  // namespace softshell
