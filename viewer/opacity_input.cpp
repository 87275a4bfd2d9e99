// Opacity input for the renderers: read, and classify raw data.
#include "opacity_input.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <optional>
#include <sstream>

#include "auto_iso.hpp"
#include "bone_cue.hpp"
#include "shadow_walls.hpp"
#include "speckle.hpp"
#include "error.hpp"
#include "io.hpp"
#include "filter.hpp"
#include "host_memory.hpp"
#include "mask.hpp"
#include "memory_need.hpp"
#include "text.hpp"

namespace softshell::viewer {

bool looks_like_opacity(const Volume& v) {
  if (v.source_type != ScalarType::Float32 && v.source_type != ScalarType::Float64) return false;
  return std::all_of(v.data.begin(), v.data.end(), [](float f) { return f >= 0.0f && f <= 1.0f; });
}

OpacityInput load_opacity(Runtime& rt, const std::string& path, InputKind kind, const std::string& iso_text,
                          const VariationalParams* weights, std::optional<std::size_t> frame, BoneCueMode bone_cue,
                          int beam_axis) {
  OpacityInput in;
  Volume v;
  if (const std::size_t frames = read_any_header(path).frames; frames > 1) {
    // 3D+t: an opacity sequence is played (every frame kept); a raw one
    // needs a frame chosen, classified alone.
    const std::string range = " (0 to " + std::to_string(frames - 1) + ")";
    if (frame && *frame >= frames)
      throw input_error(path, "--frame " + std::to_string(*frame) + ": the file holds " + std::to_string(frames) +
                                  " frames" + range);
    std::vector<Volume> all = read_frames(path);
    for (const Volume& f : all)
      require_finite(f, path, "replace them first (e.g. softshell lowpass IN --sigma 0 --replace-non-finite 0 -o OUT)");
    const bool opacity = kind != InputKind::Raw && std::all_of(all.begin(), all.end(), looks_like_opacity);
    if (opacity) {
      in.frame = frame.value_or(0);
      in.u = all[in.frame];
      in.sequence = std::move(all);
      in.note = "opacity sequence " + path + ": " + std::to_string(frames) + " frames, frame " +
                std::to_string(in.frame);
      return in;
    }
    if (kind == InputKind::Opacity)
      throw input_error(path, "not an opacity sequence (expected float samples in [0, 1] in every frame); drop "
                              "--opacity to classify one frame");
    if (!frame)
      throw input_error(path, "a sequence of " + std::to_string(frames) + " raw 3-D frames: classify it first "
                              "(softshell classify " + path + " --iso auto -o U.nrrd, then view U.nrrd), or choose "
                              "one frame with --frame K" + range);
    v = std::move(all[*frame]);
  } else {
    v = read_volume(path, std::nullopt, frame);
  }
  require_finite(v, path, "replace them first (e.g. softshell lowpass IN --sigma 0 --replace-non-finite 0 -o OUT)");
  const bool opacity = kind == InputKind::Opacity || (kind == InputKind::Auto && looks_like_opacity(v));
  if (opacity) {
    if (!looks_like_opacity(v))
      throw input_error(path, "not an opacity volume (expected float samples in [0, 1], got " +
                                  std::string(scalar_type_name(v.source_type)) + "); drop --opacity to classify it");
    in.u = std::move(v);
    in.note = "opacity volume " + path;
    return in;
  }
  // As `softshell classify IN --iso auto` does: auto mask, near field
  // removed, auto isovalue, unscanned voxels filled for the lowpass and held
  // at u = 0; too wide a lowpass or too large a volume refused first.
  VariationalParams defaults;
  defaults.sigma_mm = 1.0;
  if (weights) defaults = *weights;
  check_lowpass_sigma(defaults.sigma_mm, v.spacing, "the classifier's lowpass sigma");
  check_lowpass_sigma(defaults.grad_sigma_mm, v.spacing, "the classifier's --grad-sigma");
  check_classify_memory(rt, path, v.dims, Classifier::Variational, true);
  // The host stages reuse each other's freed blocks; the free pages go back
  // to the kernel before the device work (host/host_memory.hpp).
  std::optional<KeepFreedMemory> keep_freed(std::in_place);
  in.bmode = v;  // before the near field is removed: the slices show the data as read
  MaskReport mr;
  MaskParams mp;
  if (beam_axis >= 0) mp.beam_axis = beam_axis;  // else z, as classify's
  // Float data whose fill is not 0: it becomes 0, as classify does (host/mask.hpp).
  in.fill = unscanned_fill_value(v);
  move_fill_to_zero(v, in.fill);
  in.mask = scanned_mask(v, mp, &mr);
  if (mr.unscanned == 0) in.mask.clear();
  if (in.fill != 0.0) darken_scanned_fill(v, in.mask);
  const std::vector<std::uint8_t> before = in.mask;
  NearFieldParams np;
  np.axis = beam_axis;  // the near field is an occluder (docs/real-data.md)
  const NearFieldReport nf = remove_near_field(v, in.mask, np);
  // The window under the band, held when the shell draws a sheet there (as classify does; host/mask.hpp).
  // A small volume's length scales shrink with it, as classify's do
  // (host/variational.hpp, small_volume_scale); and it has no skin window
  // (as classify).
  const double scale = small_volume_scale(v.dims, v.spacing, kSmallVolumeMm);
  BandSheetParams bsp;
  if (scale < 1.0) bsp.skin_mm = 0;
  const std::vector<std::uint8_t> underside =
      band_underside(v, nf, before, in.mask, bsp.window_mm, bsp.deep_mm, bsp.skin_mm);
  const std::vector<std::uint8_t>* mask = in.mask.empty() ? nullptr : &in.mask;
  // In place: the isovalue reads the scanned samples only, as classify does.
  if (mask) fill_unscanned_in_place(v, in.mask);
  // Given weights are the user's and stay as they are.
  if (!weights) scale_length_scales(defaults, scale);
  // The shadow walls' isovalue: with auto, shadow_test_iso's, as classify's
  // (host/auto_iso.hpp); else the isovalue.
  std::optional<double> wall_iso;
  if (iso_text == "auto") {
    // The local rule's field levelled out, as classify does (host/auto_iso.hpp).
    AutoIsoParams ap;
    scale_length_scales(ap, scale);
    ap.beam_axis = nf.axis;
    AutoIsoReport rep;
    in.iso = auto_iso_level_in_place(v, mask, ap, &rep);
    wall_iso = shadow_test_iso(rep, in.iso);
    in.data = std::move(v);
  } else {
    char* end = nullptr;
    in.iso = std::strtod(iso_text.c_str(), &end);
    if (iso_text.empty() || *end != '\0' || !std::isfinite(in.iso))
      throw InputError("--iso: expected a number in the input's intensity units or 'auto', got '" + iso_text + "'");
    std::cerr << iso_outside_data(in.bmode, in.iso);  // as classify warns; in.bmode: the samples as read
    in.iso -= in.fill;
    in.data = std::move(v);
  }
  in.params = defaults;
  // --grad-sigma's default from the data's speckle, as classify's (host/speckle.hpp);
  // also with given weights (a parameters file holds none, and classify
  // --params FILE takes the default too), not with the paper's functional.
  std::optional<GradSigmaChoice> grad_choice;
  if (!(weights && weights->literal())) {
    grad_choice = auto_grad_sigma(in.data, mask, nf.axis, scale);
    in.params.grad_sigma_mm = grad_choice->sigma_mm;
  }
  in.params.v_iso = in.data.intensity_map().to_unit(in.iso);
  // Shells on bright echoes' crests, as classify's default (host/crest.hpp);
  // not with the paper's functional.
  if (!(weights && weights->literal())) in.params.crest.ridge = kEchoCrestRidge, in.params.crest.axis = nf.axis;
  // The bone cue: classify's default is off (docs/parameters.md says why); a preset may set it.
  in.beam_axis = nf.axis;
  in.bone_cue = bone_cue;
  BoneCueParams bp;
  bp.axis = nf.axis;
  BoneCueReport br;
  // The walls of acoustic shadows weighted down, as classify does by default
  // (host/shadow_walls.hpp); not with the paper's functional.
  ShadowWallReport wr;
  keep_freed.reset();  // before the device work, as classify does
  if (!(weights && weights->literal())) {
    ShadowWallParams wp = shadow_wall_params(in.params, nf.axis);
    wp.underside = grad_choice && underside_applies(grad_choice->falling, grad_choice->rising);  // as classify's default
    in.walls = std::make_shared<const std::vector<float>>(
        shadow_wall_weight(rt, in.data, mask, wall_iso.value_or(in.iso), wp, &wr));
  }
  set_edge_weights(in.params, bone_cue_weights(in.data, mask, bone_cue, bp, &br), in.walls);
  in.u = reclassify(rt, in, in.params, nullptr, &in.report);  // keeps in.classifier
  BandSheetReport sheet;
  if (!underside.empty() && in.report.converged) {
    sheet = hold_band_sheet(in.u, underside, nf.axis, in.mask);
    if (sheet.held) {
      in.classifier.reset();  // its fixed voxels change: a new one, on the new mask
      in.u = reclassify(rt, in, in.params, nullptr, &in.report);
    }
  }
  in.classified = true;
  std::ostringstream note;
  note << "classified " << path << " (" << scalar_type_name(in.data.source_type) << (weights ? ") with the given weights: iso " : ") with the defaults: iso ")
       << std::setprecision(4) << in.iso + in.fill << (iso_text == "auto" ? " (auto)" : "") << ", " << in.report.cycles
       << " iterations, relative residual " << std::scientific << std::setprecision(2)
       << (in.report.residuals.empty() ? 0.0 : in.report.residuals.back())
       << (in.report.converged ? "" : " (NOT converged)") << ", bone cue " << (br.on ? "on" : "off")
       << ", shadow walls " << (in.walls ? "weighted down" : "kept");
  if (in.params.crest.ridge > 0 && in.classifier)
    note << ", " << in.classifier->crest().crests << " echo crests along " << "xyz"[in.params.crest.axis];
  if (grad_choice)
    note << ", gradient lowpass " << std::fixed << std::setprecision(2) << grad_choice->sigma_mm << " mm ("
         << (grad_choice->echoes ? "from the speckle" : "the strong edges are no echoes") << ")";
  if (sheet.patches > 0 || sheet.deep_patches > 0) {
    const auto share = [&](std::size_t lines) { return 100.0 * double(lines) / double(sheet.lines); };
    note << ", the band's underside held (" << std::fixed << std::setprecision(0);
    if (sheet.patches > 0) note << "a sheet on " << share(sheet.held_lines) << " % of its lines";
    if (sheet.patches > 0 && sheet.deep_patches > 0) note << ", ";
    if (sheet.deep_patches > 0) note << "a flat sheet deeper under it on " << share(sheet.deep_lines) << " % of its lines";
    note << ")";
  }
  if (sheet.skin_sheets > 0)
    note << ", " << sheet.skin_sheets << (sheet.skin_sheets == 1 ? " layer" : " layers")
         << " under the probe held (a sheet following the skin line on " << std::fixed << std::setprecision(0)
         << 100.0 * double(sheet.skin_sheet_lines) / double(std::max<std::size_t>(sheet.skin_lines, 1))
         << " % of the lines without a band)";
  in.note = note.str();
  return in;
}

void attach_bmode(OpacityInput& in, const std::string& path) {
  std::vector<Volume> frames = read_frames(path);
  if (frames.size() > 1 && frames.size() != in.sequence.size())
    throw input_error(path, "--volume holds " + std::to_string(frames.size()) + " frames, the opacity " +
                                std::to_string(std::max<std::size_t>(in.sequence.size(), 1)));
  for (const Volume& f : frames) require_finite(f, path, "the B-mode volume must be finite");
  Volume b = frames.size() > 1 ? frames[in.frame] : std::move(frames.front());
  if (b.dims != in.u.dims)
    throw input_error(path, "--volume has dims " + dims_text(b.dims) + ", the opacity " + dims_text(in.u.dims));
  if (frames.size() > 1) in.bmode_sequence = std::move(frames);
  in.bmode = std::move(b);
}

bool set_bone_cue(OpacityInput& in, BoneCueMode mode) {
  if (!in.classified) return false;
  BoneCueParams bp;
  bp.axis = in.beam_axis;
  BoneCueReport br;
  set_edge_weights(in.params, bone_cue_weights(in.data, in.mask.empty() ? nullptr : &in.mask, mode, bp, &br),
                   in.walls);
  in.bone_cue = mode;
  return br.on;
}

Volume reclassify(Runtime& rt, OpacityInput& in, const VariationalParams& p, const Volume* init,
                  SolveReport* report) {
  if (in.classifier && in.classifier->can_update(p)) {
    in.classifier->update(p);
  } else {
    in.classifier.reset();  // free its device memory before the new one is built
    in.classifier = std::make_shared<VariationalClassifier>(rt, in.data, p, SolverParams{},
                                                            in.mask.empty() ? nullptr : &in.mask);
    // Every slider re-solves: keep the linear solution to start from.
    in.classifier->keep_resolve_start(true);
  }
  return in.classifier->solve(report, init, true);
}

}  // namespace softshell::viewer
