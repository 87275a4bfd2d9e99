// `softshell view IN`: the interactive viewer (viewer/viewer_app.*). A raw
// ultrasound volume is classified first with the defaults. Built into the
// viewer library; registered only when the viewer is built.
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <set>
#include <tuple>

#include "cli_common.hpp"
#include "cli_render_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "io.hpp"
#include "params_file.hpp"
#include "presets.hpp"
#include "bone_cue.hpp"
#include "progress.hpp"
#include "text.hpp"
#include "viewer_app.hpp"

namespace softshell::cli {
namespace {

struct ViewOptions {
  std::string in, device, size = "1200x800", view = "0,0", crop, iso = "auto", screenshot, renderer;
  std::string beam_axis = "auto";  // --beam-axis, as classify's
  std::string colour_map;  // solid | depth; empty: the preset's (default solid)
  std::string light;       // AZ,EL; empty: the preset's
  std::string params, volume, save_params, save_u, save_mesh, cursor;
  float overlay = 0.5f;
  std::set<std::string> given;  // long option names given on the command line
  bool screenshot_panel = false;
  int frames = 0;
  std::optional<std::size_t> frame;  // --frame K: 3D+t
  double play = 0;                   // --play FPS
  bool quiet = false;
  SplatViewOptions splat;
};

// --params FILE: every key the command line does not give (host/params_file.hpp).
ViewOptions with_params_file(ViewOptions o, viewer::ViewerOptions& v, VariationalParams& weights, bool& have_weights) {
  if (o.params.empty()) return o;
  const ParamsFile f = read_params_file(o.params);
  const auto free = [&](const char* key, const char* option) { return f.find(key) && !o.given.count(option); };
  const auto list = [&](const char* key) {
    std::string t;
    const std::vector<double> values = *f.numbers(key);
    for (double x : values) t += (t.empty() ? "" : ",") + format_number(x);
    return t;
  };
  if (free("iso", "--iso")) o.iso = *f.find("iso");
  if (free("preset", "--preset")) o.splat.preset = *f.find("preset");
  // What the file sets counts as given: a preset does not override it.
  for (const auto& [key, option] : {std::pair<const char*, const char*>{"threshold", "--threshold"},
                                    {"colour_map", "--colour-map"}, {"light", "--light"}})
    if (f.find(key)) o.given.insert(option);
  // --method on the command line picks the renderer too: the file's does not override it.
  if (free("renderer", "--renderer") && !o.given.count("--method")) o.renderer = *f.find("renderer");
  if (free("colour_map", "--colour-map")) o.colour_map = *f.find("colour_map");
  if (free("threshold", "--threshold")) o.splat.threshold = float(*f.number("threshold"));
  if (free("crop", "--crop")) o.crop = list("crop");
  if (free("view", "--view")) o.view = list("view");
  if (f.find("mesh_level")) v.mesh_level = float(*f.number("mesh_level"));
  if (f.find("distance")) v.distance = float(*f.number("distance"));
  if (f.find("light")) v.light = *f.numbers("light");
  if (f.find("colour")) v.colour = *f.numbers("colour");
  if (f.find("background")) v.background = *f.numbers("background");
  const std::pair<const char*, double*> keys[] = {{"sigma", &weights.sigma_mm}, {"alpha", &weights.alpha},
                                                  {"beta", &weights.beta},      {"gamma", &weights.gamma},
                                                  {"omega", &weights.omega},    {"delta", &weights.delta},
                                                  {"epsilon", &weights.epsilon}, {"kappa", &weights.kappa},
                                                  {"shell_shift", &weights.shell_shift_mm}};
  for (const auto& [key, value] : keys)
    if (f.find(key)) *value = *f.number(key), have_weights = true;
  return o;
}

int run_view(const ViewOptions& given_options) {
  viewer::ViewerOptions v;
  VariationalParams weights;
  weights.sigma_mm = 1.0;  // classify's default
  bool have_weights = false;
  const ViewOptions o = with_params_file(given_options, v, weights, have_weights);
  std::tie(v.width, v.height) = parse_size(o.size, "--size");
  std::tie(v.azimuth, v.elevation) = parse_view(o.view, "--view");
  v.settings = o.splat.settings();
  v.params = o.splat.params();
  // A preset first (what the command line or the parameters file gives wins).
  BoneCueMode bone_cue = BoneCueMode::Off;
  if (!o.splat.preset.empty()) {
    const Preset& p = preset_or_throw(o.splat.preset);
    apply_preset(p, v.settings, v.params, o.given);
    parse_bone_cue_mode(p.bone_cue, bone_cue);
    v.preset = p.name;
  }
  if (!o.light.empty()) std::tie(v.settings.light_azimuth, v.settings.light_elevation) = parse_light(o.light, "--light");
  if (!o.crop.empty()) parse_crop(o.crop, v.settings);
  // --method mc / raycast start with that renderer; --renderer (initial;
  // the panel switches) overrides --method.
  if (o.splat.method == "mc") v.renderer = viewer::ViewRenderer::Mesh;
  if (o.splat.method == "raycast") v.renderer = viewer::ViewRenderer::Raycast;
  if (o.renderer == "splat" || o.renderer == "oriented") {
    v.settings.method = viewer::SplatMethod::Oriented;
    v.renderer = viewer::ViewRenderer::Splats;
  } else if (o.renderer == "isosplat" || o.renderer == "isotropic") {
    v.settings.method = viewer::SplatMethod::Isotropic;
    v.renderer = viewer::ViewRenderer::Splats;
  } else if (o.renderer == "mc") {
    v.renderer = viewer::ViewRenderer::Mesh;
  } else if (o.renderer == "raycast") {
    v.renderer = viewer::ViewRenderer::Raycast;
  } else if (!o.renderer.empty()) {
    throw InputError("--renderer " + o.renderer + ": unknown (renderers: splat, isosplat, mc, raycast)");
  }
  if (o.frames < 0) throw InputError("--frames must be >= 0");
  if (!o.screenshot.empty() && o.frames == 0) throw InputError("--screenshot needs --frames N");
  if (!o.screenshot.empty()) {
    ensure_distinct_output(o.in, o.screenshot);
    check_output(o.screenshot, OutputKind::Png, "--screenshot");  // before the splats are made
  }
  for (const std::string* out : {&o.save_params, &o.save_u, &o.save_mesh}) {
    if (out->empty()) continue;
    if (o.frames == 0) throw InputError("--save-params, --save-u and --save-mesh need --frames N");
    ensure_distinct_output(o.in, *out);
  }
  if (!o.save_u.empty()) check_output(o.save_u, OutputKind::Volume, "--save-u");
  if (!o.save_mesh.empty() && (o.save_mesh.size() < 4 || o.save_mesh.substr(o.save_mesh.size() - 4) != ".ply")) throw InputError("--save-mesh: expected a .ply file name");
  if (!o.save_params.empty() && o.save_params == o.params) throw InputError("--save-params: the same file as --params");
  if (!(o.overlay >= 0 && o.overlay <= 1)) throw InputError("--overlay must be in [0, 1]");
  if (!o.cursor.empty()) {
    int x = 0, y = 0, z = 0, n = 0;
    if (std::sscanf(o.cursor.c_str(), "%d,%d,%d%n", &x, &y, &z, &n) != 3 || n != int(o.cursor.size()) || x < 0 ||
        y < 0 || z < 0)
      throw InputError("--cursor: expected X,Y,Z voxel indices >= 0, got '" + o.cursor + "'");
    v.cursor = {x, y, z};
  }
  v.overlay = o.overlay;
  if (!o.colour_map.empty()) {
    if (o.colour_map != "solid" && o.colour_map != "depth") throw InputError("--colour-map: expected solid or depth");
    v.settings.depth_colour = o.colour_map == "depth";
  }
  v.iso_text = o.iso;
  v.save_params = o.save_params, v.save_u = o.save_u, v.save_mesh = o.save_mesh;
  v.frames = o.frames;
  v.play_fps = o.play;
  v.screenshot = o.screenshot;
  v.screenshot_panel = o.screenshot_panel;
  v.quiet = o.quiet;
  std::optional<progress::Stage> stage(std::in_place, "view: load");
  Runtime rt(o.device);
  viewer::OpacityInput input =
      viewer::load_opacity(rt, o.in, o.splat.input_kind(), o.iso, have_weights ? &weights : nullptr, o.frame, bone_cue,
                           beam_axis_option(o.beam_axis));
  if (!o.volume.empty()) viewer::attach_bmode(input, o.volume);
  const std::string settled =
      settle_orientation(v.params, !input.bmode.data.empty(), o.given.count("--orientation") > 0, o.in);
  if (!settled.empty() && !o.quiet) std::cout << "view: " << settled << '\n';
  for (int a = 0; a < 3; ++a)
    if (v.cursor[a] >= int(input.u.dims[a]))
      throw InputError("--cursor: outside the volume (" + dims_text(input.u.dims) + ")");
  stage.reset();
  if (!o.quiet) std::cout << "view: " << input.note << '\n';
  return viewer::run_viewer(rt, std::move(input), v);
}

}  // namespace

void add_view_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<ViewOptions>();
  auto* sub = app.add_subcommand(
      "view",
      "Interactive viewer: oriented splats (or isotropic splats, the Marching Cubes mesh, ray casting) with an orbit "
      "camera; a panel docked on the left (histogram with the isovalue, re-classification, rendering, cut-away, "
      "slices, save u / mesh / parameters) and three slice views under the 3-D view (axial, coronal, sagittal: the "
      "B-mode data with u overlaid, linked by a 3-D cursor). Drag rotates, right-drag pans, the wheel zooms; a click "
      "on a slice moves the cursor, the wheel over a slice pages it; S saves a screenshot of the 3-D view, R resets "
      "the view, Esc quits (docs/rendering.md).");
  sub->add_option("IN", o->in, "Opacity volume (float in [0, 1]) or raw ultrasound volume (classified first)")
      ->required();
  sub->add_option("--size", o->size, "Window size")->capture_default_str()->type_name("WxH");
  sub->add_option("--view", o->view, "Initial camera azimuth,elevation in degrees (as for render)")
      ->capture_default_str()
      ->type_name("AZ,EL");
  sub->add_option("--crop", o->crop, "Initial crop box, fractions per axis")->type_name("X0,X1,Y0,Y1,Z0,Z1");
  sub->add_option("--iso", o->iso, "Isovalue for classifying a raw volume (its units, or auto)")->capture_default_str();
  add_beam_axis_option(sub, o->beam_axis, "Classifying a raw volume: the axis its beam runs along (as classify's)");
  sub->add_option("--renderer", o->renderer,
                  "Initial renderer (the panel switches): splat (oriented splats), isosplat (isotropic splats), mc "
                  "(Marching Cubes mesh at level 0.2) or raycast (the OpenCL ray caster); overrides --method")
      ->type_name("splat|isosplat|mc|raycast")
      ->check(one_of({"splat", "isosplat", "mc", "raycast"}));
  sub->add_option("--frames", o->frames, "Draw N frames, then quit (for scripts and tests); prints the mean time per frame after the first")
      ->check(int_range(0, 1000000));
  sub->add_option("--frame", o->frame,
                  "3D+t (a 4-D NRRD): the frame to start on (an opacity sequence: all frames are loaded and the "
                  "panel's slider and play button step through them); a sequence of raw frames needs one, "
                  "classified alone")
      ->type_name("K");
  sub->add_option("--play", o->play,
                  "3D+t: play the opacity sequence from the start at this many frames per second (with --frames N, "
                  "one sequence frame per drawn frame)")
      ->type_name("FPS")
      ->check(real_range(0, 120));
  sub->add_option("--screenshot", o->screenshot, "With --frames: save the last frame's 3-D view alone, at the window size, as PNG");
  sub->add_flag("--screenshot-panel", o->screenshot_panel,
                "Save the whole window as --screenshot instead (panel, 3-D view with scale bar and axes, slice views) and print "
                "where the slice images and the histogram are");
  sub->add_option("--params", o->params,
                  "Parameters file (as the panel's 'save parameters' writes it, docs/rendering.md): isovalue, "
                  "classification weights, renderer, threshold, light, colours, crop, camera; options given here win")
      ->type_name("FILE");
  sub->add_option("--volume", o->volume,
                  "B-mode volume for the slice views and --orientation data when IN is an opacity volume (same "
                  "dims); without it the slices show u")
      ->type_name("V");
  sub->add_option("--cursor", o->cursor, "Initial 3-D cursor (voxel indices): the slices shown; default the centre")
      ->type_name("X,Y,Z");
  sub->add_option("--colour-map", o->colour_map,
                  "solid: one colour (the default); depth: colour by depth along the beam (z), light near the "
                  "transducer to dark red-brown deep (splats and mesh; the ray caster draws one colour)")
      ->type_name("solid|depth")
      ->check(one_of({"solid", "depth"}));
  sub->add_option("--light", o->light,
                  "Light direction from the view direction in degrees, azimuth (right +) and elevation (up +), each "
                  "in [-90, 90] (default -30,30; the panel moves it)")
      ->type_name("AZ,EL");
  sub->add_option("--overlay", o->overlay, "Initial opacity of the u overlay on the B-mode slices")
      ->capture_default_str()
      ->check(real_range(0, 1));
  sub->add_option("--save-params", o->save_params, "With --frames: save the parameters file at the end")
      ->type_name("FILE");
  sub->add_option("--save-u", o->save_u, "With --frames: save u (float, .nrrd/.mha/.mhd) at the end")->type_name("FILE");
  sub->add_option("--save-mesh", o->save_mesh, "With --frames: save the Marching Cubes mesh of u at the mesh level (PLY)")
      ->type_name("FILE.ply");
  o->splat.add_to(sub, view_methods());
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing but errors");
  add_device_option(sub, o->device);
  sub->callback([&action, o, sub] {
    for (const CLI::Option* opt : sub->get_options())
      if (opt->count() > 0) o->given.insert("--" + opt->get_single_name());
    action = [o] { return run_view(*o); };
  });
}

}  // namespace softshell::cli
