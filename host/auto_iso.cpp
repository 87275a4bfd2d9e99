// `--iso auto` (host/auto_iso.hpp): mean gradient magnitude of the lowpassed
// volume per value bin, and its peak. Host code: one separable Gaussian and
// one histogram pass, a fraction of a second on the volumes softshell meets.
// Every pass over the voxels is split in z-ranges over threads
// (AutoIsoParams::threads); per-range results are combined in z order and
// sums are taken per z-plane, so the result is the same for any thread count.
#include "auto_iso.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "blur.hpp"
#include "error.hpp"
#include "filter.hpp"
#include "io.hpp"
#include "parallel.hpp"

namespace softshell {
namespace {

// For x in [0, len) of a row of v~ (c: its first voxel; sy, sz: the strides):
// g[x] = |central-difference gradient| (h2: twice the spacings) and bin[x] =
// the histogram bin of c[x] (lo, width, bins), in double: vectorised (this
// file is built with -fno-math-errno, which a vectorised sqrt needs; built
// for AVX2 too, with the default build's bits). The spacings and the bin width enter as
// reciprocals: four divisions per voxel were a quarter of the pass (16 of
// 83 ms at 256^3); a product may differ from the quotient in the last bit.
__attribute__((target_clones("avx2", "default"))) void row_gradients(
    const float* c, std::size_t len, std::size_t sy, std::size_t sz, double h2x, double h2y, double h2z, double lo,
    double width, int bins, float* g, int* bin) {
  // The six neighbours' rows (c is an interior voxel: all inside the array).
  const float *xm = c - 1, *xp = c + 1, *ym = c - sy, *yp = c + sy, *zm = c - sz, *zp = c + sz;
  const double ix = 1 / h2x, iy = 1 / h2y, iz = 1 / h2z, iw = 1 / width;
  for (std::size_t x = 0; x < len; ++x) {
    const double gx = (xp[x] - xm[x]) * ix, gy = (yp[x] - ym[x]) * iy, gz = (zp[x] - zm[x]) * iz;
    g[x] = float(std::sqrt(gx * gx + gy * gy + gz * gz));
  }
  // bin null: the gradients only (the rules other than Edge bin nothing).
  if (!bin) return;
  // Clamped before the conversion: the row's unusable voxels (outside the
  // mask) may lie far outside [lo, hi], and a float beyond int's range
  // converted to int is undefined (found by fuzz_classify). fmax/fmin take
  // a NaN to the other operand. For every finite value the same bin as
  // clamping the converted int.
  for (std::size_t x = 0; x < len; ++x) bin[x] = int(std::fmax(0.0, std::fmin(double(bins - 1), (c[x] - lo) * iw)));
}

// One row of the isovalue field, trilinear from the four coarse rows around
// it (x0, x1, tx per voxel; ty, tz for the row), mapped back to file units and
// clamped: the per-voxel expressions as they were, vectorised (gathers) in
// the AVX2 build, the same bits.
__attribute__((target_clones("avx2", "default"))) void field_row(float* __restrict out, std::size_t nx, const float* r00,
                                                              const float* r10, const float* r01, const float* r11,
                                                              const std::uint32_t* x0s, const std::uint32_t* x1s,
                                                              const float* txs, float ty, float tz, double local_iso,
                                                              double spread, double lo, double hi) {
  for (std::size_t x = 0; x < nx; ++x) {
    const std::uint32_t x0 = x0s[x], x1 = x1s[x];
    const float tx = txs[x];
    const float a00 = r00[x0] + tx * (r00[x1] - r00[x0]);
    const float a10 = r10[x0] + tx * (r10[x1] - r10[x0]);
    const float a01 = r01[x0] + tx * (r01[x1] - r01[x0]);
    const float a11 = r11[x0] + tx * (r11[x1] - r11[x0]);
    const float b0 = a00 + ty * (a10 - a00), b1 = a01 + ty * (a11 - a01);
    const double t = double(b0 + tz * (b1 - b0));
    out[x] = float(std::clamp(local_iso + spread * t, lo, hi));
  }
}

// v[x] - field[x] + iso for one row, in place (level_isovalue's expression).
void level_row(float* v, const float* field, std::size_t len, double iso) {
  // In double, then clamped to float's range: on float data spanning
  // +-3e38 the difference would overflow to infinity (found by fuzzing).
  const double big = std::numeric_limits<float>::max();
  for (std::size_t x = 0; x < len; ++x) v[x] = float(std::clamp(double(v[x]) - double(field[x]) + iso, -big, big));
}

}  // namespace

float kth_nonnegative(const float* g, std::size_t n, std::size_t k, int threads) {
  return kth_smallest_where(n, k, threads, [g](std::size_t i, float& f) {
    f = g[i];
    return f >= 0;
  });
}

double auto_iso(const Volume& v, const std::vector<std::uint8_t>* mask, const AutoIsoParams& params,
                AutoIsoReport* report, Volume* level) {
  const Dims3& d = v.dims;
  const std::size_t n = v.voxels();
  if (mask && mask->size() != n) throw std::invalid_argument("auto_iso: mask size differs from the volume");
  if (level && (level->dims != d || level->data.size() != n))
    throw std::invalid_argument("auto_iso: the volume to level differs in size from the volume");
  if (params.bins < 4 || !(params.sigma_mm >= 0) || !(params.min_bin_share >= 0))
    throw InputError("auto iso: bins must be >= 4, sigma and min_bin_share >= 0");
  if (d[0] < 3 || d[1] < 3 || d[2] < 3)
    throw InputError("--iso auto needs a volume of at least 3 voxels along each axis, got " + std::to_string(d[0]) +
                     "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]));
  if (v.data.size() != n) throw std::invalid_argument("auto_iso: volume data size differs from its dims");
  // Safety only, the rule is unchanged: a NaN or Inf sample would reach the
  // histogram's integer bin index, and a lowpass hundreds of voxels wide (a
  // spacing in metres read as mm) would take hours.
  require_finite(v, "--iso auto", "");
  for (int axis = 0; axis < 3; ++axis) {
    const double sigma_vox = std::max(1.0, params.sigma_mm / v.spacing[axis]);
    if (std::ceil(3.0 * sigma_vox) > kMaxLowpassRadius) {
      std::ostringstream m;
      m << "--iso auto: its " << params.sigma_mm << " mm lowpass is " << sigma_vox << " voxels along " << "xyz"[axis]
        << " (spacing " << v.spacing[axis] << " mm), more than the " << std::floor(10 * kMaxLowpassRadius / 3.0) / 10.0
        << " it allows; check the spacing's unit (mm) or give --iso V";
      throw InputError(m.str());
    }
  }

  const int threads = host_threads(params.threads);
  const std::size_t inner_planes = d[2] - 2;  // the interior planes [1, nz - 1)
  auto over_voxels = [&](auto&& f) { parallel_ranges(n, threads, f); };

  // v~: normalised convolution of the scanned samples. The large arrays are
  // first written by the threads that use them (a page's first touch costs a
  // fault, 2 ms per 4 MB on this kind of VM: a serial zero-fill of the four
  // 256^3 arrays took 0.15 s), a plane at a time just before its x and y
  // blurs, while it is in cache.
  HostVector<float> num(n), den(mask ? n : 0);
  std::array<std::vector<float>, 3> w;
  for (int axis = 0; axis < 3; ++axis)
    w[std::size_t(axis)] = gaussian_weights(std::max(1.0, params.sigma_mm / v.spacing[axis]), 3.0);
  const std::size_t plane = d[0] * d[1];
  // Per plane, for the rule on clipped echoes (below): the largest scanned
  // sample, how many samples equal it, and how many are scanned; taken while
  // the plane is in cache.
  constexpr float kNone = -std::numeric_limits<float>::infinity();
  const bool want_top = params.rule == AutoIsoRule::Local;
  std::vector<float> plane_top(want_top ? d[2] : 0, kNone), plane_bottom(plane_top.size(), -kNone);
  std::vector<std::size_t> plane_at_top(plane_top.size(), 0), plane_at_bottom(plane_top.size(), 0),
      plane_scanned(plane_top.size(), 0);
  blur_3d(num.data(), mask ? den.data() : nullptr, d, w[0], w[1], w[2], threads, [&](std::size_t z) {
    const std::size_t i0 = z * plane, i1 = i0 + plane;
    if (mask) {
      for (std::size_t i = i0; i < i1; ++i) {
        den[i] = (*mask)[i] ? 1.0f : 0.0f;
        num[i] = (*mask)[i] ? v.data[i] : 0.0f;
      }
    } else {
      std::copy(v.data.begin() + std::ptrdiff_t(i0), v.data.begin() + std::ptrdiff_t(i1), num.data() + i0);
    }
    if (!want_top) return;
    float top = kNone, bottom = -kNone;
    std::size_t at_top = 0, at_bottom = 0, scanned = plane;
    if (mask) {
      scanned = 0;
      for (std::size_t i = i0; i < i1; ++i)
        top = std::max(top, den[i] > 0.0f ? num[i] : kNone), bottom = std::min(bottom, den[i] > 0.0f ? num[i] : -kNone);
      for (std::size_t i = i0; i < i1; ++i)
        at_top += (den[i] > 0.0f) & (num[i] == top), at_bottom += (den[i] > 0.0f) & (num[i] == bottom),
            scanned += den[i] > 0.0f;
    } else {
      for (std::size_t i = i0; i < i1; ++i) top = std::max(top, num[i]), bottom = std::min(bottom, num[i]);
      for (std::size_t i = i0; i < i1; ++i) at_top += num[i] == top, at_bottom += num[i] == bottom;
    }
    plane_top[z] = top, plane_at_top[z] = at_top, plane_scanned[z] = scanned;
    plane_bottom[z] = bottom, plane_at_bottom[z] = at_bottom;
  });
  // Voxels that count: inside, scanned with their six neighbours; a flag
  // per voxel (1: usable; 0 on the volume's faces), formed a row at a time
  // (byte operations that vectorise). Its storage later holds the climbs'
  // upward steps.
  const std::size_t sy = d[0], sz = d[0] * d[1];
  HostVector<std::uint8_t> flags(n);
  std::uint8_t* const usable = flags.data();
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  std::size_t used = 0;
  {
    // Per plane: v~ normalised, the usable flags, then (interior planes) the
    // usable voxels' min, max and count (exact, in any order) while the
    // plane is in cache.
    std::vector<double> plo(d[2], lo), phi(d[2], hi);
    std::vector<std::size_t> pused(d[2], 0);
    parallel_ranges(d[2], threads, [&](std::size_t z0, std::size_t z1) {
      for (std::size_t z = z0; z < z1; ++z) {
        if (mask)
          for (std::size_t i = z * sz; i < (z + 1) * sz; ++i) num[i] = den[i] > 1e-6f ? num[i] / den[i] : 0.0f;
        std::uint8_t* const u = usable + z * sz;
        std::fill(u, u + sz, std::uint8_t{0});
        if (z == 0 || z + 1 == d[2]) continue;
        double plane_lo = plo[z], plane_hi = phi[z];
        std::size_t plane_used = 0;
        for (std::size_t y = 1; y + 1 < d[1]; ++y) {
          const std::size_t row = v.index(1, y, z), len = d[0] - 2;
          std::uint8_t* const ur = usable + row;
          if (mask) {
            // The row and its six neighbours' rows (all inside the array).
            const std::uint8_t* const m = mask->data() + row;
            const std::uint8_t *xm = m - 1, *xp = m + 1, *ym = m - sy, *yp = m + sy, *zm = m - sz, *zp = m + sz;
            for (std::size_t x = 0; x < len; ++x)
              ur[x] = std::uint8_t((m[x] != 0) & (xm[x] != 0) & (xp[x] != 0) & (ym[x] != 0) & (yp[x] != 0) &
                                   (zm[x] != 0) & (zp[x] != 0));
          } else {
            std::fill(ur, ur + len, std::uint8_t{1});
          }
          for (std::size_t x = 0; x < len; ++x) {
            if (!ur[x]) continue;
            const double f = num[row + x];
            plane_lo = std::min(plane_lo, f), plane_hi = std::max(plane_hi, f);
            ++plane_used;
          }
        }
        plo[z] = plane_lo, phi[z] = plane_hi, pused[z] = plane_used;
      }
    });
    for (std::size_t z = 0; z < d[2]; ++z) lo = std::min(lo, plo[z]), hi = std::max(hi, phi[z]), used += pused[z];
  }
  if (used == 0) throw InputError("--iso auto: no scanned voxels to take the isovalue from");
  if (!(hi > lo)) throw InputError("--iso auto: the volume is constant, it has no boundary to pick an isovalue at");

  const int bins = params.bins;
  const double width = (hi - lo) / bins;
  if (!(width > 0) || !std::isfinite(width))  // a range of a few denormals
    throw InputError("--iso auto: the volume is constant, it has no boundary to pick an isovalue at");
  // The histogram of |grad v~| over v~ serves the Edge rule alone (a
  // quarter of this pass at 256^3 for the others).
  const bool binned = params.rule == AutoIsoRule::Edge;
  std::vector<double> sum(binned ? bins : 0, 0.0);
  std::vector<std::size_t> count(binned ? bins : 0, 0);
  // |grad v~| per usable voxel (-1 elsewhere), for both rules.
  const double hx = v.spacing[0], hy = v.spacing[1], hz = v.spacing[2];
  // den is not needed any more: with a mask its storage holds gfield.
  HostVector<float> own_gfield(mask ? 0 : n);
  float* const gfield = mask ? den.data() : own_gfield.data();
  {
    // Per plane: the histogram's sums and counts, added up in z order.
    std::vector<double> psum(binned ? d[2] * std::size_t(bins) : 0, 0.0);
    std::vector<std::size_t> pcount(psum.size(), 0);
    // Each row's gradients and bins first, for all its voxels (a loop without
    // branches that vectorises), then the usable ones entered; gfield -1
    // where a voxel is not usable (the faces too).
    const std::size_t len = d[0] - 2;
    parallel_ranges(d[2], threads, [&](std::size_t z0, std::size_t z1) {
      std::vector<float> g(len);
      std::vector<int> bin(binned ? len : 0);
      for (std::size_t z = z0; z < z1; ++z) {
        float* const gplane = gfield + z * sz;
        if (z == 0 || z + 1 == d[2]) {
          std::fill(gplane, gplane + sz, -1.0f);
          continue;
        }
        std::fill(gplane, gplane + sy, -1.0f);
        std::fill(gplane + sz - sy, gplane + sz, -1.0f);
        for (std::size_t y = 1; y + 1 < d[1]; ++y) {
          const std::size_t row = v.index(1, y, z);
          row_gradients(num.data() + row, len, sy, sz, 2 * hx, 2 * hy, 2 * hz, lo, width, bins, g.data(),
                        binned ? bin.data() : nullptr);
          const std::uint8_t* const ur = usable + row;
          float* const gr = gfield + row;
          gr[-1] = -1.0f, gr[len] = -1.0f;
          for (std::size_t x = 0; x < len; ++x) gr[x] = ur[x] ? g[x] : -1.0f;
          if (!binned) continue;
          double* const ps = psum.data() + z * std::size_t(bins);
          std::size_t* const pc = pcount.data() + z * std::size_t(bins);
          for (std::size_t x = 0; x < len; ++x) {
            if (!ur[x]) continue;
            ps[bin[x]] += g[x];
            ++pc[bin[x]];
          }
        }
      }
    });
    for (std::size_t z = 0; binned && z < d[2]; ++z)
      for (int b = 0; b < bins; ++b) sum[b] += psum[z * std::size_t(bins) + std::size_t(b)], count[b] += pcount[z * std::size_t(bins) + std::size_t(b)];
  }
  // Mean per bin where there are enough voxels, smoothed [1 2 1] over the
  // valid bins; the peak's centre is the isovalue.
  const auto min_count = std::max<std::size_t>(1, std::size_t(std::ceil(params.min_bin_share * double(used))));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> mean(binned ? bins : 0, nan);
  for (int b = 0; binned && b < bins; ++b)
    if (count[b] >= min_count) mean[b] = sum[b] / double(count[b]);
  int best = -1;
  double best_value = -1;
  for (int b = 0; binned && b < bins; ++b) {
    if (std::isnan(mean[b])) continue;
    double s = 2 * mean[b], w = 2;
    if (b > 0 && !std::isnan(mean[b - 1])) s += mean[b - 1], w += 1;
    if (b + 1 < bins && !std::isnan(mean[b + 1])) s += mean[b + 1], w += 1;
    if (s / w > best_value) best_value = s / w, best = b;
  }
  if (binned && best < 0) throw InputError("--iso auto: too few scanned voxels to take the isovalue from");
  const double edge_iso = binned ? lo + (best + 0.5) * width : nan;

  // The echo ridge: from every strong-edge voxel (|grad v~| in the top
  // edge_share of the usable voxels) climb v~ through the 26 neighbours to
  // the crest of the boundary echo; the median crest value is the ridge.
  const std::size_t kth = std::min(used - 1, std::size_t(double(used) * (1.0 - params.edge_share)));
  const float edge_threshold = kth_nonnegative(gfield, n, kth, threads);
  std::vector<float> crests, locals;
  std::vector<std::size_t> local_at;
  float clip_level = std::numeric_limits<float>::infinity();
  double clipped_share = 0;
  std::size_t clipped_edges = 0;
  float floor_level = -std::numeric_limits<float>::infinity();
  double floor_share = 0;
  std::size_t floored_edges = 0;
  float floor_drop = 0;
  std::vector<std::size_t> cut_edges;
  // Climbs v~ from voxel (x, y, z) through the 26 neighbours, up (sign 1) or
  // down (sign -1), at most climb_n steps (climb_steps_for); returns the voxel
  // reached.
  // The 26 neighbours as index offsets, in the order (dz, dy, dx) ascending:
  // ties keep the first. A climb stays on usable voxels, which are interior,
  // so every neighbour is inside the volume, and the ones on its faces are
  // never usable (gfield -1): no bounds checks are needed.
  std::array<long, 26> around{};
  {
    int k = 0;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (dx || dy || dz) around[std::size_t(k++)] = dx + long(d[0]) * (dy + long(d[1]) * dz);
  }
  // The climbs read one array: v~ where usable, NaN elsewhere (a NaN is
  // greater than nothing, so an unusable neighbour is never chosen, up or
  // down; the same choices as testing gfield). v~ is not needed after them.
  over_voxels([&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i)
      if (gfield[i] < 0) num[i] = std::numeric_limits<float>::quiet_NaN();
  });
  // A voxel's step (which neighbour, or none: 26) depends on the voxel alone,
  // and the climbs from neighbouring edge voxels run along the same ridges
  // (at 256^3 about 9 M steps from 1.5 M climbs): each voxel's step, up and
  // down, is found once and kept (255: not yet). Two threads may find the
  // same step at once and store the same byte: relaxed atomic accesses.
  constexpr std::uint8_t kUnknown = 255, kStay = 26;
  HostVector<std::uint8_t> step_up = std::move(flags), step_down(params.rule == AutoIsoRule::Local ? n : 0);
  over_voxels([&](std::size_t i0, std::size_t i1) {
    std::fill(step_up.data() + i0, step_up.data() + i1, kUnknown);
    if (step_down.size()) std::fill(step_down.data() + i0, step_down.data() + i1, kUnknown);
  });
  // Both of a voxel's steps are found in one look at its neighbours (a
  // climb's first voxel, the edge, is always looked at both ways): up to the
  // first strictly greater maximum, down to the first strictly smaller
  // minimum, the choices of comparing sign * v~ (-c > -b is c < b for every
  // float but NaN, and false for NaN either way).
  //
  // A climb is a chain of dependent loads (the step, then the neighbour's
  // step): the climbs of a plane's edges advance together, one step each
  // per round, so that their loads overlap (one at a time, the climbs were
  // a fifth of the isovalue's time at 256^3). Each climb's steps are the
  // ones it takes alone: `at` holds the start voxels and gets the voxels
  // reached.
  const int climb_n = climb_steps_for(params, v.spacing);
  auto climb_all = [&](std::vector<std::size_t>& at, float sign, std::vector<std::uint32_t>& live) {
    std::uint8_t* steps = sign > 0 ? step_up.data() : step_down.data();
    live.resize(at.size());
    for (std::size_t j = 0; j < at.size(); ++j) live[j] = std::uint32_t(j);
    for (int step = 0; step < climb_n && !live.empty(); ++step) {
      std::size_t kept = 0;
      for (std::size_t t = 0; t < live.size(); ++t) {
        const std::uint32_t j = live[t];
        const std::size_t i = at[j];
        std::uint8_t k = __atomic_load_n(&steps[i], __ATOMIC_RELAXED);
        if (k == kUnknown) {
          std::uint8_t up = kStay, down = kStay;
          float high = num[i], low = num[i];
          for (std::uint8_t q = 0; q < 26; ++q) {
            const float c = num[std::size_t(long(i) + around[q])];
            if (c > high) up = q, high = c;
            if (c < low) down = q, low = c;
          }
          __atomic_store_n(&step_up[i], up, __ATOMIC_RELAXED);
          if (!step_down.empty()) __atomic_store_n(&step_down[i], down, __ATOMIC_RELAXED);
          k = sign > 0 ? up : down;
        }
        if (k == kStay) continue;
        at[j] = std::size_t(long(i) + around[k]);
        live[kept++] = j;
      }
      live.resize(kept);
    }
  };
  {
    // An edge whose trough lies at the data's floor: its place in `locals`,
    // its trough and crest, and how far v~ falls past the crest (a share of
    // the contrast).
    struct Floored {
      std::size_t local;
      float trough, crest, drop;
    };
    // Per range of planes its own lists, joined in z order: the serial order.
    struct Found {
      std::vector<float> crests, locals;
      std::vector<std::size_t> local_at, cut;
      std::size_t clipped = 0;
      std::vector<Floored> floored;
    };
    // The strong edges crowd into some planes: chunks of a few planes each,
    // handed to the threads as they become free.
    const int chunks = std::max(1, int(inner_planes / 4));
    // Clipped echoes (docs/real-data.md, "Clipped echoes"): where the data
    // sit at their ceiling (the largest scanned sample) on at least
    // clip_share of the scanned samples, an edge whose crest lies within
    // clip_margin of v~'s range of that ceiling was cut off by the display's
    // log compression; its true crest is higher, and the boundary lies
    // nearer the crest than local_fraction of the visible contrast.
    if (want_top) {
      const std::size_t scanned = std::accumulate(plane_scanned.begin(), plane_scanned.end(), std::size_t(0));
      // The largest (or, `lowest`, the smallest) of the planes' extremes and
      // the share of the scanned samples at it.
      const auto extreme = [&](const std::vector<float>& level, const std::vector<std::size_t>& count, bool lowest) {
        float e = lowest ? -kNone : kNone;
        std::size_t at = 0;
        for (std::size_t z = 0; z < d[2]; ++z) {
          if (lowest ? level[z] < e : level[z] > e) e = level[z], at = 0;
          if (level[z] == e) at += count[z];
        }
        return std::pair<float, double>{e, scanned ? double(at) / double(scanned) : 0.0};
      };
      const auto [top, top_share] = extreme(plane_top, plane_at_top, false);
      clipped_share = top_share;
      if (scanned && top_share >= params.clip_share) clip_level = float(double(top) - params.clip_margin * (hi - lo));
      // The same at the floor (the smallest scanned sample): fluid below the
      // display's floor.
      const auto [bottom, bottom_share] = extreme(plane_bottom, plane_at_bottom, true);
      floor_share = bottom_share;
      if (scanned && floor_share >= params.floor_share)
        floor_level = float(double(bottom) + params.clip_margin * (hi - lo));
    }
    // Crests cut off up the beam (AutoIsoParams::cut_crest_votes): an
    // unusable voxel (NaN) among the nine of the plane above the crest, one
    // step toward the probe, other than the volume's side faces (a crest
    // beside a side face is not cut up the beam). A crest is usable, so
    // interior: the nine exist.
    const bool cut_test = params.rule == AutoIsoRule::Local && !params.cut_crest_votes;
    const int beam = std::clamp(params.beam_axis, 0, 2);
    const int a1 = beam == 0 ? 1 : 0, a2 = beam == 2 ? 1 : 2;
    const long st[3] = {1, long(d[0]), long(d[0] * d[1])};
    // A voxel's (x, y, z) from its index.
    const auto voxel_of = [&](std::size_t i) {
      return std::array<std::size_t, 3>{i % d[0], (i / d[0]) % d[1], i / (d[0] * d[1])};
    };
    auto cut_up = [&](std::size_t i) {
      const std::array<std::size_t, 3> c = voxel_of(i);
      for (int u = -1; u <= 1; ++u) {
        const std::size_t p1 = std::size_t(long(c[a1]) + u);
        if (p1 == 0 || p1 + 1 == d[std::size_t(a1)]) continue;
        for (int w = -1; w <= 1; ++w) {
          const std::size_t p2 = std::size_t(long(c[a2]) + w);
          if (p2 == 0 || p2 + 1 == d[std::size_t(a2)]) continue;
          if (std::isnan(num[std::size_t(long(i) - st[beam] + u * st[a1] + w * st[a2])])) return true;
        }
      }
      return false;
    };
    std::vector<Found> found(std::size_t(range_count(inner_planes, chunks)));
    parallel_chunks(inner_planes, threads, chunks, [&](int k, std::size_t a, std::size_t b) {
      Found& f = found[std::size_t(k)];
      // A plane's edges (in memory order), their crests and troughs.
      std::vector<std::size_t> edges, crest_at, trough_at;
      std::vector<std::uint32_t> live;
      std::vector<std::uint8_t> cut;
      for (std::size_t z = a + 1; z < b + 1; ++z) {
        edges.clear();
        for (std::size_t y = 1; y + 1 < d[1]; ++y)
          for (std::size_t x = 1; x + 1 < d[0]; ++x) {
            const std::size_t i = v.index(x, y, z);
            if (gfield[i] >= edge_threshold && gfield[i] > 0) edges.push_back(i);
          }
        crest_at = edges;
        climb_all(crest_at, 1.0f, live);
        for (const std::size_t at : crest_at) f.crests.push_back(num[at]);
        if (params.rule != AutoIsoRule::Local) continue;
        // The troughs of the edges whose crest is not cut up the beam.
        cut.assign(edges.size(), 0);
        trough_at.clear();
        for (std::size_t e = 0; e < edges.size(); ++e) {
          cut[e] = cut_test && cut_up(crest_at[e]);
          if (!cut[e]) trough_at.push_back(edges[e]);
        }
        climb_all(trough_at, -1.0f, live);
        for (std::size_t e = 0, t = 0; e < edges.size(); ++e) {
          const std::size_t i = edges[e];
          if (cut[e]) {
            f.cut.push_back(i);
            continue;
          }
          const std::size_t at_crest = crest_at[e], at_trough = trough_at[t++];
          const float crest = num[at_crest];
          const float trough = num[at_trough];
          const bool clipped = crest >= clip_level;
          const bool at_floor = !clipped && trough <= floor_level;
          f.clipped += clipped;
          if (at_floor) {
            // How far v~ falls floor_reach_mm past the crest, on from the
            // trough, as a share of the edge's contrast (the volume's
            // median decides below).
            const std::array<std::size_t, 3> ct = voxel_of(at_crest), tt = voxel_of(at_trough);
            double dir[3], len = 0;
            for (int a = 0; a < 3; ++a)
              dir[a] = (double(ct[a]) - double(tt[a])) * v.spacing[std::size_t(a)], len += dir[a] * dir[a];
            len = std::sqrt(len);
            if (len > 0 && crest > trough) {
              std::size_t q[3];
              for (int a = 0; a < 3; ++a)
                q[a] = std::size_t(std::clamp(
                    std::lround(double(ct[a]) + params.floor_reach_mm * dir[a] / len / v.spacing[std::size_t(a)]),
                    0L, long(d[std::size_t(a)]) - 1));
              const float beyond = num[v.index(q[0], q[1], q[2])];
              if (std::isfinite(beyond))
                f.floored.push_back({f.locals.size(), trough, crest, float((crest - beyond) / (crest - trough))});
            }
          }
          const double fraction = clipped ? params.clip_fraction : params.local_fraction;
          f.locals.push_back(float(trough + fraction * (crest - trough)));
          f.local_at.push_back(i);
        }
      }
    });
    std::vector<Floored> floored;
    {
      std::size_t edges = 0, kept = 0, cut = 0;
      for (const Found& f : found) edges += f.crests.size(), kept += f.locals.size(), cut += f.cut.size();
      crests.reserve(edges), locals.reserve(kept), local_at.reserve(kept), cut_edges.reserve(cut);
    }
    for (const Found& f : found) {
      for (Floored e : f.floored) e.local += locals.size(), floored.push_back(e);
      cut_edges.insert(cut_edges.end(), f.cut.begin(), f.cut.end());
      crests.insert(crests.end(), f.crests.begin(), f.crests.end());
      locals.insert(locals.end(), f.locals.begin(), f.locals.end());
      local_at.insert(local_at.end(), f.local_at.begin(), f.local_at.end());
      clipped_edges += f.clipped;
    }
    if (!floored.empty()) {
      // The floored edges' crests are peaks, not plateaus, in their median
      // (AutoIsoParams::floor_drop): they take floor_fraction.
      std::vector<float> drops(floored.size());
      for (std::size_t j = 0; j < floored.size(); ++j) drops[j] = floored[j].drop;
      std::nth_element(drops.begin(), drops.begin() + long(drops.size() / 2), drops.end());
      floor_drop = drops[drops.size() / 2];
      if (params.floor_fraction != params.local_fraction && double(floor_drop) >= params.floor_drop)
        for (const Floored& e : floored) locals[e.local] = float(e.trough + params.floor_fraction * (e.crest - e.trough));
      floored_edges = floored.size();
    }
  }
  if (crests.empty())  // no usable voxel has a gradient (e.g. a one-voxel checkerboard)
    throw InputError("--iso auto: the volume has no boundary to pick an isovalue at (|grad v~| is 0 everywhere)");
  // The medians by the threads' selection (the order statistics nth_element gives).
  const double ridge_iso = median_of(crests, threads);
  double local_iso = ridge_iso;
  HostVector<float> field;  // resize leaves it untouched: the threads filling it touch it first
  if (!locals.empty()) {
    local_iso = median_of(locals, threads);
    if (params.want_field) {
      // Normalised convolution of the edges' isovalues, with the global
      // median as a prior weighing field_prior_share of the mean edge density.
      // The field is smooth (sigma of several voxels): it is formed on a grid
      // coarser by f per axis (cells summing f^3 voxels) where sigma allows,
      // and interpolated back trilinearly.
      std::array<std::size_t, 3> f{1, 1, 1}, dc{};
      std::array<double, 3> sigma_vox{};
      for (int a = 0; a < 3; ++a) {
        const double mm = a == params.beam_axis ? params.field_depth_sigma_mm : params.field_sigma_mm;
        sigma_vox[a] = std::max(1.0, mm / v.spacing[a]);
        f[a] = sigma_vox[a] >= 3.0 ? 2 : 1;
        dc[a] = (d[a] + f[a] - 1) / f[a];
      }
      const Dims3 dcoarse{dc[0], dc[1], dc[2]};
      const std::size_t nc = dc[0] * dc[1] * dc[2];
      // The edges' isovalues enter as t = (value - local_iso) / spread, in
      // [-1, 1]: sums and blurs of t cannot overflow however large the
      // samples (float data near 3.4e38), and the field, a weighted mean of
      // the t and of the prior's 0, maps back into [min, max] of the values.
      double lo_local = local_iso, hi_local = local_iso;
      for (float x : locals) lo_local = std::min(lo_local, double(x)), hi_local = std::max(hi_local, double(x));
      const double spread = std::max({hi_local - local_iso, local_iso - lo_local, 1e-30});
      std::vector<float> fn(nc, 0.0f), fd(nc, 0.0f);
      for (std::size_t k = 0; k < locals.size(); ++k) {
        const std::size_t i = local_at[k];
        const std::size_t x = i % d[0], y = (i / d[0]) % d[1], z = i / (d[0] * d[1]);
        const std::size_t c = x / f[0] + dc[0] * (y / f[1] + dc[1] * (z / f[2]));
        fn[c] += float((double(locals[k]) - local_iso) / spread), fd[c] += 1.0f;
      }
      // Unnormalised Gaussian: the density of edges per cell stays comparable to the prior.
      std::array<std::vector<float>, 3> wc;
      for (int axis = 0; axis < 3; ++axis)
        wc[std::size_t(axis)] = gaussian_weights(std::max(1.0, sigma_vox[axis] / double(f[axis])), 3.0);
      blur_3d(fn.data(), fd.data(), dcoarse, wc[0], wc[1], wc[2], threads, [](std::size_t) {});
      // fd is now the Gaussian-weighted edge count per cell (weights sum to
      // 1 per axis); the prior is field_prior_share of the volume's mean
      // count per cell (edges per scanned voxel, f^3 voxels a cell), so its
      // weight against the edges is the same at any voxel size.
      const double prior = params.field_prior_share * double(locals.size()) / double(used) * double(f[0] * f[1] * f[2]);
      std::vector<float> coarse(nc);
      for (std::size_t c = 0; c < nc; ++c) coarse[c] = float(double(fn[c]) / (double(fd[c]) + prior));
      // Levelling in place forms the field row by row and keeps none of it.
      if (!level) field.resize(n);
      // Trilinear from cell centres: voxel x sits at (x + 0.5) / f - 0.5 cells.
      auto weights = [&](int a, std::size_t x, std::size_t& c0, std::size_t& c1, float& t) {
        const double pos = std::clamp((double(x) + 0.5) / double(f[a]) - 0.5, 0.0, double(dc[a] - 1));
        c0 = std::size_t(pos), c1 = std::min(c0 + 1, dc[a] - 1), t = float(pos - double(c0));
      };
      // The x weights once, and a voxel row's four coarse rows once per row:
      // the same values and operations as per voxel.
      std::vector<std::uint32_t> wx0(d[0]), wx1(d[0]);
      std::vector<float> wtx(d[0]);
      for (std::size_t x = 0; x < d[0]; ++x) {
        std::size_t c0, c1;
        weights(0, x, c0, c1, wtx[x]);
        wx0[x] = std::uint32_t(c0), wx1[x] = std::uint32_t(c1);
      }
      parallel_ranges(d[2], threads, [&](std::size_t za, std::size_t zb) {
      std::vector<float> row(level ? d[0] : 0);
      for (std::size_t z = za; z < zb; ++z) {
        std::size_t z0, z1;
        float tz;
        weights(2, z, z0, z1, tz);
        for (std::size_t y = 0; y < d[1]; ++y) {
          std::size_t y0, y1;
          float ty;
          weights(1, y, y0, y1, ty);
          const float* r00 = coarse.data() + dc[0] * (y0 + dc[1] * z0);
          const float* r10 = coarse.data() + dc[0] * (y1 + dc[1] * z0);
          const float* r01 = coarse.data() + dc[0] * (y0 + dc[1] * z1);
          const float* r11 = coarse.data() + dc[0] * (y1 + dc[1] * z1);
          const std::size_t at = d[0] * (y + d[1] * z);
          field_row(level ? row.data() : field.data() + at, d[0], r00, r10, r01, r11, wx0.data(), wx1.data(),
                    wtx.data(), ty, tz, local_iso, spread, lo_local, hi_local);
          if (level) level_row(level->data.data() + at, row.data(), d[0], local_iso);
        }
      }
      });
    }
  }
  // The isovalue above the bulk (AutoIsoParams::bulk_spread), on the data
  // as levelled: every level then sits at the one isovalue.
  Bulk bulk;
  double guarded_iso = local_iso;
  if (params.rule == AutoIsoRule::Local && params.want_field && level && params.bulk_spread > 0 && !locals.empty()) {
    bulk = bulk_of(*level, mask, params.bulk_sigma_mm, threads);
    guarded_iso = bulk_raised_iso(local_iso, ridge_iso, bulk, params.bulk_spread, params.bulk_max_step,
                                  params.bulk_max_width);
  }
  const double iso = params.rule == AutoIsoRule::EchoRidge ? ridge_iso
                     : params.rule == AutoIsoRule::Local   ? guarded_iso
                                                           : edge_iso;
  if (report) {
    report->iso = iso;
    report->edge_iso = edge_iso;
    report->ridge_iso = ridge_iso;
    report->crests = crests.size();
    report->lo = lo;
    report->hi = hi;
    report->mean_gradient = std::move(mean);
    report->count = std::move(count);
    report->voxels = used;
    report->local_iso = local_iso;
    report->clipped_share = clipped_share;
    report->clip_level = clip_level;
    report->clipped_edges = clipped_edges;
    report->floor_share = floor_share;
    report->floor_level = floor_level;
    report->floored_edges = floored_edges;
    report->floor_drop = floor_drop;
    report->cut_edges = std::move(cut_edges);
    report->field = std::move(field);
    report->bulk_mode = bulk.mode, report->bulk_half_width = bulk.half_width;
    report->bulk_reach = bulk.mode + params.bulk_spread * bulk.half_width;
    report->bulk_raised = guarded_iso != local_iso;
  }
  return iso;
}

Bulk bulk_of(const Volume& v, const std::vector<std::uint8_t>* mask, double sigma_mm, int threads) {
  const Dims3& d = v.dims;
  const std::size_t n = v.voxels();
  if (mask && mask->size() != n) throw std::invalid_argument("bulk_of: mask size differs from the volume");
  if (!(sigma_mm > 0)) throw std::invalid_argument("bulk_of: the lowpass must be positive");
  threads = host_threads(threads);
  Bulk b;
  const auto in = [&](std::size_t i) { return !mask || (*mask)[i] != 0; };
  // The lowpass, each plane copied in just before its blur (in cache, and
  // first touched by the thread that blurs it); the blur is the same for any
  // split of the planes.
  const std::size_t plane = d[0] * d[1];
  HostVector<float> low(n);
  blur_3d(low.data(), nullptr, d, gaussian_weights(sigma_mm / v.spacing[0], 3.0),
          gaussian_weights(sigma_mm / v.spacing[1], 3.0), gaussian_weights(sigma_mm / v.spacing[2], 3.0), threads,
          [&](std::size_t z) {
            std::copy(v.data.begin() + std::ptrdiff_t(z * plane), v.data.begin() + std::ptrdiff_t((z + 1) * plane),
                      low.data() + z * plane);
          });
  // Histograms per range of voxels, added up (counts: the same for any split).
  const auto histogram = [&](double lo, double hi, int bins) {
    const int parts = range_count(n, threads);
    std::vector<std::vector<std::size_t>> part(std::size_t(parts), std::vector<std::size_t>(std::size_t(bins), 0));
    const double scale = double(bins) / (hi - lo);
    // Four counts per bin, a voxel's in the one of its index mod 4 (the
    // lowpass is smooth: neighbours mostly share a bin, and one count made
    // a chain of stores and reloads through memory), added up after.
    constexpr std::size_t kWays = 4;
    const std::size_t nb = std::size_t(bins);
    for (auto& p : part) p.assign(kWays * nb, 0);
    parallel_ranges_indexed(n, parts, [&](int k, std::size_t i0, std::size_t i1) {
      std::size_t* const h = part[std::size_t(k)].data();
      // The bin clamped in double and then truncated: for every finite value
      // the bin of clamping floor's (a call per voxel without SSE4.1's
      // rounding); no branch on the mask.
      const double top = double(bins - 1);
      const auto bin = [&](std::size_t i) { return std::size_t(std::min(top, std::max(0.0, (double(low[i]) - lo) * scale))); };
      std::size_t i = i0;
      for (; i + kWays <= i1; i += kWays)
        for (std::size_t w = 0; w < kWays; ++w) h[w * nb + bin(i + w)] += in(i + w);
      for (; i < i1; ++i) h[bin(i)] += in(i);
    });
    std::vector<std::size_t> h(nb, 0);
    for (const auto& p : part)
      for (std::size_t w = 0; w < kWays; ++w)
        for (std::size_t k = 0; k < nb; ++k) h[k] += p[w * nb + k];
    return h;
  };
  // The extremes of the lowpass over the scanned voxels and their count, per
  // plane, then joined (the same for any split).
  std::vector<float> plane_min(d[2], INFINITY), plane_max(d[2], -INFINITY);
  std::vector<std::size_t> plane_count(d[2], 0);
  parallel_ranges(d[2], threads, [&](std::size_t z0, std::size_t z1) {
    for (std::size_t z = z0; z < z1; ++z) {
      float lo = INFINITY, hi = -INFINITY;
      std::size_t c = 0;
      for (std::size_t i = z * plane; i < (z + 1) * plane; ++i)
        if (in(i)) lo = std::min(lo, low[i]), hi = std::max(hi, low[i]), ++c;
      plane_min[z] = lo, plane_max[z] = hi, plane_count[z] = c;
    }
  });
  double mn = INFINITY, mx = -INFINITY;
  std::size_t count = 0;
  for (std::size_t z = 0; z < d[2]; ++z)
    if (plane_count[z])
      mn = std::min(mn, double(plane_min[z])), mx = std::max(mx, double(plane_max[z])), count += plane_count[z];
  if (count < 1000 || !(mx > mn) || !std::isfinite(mx - mn)) return b;
  // The 0.5th and 99.5th percentiles from a fine histogram (to 1/4096 of the range).
  constexpr int kFine = 4096;
  const std::vector<std::size_t> fine = histogram(mn, mx, kFine);
  const auto quantile_edge = [&](double q, bool upper) {
    const std::size_t target = std::size_t(q * double(count));
    std::size_t sum = 0;
    for (int k = 0; k < kFine; ++k) {
      sum += fine[std::size_t(k)];
      if (sum > target) return mn + (mx - mn) * double(k + (upper ? 1 : 0)) / kFine;
    }
    return mx;
  };
  const double lo = quantile_edge(0.005, false), hi = quantile_edge(0.995, true);
  if (!(hi > lo)) return b;
  constexpr int kBins = 128;
  const std::vector<std::size_t> h = histogram(lo, hi, kBins);
  std::vector<double> hs(kBins, 0.0);
  for (int k = 0; k < kBins; ++k) {
    double sum = 0, w = 0;
    for (int j = std::max(0, k - 2); j <= std::min(kBins - 1, k + 2); ++j) sum += double(h[std::size_t(j)]), w += 1;
    hs[std::size_t(k)] = sum / w;
  }
  const int mode = int(std::max_element(hs.begin(), hs.end()) - hs.begin());
  int r = mode;
  while (r + 1 < kBins && hs[std::size_t(r)] > 0.5 * hs[std::size_t(mode)]) ++r;
  const double width = (hi - lo) / kBins;
  b.measured = true;
  b.mode = lo + (mode + 0.5) * width;
  b.half_width = (r - mode) * width;
  return b;
}

double bulk_raised_iso(double iso, double crest, const Bulk& bulk, double spread, double max_step, double max_width) {
  if (!bulk.measured || !(spread > 0)) return iso;
  const double reach = bulk.mode + spread * bulk.half_width;
  if (iso > bulk.mode && iso < reach && crest > reach && reach - iso <= max_step * (crest - iso) &&
      bulk.half_width <= max_width * (crest - bulk.mode))
    return reach;
  return iso;
}

int climb_steps_for(const AutoIsoParams& p, const Vec3d& spacing) {
  const double h = std::min({spacing[0], spacing[1], spacing[2]});
  int steps = std::max(0, p.climb_steps);
  // The bound keeps a spacing in metres read as mm from climbing for ever
  // (auto_iso refuses such a lowpass before it climbs).
  if (p.climb_mm > 0 && h > 0) steps = std::max(steps, int(std::min(1000.0, std::ceil(p.climb_mm / h - 1e-9))));
  return steps;
}

void scale_length_scales(AutoIsoParams& p, double f) {
  p.climb_mm *= f;
  p.sigma_mm *= f, p.field_sigma_mm *= f, p.field_depth_sigma_mm *= f, p.bulk_sigma_mm *= f;
}

Volume level_isovalue(const Volume& v, const float* field, std::size_t field_size, double iso) {
  if (field_size != v.voxels()) throw std::invalid_argument("level_isovalue: field size differs from the volume");
  Volume out = v;
  parallel_ranges(out.data.size(), host_threads(0), [&](std::size_t i0, std::size_t i1) {
    level_row(out.data.data() + i0, field + i0, i1 - i0, iso);
  });
  return out;
}

namespace {
// The Local rule with its field: what levelling needs.
AutoIsoParams with_local_field(AutoIsoParams params) {
  params.rule = AutoIsoRule::Local;
  params.want_field = true;
  return params;
}
}  // namespace

LevelledVolume auto_iso_levelled(const Volume& v, const std::vector<std::uint8_t>* mask, const Volume* target,
                                 const AutoIsoParams& params, AutoIsoReport* report) {
  LevelledVolume out;
  out.data = target ? *target : v;
  out.iso = auto_iso(v, mask, with_local_field(params), report, &out.data);
  return out;
}

double auto_iso_level_in_place(Volume& v, const std::vector<std::uint8_t>* mask, const AutoIsoParams& params,
                               AutoIsoReport* report) {
  return auto_iso(v, mask, with_local_field(params), report, &v);
}

std::string iso_outside_data(const Volume& in, double iso) {
  float lo = INFINITY, hi = -INFINITY;
  for (float x : in.data) lo = std::min(lo, x), hi = std::max(hi, x);
  if (!(lo <= hi) || (iso >= lo && iso <= hi)) return "";
  std::ostringstream w;
  w << "softshell: warning: --iso " << iso << " is outside the data's value range [" << lo << ", " << hi << "] ("
    << scalar_type_name(in.source_type) << " samples); no boundary lies at that value\n";
  return w.str();
}

}  // namespace softshell
