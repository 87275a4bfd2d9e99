// Parameter study of the variational classifier on phantoms with ground truth
// (docs/parameters.md): every combination of the given parameter values is
// classified and evaluated on every phantom, and the mean metrics per setting
// are printed, best first (by the number of goals met, then F1).
//
//   softshell_study_params [--shapes face,spine] [--sizes 96] [--seeds 1,2,3]
//                          [--iso-frac F] [--top K] [KEY=V1:V2:...]...
// KEY is one of alpha beta gamma omega delta epsilon u_ind sigma grad_sigma kappa,
// or iso_frac (v_iso = fluid + iso_frac (tissue - fluid), overriding --iso-frac).
// --iso-frac auto takes v_iso from `--iso auto` instead.
// --tensor-sigma S scores the structure-tensor splat orientation (0: grad u).
// Goals (issue 4): precision >= 0.60, recall >= 0.92, blobs <= 5, normal <= 15.
#include <algorithm>
#include <cstdio>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "auto_iso.hpp"
#include "error.hpp"
#include "metrics.hpp"
#include "param_keys.hpp"
#include "phantom.hpp"
#include "variational.hpp"

using namespace softshell;

namespace {

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep)) out.push_back(item);
  return out;
}

void set_param(VariationalParams& p, const std::string& key, double v) {
  if (!set_variational_param(p, key, v)) throw InputError("unknown parameter " + key);
}

struct Mean {
  double precision = 0, recall = 0, blobs = 0, normal = 0, opaque = 0, splats = 0, cycles = 0, seconds = 0;
  int n = 0, unconverged = 0;
  int goals() const {
    return (precision / n >= 0.6) + (recall / n >= 0.92) + (blobs / n <= 5) + (normal / n <= 15);
  }
  double f1() const {
    const double p = precision / n, r = recall / n;
    return p + r > 0 ? 2 * p * r / (p + r) : 0;
  }
};

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> shapes{"face"}, sizes{"96"}, seeds{"1", "2", "3"};
  double iso_frac = 0.5, tensor_sigma = 0;
  bool iso_auto = false;  // --iso-frac auto: v_iso by `--iso auto` (host/auto_iso.hpp)
  int top = 20;
  std::vector<std::pair<std::string, std::vector<double>>> grid;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] { return i + 1 < argc ? std::string(argv[++i]) : std::string(); };
    if (a == "--shapes") shapes = split(next(), ',');
    else if (a == "--sizes") sizes = split(next(), ',');
    else if (a == "--seeds") seeds = split(next(), ',');
    else if (a == "--iso-frac") {
      const std::string f = next();
      iso_auto = f == "auto";
      if (!iso_auto) iso_frac = std::stod(f);
    }
    else if (a == "--top") top = std::stoi(next());
    else if (a == "--tensor-sigma") tensor_sigma = std::stod(next());
    else if (a.find('=') != std::string::npos) {
      std::vector<double> vals;
      for (const auto& v : split(a.substr(a.find('=') + 1), ':')) vals.push_back(std::stod(v));
      grid.emplace_back(a.substr(0, a.find('=')), vals);
    } else {
      std::fprintf(stderr, "usage: softshell_study_params [--shapes ..] [--sizes ..] [--seeds ..] [--iso-frac F] "
                           "[--top K] [--tensor-sigma S] [KEY=V1:V2...]...\n");
      return 2;
    }
  }
  try {
    Runtime rt("");
    struct Case {
      Phantom ph;
      double iso;
      double iso_at(double frac) const {
        return ph.volume.intensity_map().to_unit(ph.fluid_median + frac * (ph.tissue_median - ph.fluid_median));
      }
    };
    std::vector<Case> cases;
    for (const auto& sh : shapes)
      for (const auto& sz : sizes)
        for (const auto& sd : seeds) {
          PhantomParams pp;
          if (!parse_phantom_shape(sh, pp.shape)) throw InputError("unknown shape " + sh);
          pp.size = std::stoi(sz);
          pp.seed = std::stoull(sd);
          Case c{make_phantom(rt, pp), 0};
          c.iso = iso_auto ? c.ph.volume.intensity_map().to_unit(auto_iso(c.ph.volume, nullptr)) : c.iso_at(iso_frac);
          cases.push_back(std::move(c));
        }
    std::size_t combos = 1;
    for (const auto& g : grid) combos *= g.second.size();
    std::vector<std::pair<std::string, Mean>> results;
    for (std::size_t c = 0; c < combos; ++c) {
      VariationalParams p;
      std::string label;
      std::size_t rest = c;
      double frac = iso_frac;
      for (const auto& [key, vals] : grid) {
        const double v = vals[rest % vals.size()];
        rest /= vals.size();
        if (key == "iso_frac") frac = v;
        else set_param(p, key, v);
        char buf[64];
        std::snprintf(buf, sizeof buf, "%s=%g ", key.c_str(), v);
        label += buf;
      }
      Mean m;
      for (const Case& k : cases) {
        p.v_iso = frac == iso_frac ? k.iso : k.iso_at(frac);
        SolverParams sp;
        sp.max_cycles = 60;
        SolveReport rep;
        const Volume u = classify_variational(rt, k.ph.volume, p, sp, &rep);
        MetricsParams mp;
        mp.beam = k.ph.beam;
        mp.tensor_sigma = tensor_sigma;
        const Metrics met = evaluate_opacity(u, k.ph.truth_sdf, mp);
        m.precision += met.precision, m.recall += met.recall, m.blobs += double(met.spurious_blobs);
        m.normal += met.normal_error_deg, m.opaque += met.percent_opaque, m.splats += double(met.splats);
        m.cycles += rep.cycles, m.seconds += rep.seconds, ++m.n, m.unconverged += !rep.converged;
      }
      results.emplace_back(label, m);
      std::fprintf(stderr, "\r%zu/%zu", c + 1, combos);
    }
    std::fprintf(stderr, "\n");
    std::stable_sort(results.begin(), results.end(), [](const auto& a, const auto& b) {
      return a.second.goals() != b.second.goals() ? a.second.goals() > b.second.goals() : a.second.f1() > b.second.f1();
    });
    std::printf("| setting | goals | precision | recall | blobs | normal (deg) | %% opaque (u > %g) | splats | iters | unconv |\n", kOpaqueLevel);
    std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
    for (int i = 0; i < int(results.size()) && i < top; ++i) {
      const auto& [label, m] = results[i];
      const double n = m.n;
      std::printf("| %s| %d | %.3f | %.3f | %.1f | %.1f | %.1f | %.0f | %.1f | %d |\n", label.c_str(), m.goals(),
                  m.precision / n, m.recall / n, m.blobs / n, m.normal / n, m.opaque / n, m.splats / n, m.cycles / n,
                  m.unconverged);
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "softshell_study_params: %s\n", e.what());
    return 2;
  }
}
