// Shadow walls (host/shadow_walls.hpp).
#include "shadow_walls.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>

#include "filter.hpp"
#include "mask.hpp"
#include "parallel.hpp"

namespace softshell {

FanBeams fan_beams(const std::vector<std::uint8_t>& scanned, const Dims3& dims, const Vec3d& spacing, int axis) {
  FanBeams fan;
  if (axis < 0 || axis > 2) throw std::invalid_argument("fan_beams: beam axis must be 0, 1 or 2");
  const std::size_t n = dims[0] * dims[1] * dims[2];
  if (scanned.size() != n || n == 0) return fan;
  const std::size_t ax = std::size_t(axis), planes = dims[ax];
  // Per plane along the beam: each axis's first and last scanned coordinate.
  std::vector<long> lo[3], hi[3];
  for (int a = 0; a < 3; ++a) lo[a].assign(planes, -1), hi[a].assign(planes, -1);
  std::size_t i = 0;
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x, ++i) {
        if (!scanned[i]) continue;
        const long c[3] = {long(x), long(y), long(z)};
        const std::size_t d = std::size_t(c[ax]);
        for (int a = 0; a < 3; ++a) {
          if (lo[a][d] < 0 || c[a] < lo[a][d]) lo[a][d] = c[a];
          hi[a][d] = std::max(hi[a][d], c[a]);
        }
      }
  std::size_t first = planes, used = 0;
  for (std::size_t d = 0; d < planes; ++d)
    if (lo[ax][d] >= 0) first = std::min(first, d), ++used;
  if (used == 0) return fan;
  // A side's line c = a + b d through its planes off the volume's faces:
  // Theil-Sen (the median of the pairwise slopes, then the median offset),
  // so a shadow or a gap reaching the side on some planes does not tilt it;
  // then least squares over the planes within 2 voxels of that line. Returns
  // false when fewer than kFanMinPlanes, or fewer than half the side's
  // planes, lie on it.
  struct Line {
    double a = 0, b = 0, rms = 0;
  };
  const auto fit = [&](const std::vector<long>& side, long face, Line& out) {
    std::vector<std::size_t> ds;
    for (std::size_t d = 0; d < planes; ++d)
      if (side[d] >= 0 && side[d] != face) ds.push_back(d);
    if (ds.size() < std::size_t(kFanMinPlanes)) return false;
    std::vector<double> slopes;
    slopes.reserve(ds.size() * (ds.size() - 1) / 2);
    for (std::size_t j = 0; j < ds.size(); ++j)
      for (std::size_t k = j + 1; k < ds.size(); ++k)
        slopes.push_back(double(side[ds[k]] - side[ds[j]]) / double(ds[k] - ds[j]));
    const auto median = [](std::vector<double>& x) {
      std::nth_element(x.begin(), x.begin() + std::ptrdiff_t(x.size() / 2), x.end());
      return x[x.size() / 2];
    };
    const double b0 = median(slopes);
    std::vector<double> offsets;
    for (std::size_t d : ds) offsets.push_back(double(side[d]) - b0 * double(d));
    const double a0 = median(offsets);
    std::vector<std::size_t> on;
    for (std::size_t d : ds)
      if (std::fabs(double(side[d]) - (a0 + b0 * double(d))) <= 2.0) on.push_back(d);
    if (on.size() < std::size_t(kFanMinPlanes) || 2 * on.size() < ds.size()) return false;
    double sd = 0, sc = 0, sdd = 0, sdc = 0;
    for (std::size_t d : on) sd += double(d), sc += double(side[d]), sdd += double(d) * double(d), sdc += double(d) * double(side[d]);
    const double m = double(on.size()), den = m * sdd - sd * sd;
    if (!(den > 0)) return false;
    out.b = (m * sdc - sd * sc) / den, out.a = (sc - out.b * sd) / m;
    double ss = 0;
    for (std::size_t d : on) {
      const double r = double(side[d]) - (out.a + out.b * double(d));
      ss += r * r;
    }
    out.rms = std::sqrt(ss / m);
    return true;
  };
  double apex_depth = 0;
  int spreading = 0;
  for (std::size_t a = 0; a < 3; ++a) {
    if (a == ax) continue;
    Line left, right;
    if (!fit(lo[a], 0, left) || !fit(hi[a], long(dims[a]) - 1, right)) continue;
    const double k = spacing[a] / spacing[ax];  // index slope -> mm per mm
    if (!(-left.b * k >= kFanMinSlope && right.b * k >= kFanMinSlope)) continue;
    // A probe's sector is symmetric about its middle beam: sides that
    // spread at very different rates are a sweep's edges, not a sector's.
    if (!(-left.b <= kFanMaxSkew * right.b && right.b <= kFanMaxSkew * -left.b)) continue;
    if (!(left.rms <= kFanMaxRms && right.rms <= kFanMaxRms)) continue;
    const double d_apex = (left.a - right.a) / (right.b - left.b);  // where the sides meet
    if (!(d_apex < double(first))) continue;
    fan.spreads[a] = true;
    fan.apex[a] = left.a + left.b * d_apex;
    fan.rms_voxels = std::max({fan.rms_voxels, left.rms, right.rms});
    apex_depth += d_apex, ++spreading;
  }
  if (spreading == 0) return FanBeams{};
  fan.found = true;
  fan.apex[ax] = apex_depth / spreading;  // a volume probe's two sectors share one apex
  return fan;
}

namespace {

// std::lround(x) for |x| < 2^52 without a libm call: x - trunc(x) is exact
// there, and a half rounds away from zero.
long round_half_away(double x) {
  long r = long(x);
  const double frac = x - double(r);
  if (frac >= 0.5) ++r;
  else if (frac <= -0.5) --r;
  return r;
}

// Where the beam through coordinate t (0 <= t < size) of the plane `dd`
// voxels below a fan's apex along the beam axis crosses the plane `step`
// further down (+1 the plane below, -1 the plane above), along the plane's
// axis k: a table over t, -1 where it leaves the volume. Straight (t itself)
// unless `spread` and the fan spreads along k. Per plane and axis, not per
// voxel: the same expression gives the same value without a division and a
// rounding per voxel.
void beam_crossings(const FanBeams& fan, std::size_t k, std::size_t size, double dd, double step, bool spread,
                    std::vector<long>& out) {
  out.resize(size);
  for (std::size_t t = 0; t < size; ++t) {
    long at = long(t);
    if (spread && fan.spreads[k]) {
      at = round_half_away(fan.apex[k] + (double(t) - fan.apex[k]) * (dd + step) / dd);
      if (at < 0 || at >= long(size)) at = -1;
    }
    out[t] = at;
  }
}

}  // namespace

std::vector<float> shadow_wall_weight(Runtime& rt, const Volume& v, const std::vector<std::uint8_t>* scanned,
                                      double iso, const ShadowWallParams& params, ShadowWallReport* report) {
  const Dims3& d = v.dims;
  const std::size_t n = v.voxels();
  if (scanned && scanned->size() != n) throw std::invalid_argument("shadow_wall_weight: mask size differs from the volume");
  if (params.axis < 0 || params.axis > 2) throw std::invalid_argument("shadow_wall_weight: beam axis must be 0, 1 or 2");
  const int ax = params.axis;
  const std::size_t stride[3] = {1, d[0], d[0] * d[1]};
  const auto is_scanned = [&](std::size_t i) { return !scanned || (*scanned)[i] != 0; };
  const int threads = host_threads(0);
  // 1. Shadow: per beam line, a scanned voxel below the isovalue at least
  // gap_mm below the deepest scanned voxel above the isovalue further up the
  // line. Walked plane by plane along the beam axis in memory order, one
  // state per line (the lines split over threads by rows).
  const Volume vs = lowpass_volume(rt, v, {params.sigma_mm, 3.0});
  std::vector<float> shadow(n, 0.0f);
  const float level = float(iso);
  const double h_ax = v.spacing[std::size_t(ax)];
  const FanBeams fan = params.fan && scanned ? fan_beams(*scanned, d, v.spacing, ax) : FanBeams{};
  // The beam through voxel c (unit, in mm): from the fan's apex, else along
  // the axis. Its components before normalising, and their length; each
  // component depends on its own coordinate alone, so it is kept per axis
  // and coordinate (formed per voxel it cost the passes below a
  // multiplication and a subtraction per axis).
  std::array<std::vector<double>, 3> component;
  for (int k = 0; k < 3; ++k) {
    const double h = v.spacing[std::size_t(k)];
    std::vector<double>& b = component[std::size_t(k)];
    b.resize(d[std::size_t(k)]);
    for (std::size_t t = 0; t < b.size(); ++t)
      b[t] = k == ax ? (double(t) - (fan.found ? fan.apex[k] : -1.0)) * h
             : fan.spreads[k] ? (double(t) - fan.apex[k]) * h
                              : 0.0;
  }
  const auto beam_unnormalised = [&](const std::size_t c[3], double b[3]) {
    double len = 0;
    for (int k = 0; k < 3; ++k) {
      b[k] = component[std::size_t(k)][c[k]];
      len += b[k] * b[k];
    }
    return std::sqrt(len);
  };
  const auto beam_at = [&](const std::size_t c[3], double b[3]) {
    const double len = beam_unnormalised(c, b);
    for (int k = 0; k < 3; ++k) b[k] /= len;
  };
  // A shadow that lasts: a scanned voxel under the level from which every
  // scanned voxel down its beam to the end is under it too (unscanned
  // voxels pass it on). Such a shadow starts lasting_gap_mm under its
  // occluder instead of gap_mm (a cyst has its far wall and the tissue
  // behind it below; a bone, its shadow). Walked up the beams from the last
  // plane along the axis, one state per voxel of the plane: a voxel's
  // successor is the nearest voxel of the plane below on its beam (in a fan
  // from the apex; else straight down the axis).
  std::vector<std::uint8_t> lasting;
  const bool short_gap = params.lasting_gap_mm < params.gap_mm;
  if (short_gap) {
    lasting.assign(n, 0);
    const std::size_t la = ax == 0 ? 1 : 0, lb = ax == 2 ? 1 : 2;  // the plane's axes
    const std::size_t planes = d[std::size_t(ax)], per_plane = n / planes;
    std::vector<std::uint8_t> next(per_plane, 1), cur(per_plane, 1);
    std::vector<long> below[3];
    for (std::size_t depth = planes; depth-- > 0;) {
      const double dd = double(depth) - fan.apex[ax];
      const bool last = depth + 1 == planes;
      for (const std::size_t k : {la, lb})
        beam_crossings(fan, k, d[k], dd, 1.0, !last && fan.found && dd > 1.0, below[k]);
      parallel_ranges(d[lb], per_plane >= 65536 ? threads : 1, [&](std::size_t q0, std::size_t q1) {
        for (std::size_t q = q0; q < q1; ++q)
          for (std::size_t p = 0; p < d[la]; ++p) {
            std::size_t c[3];
            c[ax] = depth, c[la] = p, c[lb] = q;
            const std::size_t i = c[0] * stride[0] + c[1] * stride[1] + c[2] * stride[2];
            // Past the end of the beam (the last plane, or off the sides): dark.
            std::uint8_t after = 1;
            if (!last) {
              const long pa = below[la][p], pb = below[lb][q];
              if (pa >= 0 && pb >= 0) after = next[std::size_t(pa) + d[la] * std::size_t(pb)];
            }
            const std::size_t cell = p + d[la] * q;
            if (!is_scanned(i)) {
              cur[cell] = after;
              continue;
            }
            cur[cell] = lasting[i] = after && vs.data[i] < level ? 1 : 0;
          }
      });
      next.swap(cur);
    }
  }
  const auto gap_for = [&](std::size_t i) { return short_gap && lasting[i] ? params.lasting_gap_mm : params.gap_mm; };
  if (fan.found) {
    // Down each beam from the apex, plane by plane along the axis: a voxel's
    // predecessor is the nearest voxel of the plane above on its beam, and a
    // beam's state (the depth of its deepest bright voxel, and of its first
    // scanned one) passes down the beams; unscanned voxels pass it on. The
    // gap is measured along the beam. A bright voxel within fan_skip_mm of
    // its beam's first scanned voxel occludes nothing: a fan's beams all
    // meet under the probe, and what is left bright there (the near field's
    // remnants, skin) would shade the whole sector.
    const std::size_t planes = d[std::size_t(ax)], per_plane = n / planes;
    const std::size_t la = ax == 0 ? 1 : 0, lb = ax == 2 ? 1 : 2;  // the plane's axes
    std::vector<long> prev(per_plane, -1), cur(per_plane, -1), prev_top(per_plane, -1), cur_top(per_plane, -1);
    // Per plane, a table along each of the plane's two axes of where the
    // beam through coordinate t crosses the plane above (beam_crossings).
    std::vector<long> above[3];
    for (std::size_t depth = 0; depth < planes; ++depth) {
      const double dd = double(depth) - fan.apex[ax];
      const bool from_above = depth > 0 && dd > 1.0;
      for (const std::size_t k : {la, lb}) beam_crossings(fan, k, d[k], dd, -1.0, from_above, above[k]);
      parallel_ranges(d[lb], per_plane >= 65536 ? threads : 1, [&](std::size_t q0, std::size_t q1) {
        for (std::size_t q = q0; q < q1; ++q)
          for (std::size_t p = 0; p < d[la]; ++p) {
            std::size_t c[3];
            c[ax] = depth, c[la] = p, c[lb] = q;
            const std::size_t i = c[0] * stride[0] + c[1] * stride[1] + c[2] * stride[2];
            const std::size_t cell = p + d[la] * q;
            long up = -1, top = -1;
            if (from_above) {
              // The plane above, where this voxel's beam crosses it.
              const long pa = above[la][p], pb = above[lb][q];
              if (pa >= 0 && pb >= 0) {
                const std::size_t pcell = std::size_t(pa) + d[la] * std::size_t(pb);
                up = prev[pcell], top = prev_top[pcell];
              }
            }
            cur[cell] = up;
            cur_top[cell] = top;
            if (!is_scanned(i)) continue;
            if (top < 0) cur_top[cell] = top = long(depth);
            // mm along the beam per plane (formed only where a test needs it).
            const auto along = [&] {
              double b[3];
              const double len = beam_unnormalised(c, b);
              return h_ax / std::fabs(b[ax] / len);
            };
            if (vs.data[i] > level) {
              if (double(long(depth) - top) * along() >= params.fan_skip_mm) cur[cell] = long(depth);
            } else if (up >= 0 && vs.data[i] < level) {
              if (double(long(depth) - up) * along() >= gap_for(i)) shadow[i] = 1.0f;
            }
          }
      });
      prev.swap(cur);
      prev_top.swap(cur_top);
    }
  } else {
    // A line is indexed by its voxels' coordinates across the beam; the
    // outer loops' rows are split over threads so that each owns its lines.
    const std::size_t nx = d[0], ny = d[1], nz = d[2];
    std::vector<long> last_bright(n / d[std::size_t(ax)], -1);
    const auto visit = [&](std::size_t i, std::size_t line, std::size_t depth) {
      if (!is_scanned(i)) return;
      if (vs.data[i] > level) last_bright[line] = long(depth);
      else if (last_bright[line] >= 0 && vs.data[i] < level &&
               double(long(depth) - last_bright[line]) * h_ax >= gap_for(i))
        shadow[i] = 1.0f;
    };
    if (ax == 2) {
      parallel_ranges(ny, threads, [&](std::size_t y0, std::size_t y1) {
        for (std::size_t z = 0; z < nz; ++z)
          for (std::size_t y = y0; y < y1; ++y)
            for (std::size_t x = 0; x < nx; ++x) visit(x + nx * (y + ny * z), x + nx * y, z);
      });
    } else if (ax == 1) {
      parallel_ranges(nz, threads, [&](std::size_t z0, std::size_t z1) {
        for (std::size_t z = z0; z < z1; ++z)
          for (std::size_t y = 0; y < ny; ++y)
            for (std::size_t x = 0; x < nx; ++x) visit(x + nx * (y + ny * z), x + nx * z, y);
      });
    } else {
      parallel_ranges(nz, threads, [&](std::size_t z0, std::size_t z1) {
        for (std::size_t z = z0; z < z1; ++z)
          for (std::size_t y = 0; y < ny; ++y)
            for (std::size_t x = 0; x < nx; ++x) visit(x + nx * (y + ny * z), y + ny * z, x);
      });
    }
  }
  // 2. Walls: edges of the gradient lowpass (the shadow test's when the two
  // sigmas agree, the default) across the beam, between a shadow on their
  // dark side and no shadow on their bright side (reach_mm down and up the
  // gradient, trilinear in the shadow indicator).
  std::optional<Volume> own_vg;
  if (params.grad_sigma_mm != params.sigma_mm) own_vg = lowpass_volume(rt, v, {params.grad_sigma_mm, 3.0});
  const Volume& vg = own_vg ? *own_vg : vs;
  Volume wall(d, v.spacing, ScalarType::Float32);
  wall.data.assign(n, 0.0f);
  const auto sample = [&](const std::vector<float>& field, double x, double y, double z) {
    const double c[3] = {std::clamp(x, 0.0, double(d[0] - 1)), std::clamp(y, 0.0, double(d[1] - 1)),
                         std::clamp(z, 0.0, double(d[2] - 1))};
    std::size_t i0[3], i1[3];
    double f[3];
    for (int k = 0; k < 3; ++k) {
      i0[k] = std::size_t(c[k]);  // c >= 0: floor's value, without a libm call
      i1[k] = std::min(i0[k] + 1, d[std::size_t(k)] - 1);
      f[k] = c[k] - double(i0[k]);
    }
    double s = 0;
    for (int corner = 0; corner < 8; ++corner) {
      const std::size_t xi = corner & 1 ? i1[0] : i0[0], yi = corner & 2 ? i1[1] : i0[1], zi = corner & 4 ? i1[2] : i0[2];
      const double wgt = (corner & 1 ? f[0] : 1 - f[0]) * (corner & 2 ? f[1] : 1 - f[1]) * (corner & 4 ? f[2] : 1 - f[2]);
      s += wgt * field[xi + d[0] * (yi + d[1] * zi)];
    }
    return s;
  };
  // grad v~ at voxel i (coordinates c; central differences, one-sided at the
  // faces), in units per mm; returns its length.
  const auto gradient_at = [&](std::size_t i, const std::size_t c[3], double g[3]) {
    for (int k = 0; k < 3; ++k) {
      const std::size_t lo = c[k] > 0 ? i - stride[k] : i, hi = c[k] + 1 < d[std::size_t(k)] ? i + stride[k] : i;
      const double span = double((c[k] + 1 < d[std::size_t(k)]) + (c[k] > 0)) * v.spacing[std::size_t(k)];
      g[k] = span > 0 ? (double(vg.data[hi]) - double(vg.data[lo])) / span : 0.0;
    }
    return std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  };
  // An edge's two sides, reach_mm down (dark) and up (bright) its gradient
  // g of length m > 0, in voxel coordinates.
  const auto sides_of = [&](const std::size_t c[3], const double g[3], double m, double dark[3], double bright[3]) {
    for (int k = 0; k < 3; ++k) {
      const double step = params.reach_mm * g[k] / m / v.spacing[std::size_t(k)];
      dark[k] = double(c[k]) - step, bright[k] = double(c[k]) + step;
    }
  };
  // Voxels with no shadow within reach: their dark side's sample is 0 (its
  // eight corners are), so their wall is 0 (0 times the bright side's
  // share, in [0, 1]), as written below; skipped. The dark side lies at
  // most reach_mm / spacing voxels away along each axis, and its sample
  // reads the voxels at and after its floor: the shadow dilated by a cube of
  // that reach plus one (a superset) marks every voxel that may have one.
  std::vector<std::uint8_t> near(n);
  {
    int r = 1;
    for (int k = 0; k < 3; ++k)
      r = std::max(r, int(std::ceil(params.reach_mm / v.spacing[std::size_t(k)])) + 1);
    // (A reach of many voxels, fine spacing: every voxel is visited, as
    // without the test; the cube filter's cost grows with its width.)
    const bool wide = r > 32;
    parallel_ranges(n, threads, [&](std::size_t i0, std::size_t i1) {
      for (std::size_t i = i0; i < i1; ++i) near[i] = wide || shadow[i] != 0.0f ? 1 : 0;
    });
    if (!wide) mask_detail::cube_filter(near, d, r, false, threads);
  }
  parallel_ranges(d[2], threads, [&](std::size_t z0, std::size_t z1) {
    for (std::size_t z = z0; z < z1; ++z)
      for (std::size_t y = 0; y < d[1]; ++y)
        for (std::size_t x = 0; x < d[0]; ++x) {
          const std::size_t i = x + d[0] * (y + d[1] * z);
          if (!near[i] || !is_scanned(i)) continue;
          const std::size_t c[3] = {x, y, z};
          double g[3];
          const double m = gradient_at(i, c, g);
          double along = g[ax];
          if (fan.found) {
            double b[3];
            beam_at(c, b);
            along = g[0] * b[0] + g[1] * b[1] + g[2] * b[2];
          }
          if (!(m > 0) || !std::isfinite(m) || std::fabs(along) >= params.beam_cos * m) continue;
          // The dark side (down the gradient) in shadow, the bright side (up
          // it) not: an edge between a shadow and what is beside it (in
          // voxels per axis).
          double dark[3], bright[3];
          sides_of(c, g, m, dark, bright);
          // The bright side is probed at reach_mm and, where bright_near is
          // set, that share of it: in a strip narrower than the reach between
          // two shadows (the beam passing between two bones) the far probe
          // lands in the other shadow, the near one does not.
          double bright_value = sample(vs.data, bright[0], bright[1], bright[2]);
          double bright_shadow = sample(shadow, bright[0], bright[1], bright[2]);
          if (params.bright_near > 0 && params.bright_near < 1) {
            double near_side[3];
            for (int k = 0; k < 3; ++k) near_side[k] = double(c[k]) + params.bright_near * (bright[k] - double(c[k]));
            bright_value = std::max(bright_value, sample(vs.data, near_side[0], near_side[1], near_side[2]));
            bright_shadow = std::min(bright_shadow, sample(shadow, near_side[0], near_side[1], near_side[2]));
          }
          // Only where the classifier could draw it: the bright side above
          // the isovalue (the dark side, in shadow, is below it).
          if (!(bright_value > iso - params.bright_mm * m)) continue;
          wall.data[i] = float(sample(shadow, dark[0], dark[1], dark[2]) * (1.0 - bright_shadow));
        }
  });
  // 2b. The underside of a thin echo (params.underside): an edge falling
  // along the beam between its bright side above the isovalue and its dark
  // side below, whose bright side falls under the isovalue again within
  // underside_mm up the beam (walked in steps of the finest spacing).
  std::vector<std::uint8_t> underside;
  if (params.underside && params.underside_mm > 0) {
    underside.assign(n, 0);
    const double h = std::min({v.spacing[0], v.spacing[1], v.spacing[2]});
    parallel_ranges(d[2], threads, [&](std::size_t z0, std::size_t z1) {
      for (std::size_t z = z0; z < z1; ++z)
        for (std::size_t y = 0; y < d[1]; ++y)
          for (std::size_t x = 0; x < d[0]; ++x) {
            const std::size_t i = x + d[0] * (y + d[1] * z);
            if (!is_scanned(i)) continue;
            const std::size_t c[3] = {x, y, z};
            double g[3];
            const double m = gradient_at(i, c, g);
            double b[3] = {0.0, 0.0, 0.0};  // the beam, pointing deeper
            if (fan.found) beam_at(c, b);
            else b[ax] = 1.0;
            // Falling along the beam: the gradient points up it.
            const double along = g[0] * b[0] + g[1] * b[1] + g[2] * b[2];
            if (!(m > 0) || !std::isfinite(m) || !(along <= -params.beam_cos * m)) continue;
            double dark[3], bright[3];
            sides_of(c, g, m, dark, bright);
            if (!(sample(vs.data, bright[0], bright[1], bright[2]) > iso) ||
                !(sample(vs.data, dark[0], dark[1], dark[2]) < iso))
              continue;
            // Up the beam from the bright side, inside the volume.
            for (double t = h; t <= params.underside_mm + 1e-9; t += h) {
              double q[3];
              bool inside = true;
              for (int k = 0; k < 3; ++k) {
                q[k] = bright[k] - t * b[k] / v.spacing[std::size_t(k)];
                inside = inside && q[k] >= 0.0 && q[k] <= double(d[std::size_t(k)] - 1);
              }
              if (!inside) break;
              if (sample(vs.data, q[0], q[1], q[2]) < iso) {
                wall.data[i] = 1.0f;
                underside[i] = 1;
                break;
              }
            }
          }
    });
  }
  // 3. The weight: 1 - the lowpassed wall indicator, in [0, 1].
  const Volume ws = params.smooth_mm > 0 ? lowpass_volume(rt, wall, {params.smooth_mm, 3.0}) : wall;
  std::vector<float> weight(n);
  std::size_t scanned_count = 0, in_shadow = 0, walls = 0, undersides = 0;
  {
    // Over threads; the counts are sums (the same for any split).
    const int parts = range_count(n, threads);
    std::vector<std::array<std::size_t, 4>> counts(std::size_t(parts), {0, 0, 0, 0});
    parallel_ranges_indexed(n, threads, [&](int part, std::size_t i0, std::size_t i1) {
      std::size_t c0 = 0, c1 = 0, c2 = 0, c3 = 0;
      for (std::size_t i = i0; i < i1; ++i) {
        weight[i] = std::clamp(1.0f - ws.data[i], 0.0f, 1.0f);
        if (!is_scanned(i)) continue;
        ++c0;
        c1 += shadow[i] > 0;
        c2 += weight[i] < 0.5f;
        c3 += !underside.empty() && underside[i];
      }
      counts[std::size_t(part)] = {c0, c1, c2, c3};
    });
    for (const auto& c : counts) scanned_count += c[0], in_shadow += c[1], walls += c[2], undersides += c[3];
  }
  if (report) {
    report->fan = fan;
    report->shadow_share = scanned_count ? double(in_shadow) / double(scanned_count) : 0.0;
    report->wall_share = scanned_count ? double(walls) / double(scanned_count) : 0.0;
    report->underside_share = scanned_count ? double(undersides) / double(scanned_count) : 0.0;
  }
  return weight;
}

ShadowWallParams shadow_wall_params(const VariationalParams& p, int axis) {
  ShadowWallParams w;
  const double f = p.sigma_mm / VariationalParams{}.sigma_mm;
  w.axis = axis;
  w.sigma_mm = w.grad_sigma_mm = p.grad_sigma_mm > 0 ? p.grad_sigma_mm : p.sigma_mm;
  w.reach_mm *= f, w.smooth_mm *= f, w.gap_mm *= f, w.lasting_gap_mm *= f, w.fan_skip_mm *= f, w.underside_mm *= f;
  return w;
}

bool underside_applies(double falling, double rising) {
  return rising > 0 && falling <= kUndersideFallRatio * rising;
}

std::shared_ptr<const std::vector<float>> combine_edge_weights(std::shared_ptr<const std::vector<float>> a,
                                                               std::shared_ptr<const std::vector<float>> b) {
  if (!a) return b;
  if (!b) return a;
  if (a->size() != b->size()) throw std::invalid_argument("combine_edge_weights: sizes differ");
  auto out = std::make_shared<std::vector<float>>(*a);
  for (std::size_t i = 0; i < out->size(); ++i) (*out)[i] *= (*b)[i];
  return out;
}

void set_edge_weights(VariationalParams& p, std::shared_ptr<const std::vector<float>> cue,
                      std::shared_ptr<const std::vector<float>> walls) {
  p.edge_reference = cue ? VariationalParams::EdgeReference::Cue : VariationalParams::EdgeReference::Weighted;
  p.edge_weight = combine_edge_weights(std::move(cue), std::move(walls));
}

}  // namespace softshell
