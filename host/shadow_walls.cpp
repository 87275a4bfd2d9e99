// Shadow walls (host/shadow_walls.hpp).
#include "shadow_walls.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>

#include "filter.hpp"
#include "parallel.hpp"

namespace softshell {

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
  {
    // A line is indexed by its voxels' coordinates across the beam; the
    // outer loops' rows are split over threads so that each owns its lines.
    const std::size_t nx = d[0], ny = d[1], nz = d[2];
    std::vector<long> last_bright(n / d[std::size_t(ax)], -1);
    const auto visit = [&](std::size_t i, std::size_t line, std::size_t depth) {
      if (!is_scanned(i)) return;
      if (vs.data[i] > level) last_bright[line] = long(depth);
      else if (last_bright[line] >= 0 && vs.data[i] < level &&
               double(long(depth) - last_bright[line]) * h_ax >= params.gap_mm)
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
      i0[k] = std::size_t(std::floor(c[k]));
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
  parallel_ranges(d[2], threads, [&](std::size_t z0, std::size_t z1) {
    for (std::size_t z = z0; z < z1; ++z)
      for (std::size_t y = 0; y < d[1]; ++y)
        for (std::size_t x = 0; x < d[0]; ++x) {
          const std::size_t i = x + d[0] * (y + d[1] * z);
          if (!is_scanned(i)) continue;
          const std::size_t c[3] = {x, y, z};
          double g[3];
          for (int k = 0; k < 3; ++k) {
            const std::size_t lo = c[k] > 0 ? i - stride[k] : i, hi = c[k] + 1 < d[std::size_t(k)] ? i + stride[k] : i;
            const double span = double((c[k] + 1 < d[std::size_t(k)]) + (c[k] > 0)) * v.spacing[std::size_t(k)];
            g[k] = span > 0 ? (double(vg.data[hi]) - double(vg.data[lo])) / span : 0.0;
          }
          const double m = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
          if (!(m > 0) || !std::isfinite(m) || std::fabs(g[ax]) >= params.beam_cos * m) continue;
          // The dark side (down the gradient) in shadow, the bright side (up
          // it) not: an edge between a shadow and what is beside it (in
          // voxels per axis).
          double dark[3], bright[3];
          for (int k = 0; k < 3; ++k) {
            const double step = params.reach_mm * g[k] / m / v.spacing[std::size_t(k)];
            dark[k] = double(c[k]) - step, bright[k] = double(c[k]) + step;
          }
          // Only where the classifier could draw it: the bright side above
          // the isovalue (the dark side, in shadow, is below it).
          if (!(sample(vs.data, bright[0], bright[1], bright[2]) > iso - params.bright_mm * m)) continue;
          wall.data[i] = float(sample(shadow, dark[0], dark[1], dark[2]) *
                               (1.0 - sample(shadow, bright[0], bright[1], bright[2])));
        }
  });
  // 3. The weight: 1 - the lowpassed wall indicator, in [0, 1].
  const Volume ws = params.smooth_mm > 0 ? lowpass_volume(rt, wall, {params.smooth_mm, 3.0}) : wall;
  std::vector<float> weight(n);
  std::size_t scanned_count = 0, in_shadow = 0, walls = 0;
  for (std::size_t i = 0; i < n; ++i) {
    weight[i] = std::clamp(1.0f - ws.data[i], 0.0f, 1.0f);
    if (!is_scanned(i)) continue;
    ++scanned_count;
    in_shadow += shadow[i] > 0;
    walls += weight[i] < 0.5f;
  }
  if (report) {
    report->shadow_share = scanned_count ? double(in_shadow) / double(scanned_count) : 0.0;
    report->wall_share = scanned_count ? double(walls) / double(scanned_count) : 0.0;
  }
  return weight;
}

ShadowWallParams shadow_wall_params(const VariationalParams& p, int axis) {
  ShadowWallParams w;
  const double f = p.sigma_mm / VariationalParams{}.sigma_mm;
  w.axis = axis;
  w.sigma_mm = w.grad_sigma_mm = p.grad_sigma_mm > 0 ? p.grad_sigma_mm : p.sigma_mm;
  w.reach_mm *= f, w.smooth_mm *= f, w.gap_mm *= f;
  return w;
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
