// The Levoy baselines: metrics of Levoy's classifier on the raw and the
// lowpassed phantom volumes, the numbers the variational classifier must beat.
//
//   softshell_study_levoy [--size N] [--seeds 1,2,3] [--shapes face,spine] [--device D]
//
// For each shape, seed and lowpass sigma (0, 1, 1.5, 2 voxels) it runs Levoy at
// a grid of isovalues and thicknesses and prints, per shape and sigma, the
// mean over seeds of every metric (a) at the default setting and (b) at the
// setting with the best F1 of precision and recall — Levoy at its best, so the
// baseline is a fair one. Isovalues: fractions of the way from the fluid
// median to the median intensity on the facing true surface (an oracle a user
// approximates by reading a bright boundary off a slice).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "error.hpp"
#include "levoy.hpp"
#include "metrics.hpp"
#include "phantom.hpp"

using namespace softshell;

namespace {

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(item);
  return out;
}

double median_on_facing_surface(const Phantom& p) {
  std::vector<float> vals;
  const Volume& sdf = p.truth_sdf;
  for (std::size_t z = 1; z + 1 < sdf.dims[2]; ++z)
    for (std::size_t y = 1; y + 1 < sdf.dims[1]; ++y)
      for (std::size_t x = 1; x + 1 < sdf.dims[0]; ++x) {
        if (std::abs(sdf.at(x, y, z)) > 1.0f) continue;
        const double nz = sdf.at(x, y, z + 1) - sdf.at(x, y, z - 1);
        const double nx = sdf.at(x + 1, y, z) - sdf.at(x - 1, y, z);
        const double ny = sdf.at(x, y + 1, z) - sdf.at(x, y - 1, z);
        const double len = std::sqrt(nx * nx + ny * ny + nz * nz);
        if (len > 0 && -nz / len >= 0.3) vals.push_back(p.volume.at(x, y, z));
      }
  if (vals.empty()) return p.tissue_median;
  std::nth_element(vals.begin(), vals.begin() + vals.size() / 2, vals.end());
  return vals[vals.size() / 2];
}

struct Row {
  double precision = 0, recall = 0, blobs = 0, normal = 0, opaque = 0, splats = 0;
  void add(const Metrics& m) {
    precision += m.precision, recall += m.recall, blobs += double(m.spurious_blobs);
    normal += m.normal_error_deg, opaque += m.percent_opaque, splats += double(m.splats);
  }
  Row mean(double n) const { return {precision / n, recall / n, blobs / n, normal / n, opaque / n, splats / n}; }
  double f1() const { return precision + recall > 0 ? 2 * precision * recall / (precision + recall) : 0; }
};

}  // namespace

int main(int argc, char** argv) {
  int size = 96;
  std::vector<std::string> seeds{"1", "2", "3"}, shapes{"face", "spine"};
  std::string device;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i], v = argv[i + 1];
    if (a == "--size") size = std::atoi(v.c_str());
    else if (a == "--seeds") seeds = split(v);
    else if (a == "--shapes") shapes = split(v);
    else if (a == "--device") device = v;
    else {
      std::fprintf(stderr, "usage: softshell_study_levoy [--size N] [--seeds 1,2,3] [--shapes face,spine] [--device D]\n");
      return 2;
    }
  }
  try {
    Runtime rt(device);
    const double sigmas[] = {0.0, 1.0, 1.5, 2.0};  // voxels
    const double fractions[] = {0.5, 0.65, 0.8, 1.0};
    const double thicknesses[] = {1.0, 2.0};
    std::printf("Levoy baselines, %d^3 phantoms, seeds %zu, device %s\n\n", size, seeds.size(),
                rt.info().label().c_str());
    std::printf("| shape | sigma (vox) | setting | iso frac | r (vox) | precision | recall | blobs | normal err (deg) | %% opaque (u > %g) | splats |\n", kOpaqueLevel);
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (const auto& shape_name : shapes) {
      PhantomParams pp;
      if (!parse_phantom_shape(shape_name, pp.shape)) throw InputError("unknown shape " + shape_name);
      pp.size = size;
      std::vector<Phantom> phantoms;
      std::vector<double> iso_lo, iso_hi;
      for (const auto& s : seeds) {
        pp.seed = std::stoull(s);
        phantoms.push_back(make_phantom(rt, pp));
        iso_lo.push_back(phantoms.back().fluid_median);
        iso_hi.push_back(median_on_facing_surface(phantoms.back()));
      }
      for (double sigma : sigmas) {
        // key: (fraction index, thickness index) -> summed metrics over seeds
        std::map<std::pair<int, int>, Row> sums;
        for (std::size_t k = 0; k < phantoms.size(); ++k) {
          const Phantom& ph = phantoms[k];
          for (int fi = 0; fi < 4; ++fi)
            for (int ti = 0; ti < 2; ++ti) {
              LevoyParams lp;
              lp.iso = iso_lo[k] + fractions[fi] * (iso_hi[k] - iso_lo[k]);
              lp.thickness = thicknesses[ti];
              lp.sigma_mm = sigma * ph.volume.spacing[0];
              const Volume u = classify_levoy(rt, ph.volume, lp);
              MetricsParams mp;
              mp.beam = ph.beam;
              sums[{fi, ti}].add(evaluate_opacity(u, ph.truth_sdf, mp));
            }
        }
        const double n = double(phantoms.size());
        auto print = [&](const char* label, std::pair<int, int> key) {
          const Row r = sums[key].mean(n);
          std::printf("| %s | %.1f | %s | %.2f | %.0f | %.3f | %.3f | %.1f | %.1f | %.1f | %.0f |\n", shape_name.c_str(),
                      sigma, label, fractions[key.first], thicknesses[key.second], r.precision, r.recall, r.blobs,
                      r.normal, r.opaque, r.splats);
        };
        print("default", {1, 0});
        std::pair<int, int> best{1, 0};
        for (const auto& [key, row] : sums)
          if (row.mean(n).f1() > sums[best].mean(n).f1()) best = key;
        print("best F1", best);
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "softshell_study_levoy: %s\n", e.what());
    return 2;
  }
}
