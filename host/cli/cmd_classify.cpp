// `softshell classify IN --iso V -o OUT`: opacity classification, by the
// paper's variational method (default) or Levoy's isovalue-contour classifier
// (the paper's Figure 2b baseline).
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <optional>
#include <sstream>
#include <memory>
#include <set>

#include "auto_iso.hpp"
#include "host_memory.hpp"
#include "classify_checks.hpp"
#include "cl_runtime.hpp"
#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "io.hpp"
#include "levoy.hpp"
#include "mask.hpp"
#include "progress.hpp"
#include "metrics.hpp"
#include "memory_need.hpp"
#include "bone_cue.hpp"
#include "shadow_walls.hpp"
#include "speckle.hpp"
#include "filter.hpp"
#include "variational.hpp"
#include "text.hpp"
#include "params_file.hpp"
#include "presets.hpp"

namespace softshell::cli {
namespace {

// The report's words for the share the reference edge gradient was taken
// from: the top edge_share, or (VariationalParams::edge_split) the top
// edge_share_fine, with the ratio that decided. With the bone cue (its own
// reference, no ratio measured) or a given g_ref: the share, as before.
std::string edge_share_text(const VariationalParams& r, const VariationalParams& p) {
  std::ostringstream t;
  t << std::fixed << std::setprecision(1);
  if (!(r.g_ref_ratio > 0)) {
    t << "top " << 100 * p.edge_share << " %";
  } else if (const double w = edge_split_weight(r.g_ref_ratio, p.edge_split, p.edge_split_from); w >= 1) {
    t << "top " << 100 * p.edge_share_fine << " %: its median " << std::setprecision(2) << r.g_ref_ratio
      << " x the top " << std::setprecision(1) << 100 * p.edge_share << " %'s, a small object's walls among speckle";
  } else if (w > 0) {
    t << "top " << 100 * p.edge_share << " % and top " << 100 * p.edge_share_fine << " % blended, "
      << std::setprecision(0) << 100 * w << " % the latter: its median " << std::setprecision(2) << r.g_ref_ratio
      << " x the former's, between --edge-split-from " << p.edge_split_from << " and --edge-split " << p.edge_split;
  } else {
    t << "top " << 100 * p.edge_share << " %; the top " << 100 * p.edge_share_fine << " %'s median "
      << std::setprecision(2) << r.g_ref_ratio << " x its";
  }
  return t.str();
}

struct ClassifyOptions {
  std::string in, out, device, method = "variational", iso, init, cycle = "pcg", smoother = "gs", mask = "auto";
  std::string near_field = "remove", reverb = "remove", depth_clip;
  std::string band_sheet = "hold";  // host/mask.hpp, hold_band_sheet
  std::string params;  // --params FILE
  std::vector<std::string> inputs;  // IN...: one volume, or a sequence's 3-D files (names or quoted patterns)
  std::vector<std::string> files;   // a sequence given as files (expand_input_files); empty otherwise
  std::string per_frame;            // --per-frame-files PATTERN
  std::string bone_cue = "off";  // docs/parameters.md: off by default (it lost bone on a real sweep)
  std::string shadow_walls = "remove";  // host/shadow_walls.hpp: weighted down by default
  std::string echo_underside = "auto";  // host/shadow_walls.hpp, ShadowWallParams::underside
  std::string beam_axis = "auto";       // --beam-axis: auto (the data's own, beam_axis_of) or x, y, z
  double thickness = 1.0;
  double iso_fraction = AutoIsoParams().local_fraction, iso_field_sigma = AutoIsoParams().field_sigma_mm;
  double iso_field_depth_sigma = AutoIsoParams().field_depth_sigma_mm;
  double iso_climb = AutoIsoParams().climb_mm;
  double iso_clip_fraction = AutoIsoParams().clip_fraction;
  double iso_floor_fraction = AutoIsoParams().floor_fraction;
  double iso_bulk_spread = AutoIsoParams().bulk_spread;
  std::optional<double> sigma;  // unset: 1 mm for variational, 0 (raw) for levoy
  VariationalParams vp;
  SolverParams sp;
  bool compress = false, quiet = false, stats = false, no_fmg = false, literal = false, no_iso_field = false;
  std::set<std::string> given;  // long option names given on the command line
  double small_volume_mm = kSmallVolumeMm;  // small_volume_scale's reference extent (0: off)
  double auto_iso_sigma = AutoIsoParams().sigma_mm;
  std::string scale_text;          // for the report, when the length scales shrank
  double length_scale = 1.0;       // small_volume_scale, 1 unless the volume is small
  std::string grad_sigma_text;     // for the report: how --grad-sigma's default was chosen
  RawOptions raw;
  NonFiniteOption non_finite;
  std::string warm_start = "on";  // 3D+t: each frame's linear solve starts from the previous frame's
  // 3D+t (run_sequence): one frame's classification hands its results here
  // instead of writing and printing them; null for a 3-D classification.
  struct FrameHooks {
    Runtime* rt = nullptr;      // the sequence's device, set up once
    SequenceStart start;        // the warm start (variational)
    Volume* u = nullptr;        // the frame's opacity
    SolveReport* report = nullptr;
    double* iso = nullptr;      // the isovalue used (file units)
  };
  FrameHooks* hooks = nullptr;
};

// A number, or nullopt for "auto".
std::optional<double> parse_iso(const std::string& text) {
  if (text == "auto" || text == "auto-local" || text == "auto-ridge" || text == "auto-edge") return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !std::isfinite(v))
    throw InputError("--iso: expected a number in the input's intensity units, auto, auto-local, auto-ridge or auto-edge, got '" +
                     text + "'");
  return v;
}

std::string format_iso(double iso) {
  std::ostringstream s;
  s << iso;
  return s.str();
}

// The data region (host/mask.hpp): derived from the zero fill, read from a
// file, or everything. Empty vector: no mask.
struct DataMask {
  std::vector<std::uint8_t> scanned;  // empty: every voxel scanned
  std::string text;                   // for the report
  // The window under a removed near-field band (host/mask.hpp,
  // band_underside; empty: none) and the beam axis it lies along: held at
  // u = 0 and solved again when the shell draws a sheet in it.
  std::vector<std::uint8_t> underside;
  int axis = -1;
  // Float data's unscanned fill, subtracted from the data before the mask
  // (host/mask.hpp, unscanned_fill_value; 0: none): isovalues and
  // brightness are reported in the file's units, that is plus this.
  double fill = 0;
};

// A map in the file's units for the report: `map` is the data's less `fill`.
IntensityMap in_file_units(IntensityMap map, double fill) {
  map.lo += fill, map.hi += fill;
  return map;
}

// A mask or initial opacity of the volume's dims is used index by index; if
// its header places those voxels elsewhere in the world (another spacing,
// origin or orientation), it was likely made for another volume: say so.
void warn_if_elsewhere(const std::string& option, const std::string& path, const Volume& in) {
  const VolumeHeader h = read_volume_header(path);
  Volume g({1, 1, 1}, h.spacing);
  g.origin = h.origin;
  g.frame = h.frame;
  const std::string differs = grid_mismatch(in, g);
  if (!differs.empty())
    std::cerr << "softshell: warning: " << option << " " << path << " lies elsewhere in the world than the volume ("
              << differs << "); its voxels are used index by index\n";
}

DataMask make_mask(const std::string& option, const Volume& in, int beam_axis) {
  DataMask m;
  const auto percent = [&](std::size_t k) {
    std::ostringstream s;
    s << k << " voxels unscanned (" << std::fixed << std::setprecision(1) << 100.0 * double(k) / double(in.voxels())
      << " %)";
    return s.str();
  };
  if (option == "none") {
    m.text = "none (every voxel scanned)";
  } else if (option == "auto") {
    MaskReport r;
    MaskParams params;
    if (beam_axis >= 0) params.beam_axis = beam_axis;  // else z, as always (step 2b)
    m.scanned = scanned_mask(in, params, &r);
    m.text = "auto: " + percent(r.unscanned) + " (zero fill " + std::to_string(r.zero_fill) + " + " +
             std::to_string(params.grow) + "-voxel rim" +
             (r.face_layers ? "; " + std::to_string(r.face_layers) + " of the fill in thin layers on the faces across the beam"
                            : std::string()) +
             ")";
    if (r.outside) {
      std::ostringstream t;
      t << "auto: " << percent(r.unscanned) << " (the part of the zero fill outside the data: " << std::fixed
        << std::setprecision(1) << 100 * r.outside_share << " % of it, "
        << (r.fluid_inside ? std::to_string(params.grow) + "-voxel rim" : std::string("no rim"))
        << "; the rest is dark fluid or shadow, "
        << 100 * r.enclosed_share << " % of the fill lying between echoes along the beam";
      if (r.fluid_inside) t << ", " << 100 * r.inside_share << " % inside the data's hull";
      t << ")";
      m.text = t.str();
    } else if (r.rejected) {
      std::ostringstream t;
      t << "auto: none; the zero fill is dark fluid, not an unswept region (" << std::fixed << std::setprecision(1)
        << 100 * r.enclosed_share << " % of it between echoes along the beam, " << r.faces_with_data
        << " faces with data; --mask none/FILE to choose)";
      m.scanned.clear(), m.text = t.str();
    } else if (r.unscanned == 0) {
      m.scanned.clear(), m.text = "auto: no unscanned region (no solid zero fill at the border)";
    }
  } else {
    try {
      m.scanned = read_mask(option, in.dims);
      warn_if_elsewhere("--mask", option, in);
    } catch (const InputError& e) {
      throw InputError(std::string("--mask ") + e.what());
    }
    m.text = option + ": " + percent(count_unscanned(m.scanned));
  }
  return m;
}

void write_opacity(const ClassifyOptions& o, const Volume& u) {
  const progress::Stage stage("write");
  WriteOptions w;
  w.type = ScalarType::Float32;
  w.compress = o.compress;
  write_volume(o.out, u, w);
}

// The variational parameters of the options, checked (all but v_iso):
// refused before anything is read.
VariationalParams variational_params(const ClassifyOptions& o) {
  VariationalParams p = o.vp;
  p.sigma_mm = o.sigma.value_or(1.0);
  if (o.literal) {
    // The paper's terms exactly; weights not given on the command line take
    // the values the earlier study chose for the literal functional.
    const VariationalParams lit = VariationalParams::literal_defaults();
    const auto given = [&](const char* name) { return o.given.count(name) > 0; };
    if (!given("--alpha")) p.alpha = lit.alpha;
    if (!given("--beta")) p.beta = lit.beta;
    if (!given("--gamma")) p.gamma = lit.gamma;
    if (!given("--omega")) p.omega = lit.omega;
    if (!given("--delta")) p.delta = lit.delta;
    if (!given("--epsilon")) p.epsilon = lit.epsilon;
    p.grad_sigma_mm = 0, p.kappa = 0, p.thickness_mm = 0, p.edge_share = 0, p.sharpen_iterations = 0, p.max_gain = 0;
    p.crest.ridge = 0;
  }
  check_variational_params(p);
  return p;
}

SolverParams solver_params(const ClassifyOptions& o) {
  SolverParams sp = o.sp;
  if (o.cycle != "pcg" && o.cycle != "v") throw InputError("--cycle must be pcg or v");
  if (o.smoother != "gs" && o.smoother != "jacobi") throw InputError("--smoother must be gs or jacobi");
  check_solver_params(sp);
  sp.krylov = o.cycle == "pcg";
  sp.jacobi = o.smoother == "jacobi";
  sp.full_multigrid = !o.no_fmg;
  return sp;
}

int run_levoy(const ClassifyOptions& o, Runtime& rt, const Volume& in, double iso, const std::string& iso_text,
              const std::string& iso_warning, const DataMask& mask, Clock::time_point t0) {
  std::cerr << iso_warning;
  LevoyParams p;
  p.iso = iso;
  p.thickness = o.thickness;
  p.sigma_mm = o.sigma.value_or(0.0);
  LevoyReport report;
  std::optional<progress::Stage> stage(std::in_place, "levoy");
  Volume u = classify_levoy(rt, in, p, &report);
  stage.reset();
  // Levoy's classifier has no notion of a data region: unscanned voxels get
  // opacity 0 after the fact (docs/real-data.md).
  if (!mask.scanned.empty())
    for (std::size_t i = 0; i < u.data.size(); ++i)
      if (!mask.scanned[i]) u.data[i] = 0.0f;
  if (o.hooks) {
    *o.hooks->u = std::move(u);
    if (o.hooks->iso) *o.hooks->iso = iso + mask.fill;
    return 0;
  }
  write_opacity(o, u);
  if (!o.quiet) {
    std::size_t drawn = 0;
    for (float a : u.data) drawn += a > 0.2f;
    std::cout << std::fixed << std::setprecision(3) << "classify (levoy) " << o.in << " -> " << o.out << '\n'
              << "  volume   " << dims_text(in.dims) << ' ' << scalar_type_name(in.source_type) << ", iso " << p.iso + mask.fill
              << iso_text << ", thickness " << p.thickness << " voxels (" << levoy_thickness_mm(p.thickness, in.spacing)
              << " mm), lowpass sigma " << p.sigma_mm << " mm\n"
              << "  mask     " << mask.text << '\n'
              << (o.scale_text.empty() ? "" : "  scale    " + o.scale_text + "\n")
              << "  opacity  " << drawn << " voxels above 0.2 (" << std::setprecision(1)
              << 100.0 * double(drawn) / double(u.voxels()) << " %)\n"
              << std::setprecision(3) << "  device   " << rt.info().label() << '\n'
              << "  time     lowpass " << report.lowpass << " s, gradient " << report.gradient << " s, classify "
              << report.classify << " s, total " << seconds_since(t0) << " s\n";
  }
  return 0;
}

int run_variational(const ClassifyOptions& o, Runtime& rt, const Volume& in, double iso, const std::string& iso_text,
                    const std::string& iso_warning, const DataMask& mask, Clock::time_point t0,
                    std::shared_ptr<const std::vector<float>> bone_cue, std::shared_ptr<const std::vector<float>> walls,
                    const std::string& bone_cue_text) {
  const IntensityMap map = in.intensity_map();
  VariationalParams p = variational_params(o);
  set_edge_weights(p, std::move(bone_cue), std::move(walls));
  p.v_iso = map.to_unit(iso);
  check_normalised_iso(p.v_iso, format_iso(iso + mask.fill), in_file_units(map, mask.fill).describe());
  std::cerr << iso_warning;
  const SolverParams sp = solver_params(o);
  std::optional<Volume> init;
  if (!o.init.empty()) {
    init = read_volume(o.init);
    if (init->dims != in.dims)
      throw InputError(o.init + ": --init has dims " + dims_text(init->dims) + ", the volume " + dims_text(in.dims));
    require_finite(*init, o.init, "an initial opacity must be finite");
    warn_if_elsewhere("--init", o.init, in);
    // classify writes opacities in [0, 1]; anything else (a signed distance,
    // a B-mode volume) is not a start the solver can use.
    float lo = init->data.empty() ? 0.0f : init->data[0], hi = lo;
    for (float x : init->data) lo = std::min(lo, x), hi = std::max(hi, x);
    if (lo < -1e-3f || hi > 1.001f) {
      std::ostringstream r;
      r << "--init is not an opacity volume: its values lie in [" << lo << ", " << hi
        << "], an opacity (the output of classify) in [0, 1]";
      throw input_error(o.init, r.str());
    }
  }
  SolveReport report;
  ClassifyTiming timing;
  Volume u = classify_variational(rt, in, p, sp, &report, init ? &*init : nullptr,
                                 mask.scanned.empty() ? nullptr : &mask.scanned, &timing,
                                 o.hooks ? &o.hooks->start : nullptr);
  // The band's underside drawn as a sheet (host/mask.hpp, hold_band_sheet):
  // held at u = 0 and solved again, at the same isovalue.
  std::string sheet_text;
  if (!mask.underside.empty() && report.converged) {
    std::vector<std::uint8_t> held = mask.scanned;
    const BandSheetReport bs = hold_band_sheet(u, mask.underside, mask.axis, held);
    if (bs.held) {
      const ClassifyTiming first = timing;  // both classifications' times are reported
      std::optional<progress::Stage> stage(std::in_place, "band sheet");
      u = classify_variational(rt, in, p, sp, &report, init ? &*init : nullptr, &held, &timing,
                               o.hooks ? &o.hooks->start : nullptr);
      timing.setup += first.setup, timing.solve += first.solve;
      std::ostringstream t;
      const BandSheetParams bp;
      t << std::fixed << std::setprecision(0)
        << (bs.patches > 0 || bs.deep_patches > 0 ? "; the band's underside drawn as a sheet: "
                                                  : "; a layer under the probe drawn as a sheet: ");
      if (bs.patches > 0)
        t << bs.patches << (bs.patches == 1 ? " patch" : " patches") << " on "
          << 100.0 * double(bs.held_lines) / double(bs.lines) << " % of its lines, the " << std::setprecision(1)
          << bp.window_mm << " mm under it held at u = 0 there";
      if (bs.patches > 0 && bs.deep_patches > 0) t << ", and ";
      if (bs.deep_patches > 0)
        t << std::setprecision(0) << bs.deep_patches << (bs.deep_patches == 1 ? " flat sheet" : " flat sheets")
          << " deeper on " << 100.0 * double(bs.deep_lines) / double(bs.lines) << " % of its lines, "
          << std::setprecision(1) << bp.window_mm << "-" << bp.deep_mm << " mm under it, held there";
      if ((bs.patches > 0 || bs.deep_patches > 0) && bs.skin_sheets > 0) t << ", and ";
      if (bs.skin_sheets > 0)
        t << std::setprecision(0) << bs.skin_sheets << (bs.skin_sheets == 1 ? " sheet" : " sheets")
          << (bs.skin_pieces > 0 ? " (and " + std::to_string(bs.skin_pieces) +
                                       (bs.skin_pieces == 1 ? " piece" : " pieces") + " at their depth)"
                                 : std::string())
          << " following the skin line in its first " << std::setprecision(1) << bp.skin_mm << " mm"
          << (bs.lines > 0 ? " where no band was removed" : "") << std::setprecision(0) << " ("
          << 100.0 * double(bs.skin_sheet_lines) / double(std::max<std::size_t>(bs.skin_lines, 1))
          << " % of those lines), held there";
      t << " (" << bs.voxels << " voxels) and solved again (--band-sheet keep to keep it)";
      sheet_text = t.str();
    }
  }
  auto history = [&] {
    std::ostringstream s;
    s << std::scientific << std::setprecision(2);
    for (double r : report.residuals) s << ' ' << r;
    return s.str();
  };
  if (!report.converged) {
    std::ostringstream msg;
    msg << "classification did not converge: relative residual " << std::scientific << std::setprecision(2)
        << report.residuals.back() << " after " << report.cycles << " iterations (--tol " << sp.tol
        << "); nothing written; try --max-cycles, or check the parameters (history:" << history() << ")";
    throw NotConvergedError(msg.str());
  }
  if (o.hooks) {
    *o.hooks->u = std::move(u);
    if (o.hooks->report) *o.hooks->report = report;
    if (o.hooks->iso) *o.hooks->iso = iso + mask.fill;
    return 0;
  }
  write_opacity(o, u);
  if (!o.quiet) {
    std::size_t drawn = 0, opaque = 0;
    for (float a : u.data) drawn += a > 0.2f, opaque += a > kOpaqueLevel;
    std::cout << std::fixed << std::setprecision(3) << "classify (variational) " << o.in << " -> " << o.out << '\n'
              << "  volume   " << dims_text(in.dims) << ' ' << scalar_type_name(in.source_type) << ", iso " << iso + mask.fill
              << iso_text << " (" << p.v_iso << " normalised, " << in_file_units(map, mask.fill).describe() << ")\n"
              << "  mask     " << mask.text << sheet_text << '\n'
              << (o.scale_text.empty() ? "" : "  scale    " + o.scale_text + "\n")
              << "  params   alpha " << p.alpha << " beta " << p.beta << " gamma " << p.gamma << " omega " << p.omega
              << " delta " << p.delta << " epsilon " << p.epsilon << " u_ind " << p.u_ind << " sigma " << p.sigma_mm
              << " mm, kappa " << p.kappa << " grad-sigma " << p.grad_sigma_mm << " mm" << o.grad_sigma_text
              << (p.literal() ? " (the paper's functional)" : "") << "\n"
              << "  bone cue " << bone_cue_text << "\n";
    if (!p.literal())
      std::cout << "  shell    thickness " << timing.resolved.thickness_mm << " mm, profile power " << p.profile_power
                << ", reference edge gradient " << std::setprecision(4) << timing.resolved.g_ref
                << " per mm (" << edge_share_text(timing.resolved, p) << "), edge power "
                << std::setprecision(3) << p.edge_power << ", shift " << timing.resolved.shell_shift_mm << " mm\n";
    if (!p.literal()) {
      std::cout << "  crest    ";
      if (!(p.crest.ridge > 0)) {
        std::cout << "echo crest off (--echo-crest 0)\n";
      } else {
        const CrestReport& cr = timing.crest;
        std::cout << "echo crest " << cr.crests << " crests along " << "xyz"[p.crest.axis] << ", " << cr.voxels
                  << " voxels re-centred (ridge " << std::setprecision(2) << p.crest.ridge << ", crests above "
                  << std::setprecision(3) << cr.threshold << " normalised, the " << std::setprecision(1)
                  << 100 * p.crest.quantile << "th percentile)" << std::setprecision(3) << "\n";
      }
    }
    std::cout << "  solve    " << report.levels << " levels, " << report.cycles << (sp.krylov ? " PCG iterations" : " V-cycles")
              << ", relative residual " << std::scientific << std::setprecision(2) << report.residuals.back()
              << std::fixed << std::setprecision(3) << '\n'
              << "  opacity  " << drawn << " splats (u > 0.2), " << std::setprecision(1)
              << 100.0 * double(opaque) / double(u.voxels()) << " % opaque (u > " << std::setprecision(2)
              << kOpaqueLevel << ")\n"
              << std::setprecision(3) << "  device   " << rt.info().label() << '\n'
              << "  time     setup " << timing.setup << " s, solve " << timing.solve << " s, total " << seconds_since(t0)
              << " s\n";
    if (o.stats) std::cout << "  residuals" << history() << '\n';
  }
  return 0;
}

// --params FILE: the isovalue and the weights from a parameters file
// (host/params_file.hpp) where the command line does not give them; the
// file's rendering keys are for `view` and ignored here.
ClassifyOptions with_params_file(ClassifyOptions o) {
  if (o.params.empty()) return o;
  const ParamsFile f = read_params_file(o.params);
  const auto take = [&](const char* key, const std::string& option) {
    if (!f.find(key) || o.given.count(option)) return false;
    o.given.insert(option);  // counts as given (--literal keeps it)
    return true;
  };
  if (take("iso", "--iso")) o.iso = *f.find("iso");
  // A preset's classification part (host/presets.hpp): the bone cue.
  if (take("preset", "--bone-cue")) o.bone_cue = find_preset(*f.find("preset"))->bone_cue;
  if (take("sigma", "--sigma")) o.sigma = *f.number("sigma");
  const std::pair<const char*, double*> weights[] = {{"alpha", &o.vp.alpha}, {"beta", &o.vp.beta},
                                                     {"gamma", &o.vp.gamma}, {"omega", &o.vp.omega},
                                                     {"delta", &o.vp.delta}, {"epsilon", &o.vp.epsilon},
                                                     {"kappa", &o.vp.kappa}};
  for (const auto& [key, value] : weights)
    if (take(key, std::string("--") + key)) *value = *f.number(key);
  if (take("shell_shift", "--shell-shift")) o.vp.shell_shift_mm = *f.number("shell_shift");
  return o;
}

int run_classify(const ClassifyOptions& given_options);

// Every frame of a 3D+t sequence (docs/formats.md, "3D+t sequences"): each
// frame classified as `classify --frame K` would (its own mask, near field
// and automatic isovalue), on one device, the linear solve warm-started from
// the previous frame's (--warm-start on); the frames written as one 4-D NRRD
// at the end (atomically: an interrupted run leaves no output).
int run_sequence(const ClassifyOptions& o, const VolumeHeader& head, Clock::time_point t0) {
  const std::size_t n = o.files.empty() ? head.frames : o.files.size();
  std::string ext = o.out.size() >= 5 ? o.out.substr(o.out.size() - 5) : o.out;
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (ext != ".nrrd")
    throw InputError("-o " + o.out + ": " + o.in + " is a sequence of " + std::to_string(n) +
                     " frames, written as a 4-D NRRD only: use a .nrrd output, or --frame K for one frame");
  if (!o.init.empty())
    throw InputError("--init: not with a sequence (each frame starts from the previous one; --warm-start off for "
                     "cold starts), or choose one frame with --frame K");
  const bool warm = o.warm_start == "on" && o.method == "variational";
  const progress::Stage command("classify " + std::to_string(n) + " frames");
  Runtime rt(o.device);
  std::vector<Volume> us(n);
  std::vector<float> linear, next_linear;
  std::vector<double> isos(n, 0.0), secs(n, 0.0);
  std::vector<int> iterations(n, 0);
  for (std::size_t k = 0; k < n; ++k) {
    const auto tk = Clock::now();
    const progress::Stage frame("frame " + std::to_string(k + 1) + "/" + std::to_string(n));
    ClassifyOptions f = o;
    if (o.files.empty()) {
      f.raw.frame = k;
    } else {
      f.in = o.files[k];
      f.files.clear();
    }
    f.quiet = true;
    ClassifyOptions::FrameHooks h;
    SolveReport report;
    h.rt = &rt;
    h.u = &us[k];
    h.report = &report;
    h.iso = &isos[k];
    h.start.linear_in = warm && k > 0 ? &linear : nullptr;
    h.start.linear_out = warm ? &next_linear : nullptr;
    f.hooks = &h;
    run_classify(f);
    linear.swap(next_linear);
    secs[k] = seconds_since(tk);
    iterations[k] = report.cycles;
    if (!o.quiet)
      std::cout << std::fixed << std::setprecision(3) << "  frame " << k << ": iso " << std::setprecision(2) << isos[k]
                << ", " << report.cycles << " iterations" << (warm && k > 0 ? " (warm)" : "") << ", "
                << std::setprecision(3) << secs[k] << " s\n"
                << std::flush;
  }
  {
    const progress::Stage stage("write");
    WriteOptions w;
    w.type = ScalarType::Float32;
    w.compress = o.compress;
    write_frames(o.out, us, w);
    if (!o.per_frame.empty())
      for (std::size_t k = 0; k < n; ++k) write_volume(frame_path(o.per_frame, k, n), us[k], w);
  }
  if (!o.quiet) {
    double total = 0;
    for (double t : secs) total += t;
    const auto [lo, hi] = std::minmax_element(isos.begin(), isos.end());
    std::cout << std::fixed << std::setprecision(3) << "classify (" << o.method << ") "
              << (o.files.empty() ? o.in : o.files.front() + " ... " + o.files.back()) << " -> " << o.out;
    if (!o.per_frame.empty())
      std::cout << " and " << frame_path(o.per_frame, 0, n) << " ... " << frame_path(o.per_frame, n - 1, n);
    std::cout << '\n'
              << "  sequence " << n << " frames of " << dims_text(head.dims) << ", warm start "
              << (warm ? "on" : "off") << ", iso " << std::setprecision(2) << *lo << " to " << *hi << '\n'
              << std::setprecision(3) << "  time     " << total / double(n) << " s per frame (" << std::setprecision(2)
              << double(n) / total << " frames/s), total " << std::setprecision(3) << seconds_since(t0) << " s\n";
  }
  return 0;
}

int run_classify(const ClassifyOptions& given_options) {
  const auto t0 = Clock::now();
  // The parameters file first; then the length scales may shrink with a small volume.
  ClassifyOptions o = with_params_file(given_options);
  if (o.iso.empty()) throw InputError("--iso is required (a number, auto, ...), or an iso key in --params");
  if (o.method != "levoy" && o.method != "variational")
    throw InputError("--method " + o.method + ": unknown (methods: variational, levoy)");
  const bool variational = o.method == "variational";
  const std::optional<double> given_iso = parse_iso(o.iso);
  if (o.mask.empty()) throw InputError("--mask: expected FILE, auto or none");
  if (o.near_field != "remove" && o.near_field != "keep")
    throw InputError("--near-field: expected remove or keep, got '" + o.near_field + "'");
  // --depth-clip MIN,MAX (mm below the skin line; MAX may be inf).
  std::optional<std::pair<double, double>> depth_clip;
  if (!o.depth_clip.empty()) {
    const auto comma = o.depth_clip.find(',');
    char* e1 = nullptr;
    char* e2 = nullptr;
    const std::string a = o.depth_clip.substr(0, comma), b = comma == std::string::npos ? "" : o.depth_clip.substr(comma + 1);
    const double lo = std::strtod(a.c_str(), &e1), hi = std::strtod(b.c_str(), &e2);
    if (a.empty() || b.empty() || *e1 != '\0' || *e2 != '\0' || !std::isfinite(lo) || std::isnan(hi) || lo < 0 ||
        !(hi > lo))
      throw InputError("--depth-clip: expected MIN,MAX in mm below the skin line with 0 <= MIN < MAX (MAX may be inf), "
                       "got '" + o.depth_clip + "'");
    depth_clip.emplace(lo, hi);
  }
  if (o.reverb != "remove" && o.reverb != "keep")
    throw InputError("--reverb: expected remove or keep, got '" + o.reverb + "'");
  if (o.band_sheet != "hold" && o.band_sheet != "keep")
    throw InputError("--band-sheet: expected hold or keep, got '" + o.band_sheet + "'");
  BoneCueMode cue_mode = BoneCueMode::Off;
  if (!parse_bone_cue_mode(o.bone_cue, cue_mode))
    throw InputError("--bone-cue: expected auto, on or off, got '" + o.bone_cue + "'");
  if (o.literal && cue_mode == BoneCueMode::Auto) cue_mode = BoneCueMode::Off;  // the paper's functional exactly
  // Every parameter before any file is read.
  if (variational) variational_params(o);
  if (variational) solver_params(o);
  if (!variational && (!(o.thickness > 0) || o.thickness > 100)) throw InputError("--thickness must be in (0, 100] voxels");
  const std::string mask_file = o.mask != "auto" && o.mask != "none" ? o.mask : "";
  const auto raw = o.raw.spec();
  // A sequence given as 3-D files (a list, or a quoted pattern): checked
  // whole before any work; --frame K picks one of them.
  bool frame_picked = o.raw.frame.has_value();
  if (!o.hooks && !o.inputs.empty()) {
    std::vector<std::string> files = expand_input_files(o.inputs);
    if (files.size() > 1) {
      if (o.raw.frame) {
        if (*o.raw.frame >= files.size())
          throw InputError("--frame " + std::to_string(*o.raw.frame) + ": the sequence has " +
                           std::to_string(files.size()) + " frames (0 to " + std::to_string(files.size() - 1) + ")");
        o.in = files[*o.raw.frame];
        o.raw.frame.reset();
      } else {
        o.files = std::move(files);
        o.in = o.files.front();
      }
    } else {
      o.in = files.front();
    }
  }
  std::vector<std::string> outputs{o.out};
  if (!o.per_frame.empty()) check_frame_pattern(o.per_frame, "--per-frame-files");
  {
    std::vector<std::string> inputs{o.in, mask_file, o.init, o.params};
    inputs.insert(inputs.end(), o.files.begin(), o.files.end());
    ensure_distinct_outputs(inputs, outputs);
  }
  check_output(o.out, OutputKind::Volume);  // before any work: a typo costs nothing
  if (!o.files.empty()) {
    // Every file one 3-D frame of one grid, before any work.
    const VolumeHeader first = read_volume_header(o.files.front(), raw);
    for (const std::string& file : o.files) {
      const VolumeHeader h = raw ? read_volume_header(file, raw) : read_any_header(file);
      if (h.frames > 1)
        throw InputError(file + ": a sequence of " + std::to_string(h.frames) +
                         " frames itself; a sequence given as files takes 3-D files");
      Volume a({1, 1, 1}, first.spacing), b({1, 1, 1}, h.spacing);
      a.origin = first.origin;
      a.frame = first.frame;
      b.origin = h.origin;
      b.frame = h.frame;
      const std::string differs = grid_mismatch(a, b);
      if (h.dims != first.dims || !differs.empty())
        throw InputError(file + ": " + (h.dims != first.dims ? dims_text(h.dims) + " voxels" : differs) +
                         ", unlike " + o.files.front() + " (" + dims_text(first.dims) +
                         "): the frames of a sequence share one grid");
    }
  }
  // A 3D+t sequence without --frame: every frame (run_sequence).
  if (!o.hooks && (!o.files.empty() || (!raw && !o.raw.frame))) {
    const VolumeHeader any = o.files.empty() ? read_any_header(o.in) : read_volume_header(o.files.front(), raw);
    if (any.frames > 1 || !o.files.empty()) {
      if (!o.per_frame.empty()) {
        const std::size_t n = o.files.empty() ? any.frames : o.files.size();
        std::vector<std::string> frame_outputs;
        for (std::size_t k = 0; k < n; ++k) frame_outputs.push_back(frame_path(o.per_frame, k, n));
        std::vector<std::string> inputs{o.in, mask_file, o.params};
        inputs.insert(inputs.end(), o.files.begin(), o.files.end());
        frame_outputs.push_back(o.out);
        ensure_distinct_outputs(inputs, frame_outputs);
        for (std::size_t k = 0; k < n; ++k) {
          if (frame_outputs[k] == o.out)
            throw InputError("--per-frame-files " + o.per_frame + ": frame " + std::to_string(k) + " would be -o " + o.out);
          check_output(frame_outputs[k], OutputKind::Volume, "--per-frame-files");
        }
      }
      return run_sequence(o, any, t0);
    }
  }
  if (!o.per_frame.empty() && !o.hooks)
    throw InputError(frame_picked
                         ? "--per-frame-files: not with --frame K (-o writes the one frame)"
                         : "--per-frame-files: " + o.in + " is one 3-D volume, not a sequence (a 4-D NRRD, or several 3-D files)");
  // The header first: sizes, data files, the lowpasses' widths and the
  // memory the classifier needs are all checked before a sample is read.
  const VolumeHeader head = read_volume_header(o.in, raw, o.raw.frame);
  // Small volumes (docs/parameters.md): the default length scales shrink
  // with a volume whose smallest extent is below --small-volume; those given
  // on the command line, and the paper's functional, stay.
  if (const double scale = o.literal ? 1.0 : small_volume_scale(head.dims, head.spacing, o.small_volume_mm); scale < 1.0) {
    const auto given = [&](const char* name) { return o.given.count(name) > 0; };
    if (variational && !given("--sigma")) o.sigma = scale * VariationalParams().sigma_mm;
    if (!given("--grad-sigma")) o.vp.grad_sigma_mm *= scale;
    if (!given("--shell")) o.vp.thickness_mm *= scale;
    if (!given("--shell-shift")) o.vp.shell_shift_mm *= scale;
    if (!given("--iso-field-sigma")) o.iso_field_sigma *= scale;
    if (!given("--iso-field-depth-sigma")) o.iso_field_depth_sigma *= scale;
    if (!given("--iso-climb")) o.iso_climb *= scale;
    // beta and kappa are squared lengths (mm^2; host/variational.hpp).
    if (!given("--beta")) o.vp.beta *= scale * scale;
    if (!given("--kappa")) o.vp.kappa *= scale * scale;
    o.auto_iso_sigma *= scale;
    std::ostringstream t;
    t << "small volume (smallest extent " << std::fixed << std::setprecision(1) << scale * o.small_volume_mm
      << " mm < --small-volume " << o.small_volume_mm << " mm): default length scales x" << std::setprecision(2)
      << scale;
    o.scale_text = t.str();
    o.length_scale = scale;
  }
  if (variational) {
    const VariationalParams vp = variational_params(o);
    check_lowpass_sigma(vp.sigma_mm, head.spacing, "--sigma");
    check_lowpass_sigma(vp.grad_sigma_mm, head.spacing, "--grad-sigma");
  } else {
    check_lowpass_sigma(o.sigma.value_or(0.0), head.spacing, "--sigma");
  }
  std::optional<progress::Stage> command;
  if (!o.hooks) command.emplace("classify");
  std::optional<progress::Stage> step(std::in_place, "device");
  std::optional<Runtime> own_rt;
  Runtime& rt = o.hooks && o.hooks->rt ? *o.hooks->rt : own_rt.emplace(o.device);
  step.emplace("read");
  // The host stages reuse each other's freed blocks; the free pages go back
  // to the kernel before the device work (host/host_memory.hpp).
  std::optional<KeepFreedMemory> keep_freed(std::in_place);
  // A tolerance below 1e-4 is reached by float64 refinement (host/multigrid.cpp).
  check_classify_memory(rt, o.in, head.dims, variational ? Classifier::Variational : Classifier::Levoy,
                        o.mask != "none", variational && o.sp.tol < 1e-4);
  Volume in = read_volume(o.in, raw, o.raw.frame);
  o.non_finite.apply(in, o.in);
  const std::string iso_warning = given_iso ? iso_outside_data(in, *given_iso) : "";
  step.emplace("mask");
  // --beam-axis: the user's beam axis for every step that follows the beam
  // (the mask's dark-fluid test, the near field, the depth clip, the
  // isovalue field, the bone cue, the shadow walls); auto: the data's own.
  const int given_axis = beam_axis_option(o.beam_axis);
  // Float data whose fill is not 0 (host/mask.hpp): the fill becomes 0, as
  // the mask and the near field take it, and what the mask leaves scanned of
  // it as dark as the darkest data.
  const double fill = o.mask == "auto" ? unscanned_fill_value(in) : 0.0;
  move_fill_to_zero(in, fill);
  DataMask mask = make_mask(o.mask, in, given_axis);
  mask.fill = fill;
  if (fill != 0.0) {
    darken_scanned_fill(in, mask.scanned);
    std::ostringstream t;
    t << " (float data: their fill, " << format_iso(fill) << ", counted as 0)";
    const std::size_t colon = mask.text.find(':');
    mask.text.insert(colon == std::string::npos ? mask.text.size() : colon, t.str());
  }
  std::vector<std::uint8_t> clip;  // --depth-clip: the scanned region with the clip applied
  std::size_t unscanned_before_clip = 0;
  int axis = given_axis;
  if (depth_clip) {
    clip = mask.scanned.empty() ? std::vector<std::uint8_t>(in.voxels(), 1) : mask.scanned;
    unscanned_before_clip = count_unscanned(clip);
    if (axis < 0) axis = beam_axis_of(in, &clip);
    clip_depth(in, clip, axis, depth_clip->first, depth_clip->second);
    if (mask.scanned.empty()) mask.scanned.assign(in.voxels(), 1);
  }
  int beam_axis = axis;  // the beam axis (-1: not looked for); the near field's when it is looked for
  if (o.near_field == "remove" || o.reverb == "remove") {
    // The bright near field under the probe is an occluder, not the object
    // (docs/real-data.md, "The near field"); the equally spaced copies of a
    // flat reflector below it are ghosts ("Reverberations").
    NearFieldParams np;
    np.axis = given_axis;
    np.reverb = o.reverb == "remove";
    np.band = o.near_field == "remove";
    const std::vector<std::uint8_t> before = variational && np.band && o.band_sheet == "hold" ? mask.scanned
                                                                                             : std::vector<std::uint8_t>();
    const NearFieldReport nf = remove_near_field(in, mask.scanned, np);
    beam_axis = nf.axis;
    if (variational && np.band && o.band_sheet == "hold") {
      // Also with no band: the skin window (host/mask.hpp,
      // BandSheetParams::skin_mm), but not under a --depth-clip (the clipped
      // region's first voxel is no skin line) nor in a small volume (a crop
      // thinner than --small-volume: the layers under the probe need not
      // lie in it, and the window would span most of it).
      BandSheetParams bp;
      if (depth_clip || o.length_scale < 1.0) bp.skin_mm = 0;
      mask.underside = band_underside(in, nf, before, mask.scanned, bp.window_mm, bp.deep_mm, bp.skin_mm);
      mask.axis = nf.axis;
    }
    std::ostringstream t;
    if (nf.found) {
      t << "; near field removed: the first " << std::fixed << std::setprecision(1) << nf.depth_mm
        << " mm below the skin line along " << "xyz"[nf.axis];
      if (nf.layered) t << " in layers";
      t << " (" << nf.voxels << " voxels, median " << std::setprecision(0) << nf.top + fill << " over " << nf.below + fill
        << " below";
      if (nf.clipped) t << ", a faint band clipped at the data's maximum";
      else if (nf.faint) t << ", a faint band: speckle spread " << std::setprecision(1) << nf.speckle_sd;
      else if (nf.skin)
        t << ", a skin line: the lines' median falls " << std::setprecision(1) << nf.step << " at its bottom, "
          << std::setprecision(1) << nf.step / std::max(nf.roughness, 1e-30) << " x its roughness below";
      if (nf.reach_lines > 0)
        t << "; " << nf.reach_lines << " lines bounded at " << std::setprecision(1) << np.layer_reach_mm
          << " mm under its median bottom (deeper, they ended only in a shadow under the band)";
      t << "; --near-field keep to draw it)";
      if (nf.echo.tail_to > 0)
        t << ", with its tail to " << std::setprecision(2) << nf.echo.tail_to << " x the band's depth ("
          << nf.echo.tail_voxels << " voxels)";
      if (nf.echo.found)
        t << ", with its " << (nf.echo.layers > 1 ? std::to_string(nf.echo.layers) + " echo layers" : std::string("echo"))
          << " at " << std::setprecision(2) << nf.echo.from << "-" << nf.echo.to
          << " x the band's depth (" << nf.echo.voxels << " of those voxels)";
    } else if (nf.too_deep)
      t << "; near field kept: the bright band (" << std::fixed << std::setprecision(1) << nf.depth_mm
        << " mm along " << "xyz"[nf.axis] << ") would be more than half of the scanned voxels";
    else if (o.near_field == "remove")
      t << "; no bright near field (beam along " << "xyz"[nf.axis] << ")";
    if (nf.reverb.found)
      t << "; reverberations removed: below the first strong echo of " << nf.reverb.lines << " beam lines from "
        << std::fixed << std::setprecision(1) << nf.reverb.cut_mm << " mm under its crest (copies every "
        << nf.reverb.spacing_mm << " mm, " << nf.reverb.voxels << " voxels; --reverb keep to draw them)";
    mask.text += t.str();
  }
  if (depth_clip) {
    // The user's depth clip that follows the sweep (docs/real-data.md),
    // depth from the skin line of the scanned region (not from the bottom of
    // a removed near field).
    for (std::size_t i = 0; i < clip.size(); ++i)
      if (!clip[i]) mask.scanned[i] = 0;
    const std::size_t clipped = count_unscanned(clip) - unscanned_before_clip;
    std::ostringstream t;
    t << "; depth clip: kept " << std::fixed << std::setprecision(1) << depth_clip->first << " to "
      << depth_clip->second << " mm below the skin line along " << "xyz"[axis] << " (" << clipped
      << " voxels clipped)";
    mask.text += t.str();
    if (count_unscanned(mask.scanned) == mask.scanned.size())
      throw InputError("--depth-clip " + o.depth_clip + ": no scanned voxel lies at that depth");
  }
  // Unscanned samples continue the scanned data, so the lowpass and the
  // gradients see no step at the edge of the sweep (host/mask.hpp); in
  // place, the unfilled samples are not needed any more (the automatic
  // isovalue reads the scanned samples only).
  if (!mask.scanned.empty()) {
    step.emplace("fill unscanned");
    fill_unscanned_in_place(in, mask.scanned);
  }
  double iso = 0;
  // The shadow walls' isovalue: with --iso auto, shadow_test_iso's
  // (host/auto_iso.hpp); else the isovalue.
  std::optional<double> wall_iso;
  std::string iso_text;
  const std::vector<std::uint8_t>* sc = mask.scanned.empty() ? nullptr : &mask.scanned;
  // The beam axis the isovalue field, the bone cue and the shadow walls take:
  // the near-field step's, else the data's own (one pass, when first asked).
  const auto beam_axis_now = [&] {
    if (beam_axis < 0) beam_axis = beam_axis_of(in, sc);
    return beam_axis;
  };
  if (given_iso) {
    iso = *given_iso - fill;
  } else {
    step.emplace("auto iso");
    // auto: for the variational shell the local rule (an isovalue field near
    // the bright side of each boundary), for Levoy's contours the edge
    // midpoint (host/auto_iso.hpp); auto-local / auto-ridge / auto-edge
    // force one.
    AutoIsoParams ap;
    if (o.iso == "auto") ap.rule = o.method == "levoy" ? AutoIsoRule::Edge : AutoIsoRule::Local;
    else if (o.iso == "auto-local") ap.rule = AutoIsoRule::Local;
    else if (o.iso == "auto-ridge") ap.rule = AutoIsoRule::EchoRidge;
    else ap.rule = AutoIsoRule::Edge;
    ap.want_field = ap.rule == AutoIsoRule::Local && !o.no_iso_field;
    ap.local_fraction = o.iso_fraction;
    ap.clip_fraction = o.iso_clip_fraction;
    ap.floor_fraction = o.iso_floor_fraction;
    ap.bulk_spread = o.iso_bulk_spread;
    ap.field_sigma_mm = o.iso_field_sigma;
    ap.field_depth_sigma_mm = o.iso_field_depth_sigma;
    if (ap.want_field) ap.beam_axis = beam_axis_now();
    ap.sigma_mm = o.auto_iso_sigma;
    ap.bulk_sigma_mm *= o.length_scale;  // a small volume's, as the other lowpasses
    ap.climb_mm = o.iso_climb;
    // The local isovalue field levelled out as it is formed: the classifier
    // then works at one isovalue on data whose brightness no longer drifts
    // (host/auto_iso.hpp).
    AutoIsoReport rep;
    iso = auto_iso(in, mask.scanned.empty() ? nullptr : &mask.scanned, ap, &rep, &in);
    iso_text = ap.rule == AutoIsoRule::Local ? (!ap.want_field ? " (auto: local rule, one value"
                                                               : " (auto: local rule, the median of a field")
               : ap.rule == AutoIsoRule::EchoRidge ? " (auto: echo ridge"
                                                   : " (auto: edge";
    if (ap.rule == AutoIsoRule::Local && ap.want_field) {
      // The field's extent: long along the beam, short across it (host/auto_iso.hpp).
      std::ostringstream t;
      t << std::setprecision(3) << " " << ap.field_depth_sigma_mm << " mm along " << "xyz"[ap.beam_axis] << ", "
        << ap.field_sigma_mm << " mm across";
      iso_text += t.str();
    }
    if (ap.rule == AutoIsoRule::Local && rep.clipped_edges) {
      // The rule for clipped echoes (host/auto_iso.hpp) was used: say so.
      std::ostringstream t;
      t << std::fixed << std::setprecision(1) << "; clipped echoes: " << 100 * rep.clipped_share
        << " % of the samples at the maximum, " << 100.0 * double(rep.clipped_edges) / double(rep.crests)
        << " % of the edges placed at " << std::setprecision(2) << ap.clip_fraction << " of their contrast";
      iso_text += t.str();
    }
    if (ap.rule == AutoIsoRule::Local && ap.floor_fraction != ap.local_fraction && rep.floored_edges &&
        rep.floor_drop >= ap.floor_drop) {
      // The rule for fluid at the floor under peaked crests was used: say so.
      std::ostringstream t;
      t << std::fixed << std::setprecision(1) << "; fluid at the floor: " << 100 * rep.floor_share
        << " % of the samples at the minimum, " << 100.0 * double(rep.floored_edges) / double(rep.crests)
        << " % of the edges placed at " << std::setprecision(2) << ap.floor_fraction
        << " of their contrast (their crests fall by " << rep.floor_drop << " of it within "
        << std::setprecision(1) << ap.floor_reach_mm << " mm)";
      iso_text += t.str();
    }
    if (rep.bulk_raised) {
      // The isovalue raised above the bulk (host/auto_iso.hpp): say from what.
      std::ostringstream t;
      t << std::fixed << std::setprecision(1) << "; raised from " << rep.local_iso + fill << " above the bulk: its mode "
        << rep.bulk_mode + fill << " + " << ap.bulk_spread << " x its half-width " << rep.bulk_half_width
        << ", the echoes' crests at " << rep.ridge_iso + fill;
      iso_text += t.str();
    }
    iso_text += ")";
    wall_iso = shadow_test_iso(rep, iso);
  }
  // Levoy's kernel takes the isovalue as a float.
  if (!variational && !(std::fabs(iso) <= 3.0e38)) throw InputError("--iso " + format_iso(iso) + " does not fit a float");
  // The bone cue (host/bone_cue.hpp): on the data the classifier sees.
  std::shared_ptr<const std::vector<float>> cue, walls;
  std::string cue_text = "off";
  if (variational && cue_mode != BoneCueMode::Off) {
    step.emplace("bone cue");
    BoneCueParams bp;
    bp.axis = beam_axis_now();
    BoneCueReport br;
    cue = bone_cue_weights(in, sc, cue_mode, bp, &br);
    std::ostringstream t;
    t << std::fixed << std::setprecision(0) << (cue ? "on" : "off") << " (" << o.bone_cue << ": of the strong edges "
      << 100 * br.falling_share << " % fall and " << 100 * br.rising_share << " % rise in brightness along the beam ("
      << "xyz"[bp.axis] << "); auto asks falling >= " << std::setprecision(1) << bp.auto_ratio << " x rising";
    if (cue) t << "; edges weighted on " << std::setprecision(1) << 100 * br.weighted_share << " % of the voxels";
    t << ")";
    cue_text = t.str();
  } else if (variational) {
    cue_text = o.literal && o.bone_cue == "auto" ? "off (--literal)" : "off";
  }
  // The host stages end here: the shadow walls run device kernels, and with
  // glibc keeping freed blocks their allocations spread over the kept heap
  // (the device part's peak rose by 40-95 MB at 256^3; host/host_memory.hpp).
  keep_freed.reset();
  // --grad-sigma's default from the data's speckle (host/speckle.hpp), on
  // the data the classifier sees; given, it stays the user's.
  std::optional<GradSigmaChoice> grad_choice;  // also the underside rule's shares
  if (variational && !o.literal && !o.given.count("--grad-sigma")) {
    step.emplace("speckle");
    const GradSigmaChoice& gc = grad_choice.emplace(auto_grad_sigma(in, sc, beam_axis_now(), o.length_scale));
    const SpeckleReport& sr = gc.speckle;
    o.vp.grad_sigma_mm = gc.sigma_mm;
    std::ostringstream t;
    t << std::fixed << std::setprecision(2);
    if (!gc.echoes)
      t << std::setprecision(0) << " (auto: the strong edges are no echoes over darker data, " << 100 * gc.falling
        << " % fall and " << 100 * gc.rising << " % rise along the beam)";
    else if (sr.measured)
      t << " (auto: " << kGradSigmaPerSpeckle << " x the speckle's " << sr.sigma_mm << " mm along " << "xyz"[sr.axis]
        << ", within " << kGradSigmaMinMm * o.length_scale << "-" << kGradSigmaMaxMm * o.length_scale << " mm)";
    else
      t << " (auto: the speckle could not be measured)";
    o.grad_sigma_text = t.str();
  }
  // The walls of acoustic shadows (host/shadow_walls.hpp): their edges
  // weighted down, like the bone cue's.
  if (variational && !o.literal && o.shadow_walls == "remove") {
    step.emplace("shadow walls");
    ShadowWallParams wp = shadow_wall_params(variational_params(o), beam_axis_now());
    if (o.echo_underside == "auto") {
      // The underside of thin echoes, where the strong edges are steps up
      // from fluid (host/shadow_walls.hpp, underside_applies).
      if (!grad_choice) grad_choice = auto_grad_sigma(in, sc, beam_axis_now(), o.length_scale);
      wp.underside = underside_applies(grad_choice->falling, grad_choice->rising);
    }
    ShadowWallReport wr;
    walls = std::make_shared<const std::vector<float>>(
        shadow_wall_weight(rt, in, sc, wall_iso.value_or(iso), wp, &wr));
    std::ostringstream t;
    t << std::fixed << std::setprecision(1) << "; shadow walls: " << 100 * wr.shadow_share
      << " % of the scanned voxels in shadow, edges weighted down on " << 100 * wr.wall_share << " %";
    if (wr.fan.found) {
      // The apex in mm on the grid (voxel coordinates x spacing).
      t << " (along the beams of a fan, apex at";
      for (int k = 0; k < 3; ++k)
        if (wr.fan.spreads[k] || k == wp.axis) t << " " << "xyz"[k] << " " << wr.fan.apex[k] * in.spacing[std::size_t(k)];
      t << " mm)";
    }
    if (wp.underside)
      t << "; the underside of thin echoes weighted down on " << 100 * wr.underside_share
        << " % (the strong edges are steps up from fluid: " << std::setprecision(0) << 100 * grad_choice->falling
        << " % fall, " << 100 * grad_choice->rising << " % rise along the beam; --echo-underside keep to draw it)";
    cue_text += t.str();
  }
  // Shells on a bright echo's crest (host/crest.hpp): along the beam.
  if (variational && !o.literal && o.vp.crest.ridge > 0) o.vp.crest.axis = beam_axis_now();
  step.reset();
  return o.method == "levoy" ? run_levoy(o, rt, in, iso, iso_text, iso_warning, mask, t0)
                             : run_variational(o, rt, in, iso, iso_text, iso_warning, mask, t0, std::move(cue),
                                               std::move(walls), cue_text);
}

}  // namespace

void add_classify_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<ClassifyOptions>();
  o->vp.crest.ridge = kEchoCrestRidge;  // on by default (host/crest.hpp)
  auto* sub = app.add_subcommand("classify", "Opacity classification of a volume (float opacity in [0, 1])");
  sub->add_option("IN", o->inputs,
                  "Input volume; or a 3D+t sequence: a 4-D NRRD, or several 3-D files of one grid (names, or a quoted "
                  "pattern such as 'frames/f*.nrrd', taken in natural order), every frame classified unless --frame K")
      ->required()
      ->type_name("IN...");
  sub->add_option("-o,--output", o->out, "Output opacity volume (.nrrd, .mha, .mhd, .nii, .nii.gz, .vti), float")->required();
  sub->add_option("--iso", o->iso,
                  "Isovalue, in the input's own intensity units (e.g. 0-255 for 8-bit data), or auto: for the "
                  "variational method a field near the bright side of each boundary (auto-local), for levoy where the "
                  "gradient of the lowpassed data peaks (auto-edge); auto-ridge: the crest of the boundary echoes "
                  "(docs/parameters.md); required unless --params gives it")
      ->type_name("V|auto|auto-local|auto-ridge|auto-edge");
  sub->add_option("--params", o->params,
                  "Parameters file (as `view` saves it: key = value lines, docs/rendering.md): iso, sigma and the "
                  "weights alpha beta gamma omega delta epsilon kappa are taken from it unless given here; its "
                  "rendering keys are ignored; an unknown key or a bad value is an error")
      ->type_name("FILE");
  sub->add_option("--echo-crest", o->vp.crest.ridge,
                  "Shells on bright echoes' crests (docs/parameters.md, \"The echo's crest\"): where an echo among "
                  "the brightest 3 % rises from above by at least this share of its fall into a shadow that lasts to "
                  "the end of the beam (a bone seen from above), the isovalue term is centred on its crest rather "
                  "than on its lower flank; 0 turns it off; the default was chosen on the cross-check")
      ->capture_default_str()
      ->check(real_range(0, 1));
  sub->add_option("--iso-fraction", o->iso_fraction,
                  "The local rule: where between a boundary's dark trough (0) and bright crest (1) its isovalue lies")
      ->capture_default_str()
      ->check(real_range(0, 1));
  sub->add_option("--iso-clip-fraction", o->iso_clip_fraction,
                  "The local rule: the same for a boundary whose echo is clipped (its crest at the data's maximum, "
                  "where at least 1 % of the samples lie): its true crest is higher (docs/real-data.md, \"Clipped "
                  "echoes\"); equal to --iso-fraction turns the rule off")
      ->capture_default_str()
      ->check(real_range(0, 1));
  sub->add_option("--iso-floor-fraction", o->iso_floor_fraction,
                  "The local rule: the same for a boundary whose dark side lies at the data's floor (where at least "
                  "1 % of the samples lie) when the boundaries' crests are peaks, not plateaus (docs/parameters.md, "
                  "\"Fluid at the floor\"); off by default (equal to --iso-fraction): it helped faint heads in fluid at 0 and cost "
                  "others as much")
      ->capture_default_str()
      ->check(real_range(0, 1));
  sub->add_option("--iso-bulk-spread", o->iso_bulk_spread,
                  "The local rule: where the isovalue lies in the upper tail of the data's most common brightness "
                  "(the bulk: its mode + this x its half-width at half maximum) and the echoes' crests stand above "
                  "it (well above a distinct bulk), the isovalue is raised to there, so the bulk's speckle is not "
                  "drawn (docs/parameters.md, \"The isovalue above the bulk\"); 0 turns the rule off")
      ->capture_default_str()
      ->check(real_range(0, 10));
  sub->add_option("--iso-field-sigma", o->iso_field_sigma,
                  "The local rule: Gaussian spread (mm) of the boundaries' isovalues into the isovalue field, across "
                  "the beam (objects of different brightness lie side by side)")
      ->capture_default_str()
      ->check(real_range(0.5, 1000, "mm"));
  sub->add_option("--iso-field-depth-sigma", o->iso_field_depth_sigma,
                  "The same along the beam (gain drifts slowly with depth; a short one levels a bone's echo against "
                  "its own shadow: docs/parameters.md)")
      ->capture_default_str()
      ->check(real_range(0.5, 1000, "mm"));
  sub->add_option("--iso-climb", o->iso_climb,
                  "--iso auto: how far (mm) each strong edge climbs at most to its echo's crest and down to its "
                  "trough, and never fewer than 6 voxels; 0: 6 voxels whatever the spacing (docs/parameters.md, "
                  "\"The climb in millimetres\")")
      ->capture_default_str()
      ->check(real_range(0, 100, "mm"));
  sub->add_flag("--no-iso-field", o->no_iso_field,
                "With the local rule: one isovalue (the median of the edges') instead of a field that follows "
                "depth and local brightness");
  sub->add_option("--mask", o->mask,
                  "Scanned region: auto (the solid zero fill at the border is unscanned, except dark fluid: zeros "
                  "between echoes, or around an object inside the data's hull; float data whose fill is another "
                  "value, such as -80 dB, have it found and counted as 0), none, or a volume FILE whose "
                  "nonzero voxels are scanned; unscanned voxels get opacity 0 (docs/real-data.md)")
      ->capture_default_str()
      ->type_name("FILE|auto|none");
  sub->add_option("--bone-cue", o->bone_cue,
                  "Variational: weight the edge strength by the bone cue, a bright echo with an acoustic shadow "
                  "beneath it along the beam (docs/numerics.md, \"The bone cue\"); auto: on when at least twice as "
                  "many of the data's strong edges fall in brightness along the beam (echo over shadow) as rise "
                  "(fluid over tissue); off with --literal. Default off: on the held-out spine phantoms auto raised "
                  "the mean F1 but lost one spine, and on a real spine sweep (LNMAXI) it lost a lamina "
                  "(docs/parameters.md)")
      ->capture_default_str()
      ->type_name("auto|on|off");
  add_beam_axis_option(sub, o->beam_axis,
                       "The axis the beam runs along, depth growing with the index (the transducer on that axis's "
                       "first face): auto takes the data's own (speckle finest along the beam, brightness changing "
                       "with depth, a fan's sector opening along it; docs/real-data.md, \"The beam axis\"); the near field, the mask's dark-fluid test, "
                       "the depth clip, the isovalue field and the shadow walls follow it");
  sub->add_option("--shadow-walls", o->shadow_walls,
                  "remove: the edges of acoustic shadows' sides (across the beam, a shadow on their dark side: dark, "
                  "under something bright further up the beam) are weighted down like the bone cue's; keep: drawn "
                  "like any edge (host/shadow_walls.hpp)")
      ->capture_default_str()
      ->type_name("remove|keep")
      ->check(one_of({"remove", "keep"}));
  sub->add_option("--echo-underside", o->echo_underside,
                  "auto: where the data's strong edges are steps up from dark fluid (they rise along the beam at "
                  "least 5 x as often as they fall: a head or a face in fluid, not bone), the far side of a thin "
                  "bright echo (falling along the beam, and under the isovalue again within 3 mm up the beam: a "
                  "skull's underside) is weighted down like a shadow's wall; keep: drawn like any edge "
                  "(docs/parameters.md, \"The underside of a thin echo\"); with --shadow-walls remove")
      ->capture_default_str()
      ->type_name("auto|keep")
      ->check(one_of({"auto", "keep"}));
  sub->add_option("--near-field", o->near_field,
                  "remove: the bright layered band under the probe (skin, fat, muscle) is found from the depth "
                  "profile and held at u = 0 like unscanned voxels, with its echoes (fainter copies of the band's "
                  "layers at about twice their depth, up to three) when there are any; keep: classify it like the rest")
      ->capture_default_str()
      ->type_name("remove|keep")
      ->check(one_of({"remove", "keep"}));
  sub->add_option("--band-sheet", o->band_sheet,
                  "hold: when the variational shell draws a sheet just under a removed near-field band (in the "
                  "3 mm under it, one patch on at least 15 % of its beam lines: the band's fading copies, not anatomy), "
                  "those 3 mm are held at u = 0 like the band and the volume solved again; the same, 3-8 mm under it, "
                  "for a flat sheet (at one depth under the band across its lines: a fascia under the fat, not an "
                  "object near the probe), held down its drawn run; and where no band was removed (or none found), "
                  "a sheet in the first 12 mm under the skin line that follows it on at least 30 % of the lines under "
                  "the probe (the skin's lower edge, a fascia: a layer under the probe), with its pieces at the same "
                  "depth; not with --depth-clip or in a small volume; keep: left as drawn (docs/parameters.md, \"The "
                  "band's underside\", \"Layers under the probe where no band was removed\")")
      ->capture_default_str()
      ->type_name("hold|keep")
      ->check(one_of({"hold", "keep"}));
  sub->add_option("--reverb", o->reverb,
                  "remove: when a flat reflector's echo repeats at equal spacing below it along the beam "
                  "(reverberation), the region below each beam line's first strong echo is held at u = 0; keep: "
                  "classify it like the rest (docs/real-data.md)")
      ->capture_default_str()
      ->type_name("remove|keep")
      ->check(one_of({"remove", "keep"}));
  sub->add_option("--depth-clip", o->depth_clip,
                  "Keep only the scanned voxels MIN to MAX mm below the skin line (each beam line's first scanned "
                  "voxel, along the data's beam axis): a clip that follows the sweep; the rest is held at u = 0 like "
                  "unscanned voxels (MAX may be inf)")
      ->type_name("MIN,MAX");
  sub->add_option("--small-volume", o->small_volume_mm,
                  "A volume whose smallest extent is below this many mm gets its default length scales (--sigma, "
                  "--grad-sigma, --shell, --iso-field-sigma, the auto isovalue's lowpass) scaled by that extent / "
                  "this, and --beta and --kappa (squared lengths) by its square; those given stay; 0: never "
                  "(docs/parameters.md)")
      ->capture_default_str()
      ->check(real_range(0, 1e6, "mm"));
  sub->add_option("--method", o->method,
                  "variational: the paper's variational classifier; levoy: Levoy's isovalue-contour opacity")
      ->capture_default_str()
      ->check(one_of({"variational", "levoy"}));
  sub->add_option("--sigma", o->sigma,
                  "Lowpass sigma in mm: v~ of the variational terms (default 1), or Levoy's input (default 0: raw)")
      ->check(real_range(0, INFINITY, "mm"));
  auto* g = sub->add_option_group("variational", "The paper's functional (normalised intensities, per mm)");
  g->add_option("--alpha", o->vp.alpha, "Weight of the isovalue term F_iso")->capture_default_str()
      ->check(real_range(0, 1e6));
  g->add_option("--beta", o->vp.beta, "Weight of the tangential term F_tan")->capture_default_str()
      ->check(real_range(0, 1e6));
  g->add_option("--gamma", o->vp.gamma, "Weight of the indication term F_ind")->capture_default_str()
      ->check(real_range(0, 1e6, "", Ends::OpenLow));
  g->add_option("--omega", o->vp.omega, "Blend of v and v~ in F_iso (1: v only)")->capture_default_str()
      ->check(real_range(0, 1));
  g->add_option("--delta", o->vp.delta, "Share of F_ind independent of |grad v| (> 0)")->capture_default_str()
      ->check(real_range(0, 1, "", Ends::OpenLow));
  g->add_option("--epsilon", o->vp.epsilon, "Regulariser of 1/(|grad v|^2 + epsilon) in F_iso")->capture_default_str()
      ->check(real_range(1e-6, 1e6));
  g->add_option("--u-ind", o->vp.u_ind, "Opacity that F_ind pulls toward")->capture_default_str()
      ->check(real_range(0, 1, "", Ends::OpenLow));
  g->add_option("--kappa", o->vp.kappa,
                "Weight of an added isotropic smoothness term kappa |grad u|^2; 0: the paper's functional")
      ->capture_default_str()
      ->check(real_range(0, 1e6));
  g->add_flag("--literal", o->literal,
              "The paper's functional exactly: --grad-sigma 0 --kappa 0 --shell 0 --edge-share 0 --sharpen 0 --max-gain 0 "
              "(overrides them), "
              "with the earlier study's weights for it (alpha 0.2 beta 3 gamma 3.5 omega 0.6 delta 0.02) unless given");
  g->add_option("--shell", o->vp.thickness_mm,
                "Shell thickness in mm (full width at half maximum across the surface, at least 2 voxels); F_iso's "
                "weight rises as (distance / half the thickness)^(2 profile-power); 0: the paper's F_iso")
      ->capture_default_str()
      ->check(real_range(0, 1000, "mm"));
  g->add_option("--shell-shift", o->vp.shell_shift_mm,
                "The shell's centre moved this far (mm) from the isosurface toward its bright side, onto the boundary "
                "echo's crest (docs/numerics.md, \"The shell on the echo\"); 0: centred on the isosurface")
      ->capture_default_str()
      ->check(real_range(0, 10, "mm"));
  g->add_option("--profile-power", o->vp.profile_power,
                "Power of the shell's normalised squared distance in F_iso (1: the paper's 1/(1+d^2) fall-off)")
      ->capture_default_str()
      ->check(real_range(1, 4));
  g->add_option("--edge-share", o->vp.edge_share,
                "The reference edge gradient is the median |grad v| of this top share of the scanned voxels; F_ind's "
                "edge weight, beta, kappa and epsilon are relative to it; 0: the paper's absolute units")
      ->capture_default_str()
      ->check(real_range(0, 0.5));
  g->add_option("--edge-split", o->vp.edge_split,
                "A small object's walls: where the median |grad v| of the top 1 % of the scanned voxels is at least "
                "this x the top --edge-share's, the strongest edges are few (a small cyst's walls among speckle) and "
                "the reference edge gradient is the top 1 %'s (docs/parameters.md, \"A small object's walls\"); 0: off")
      ->capture_default_str()
      ->check(real_range(0, 100));
  g->add_option("--edge-split-from", o->vp.edge_split_from,
                "Where that ratio lies between this and --edge-split, the reference edge gradient is blended between "
                "the two medians (the top 1 %'s weight rising linearly from 0 to 1), so that it does not jump where the "
                "ratio crosses one threshold; 0 (or not below --edge-split): a switch at --edge-split")
      ->capture_default_str()
      ->check(real_range(0, 100));
  g->add_option("--weight-cap", o->vp.weight_cap, "Upper bound of the shell F_iso weight (u outside the shell < 1/(1+cap))")
      ->capture_default_str()
      ->check(real_range(1, 1e12));
  g->add_option("--max-gain", o->vp.max_gain,
                "u_ind from the data: u scaled so the median crest of the shell reaches u_ind, by at most this "
                "factor (the system is linear in u_ind); 0: off")
      ->capture_default_str()
      ->check(real_range(0, 100));
  g->add_option("--sharpen", o->vp.sharpen_iterations,
                "Fixed-point steps of the sharpening term (a double well pulling u to 0 or u_ind, its barrier at "
                "--sharpen-barrier x the linear solution's crest); 0: the linear functional")
      ->capture_default_str()
      ->check(int_range(0, 10));
  g->add_option("--sharpen-lambda", o->vp.sharpen_lambda, "Weight of the sharpening term")
      ->capture_default_str()
      ->check(real_range(0, 1e6));
  g->add_option("--sharpen-barrier", o->vp.sharpen_barrier,
                "The sharpening term's barrier, as a fraction of the linear solution's crest")
      ->capture_default_str()
      ->check(real_range(0.05, 1));
  g->add_option("--edge-power", o->vp.edge_power, "Power of the relative edge strength in F_ind's weight")
      ->capture_default_str()
      ->check(real_range(0, 8));
  g->add_option("--grad-sigma", o->vp.grad_sigma_mm,
                "Take |grad v| (F_iso, F_ind) from v lowpassed by this sigma in mm; 0: the paper's literal terms. "
                "Default: 1.5 mm, or where the strong edges are mostly echoes over darker data (bone), 3 x the "
                "speckle's size across the beam within 1.25-1.5 mm "
                "(docs/numerics.md, \"The gradient's lowpass from the speckle\")")
      ->check(real_range(0, INFINITY, "mm"));
  g->add_option("--tol", o->sp.tol, "Stop at this relative residual")->capture_default_str()
      ->check(real_range(0, 1, "", Ends::Open));
  g->add_option("--max-cycles", o->sp.max_cycles, "Iterations before giving up (exit 3)")->capture_default_str()
      ->check(int_range(1, 100000));
  g->add_option("--levels", o->sp.max_levels, "Multigrid levels (2: the paper's two-level scheme)")->capture_default_str()
      ->check(int_range(1, 64));
  g->add_option("--cycle", o->cycle, "pcg: V-cycle-preconditioned CG; v: plain V-cycles")
      ->capture_default_str()
      ->check(one_of({"pcg", "v"}));
  g->add_option("--smoother", o->smoother,
                "gs: Gauss-Seidel (2 colours of z-planes, rows in order, on CPUs; 8 colours on GPUs); jacobi: weighted Jacobi")
      ->capture_default_str()
      ->check(one_of({"gs", "jacobi"}));
  g->add_flag("--no-fmg", o->no_fmg, "Start from u = 0 instead of a full-multigrid guess");
  g->add_option("--init", o->init,
                "Warm start from this opacity volume (the linear functional only: with --sharpen > 0, the default, "
                "every solve starts cold so the result does not depend on the start)");
  g->add_option("--warm-start", o->warm_start,
                "A 3D+t sequence (a 4-D NRRD, every frame classified when no --frame is given): on, each frame's "
                "solve starts from the previous frame's linear solution instead of full multigrid (4-28 % faster per "
                "frame, docs/formats.md); off, every frame exactly as --frame K classifies it")
      ->capture_default_str()
      ->check(one_of({"on", "off"}));
  g->add_option("--per-frame-files", o->per_frame,
                "A 3D+t sequence: also write each frame's opacity to its own 3-D file, the one run of '#' in "
                "PATTERN replaced by the zero-padded frame number (e.g. u-###.nrrd)")
      ->type_name("PATTERN");
  g->add_flag("--stats", o->stats, "Print the residual history");
  auto* lg = sub->add_option_group("levoy", "Levoy's classifier");
  lg->add_option("--thickness", o->thickness, "Transition thickness r in voxels")
      ->capture_default_str()
      ->check(real_range(0, 100, "voxels", Ends::OpenLow));
  sub->add_flag("--compress", o->compress, "Compress the output");
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  add_device_option(sub, o->device);
  o->raw.add_to(sub);
  o->non_finite.add_to(sub);
  sub->callback([&action, o, sub] {
    // The command's options and its groups' (--alpha ... live in a group).
    std::vector<const CLI::App*> apps{sub};
    for (const CLI::App* g : sub->get_subcommands([](const CLI::App* a) { return a->get_name().empty(); }))
      apps.push_back(g);
    for (const CLI::App* a : apps)
      for (const CLI::Option* opt : a->get_options())
        if (opt->count() > 0) o->given.insert("--" + opt->get_single_name());
    action = [o] { return run_classify(*o); };
  });
}

}  // namespace softshell::cli
