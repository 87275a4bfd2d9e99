// `softshell view IN`: the interactive viewer (viewer/viewer_app.*). A raw
// ultrasound volume is classified first with the defaults. Built into the
// viewer library; registered only when the viewer is built.
#include <iostream>
#include <memory>
#include <optional>
#include <tuple>

#include "cli_common.hpp"
#include "cli_render_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "progress.hpp"
#include "viewer_app.hpp"

namespace softshell::cli {
namespace {

struct ViewOptions {
  std::string in, device, size = "1200x800", view = "0,0", crop, iso = "auto", screenshot, renderer;
  bool screenshot_panel = false;
  int frames = 0;
  bool quiet = false;
  SplatViewOptions splat;
};

int run_view(const ViewOptions& o) {
  viewer::ViewerOptions v;
  std::tie(v.width, v.height) = parse_size(o.size, "--size");
  std::tie(v.azimuth, v.elevation) = parse_view(o.view, "--view");
  v.settings = o.splat.settings();
  v.params = o.splat.params();
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
  v.frames = o.frames;
  v.screenshot = o.screenshot;
  v.screenshot_panel = o.screenshot_panel;
  v.quiet = o.quiet;
  std::optional<progress::Stage> stage(std::in_place, "view: load");
  Runtime rt(o.device);
  viewer::OpacityInput input = viewer::load_opacity(rt, o.in, o.splat.input_kind(), o.iso);
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
      "camera and a panel (renderer, cut-away, re-classification). "
      "Drag rotates, right-drag pans, the wheel zooms; S saves a screenshot, R resets the view, Esc quits.");
  sub->add_option("IN", o->in, "Opacity volume (float in [0, 1]) or raw ultrasound volume (classified first)")
      ->required();
  sub->add_option("--size", o->size, "Window size")->capture_default_str()->type_name("WxH");
  sub->add_option("--view", o->view, "Initial camera azimuth,elevation in degrees (as for render)")
      ->capture_default_str()
      ->type_name("AZ,EL");
  sub->add_option("--crop", o->crop, "Initial crop box, fractions per axis")->type_name("X0,X1,Y0,Y1,Z0,Z1");
  sub->add_option("--iso", o->iso, "Isovalue for classifying a raw volume (its units, or auto)")->capture_default_str();
  sub->add_option("--renderer", o->renderer,
                  "Initial renderer (the panel switches): splat (oriented splats), isosplat (isotropic splats), mc "
                  "(Marching Cubes mesh at level 0.2) or raycast (the OpenCL ray caster); overrides --method")
      ->type_name("splat|isosplat|mc|raycast")
      ->check(one_of({"splat", "isosplat", "mc", "raycast"}));
  sub->add_option("--frames", o->frames, "Draw N frames, then quit (for scripts and tests)")
      ->check(int_range(0, 1000000));
  sub->add_option("--screenshot", o->screenshot, "With --frames: save the last frame (without the panel) as PNG");
  sub->add_flag("--screenshot-panel", o->screenshot_panel, "Draw the control panel into the --screenshot too");
  o->splat.add_to(sub, view_methods());
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing but errors");
  add_device_option(sub, o->device);
  sub->callback([&action, o] { action = [o] { return run_view(*o); }; });
}

}  // namespace softshell::cli
