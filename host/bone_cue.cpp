// The bone cue (host/bone_cue.hpp; docs/numerics.md, "The bone cue").
#include "bone_cue.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "parallel.hpp"

namespace softshell {

namespace {

// Calls f(line_start) for every line of the grid along `axis` (stride
// `stride`), split over threads by planes.
template <class F>
void for_lines(const Dims3& d, int axis, int threads, F&& f) {
  const std::size_t nx = d[0], ny = d[1], nz = d[2];
  if (axis == 0) {
    parallel_ranges(nz, host_threads(threads), [&](std::size_t b, std::size_t e) {
      for (std::size_t z = b; z < e; ++z)
        for (std::size_t y = 0; y < ny; ++y) f(nx * (y + ny * z));
    });
  } else if (axis == 1) {
    parallel_ranges(nz, host_threads(threads), [&](std::size_t b, std::size_t e) {
      for (std::size_t z = b; z < e; ++z)
        for (std::size_t x = 0; x < nx; ++x) f(x + nx * ny * z);
    });
  } else {
    parallel_ranges(ny, host_threads(threads), [&](std::size_t b, std::size_t e) {
      for (std::size_t y = b; y < e; ++y)
        for (std::size_t x = 0; x < nx; ++x) f(x + nx * y);
    });
  }
}

std::size_t stride_of(const Dims3& d, int axis) { return axis == 0 ? 1 : axis == 1 ? d[0] : d[0] * d[1]; }

double quantile(std::vector<float> s, double q) {
  if (s.empty()) return 0;
  const std::size_t k = std::min(s.size() - 1, std::size_t(q * double(s.size() - 1) + 0.5));
  std::nth_element(s.begin(), s.begin() + std::ptrdiff_t(k), s.end());
  return s[k];
}

}  // namespace

namespace bone_cue_detail {

std::vector<float> gaussian(const Volume& v, double sigma_mm, int threads) {
  std::vector<float> cur = v.data, next(v.data.size());
  if (!(sigma_mm > 0)) return cur;
  for (int a = 0; a < 3; ++a) {
    const long n = long(v.dims[std::size_t(a)]);
    const double s = sigma_mm / v.spacing[std::size_t(a)];
    const long r = std::min<long>(long(std::ceil(3 * s)), std::max<long>(n - 1, 0));
    if (r <= 0 || n < 2) continue;
    std::vector<double> w(std::size_t(2 * r + 1));
    double sum = 0;
    for (long k = -r; k <= r; ++k) sum += w[std::size_t(k + r)] = std::exp(-0.5 * double(k * k) / (s * s));
    for (double& x : w) x /= sum;
    const std::size_t st = stride_of(v.dims, a);
    std::vector<float> wf(w.begin(), w.end());
    for_lines(v.dims, a, threads, [&](std::size_t start) {
      // The line, padded by its end samples (the clamped border), in a
      // contiguous buffer: the taps then run without a branch.
      std::vector<float> line(std::size_t(n + 2 * r));
      for (long i = 0; i < n + 2 * r; ++i)
        line[std::size_t(i)] = cur[start + std::size_t(std::clamp(i - r, 0L, n - 1)) * st];
      for (long i = 0; i < n; ++i) {
        const float* x = line.data() + i;
        float acc = 0;
        for (long k = 0; k <= 2 * r; ++k) acc += wf[std::size_t(k)] * x[k];
        next[start + std::size_t(i) * st] = acc;
      }
    });
    std::swap(cur, next);
  }
  return cur;
}

}  // namespace bone_cue_detail

namespace {
std::vector<float> score_of(const Volume& v, const std::vector<std::uint8_t>* scanned, const BoneCueParams& p,
                            BoneCueReport* report, const std::vector<float>& vs);
bool auto_of(const Volume& v, const std::vector<std::uint8_t>* scanned, const BoneCueParams& p,
             BoneCueReport* report, const std::vector<float>& vs);
}  // namespace

std::vector<float> bone_cue_score(const Volume& v, const std::vector<std::uint8_t>* scanned,
                                  const BoneCueParams& p, BoneCueReport* report) {
  return score_of(v, scanned, p, report, bone_cue_detail::gaussian(v, p.sigma_mm, p.threads));
}

bool bone_cue_auto(const Volume& v, const std::vector<std::uint8_t>* scanned, const BoneCueParams& p,
                   BoneCueReport* report) {
  if (scanned && scanned->size() != v.voxels()) throw std::invalid_argument("bone_cue_auto: mask size differs from the volume");
  if (p.axis < 0 || p.axis > 2) throw std::invalid_argument("bone_cue_auto: beam axis must be 0, 1 or 2");
  return auto_of(v, scanned, p, report, bone_cue_detail::gaussian(v, p.sigma_mm, p.threads));
}

namespace {
std::vector<float> score_of(const Volume& v, const std::vector<std::uint8_t>* scanned, const BoneCueParams& p,
                            BoneCueReport* report, const std::vector<float>& vs) {
  const std::size_t n = v.voxels();
  if (scanned && scanned->size() != n) throw std::invalid_argument("bone_cue_score: mask size differs from the volume");
  if (p.axis < 0 || p.axis > 2) throw std::invalid_argument("bone_cue_score: beam axis must be 0, 1 or 2");
  if (!(p.below_to_mm > p.below_from_mm) || !(p.below_from_mm >= 0))
    throw std::invalid_argument("bone_cue_score: the window below must satisfy 0 <= from < to");
  auto in = [&](std::size_t i) { return !scanned || (*scanned)[i] != 0; };
  // The spread: q90 - q10 of v~ over the scanned voxels (a regular subsample
  // of at most ~1 M voxels).
  std::vector<float> sample;
  const std::size_t step = std::max<std::size_t>(1, n / 1000000);
  for (std::size_t i = 0; i < n; i += step)
    if (in(i)) sample.push_back(vs[i]);
  const double spread = quantile(sample, 0.9) - quantile(sample, 0.1);
  sample = {};
  if (report) report->spread = spread;
  std::vector<float> score(n, 0.0f);
  if (!(spread > 0)) return score;
  const int a = p.axis;
  const long len = long(v.dims[std::size_t(a)]);
  const double h = v.spacing[std::size_t(a)];
  // The window below the voxel along the beam, in voxels.
  const long k0 = std::max(1L, long(std::lround(p.below_from_mm / h)));
  const long k2 = std::max(k0, long(std::lround(p.below_to_mm / h)));
  const std::size_t st = stride_of(v.dims, a);
  const float inv = float(1.0 / spread);
  // The surroundings at the same depth: the mean of v~ over the scanned
  // voxels of a square of half-width lateral_mm across the beam (a
  // summed-area table per plane). A bright layer under the probe, flat or
  // curved, is as bright as its surroundings; a bone echo is not.
  std::vector<float> around(p.depth_term ? n : 0);
  if (p.depth_term) {
    const int u = a == 0 ? 1 : 0, w = a == 2 ? 1 : 2;  // the two lateral axes
    const long nu = long(v.dims[std::size_t(u)]), nw = long(v.dims[std::size_t(w)]);
    const std::size_t su = stride_of(v.dims, u), sw = stride_of(v.dims, w);
    const long ru = std::max(1L, long(std::lround(p.lateral_mm / v.spacing[std::size_t(u)])));
    const long rw = std::max(1L, long(std::lround(p.lateral_mm / v.spacing[std::size_t(w)])));
    parallel_ranges(std::size_t(len), host_threads(p.threads), [&](std::size_t b0, std::size_t e0) {
      std::vector<double> sat(std::size_t((nu + 1) * (nw + 1))), cat(sat.size());
      for (std::size_t k = b0; k < e0; ++k) {
        const std::size_t base = k * st;
        for (long j = 0; j < nw; ++j)
          for (long i = 0; i < nu; ++i) {
            const std::size_t q = base + std::size_t(i) * su + std::size_t(j) * sw;
            const bool s = in(q);
            const std::size_t c = std::size_t((j + 1) * (nu + 1) + i + 1);
            sat[c] = (s ? vs[q] : 0.0) + sat[c - 1] + sat[c - std::size_t(nu + 1)] - sat[c - std::size_t(nu + 2)];
            cat[c] = (s ? 1.0 : 0.0) + cat[c - 1] + cat[c - std::size_t(nu + 1)] - cat[c - std::size_t(nu + 2)];
          }
        for (long j = 0; j < nw; ++j)
          for (long i = 0; i < nu; ++i) {
            const long i0 = std::max(0L, i - ru), i1 = std::min(nu, i + ru + 1);
            const long j0 = std::max(0L, j - rw), j1 = std::min(nw, j + rw + 1);
            auto box = [&](const std::vector<double>& t) {
              return t[std::size_t(j1 * (nu + 1) + i1)] - t[std::size_t(j0 * (nu + 1) + i1)] -
                     t[std::size_t(j1 * (nu + 1) + i0)] + t[std::size_t(j0 * (nu + 1) + i0)];
            };
            const double c = box(cat);
            around[base + std::size_t(i) * su + std::size_t(j) * sw] = c > 0 ? float(box(sat) / c) : 0.0f;
          }
      }
    });
  }
  const std::size_t lines = n / std::size_t(len);
  std::vector<std::size_t> line_start(lines);
  {
    std::size_t k = 0;
    const std::size_t nx = v.dims[0], ny = v.dims[1], nz = v.dims[2];
    if (a == 0) {
      for (std::size_t z = 0; z < nz; ++z)
        for (std::size_t y = 0; y < ny; ++y) line_start[k++] = nx * (y + ny * z);
    } else if (a == 1) {
      for (std::size_t z = 0; z < nz; ++z)
        for (std::size_t x = 0; x < nx; ++x) line_start[k++] = x + nx * ny * z;
    } else {
      for (std::size_t y = 0; y < ny; ++y)
        for (std::size_t x = 0; x < nx; ++x) line_start[k++] = x + nx * y;
    }
  }
  parallel_ranges(lines, host_threads(p.threads), [&](std::size_t b0, std::size_t e0) {
   for (std::size_t l = b0; l < e0; ++l) {
    const std::size_t start = line_start[l];
    // Prefix sums of v~ and of the scanned count along the line.
    std::vector<double> sum(std::size_t(len) + 1, 0.0);
    std::vector<long> cnt(std::size_t(len) + 1, 0);
    for (long i = 0; i < len; ++i) {
      const std::size_t q = start + std::size_t(i) * st;
      const bool s = in(q);
      sum[std::size_t(i) + 1] = sum[std::size_t(i)] + (s ? vs[q] : 0.0);
      cnt[std::size_t(i) + 1] = cnt[std::size_t(i)] + (s ? 1 : 0);
    }
    for (long i = 0; i < len; ++i) {
      const std::size_t q = start + std::size_t(i) * st;
      if (!in(q)) continue;
      const long lo = std::min(len, i + k0), hi = std::min(len, i + k2 + 1);
      const long c = cnt[std::size_t(hi)] - cnt[std::size_t(lo)];
      if (2 * c < k2 - k0 + 1) continue;  // too little of the window is data
      const double below = (sum[std::size_t(hi)] - sum[std::size_t(lo)]) / double(c);
      // A bright voxel over a shadow: brighter than the mean of what lies
      // below it along the beam, and (depth_term) brighter than its
      // surroundings at the same depth (a bright layer under the probe is
      // not).
      double sc = vs[q] - below;
      if (p.depth_term) sc = std::min(sc, double(vs[q]) - around[q]);
      score[q] = float(sc) * inv;
    }
   }
  });
  return score;
}
}  // namespace

float bone_cue_weight_of(float s, const BoneCueParams& p) {
  const double t = std::clamp((double(s) - p.score_lo) / (p.score_hi - p.score_lo), 0.0, 1.0);
  return float(p.floor + (1.0 - p.floor) * t * t * (3.0 - 2.0 * t));
}

std::vector<float> bone_cue_weight(const Volume& v, const std::vector<float>& score, const BoneCueParams& p) {
  if (score.size() != v.voxels()) throw std::invalid_argument("bone_cue_weight: score size differs from the volume");
  std::vector<float> w0(score.size()), w(score.size());
  parallel_ranges(score.size(), host_threads(p.threads), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) w0[i] = bone_cue_weight_of(score[i], p);
  });
  // The shell lies on the echo's front flank, above its crest: each voxel
  // takes the largest weight within reach_mm below it along the beam.
  const int a = p.axis;
  const long len = long(v.dims[std::size_t(a)]);
  const long r = std::max(0L, long(std::lround(p.reach_mm / v.spacing[std::size_t(a)])));
  const std::size_t st = stride_of(v.dims, a);
  for_lines(v.dims, a, p.threads, [&](std::size_t start) {
    for (long i = 0; i < len; ++i) {
      float m = 0;
      for (long k = i, e = std::min(len - 1, i + r); k <= e; ++k) m = std::max(m, w0[start + std::size_t(k) * st]);
      w[start + std::size_t(i) * st] = m;
    }
  });
  return w;
}

namespace {
bool auto_of(const Volume& v, const std::vector<std::uint8_t>* scanned, const BoneCueParams& p,
             BoneCueReport* report, const std::vector<float>& vs) {
  const std::size_t nx = v.dims[0], ny = v.dims[1], nz = v.dims[2];
  // |grad v~|^2 per mm and its component along the beam at the interior
  // scanned voxels whose six neighbours are scanned, one in eight (odd
  // indices: statistics need no more), per range of planes in order.
  const double ih[3] = {0.5 / v.spacing[0], 0.5 / v.spacing[1], 0.5 / v.spacing[2]};
  const std::size_t sy = nx, sz = nx * ny;
  auto in = [&](std::size_t i) { return !scanned || (*scanned)[i] != 0; };
  const int parts = nz >= 3 ? range_count(nz - 2, host_threads(p.threads)) : 1;
  std::vector<std::vector<float>> g2s(static_cast<std::size_t>(parts)), gbs(static_cast<std::size_t>(parts));
  if (nx >= 3 && ny >= 3 && nz >= 3)
    parallel_ranges_indexed(nz - 2, host_threads(p.threads), [&](int k, std::size_t b, std::size_t e) {
      std::vector<float>& g2 = g2s[std::size_t(k)];
      std::vector<float>& gb = gbs[std::size_t(k)];
      for (std::size_t z = b + 1; z < e + 1; ++z) {
        if ((z & 1) == 0) continue;
        for (std::size_t y = 1; y + 1 < ny; y += 2)
          for (std::size_t x = 1; x + 1 < nx; x += 2) {
            const std::size_t i = x + sy * y + sz * z;
            if (!in(i) || !in(i - 1) || !in(i + 1) || !in(i - sy) || !in(i + sy) || !in(i - sz) || !in(i + sz))
              continue;
            const double g[3] = {(vs[i + 1] - vs[i - 1]) * ih[0], (vs[i + sy] - vs[i - sy]) * ih[1],
                                 (vs[i + sz] - vs[i - sz]) * ih[2]};
            g2.push_back(float(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]));
            gb.push_back(float(g[p.axis]));
          }
      }
    });
  std::vector<float> g2, gb;
  for (int k = 0; k < parts; ++k) {
    g2.insert(g2.end(), g2s[std::size_t(k)].begin(), g2s[std::size_t(k)].end());
    gb.insert(gb.end(), gbs[std::size_t(k)].begin(), gbs[std::size_t(k)].end());
    g2s[std::size_t(k)] = {}, gbs[std::size_t(k)] = {};
  }
  std::size_t edges = 0, falling = 0, rising = 0;
  if (!g2.empty()) {
    const double cut = quantile(g2, 1.0 - p.auto_edge_share);
    const double c2 = p.auto_beam_cos * p.auto_beam_cos;
    for (std::size_t i = 0; i < g2.size(); ++i)
      if (g2[i] >= cut && cut > 0) {
        ++edges;
        // along the beam within acos(auto_beam_cos) of it: brightness
        // falling with depth (a bright echo over a shadow) or rising (a dark
        // gap -- fluid, a shadow's end -- over tissue)
        if (double(gb[i]) * gb[i] >= c2 * g2[i]) (gb[i] < 0 ? falling : rising) += 1;
      }
  }
  const double fall = edges ? double(falling) / double(edges) : 0.0, rise = edges ? double(rising) / double(edges) : 0.0;
  const bool on = edges > 0 && fall > 0 && fall >= p.auto_ratio * rise;
  if (report) {
    report->falling_share = fall;
    report->rising_share = rise;
    report->edge_voxels = edges;
    report->on = on;
  }
  return on;
}

}  // namespace

bool parse_bone_cue_mode(const std::string& name, BoneCueMode& mode) {
  if (name == "off") mode = BoneCueMode::Off;
  else if (name == "on") mode = BoneCueMode::On;
  else if (name == "auto") mode = BoneCueMode::Auto;
  else return false;
  return true;
}

std::shared_ptr<const std::vector<float>> bone_cue_weights(const Volume& v, const std::vector<std::uint8_t>* scanned,
                                                           BoneCueMode mode, const BoneCueParams& p,
                                                           BoneCueReport* report) {
  BoneCueReport r;
  std::shared_ptr<const std::vector<float>> out;
  if (mode != BoneCueMode::Off) {
    if (scanned && scanned->size() != v.voxels())
      throw std::invalid_argument("bone_cue_weights: mask size differs from the volume");
    if (p.axis < 0 || p.axis > 2) throw std::invalid_argument("bone_cue_weights: beam axis must be 0, 1 or 2");
    const std::vector<float> vs = bone_cue_detail::gaussian(v, p.sigma_mm, p.threads);  // one lowpass for both
    const bool on = auto_of(v, scanned, p, &r, vs);
    r.on = mode == BoneCueMode::On || on;
    if (r.on) {
      const std::vector<float> score = score_of(v, scanned, p, &r, vs);
      auto w = std::make_shared<std::vector<float>>(bone_cue_weight(v, score, p));
      std::size_t scanned_n = 0, weighted = 0;
      for (std::size_t i = 0; i < w->size(); ++i)
        if (!scanned || (*scanned)[i]) ++scanned_n, weighted += (*w)[i] >= 0.5f;
      r.weighted_share = scanned_n ? double(weighted) / double(scanned_n) : 0.0;
      out = std::move(w);
    }
  }
  if (report) *report = r;
  return out;
}

}  // namespace softshell
