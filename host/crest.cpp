// Shells on a bright echo's crest: see crest.hpp.
#include "crest.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "parallel.hpp"

namespace softshell {

CrestReport crest_shells(std::vector<float>& vs, std::vector<float>& grad2, const std::vector<std::uint8_t>& fixed,
                         const Dims3& dims, const Vec3d& spacing, double v_iso, double shift_mm, double g_ref,
                         const CrestParams& p, int threads, CrestChanges* changed) {
  const std::size_t n = dims[0] * dims[1] * dims[2];
  if (vs.size() != n || grad2.size() != n || fixed.size() != n)
    throw std::invalid_argument("crest_shells: the volumes' sizes differ from the grid");
  if (p.axis < 0 || p.axis > 2) throw std::invalid_argument("crest_shells: the beam axis must be 0, 1 or 2");
  CrestReport rep;
  if (changed) *changed = {};  // also when nothing is replaced below
  if (!(p.ridge > 0) || n == 0) return rep;
  // The quantile of the scanned voxels' lowpassed v.
  std::vector<float> free_vs;
  free_vs.reserve(n);
  for (std::size_t i = 0; i < n; ++i)
    if (!fixed[i]) free_vs.push_back(vs[i]);
  if (free_vs.empty()) return rep;
  const std::size_t k = std::min(free_vs.size() - 1, std::size_t(p.quantile * double(free_vs.size() - 1)));
  std::nth_element(free_vs.begin(), free_vs.begin() + std::ptrdiff_t(k), free_vs.end());
  const float thr = std::max(free_vs[k], float(v_iso));
  rep.threshold = thr;
  free_vs = {};

  const int a = p.axis, b0 = a == 0 ? 1 : 0, b1 = a == 2 ? 1 : 2;
  const std::size_t stride[3] = {1, dims[0], dims[0] * dims[1]};
  const std::size_t len = dims[std::size_t(a)], lines = n / std::max<std::size_t>(len, 1);
  const double h = spacing[std::size_t(a)];
  if (!(h > 0) || !std::isfinite(h)) throw std::invalid_argument("crest_shells: the spacing along the beam must be positive");
  // In samples, at most the line's length (a tiny spacing must not overflow an int).
  const auto samples = [&](double mm, bool round) {
    const double k = round ? std::round(mm / h) : std::floor(mm / h + 1e-9);
    return int(std::min(k, double(len)));
  };
  const int reach = std::max(1, samples(p.reach_mm, false));
  const int above = std::max(1, samples(p.above_mm, true));
  const int pad = std::max(0, samples(p.pad_mm, true));
  const float iso = float(v_iso), min_g = float(p.min_edge * g_ref);
  const int parts = host_threads(threads);
  std::vector<std::size_t> crests(std::size_t(range_count(lines, parts)), 0), voxels(crests.size(), 0);
  std::vector<CrestChanges> part_changes(changed ? crests.size() : 0);
  parallel_ranges_indexed(lines, parts, [&](int part, std::size_t begin, std::size_t end) {
    std::vector<float> lv(len), lg(len), nv(len), ng(len), best(len);
    std::vector<std::uint8_t> lf(len);
    for (std::size_t line = begin; line < end; ++line) {
      const std::size_t c0 = line % dims[std::size_t(b0)], c1 = line / dims[std::size_t(b0)];
      const std::size_t base = c0 * stride[b0] + c1 * stride[b1], s = stride[a];
      for (std::size_t i = 0; i < len; ++i) {
        lv[i] = vs[base + i * s], lg[i] = std::sqrt(std::max(grad2[base + i * s], 0.0f)), lf[i] = fixed[base + i * s];
        best[i] = std::numeric_limits<float>::infinity();
      }
      bool any = false;
      for (int i = 1; i + 1 < int(len); ++i) {
        if (lf[std::size_t(i)] || !(lv[i] >= thr) || lv[i] < lv[i - 1] || !(lv[i] > lv[i + 1])) continue;
        // The fall: under the isovalue within reach, through scanned voxels.
        int j = -1;
        float low = lv[i];
        for (int q = i + 1; q < int(len) && q - i <= reach && !lf[std::size_t(q)]; ++q) {
          low = std::min(low, lv[q]);
          if (lv[q] < iso) { j = q; break; }
        }
        if (j < 0) continue;
        if (p.shadow) {
          bool dark = true;
          for (int q = j; q < int(len) && !lf[std::size_t(q)]; ++q)
            if (!(lv[q] < iso)) { dark = false; break; }
          if (!dark) continue;
        }
        for (int q = j + 1; q < int(len) && q - i <= reach && !lf[std::size_t(q)]; ++q) low = std::min(low, lv[q]);
        if (lv[i] - iso < float(p.lift) * (iso - low)) continue;
        // The rise from above: the crest stands out, not a step down from brightness.
        float high_low = lv[i];
        int seen = 0;
        for (int q = i - 1; q >= 0 && i - q <= above && !lf[std::size_t(q)]; --q) high_low = std::min(high_low, lv[q]), ++seen;
        if (seen == 0 || lv[i] - high_low < float(p.ridge) * (lv[i] - low)) continue;
        float G = 0;
        for (int q = i; q <= j; ++q) G = std::max(G, lg[q]);
        if (!(G >= min_g) || !(G > 0)) continue;
        for (int q = std::max(0, i - pad); q <= std::min(int(len) - 1, j + pad); ++q) {
          if (lf[std::size_t(q)]) continue;
          const float d = float((q - i) * h);
          if (std::fabs(d) >= best[q]) continue;
          best[q] = std::fabs(d);
          nv[q] = iso + float(shift_mm) * G + G * d;
          ng[q] = std::max(lg[q], G);
        }
        ++crests[std::size_t(part)];
        any = true;
      }
      if (!any) continue;
      for (std::size_t i = 0; i < len; ++i)
        if (best[i] < std::numeric_limits<float>::infinity()) {
          const std::size_t at = base + i * s;
          if (changed) {
            CrestChanges& c = part_changes[std::size_t(part)];
            c.index.push_back(at), c.vs.push_back(vs[at]), c.grad2.push_back(grad2[at]);
          }
          vs[at] = nv[i], grad2[at] = ng[i] * ng[i];
          ++voxels[std::size_t(part)];
        }
    }
  });
  for (std::size_t i = 0; i < crests.size(); ++i) rep.crests += crests[i], rep.voxels += voxels[i];
  if (changed) {
    changed->index.reserve(rep.voxels), changed->vs.reserve(rep.voxels), changed->grad2.reserve(rep.voxels);
    for (const CrestChanges& c : part_changes) {
      changed->index.insert(changed->index.end(), c.index.begin(), c.index.end());
      changed->vs.insert(changed->vs.end(), c.vs.begin(), c.vs.end());
      changed->grad2.insert(changed->grad2.end(), c.grad2.begin(), c.grad2.end());
    }
  }
  return rep;
}

}  // namespace softshell
