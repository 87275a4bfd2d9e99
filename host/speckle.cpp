#include "speckle.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "blur.hpp"
#include "bone_cue.hpp"
#include "filter.hpp"
#include "parallel.hpp"

namespace softshell {

namespace {

// Per z-plane sums: sum r^2 over the scanned voxels, and along each of x, y
// and z the sum of r(p) r(p + e) and the count over scanned pairs (z pairs
// join planes z, z+1); the beam axis's are summed too and left unused.
struct PlaneSums {
  double r2 = 0;
  double prod[3] = {0, 0, 0};
  std::size_t n = 0, pairs[3] = {0, 0, 0};
};

}  // namespace

SpeckleReport speckle_size(const Volume& v, const std::vector<std::uint8_t>* scanned, int beam_axis, int threads) {
  const Dims3& d = v.dims;
  const std::size_t n = d[0] * d[1] * d[2];
  if (scanned && scanned->size() != n) throw std::invalid_argument("speckle_size: mask size differs from the volume");
  if (beam_axis < 0 || beam_axis > 2) throw std::invalid_argument("speckle_size: beam axis must be 0, 1 or 2");
  SpeckleReport rep;
  if (n == 0) return rep;
  // The fine detail: v minus its Gaussian lowpass (clamped at the border).
  std::vector<float> low(v.data.begin(), v.data.end());
  const std::vector<float> wx = gaussian_weights(kSpeckleDetailMm / v.spacing[0], 3.0),
                           wy = gaussian_weights(kSpeckleDetailMm / v.spacing[1], 3.0),
                           wz = gaussian_weights(kSpeckleDetailMm / v.spacing[2], 3.0);
  blur_3d(low.data(), nullptr, d, wx, wy, wz, threads, [](std::size_t) {});
  const std::size_t nx = d[0], ny = d[1], nz = d[2], plane = nx * ny;
  const auto in = [&](std::size_t i) { return !scanned || (*scanned)[i] != 0; };
  const auto r = [&](std::size_t i) { return double(v.data[i]) - double(low[i]); };
  std::vector<PlaneSums> sums(nz);
  parallel_ranges(nz, host_threads(threads), [&](std::size_t z0, std::size_t z1) {
    for (std::size_t z = z0; z < z1; ++z) {
      PlaneSums& s = sums[z];
      for (std::size_t y = 0; y < ny; ++y)
        for (std::size_t x = 0; x < nx; ++x) {
          const std::size_t i = z * plane + y * nx + x;
          if (!in(i)) continue;
          const double ri = r(i);
          s.r2 += ri * ri, ++s.n;
          if (x + 1 < nx && in(i + 1)) s.prod[0] += ri * r(i + 1), ++s.pairs[0];
          if (y + 1 < ny && in(i + nx)) s.prod[1] += ri * r(i + nx), ++s.pairs[1];
          if (z + 1 < nz && in(i + plane)) s.prod[2] += ri * r(i + plane), ++s.pairs[2];
        }
    }
  });
  PlaneSums t;
  for (const PlaneSums& s : sums) {
    t.r2 += s.r2, t.n += s.n;
    for (int a = 0; a < 3; ++a) t.prod[a] += s.prod[a], t.pairs[a] += s.pairs[a];
  }
  if (t.n == 0 || !(t.r2 > 0)) return rep;
  const double var = t.r2 / double(t.n);
  double best = INFINITY;
  for (int a = 0; a < 3; ++a) {
    if (a == beam_axis || t.pairs[a] < kSpeckleMinPairs) continue;
    const double c = t.prod[a] / double(t.pairs[a]) / var;
    rep.lag1[a] = c;
    // A Gaussian speckle of sigma s: neighbours h apart correlate exp(-h^2 / (4 s^2)).
    const double cc = std::clamp(c, 1e-3, 0.999);
    const double s = v.spacing[std::size_t(a)] / std::sqrt(-4.0 * std::log(cc));
    if (s < best) best = s, rep.axis = a;
  }
  if (!std::isfinite(best)) return rep;
  rep.measured = true;
  rep.sigma_mm = best;
  return rep;
}

double grad_sigma_from_speckle(const SpeckleReport& r, double scale) {
  const double s = r.measured ? std::clamp(kGradSigmaPerSpeckle * r.sigma_mm, kGradSigmaMinMm, kGradSigmaMaxMm)
                              : kGradSigmaMaxMm;
  return s * scale;
}

GradSigmaChoice auto_grad_sigma(const Volume& v, const std::vector<std::uint8_t>* scanned, int beam_axis, double scale,
                                int threads) {
  GradSigmaChoice c;
  BoneCueParams bp;
  bp.axis = beam_axis;
  bp.threads = threads;
  BoneCueReport br;
  bone_cue_auto(v, scanned, bp, &br);
  c.falling = br.falling_share, c.rising = br.rising_share;
  c.echoes = br.edge_voxels > 0 && c.falling > 0 && c.falling >= kGradSigmaEchoRatio * c.rising;
  if (c.echoes) c.speckle = speckle_size(v, scanned, beam_axis, threads);
  c.sigma_mm = c.echoes ? grad_sigma_from_speckle(c.speckle, scale) : kGradSigmaMaxMm * scale;
  return c;
}

}  // namespace softshell
