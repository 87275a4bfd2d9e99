// `softshell evaluate OPACITY TRUTH_SDF`: surface-quality metrics of an
// opacity volume against a phantom's ground-truth signed distance field
// (precision, recall, spurious blobs, normal error, mass precision, F1,
// surface peak, shell thickness, 6-connected blobs, the paper's Table 1
// counts). Runs on the host; no OpenCL device is needed. Definitions:
// docs/metrics.md.
#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>

#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "io.hpp"
#include "metrics.hpp"
#include "orientation.hpp"
#include "text.hpp"

namespace softshell::cli {
namespace {

struct EvaluateOptions {
  std::string opacity, truth, beam = "0,0,1";
  std::string shadow = "auto";  // shadow_db volume: auto (beside the truth), none, or FILE
  std::string orientation = "tensor";  // tensor (of u), gradient (grad u), data (tensor of --volume)
  std::string volume;                  // the B-mode volume behind u, for --orientation data
  bool tensor_sigma_given = false;
  bool json = false;
  bool tolerance_mm_given = false;  // --tolerance-mm was on the command line
  MetricsParams params;
};

// "X,Y,Z" with any finite reals, not all zero (parse_vec3 wants positive ones).
std::array<double, 3> parse_direction(const std::string& text, const std::string& what) {
  const auto fail = [&] { return InputError(what + ": expected X,Y,Z with finite numbers, not all 0, got '" + text + "'"); };
  std::array<double, 3> v{};
  std::size_t pos = 0;
  for (int i = 0; i < 3; ++i) {
    const std::size_t comma = text.find(',', pos);
    if ((i < 2) == (comma == std::string::npos)) throw fail();
    const std::string field = trim(text.substr(pos, i < 2 ? comma - pos : std::string::npos));
    if (field.empty()) throw fail();
    errno = 0;
    char* end = nullptr;
    v[i] = std::strtod(field.c_str(), &end);
    if (errno == ERANGE || *end != '\0' || !std::isfinite(v[i])) throw fail();
    pos = comma + 1;
  }
  if (v[0] == 0 && v[1] == 0 && v[2] == 0) throw fail();
  return v;
}

void check_options(const EvaluateOptions& o) {
  const MetricsParams& p = o.params;
  if (!std::isfinite(p.threshold) || p.threshold < 0) throw InputError("--threshold must be a finite number >= 0");
  if (!std::isfinite(p.tolerance) || p.tolerance < 0 || p.tolerance > 1e6)
    throw InputError("--tolerance must be in [0, 1e6] voxels");
  if (!(p.facing_cos >= -1 && p.facing_cos <= 1)) throw InputError("--facing-cos must be in [-1, 1]");
  if (o.tolerance_mm_given && (!std::isfinite(p.tolerance_mm) || !(p.tolerance_mm > 0)))
    throw InputError("--tolerance-mm must be a finite number > 0 (mm)");
  if (!std::isfinite(p.opaque) || p.opaque < 0) throw InputError("--opaque must be a finite number >= 0");
  if (!std::isfinite(p.u_ind) || !(p.u_ind > 0)) throw InputError("--u-ind must be a finite number > 0");
  if (!(p.blob_rel > 0 && p.blob_rel <= 1)) throw InputError("--blob-rel must be in (0, 1]");
  if ((o.orientation == "data") != !o.volume.empty())
    throw InputError(o.volume.empty() ? "--orientation data needs --volume V (the B-mode volume behind the opacity)"
                                      : "--volume is read only by --orientation data");
  if (o.orientation == "gradient" && o.tensor_sigma_given && p.tensor_sigma > 0)
    throw InputError("--orientation gradient takes no --tensor-sigma");
  if (o.orientation == "data" && !(p.tensor_sigma > 0))
    throw InputError("--orientation data needs --tensor-sigma > 0");
}

std::string fixed(double v, int digits) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

// The truth must look like a signed distance in voxels: both signs (a zero
// set inside the volume), and |grad d| near 1 on the voxels next to that
// zero set (central differences, one-sided at the border). On an anisotropic
// grid the distance is in units of the smallest spacing (docs/metrics.md,
// "Units and anisotropic voxels"), so each axis's difference per index is
// divided by its spacing over the smallest one: a true distance's |grad| is
// 1 whichever way its surfaces face. A B-mode volume, an opacity volume or a
// distance in other units fails one of these; its metrics would be
// meaningless, so it is refused.
void check_signed_distance(const Volume& d, const std::string& path) {
  const auto bad = [&](const std::string& why) {
    return input_error(path, "TRUTH_SDF does not look like a signed distance in voxels: " + why +
                                 " (expected truth_sdf.nrrd of `softshell phantom`: negative inside, |grad| 1)");
  };
  float lo = d.data.empty() ? 0.0f : d.data[0], hi = lo;
  for (float x : d.data) lo = std::min(lo, x), hi = std::max(hi, x);
  if (!(lo < 0 && hi > 0))
    throw bad("its values lie in [" + fixed(lo, 3) + ", " + fixed(hi, 3) + "], with no sign change");
  const Dims3 n = d.dims;
  const double h_min = std::min({d.spacing[0], d.spacing[1], d.spacing[2]});
  double index_per_unit[3];
  for (int a = 0; a < 3; ++a) index_per_unit[a] = h_min > 0 ? h_min / d.spacing[std::size_t(a)] : 1.0;
  std::vector<double> grads;
  for (std::size_t z = 0; z < n[2]; ++z)
    for (std::size_t y = 0; y < n[1]; ++y)
      for (std::size_t x = 0; x < n[0]; ++x) {
        if (!(std::fabs(d.at(x, y, z)) < 1.0f)) continue;
        double g2 = 0;
        for (int a = 0; a < 3; ++a) {
          if (n[a] < 2) continue;
          std::size_t lo_i[3] = {x, y, z}, hi_i[3] = {x, y, z};
          if (lo_i[a] > 0) --lo_i[a];
          if (hi_i[a] + 1 < n[a]) ++hi_i[a];
          const double g = double(d.at(hi_i[0], hi_i[1], hi_i[2]) - d.at(lo_i[0], lo_i[1], lo_i[2])) /
                           double(hi_i[a] - lo_i[a]) * index_per_unit[a];
          g2 += g * g;
        }
        grads.push_back(std::sqrt(g2));
      }
  if (grads.empty()) throw bad("no voxel lies within 1 of its zero set (it jumps across it)");
  std::nth_element(grads.begin(), grads.begin() + std::ptrdiff_t(grads.size() / 2), grads.end());
  const double median = grads[grads.size() / 2];
  if (!(median >= 0.5 && median <= 2.0))
    throw bad("the median |grad| next to its zero set is " + fixed(median, 3) + " per voxel, not near 1");
}

int run_evaluate(EvaluateOptions o) {
  const auto t0 = Clock::now();
  o.params.beam = parse_direction(o.beam, "--beam");
  check_options(o);
  if (o.orientation == "gradient") o.params.tensor_sigma = 0;
  const Volume u = read_volume(o.opacity);
  const Volume sdf = read_volume(o.truth);
  require_finite(u, o.opacity, "an opacity volume must be finite");
  require_finite(sdf, o.truth, "a signed distance volume must be finite");
  if (u.dims != sdf.dims)
    throw InputError("dims differ: " + dims_text(u.dims) + " (" + o.opacity + ") vs " + dims_text(sdf.dims) + " (" +
                     o.truth + ")");
  check_signed_distance(sdf, o.truth);
  // The shadow loss for recall_visible: given, or shadow_db.nrrd beside the
  // truth as `softshell phantom` writes it.
  std::string shadow_path;
  if (o.shadow == "auto") {
    const std::size_t slash = o.truth.find_last_of('/');
    const std::string beside = (slash == std::string::npos ? std::string() : o.truth.substr(0, slash + 1)) +
                               "shadow_db.nrrd";
    if (std::ifstream(beside).good()) shadow_path = beside;
  } else if (o.shadow != "none") {
    shadow_path = o.shadow;
  }
  Volume shadow;
  if (!shadow_path.empty()) {
    shadow = read_volume(shadow_path);
    if (shadow.dims != sdf.dims)
      throw InputError("dims differ: " + dims_text(shadow.dims) + " (" + shadow_path + ", --shadow) vs " +
                       dims_text(sdf.dims) + " (" + o.truth + ")");
    for (float x : shadow.data)
      if (std::isnan(x)) throw input_error(shadow_path, "--shadow has NaN samples (expected a loss in dB)");
    o.params.shadow_db = &shadow;
  }
  // Orientation by the data: the tensor of the B-mode volume's orientation
  // field, as `render --orientation data` draws the splats.
  Volume field;
  if (o.orientation == "data") {
    const Volume bmode = read_volume(o.volume);
    require_finite(bmode, o.volume, "a B-mode volume must be finite");
    if (bmode.dims != u.dims)
      throw InputError("dims differ: " + dims_text(bmode.dims) + " (" + o.volume + ", --volume) vs " +
                       dims_text(u.dims) + " (" + o.opacity + ")");
    field = data_orientation_field(bmode);
    o.params.orientation_field = &field;
  }
  const double t_read = seconds_since(t0);
  const auto t1 = Clock::now();
  const Metrics m = evaluate_opacity(u, sdf, o.params);
  const double t_eval = seconds_since(t1);

  if (o.json) {
    std::cout << metrics_json(m, o.params) << '\n';
    return 0;
  }
  const MetricsParams& p = o.params;
  const double bl = std::sqrt(p.beam[0] * p.beam[0] + p.beam[1] * p.beam[1] + p.beam[2] * p.beam[2]);
  const std::string tol = fixed(m.tolerance, 2) + " voxels (" + fixed(m.tolerance_mm, 2) + " mm)",
                    thr = fixed(p.threshold, 3);
  const std::string beam = fixed(p.beam[0] / bl + 0.0, 2) + "," + fixed(p.beam[1] / bl + 0.0, 2) + "," +
                           fixed(p.beam[2] / bl + 0.0, 2);
  struct Row {
    const char* name;
    std::string value, meaning;
  };
  const Row rows[] = {
      {"precision", fixed(m.precision, 4), "share of drawn opacity (u > " + thr + ") within " + tol + " of a true surface"},
      {"recall", fixed(m.recall, 4),
       "share of true surface voxels facing the transducer with a drawn voxel within " + tol},
      {"recall_visible", p.shadow_db ? fixed(m.recall_visible, 4) : std::string("-"),
       p.shadow_db ? "recall over the " + std::to_string(m.visible_surface_voxels) +
                         " facing surface voxels not in acoustic shadow (shadow loss < " + fixed(p.visible_db, 1) +
                         " dB, " + shadow_path + ")"
                   : std::string("not computed: no shadow volume (--shadow FILE, or shadow_db.nrrd beside the truth)")},
      {"spurious_blobs", std::to_string(m.spurious_blobs),
       "drawn 26-connected blobs nowhere within " + tol + " of a true surface (" + std::to_string(m.spurious_voxels) +
           " voxels)"},
      {"components", std::to_string(m.components), "drawn 26-connected components in all"},
      {"normal_error_deg", fixed(m.normal_error_deg, 2),
       "opacity-weighted mean angle (0-90) between the splat normal (" +
           (p.tensor_sigma > 0 ? std::string(p.orientation_field ? "structure tensor of the data, " : "structure tensor of u, ") +
                                     "sigma " + fixed(p.tensor_sigma, 1) + " voxels"
                               : std::string("grad u")) +
           ") and the true normal, over " +
           std::to_string(m.normal_voxels) + " drawn voxels near a surface"},
      {"mass_precision", fixed(m.mass_precision, 4), "share of all opacity (sum of u, no threshold) within " + tol +
                                                          " of a true surface"},
      {"f1", fixed(m.f1, 4), "2 precision recall / (precision + recall)"},
      {"f1_mass", fixed(m.f1_mass, 4), "the same with mass_precision"},
      {"f1_visible", p.shadow_db ? fixed(m.f1_visible, 4) : std::string("-"), "the same with recall_visible"},
      {"surface_peak", fixed(m.surface_peak, 4),
       "median over the facing surface voxels of max u across the surface (within the tolerance) / u_ind " +
           fixed(p.u_ind, 3)},
      {"surface_peak_visible", p.shadow_db ? fixed(m.surface_peak_visible, 4) : std::string("-"),
       "the same over the visible ones (those of recall_visible)"},
      {"shell_thickness_mm", fixed(m.shell_thickness_mm, 3),
       "median full width at half maximum of u along the true normal, over " + std::to_string(m.thickness_points) +
           " points (" + std::to_string(m.thickness_censored) + " wider than the +-" + fixed(m.profile_radius_mm, 1) +
           " mm window, counted at that)"},
      {"shell_offset_mm", m.offset_points ? fixed(m.shell_offset_mm, 3) : std::string("-"),
       "median middle of the half-maximum interval along the true outward normal (+ outside the truth, - inside), "
       "over " + std::to_string(m.offset_points) + " uncensored points"},
      {"blobs6", std::to_string(m.blobs6),
       "6-connected blobs of u > " + fixed(m.blob_threshold, 4) + " (" + fixed(p.blob_rel, 2) +
           " max u) nowhere within " + tol + " of a true surface"},
      {"blob6_voxel_share", fixed(m.blob6_voxel_share, 4), "share of the voxels with u > " +
                                                               fixed(m.blob_threshold, 4) + " that lie in those blobs"},
      {"components6", std::to_string(m.components6), "6-connected components of u > " + fixed(m.blob_threshold, 4)},
      {"percent_opaque", fixed(m.percent_opaque, 2), "% of voxels with u > " + fixed(p.opaque, 3) + " (paper Table 1)"},
      {"splats", std::to_string(m.splats), "voxels with u > " + thr + ", one splat each (paper Table 1)"},
      {"facing_surface_voxels", std::to_string(m.facing_surface_voxels),
       "true surface voxels whose normal n has n.(-beam) >= " + fixed(p.facing_cos, 2) + ", beam " + beam},
  };
  std::cout << "evaluate " << o.opacity << " against " << o.truth << '\n'
            << "  volume  " << dims_text(u.dims) << ", spacing " << u.spacing[0] << ',' << u.spacing[1] << ','
            << u.spacing[2] << " mm\n";
  // Voxels are compared index by index; a truth placed elsewhere in the
  // world was likely made for another volume.
  if (const std::string differs = grid_mismatch(u, sdf); !differs.empty())
    std::cerr << "softshell: warning: the truth " << o.truth << " lies elsewhere in the world than the opacity ("
              << differs << "); voxels are compared index by index, gradients use the opacity's spacing\n";
  std::cout << "\n  " << std::left << std::setw(23) << "metric" << std::setw(10) << "value" << "meaning\n";
  for (const Row& r : rows) std::cout << "  " << std::setw(23) << r.name << std::setw(10) << r.value << r.meaning << '\n';
  std::cout << std::right << "\n  time    read " << fixed(t_read, 3) << " s, evaluate " << fixed(t_eval, 3)
            << " s\n";
  return 0;
}

}  // namespace

void add_evaluate_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<EvaluateOptions>();
  auto* sub = app.add_subcommand(
      "evaluate", "Surface-quality metrics of an opacity volume against a ground-truth SDF (docs/metrics.md)");
  sub->add_option("OPACITY", o->opacity, "Opacity volume u in [0, 1] (e.g. from classify)")->required();
  sub->add_option("TRUTH_SDF", o->truth, "Ground-truth signed distance in voxels, < 0 inside (from phantom)")
      ->required();
  sub->add_flag("--json", o->json, "Print one JSON object instead of the table");
  sub->add_option("--threshold", o->params.threshold, "Splat threshold: u > threshold is drawn (paper's epsilon)")
      ->capture_default_str()
      ->check(real_range(0, 1, "", Ends::OpenHigh));
  sub->add_option("--tolerance", o->params.tolerance, "Voxels: how near a true surface counts as on it")
      ->capture_default_str()
      ->check(real_range(0, 1e6, "voxels"));
  auto* tol_mm = sub->add_option("--tolerance-mm", o->params.tolerance_mm,
                                 "The tolerance in mm instead (overrides --tolerance; divided by the smallest spacing)")
      ->check(real_range(0, 1e6, "mm", Ends::OpenLow));
  sub->add_option("--u-ind", o->params.u_ind, "The opacity a surface should reach: surface_peak is a fraction of it")
      ->capture_default_str()
      ->check(real_range(0, 1, "", Ends::OpenLow));
  sub->add_option("--blob-rel", o->params.blob_rel,
                  "6-connected blobs are components of u > this times max u, in (0, 1]")
      ->capture_default_str()
      ->check(real_range(0, 1, "", Ends::OpenLow));
  sub->add_option("--beam", o->beam, "Beam direction X,Y,Z (transducer on the z = 0 face: 0,0,1)")
      ->capture_default_str();
  sub->add_option("--shadow", o->shadow,
                  "Shadow loss volume in dB (a phantom's shadow_db.nrrd) for recall_visible, the recall over the "
                  "surface voxels whose loss is below --visible-db: auto (shadow_db.nrrd beside TRUTH_SDF when there "
                  "is one), none, or FILE")
      ->capture_default_str()
      ->type_name("auto|none|FILE");
  sub->add_option("--visible-db", o->params.visible_db,
                  "recall_visible counts the surface voxels whose shadow loss is below this (dB)")
      ->capture_default_str()
      ->check(real_range(-1000, 1000, "dB"));
  sub->add_option("--facing-cos", o->params.facing_cos,
                  "A surface faces the transducer if its outward normal n has n.(-beam) >= this")
      ->capture_default_str()
      ->check(real_range(-1, 1));
  auto* sigma = sub->add_option("--tensor-sigma", o->params.tensor_sigma,
                                "Splat orientation scored by the normal error: the structure tensor with this sigma in "
                                "voxels (the renderer's default), or 0 for grad u (the paper's)")
                    ->capture_default_str()
                    ->check(real_range(0, 8, "voxels"));
  sub->add_option("--orientation", o->orientation,
                  "Which splat orientation the normal error scores, as render's --orientation: tensor (of u), "
                  "gradient (grad u) or data (the tensor of --volume's orientation field)")
      ->capture_default_str()
      ->check(one_of({"tensor", "gradient", "data"}));
  sub->add_option("--volume", o->volume, "The B-mode volume behind the opacity, for --orientation data")
      ->type_name("V");
  sub->add_option("--opaque", o->params.opaque,
                  "u > this counts toward percent_opaque (the paper's 'negligibly small' opacity)")
      ->capture_default_str()
      ->check(real_range(0, 1, "", Ends::OpenHigh));
  sub->callback([&action, o, tol_mm, sigma] {
    o->tolerance_mm_given = tol_mm->count() > 0;
    o->tensor_sigma_given = sigma->count() > 0;
    action = [o] { return run_evaluate(*o); };
  });
}

}  // namespace softshell::cli
