// `softshell render IN -o OUT.png`: oriented (or isotropic) splats of an
// opacity volume drawn by the OpenGL renderer of viewer/ into a hidden GLFW
// window (headless under `xvfb-run -a`). Built into the viewer library; the
// CLI registers it only when the viewer is built (SOFTSHELL_HAVE_VIEWER).
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <set>
#include <tuple>
#include <sstream>
#include <vector>

#include "cli_common.hpp"
#include "cli_render_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "progress.hpp"
#include "headless.hpp"
#include "image.hpp"
#include "text.hpp"
#include "presets.hpp"
#include "bone_cue.hpp"

namespace softshell::cli {
namespace {

struct RenderOptions {
  std::string in, out, device, size = "400x400", view = "0,0", crop, iso = "auto", colour_map, light, legend = "on";
  std::string beam_axis = "auto";  // --beam-axis, as classify's
  std::string volume;  // --volume: the B-mode behind an opacity input (for --orientation data)
  std::set<std::string> given;  // long option names given on the command line
  int turntable = 0, benchmark = 0;
  std::optional<std::size_t> frame;  // 3D+t: one frame; default every frame (splats)
  bool quiet = false;
  SplatViewOptions splat;
  std::shared_ptr<RaycastRenderOptions> raycast;  // --method raycast (cmd_figures.cpp)
  double level = 0.2;                             // --method mc (cmd_render_methods.cpp)
};

// OUT.png -> OUT-007.png for turntable frame 7, or OUT's own pattern: one
// %d conversion (an optional 0 flag and width, e.g. %03d) and %% for a
// literal %. The pattern is expanded here, never handed to printf: a path
// is not a format string.
std::string frame_path(const std::string& out, int i) {
  if (out.find('%') != std::string::npos) {
    const auto bad = [&] {
      return InputError("-o " + out + ": a turntable pattern takes exactly one %d (e.g. frame-%03d.png; %% for a %)");
    };
    std::string path;
    int conversions = 0;
    for (std::size_t k = 0; k < out.size(); ++k) {
      if (out[k] != '%') {
        path += out[k];
        continue;
      }
      if (k + 1 < out.size() && out[k + 1] == '%') {
        path += '%';
        ++k;
        continue;
      }
      std::size_t j = k + 1;
      const bool zero = j < out.size() && out[j] == '0';
      if (zero) ++j;
      int width = 0;
      while (j < out.size() && std::isdigit(static_cast<unsigned char>(out[j])) && width < 100)
        width = 10 * width + (out[j++] - '0');
      if (j >= out.size() || out[j] != 'd' || width > 32 || ++conversions > 1) throw bad();
      std::string number = std::to_string(i);
      if (int(number.size()) < width) number.insert(0, std::size_t(width) - number.size(), zero ? '0' : ' ');
      path += number;
      k = j;
    }
    if (conversions != 1) throw bad();
    return path;
  }
  const std::size_t dot = out.rfind('.'), slash = out.rfind('/');
  const std::size_t cut = dot == std::string::npos || (slash != std::string::npos && dot < slash) ? out.size() : dot;
  char num[16];
  std::snprintf(num, sizeof num, "-%03d", i);
  return out.substr(0, cut) + num + out.substr(cut);
}

std::string frames_label(int turntable) {
  return turntable > 0 ? "turntable, " + std::to_string(turntable) + " frames" : "draw";
}

// Box of the splat centres that the crop box keeps (the camera frames what
// is drawn).
std::array<Vec3d, 2> kept_box(const SplatSet& set, const viewer::RenderSettings& s) {
  SplatSet kept = set;
  kept.splats.clear();
  for (const Splat& sp : set.splats) {
    bool in = true;
    for (int a = 0; a < 3; ++a) {
      const double f = set.dims[a] > 1 ? (sp.centre[a] - set.origin[a]) / (set.spacing[a] * double(set.dims[a] - 1)) : 0.5;
      in = in && f >= s.crop_lo[a] - 1e-6 && f <= s.crop_hi[a] + 1e-6;
    }
    if (in) kept.splats.push_back(sp);
  }
  return kept.splat_box();
}

int run_render(const RenderOptions& o) {
  const auto t0 = Clock::now();
  // A 3D+t opacity sequence: the splat renderers draw every frame (or
  // --frame K); the others draw 3-D volumes only.
  const std::size_t sequence = read_any_header(o.in).frames;
  const bool splats = o.splat.method == "splat" || o.splat.method == "isosplat";
  if (sequence > 1 && !splats)
    throw InputError("--method " + o.splat.method + " draws a 3-D volume, and " + o.in + " is a sequence of " +
                     std::to_string(sequence) + " frames: use --method splat or isosplat (one PNG per frame, or --frame K)");
  if (o.frame && sequence <= 1 && *o.frame > 0)
    throw InputError("--frame " + std::to_string(*o.frame) + ": " + o.in + " is a 3-D volume (one frame, 0)");
  if (sequence > 1 && !o.frame && o.turntable > 0)
    throw InputError("--turntable on a sequence of " + std::to_string(sequence) + " frames: choose one with --frame K");
  const bool every_frame = sequence > 1 && !o.frame;
  if (o.splat.method == "raycast")
    return run_raycast_render(*o.raycast, {o.in, o.out, o.device, o.size, o.view, o.crop, o.iso, o.turntable,
                                           o.benchmark, o.quiet, o.splat.opacity, o.splat.classify});
  if (o.splat.method == "mc" || o.splat.method == "shearwarp") {
    const RaycastRenderRequest req{o.in,        o.out,     o.device,         o.size,          o.view, o.crop, o.iso,
                                   o.turntable, o.benchmark, o.quiet, o.splat.opacity, o.splat.classify};
    return o.splat.method == "mc" ? run_mesh_render(o.level, req) : run_shearwarp_render(req);
  }
  const auto [width, height] = parse_size(o.size, "--size");
  const auto [az, el] = parse_view(o.view, "--view");
  if (o.turntable < 0 || o.turntable > 3600) throw InputError("--turntable must be in [0, 3600]");
  if (o.benchmark < 0 || o.benchmark > 100000) throw InputError("--benchmark must be in [0, 100000]");
  if (o.out.size() < 4 || o.out.substr(o.out.size() - 4) != ".png") throw InputError("-o " + o.out + ": expected a .png file");
  if (o.out.find('%') != std::string::npos && o.turntable == 0 && !every_frame)
    throw InputError("-o " + o.out + ": a %d pattern needs --turntable (or a sequence)");
  viewer::RenderSettings settings = o.splat.settings();
  SplatParams splat_params = o.splat.params();
  BoneCueMode bone_cue = BoneCueMode::Off;
  if (!o.splat.preset.empty()) {  // what the command line gives wins
    const Preset& p = preset_or_throw(o.splat.preset);
    apply_preset(p, settings, splat_params, o.given);
    parse_bone_cue_mode(p.bone_cue, bone_cue);
  }
  if (!o.colour_map.empty()) settings.depth_colour = o.colour_map == "depth";
  if (!o.light.empty()) std::tie(settings.light_azimuth, settings.light_elevation) = parse_light(o.light, "--light");
  if (!o.crop.empty()) parse_crop(o.crop, settings);
  // Every file this run writes, checked against the input before anything
  // is drawn (a turntable frame may be named like the input).
  std::vector<std::string> outputs;
  const int frames = every_frame ? int(sequence) : std::max(o.turntable, 1);
  for (int i = 0; i < frames; ++i) outputs.push_back(o.turntable || every_frame ? frame_path(o.out, i) : o.out);
  ensure_distinct_outputs({o.in}, outputs);
  for (const std::string& f : outputs) check_output(f, OutputKind::Png);

  const progress::Stage command("render");
  std::optional<progress::Stage> step(std::in_place, "input");
  Runtime rt(o.device);
  viewer::OpacityInput input = viewer::load_opacity(rt, o.in, o.splat.input_kind(), o.iso, nullptr, o.frame, bone_cue,
                                                          beam_axis_option(o.beam_axis));
  if (!o.volume.empty()) viewer::attach_bmode(input, o.volume);
  const std::string settled =
      settle_orientation(splat_params, !input.bmode.data.empty(), o.given.count("--orientation") > 0, o.in);
  if (!settled.empty() && !o.quiet) std::cout << "render: " << settled << '\n';
  // The B-mode frame behind opacity frame i (one B-mode volume: behind every frame).
  const auto bmode_of = [&input](std::size_t i) -> const Volume* {
    if (i < input.bmode_sequence.size()) return &input.bmode_sequence[i];
    return input.bmode.data.empty() ? nullptr : &input.bmode;
  };
  SplatTiming st;
  step.emplace("splats");
  const SplatSet set = generate_splats(rt, input.u, splat_params, &st, bmode_of(input.frame));
  step.emplace(every_frame ? "sequence, " + std::to_string(frames) + " frames" : frames_label(o.turntable));
  if (set.splats.empty())
    throw input_error(o.in, "no voxel has opacity above the threshold " + format_number(splat_params.threshold) +
                                " (all-zero opacity?); nothing to render");

  viewer::HeadlessRenderer r(width, height);
  r.upload(set);
  viewer::OrbitCamera cam;
  const auto box = kept_box(set, settings);
  cam.fit(box[0], box[1]);
  // The depth colour map spans what is drawn, as in the viewer.
  if (box[1][2] > box[0][2]) settings.depth_lo = float(box[0][2]), settings.depth_hi = float(box[1][2]);
  cam.azimuth = az;
  cam.elevation = el;

  viewer::DrawStats stats;
  for (int i = 0; i < frames; ++i) {
    if (every_frame) {
      // Each frame's splats, the camera fitted on frame 0 (the scene's motion shows).
      if (i > 0)
        r.upload(generate_splats(rt, input.sequence[std::size_t(i)], splat_params, nullptr, bmode_of(std::size_t(i))));
    } else {
      cam.azimuth = az + 360.0f * float(i) / float(frames);
    }
    stats = r.render(cam, settings);
    Image picture = r.read().rgb();
    if (settings.depth_colour && o.legend == "on") draw_depth_legend(picture, settings.depth_lo, settings.depth_hi);
    write_png(outputs[std::size_t(i)], picture);
    step->fraction(double(i + 1) / frames, "frame " + std::to_string(i + 1) + " of " + std::to_string(frames));
  }
  step.reset();

  double ms = 0, sort_ms = 0;
  if (o.benchmark > 0) {
    // Frames as the viewer draws them: order (sort or list), draw, glFinish;
    // the camera turns a little each frame so the sort has work to do.
    r.render(cam, settings);  // warm-up
    const auto tb = Clock::now();
    for (int i = 0; i < o.benchmark; ++i) {
      cam.azimuth = az + 0.5f * float(i);
      sort_ms += r.render(cam, settings).sort_ms / o.benchmark;
    }
    ms = 1000.0 * seconds_since(tb) / o.benchmark;
  }

  if (!o.quiet) {
    std::cout << std::fixed << std::setprecision(3) << "render (" << method_name(settings) << ") " << o.in << " -> "
              << (o.turntable || every_frame ? frame_path(o.out, 0) + " ... (" + std::to_string(frames) + " frames)" : o.out) << '\n'
              << "  input    " << input.note << '\n'
              << "  splats   " << set.splats.size() << " (u > " << format_number(splat_params.threshold) << ", a = "
              << set.a << " voxels, lambda " << set.lambda << " (" << splat_gaussian_name(set.params.gaussian) << "), normals " << splat_normals_name(set.params.normals)
              << "), generated in " << st.total << " s on " << rt.info().label() << '\n'
              << "  image    " << width << "x" << height << ", view " << format_number(az) << ","
              << format_number(el) << ", " << (settings.three_normals ? "three normals" : "one normal") << ", order "
              << (settings.order == viewer::DrawOrder::Sort ? "exact depth sort" : "six presorted lists") << '\n'
              << "  gl       " << r.description() << "; splats copied through the host (no cl_khr_gl_sharing path)\n";
    if (o.benchmark > 0)
      std::cout << "  speed    " << std::setprecision(2) << ms << " ms/frame (" << std::setprecision(1)
                << 1000.0 / ms << " fps) over " << o.benchmark << " frames"
                << (settings.order == viewer::DrawOrder::Sort ? ", of which depth sort + upload " + format_number(sort_ms) + " ms" : "")
                << '\n';
    std::cout << std::setprecision(3) << "  time     " << seconds_since(t0) << " s\n";
  }
  return 0;
}

}  // namespace

void add_render_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<RenderOptions>();
  auto* sub = app.add_subcommand(
      "render",
      "Render an opacity volume with oriented (or isotropic) splats to a PNG, headless (a hidden OpenGL window; "
      "run under xvfb-run -a without a display). A raw ultrasound volume is classified first with the defaults.");
  sub->add_option("IN", o->in, "Opacity volume (float in [0, 1]) or raw ultrasound volume")->required();
  sub->add_option("-o,--output", o->out, "Output PNG (with --turntable: OUT-000.png, ... or a %d pattern)")->required();
  sub->add_option("--size", o->size, "Image size in pixels")->capture_default_str()->type_name("WxH");
  sub->add_option("--view", o->view,
                  "Camera azimuth,elevation in degrees; 0,0 looks down the beam (+z) from the transducer, x right, "
                  "-y up")
      ->capture_default_str()
      ->type_name("AZ,EL");
  sub->add_option("--frame", o->frame,
                  "3D+t (a 4-D NRRD): draw frame K; without it the splat renderers draw every frame of a sequence "
                  "(OUT-000.png, ... or a %d pattern), the camera fitted on frame 0")
      ->type_name("K");
  sub->add_option("--volume", o->volume,
                  "B-mode volume behind IN when IN is an opacity volume (same dims), for --orientation data; a raw "
                  "IN, classified here, brings its own")
      ->type_name("V");
  sub->add_option("--turntable", o->turntable, "Write N frames around the object (azimuth steps of 360/N)")
      ->check(int_range(0, 3600));
  sub->add_option("--crop", o->crop,
                  "Keep splats inside this box, fractions of the volume's extent per axis (e.g. 0,1,0,1,0,0.6)")
      ->type_name("X0,X1,Y0,Y1,Z0,Z1");
  sub->add_option("--iso", o->iso, "Isovalue for classifying a raw volume (its units, or auto)")->capture_default_str();
  add_beam_axis_option(sub, o->beam_axis, "Classifying a raw volume: the axis its beam runs along (as classify's)");
  sub->add_option("--colour-map", o->colour_map,
                  "solid: one colour (the default); depth: colour by depth along the beam, light near the transducer "
                  "to dark red-brown deep (splats)")
      ->type_name("solid|depth")
      ->check(one_of({"solid", "depth"}));
  sub->add_option("--legend", o->legend,
                  "With --colour-map depth: a colour bar of the depth range (mm along the beam) at the right edge")
      ->capture_default_str()
      ->type_name("on|off")
      ->check(one_of({"on", "off"}));
  sub->add_option("--light", o->light,
                  "Light direction from the view direction in degrees, azimuth (right +) and elevation (up +), each in "
                  "[-90, 90] (default -30,30)")
      ->type_name("AZ,EL");
  sub->add_option("--benchmark", o->benchmark, "Also time N frames and report frames per second")
      ->check(int_range(0, 100000));
  o->splat.add_to(sub, render_methods());
  o->raycast = add_raycast_render_options(sub);
  sub->add_option("--level", o->level, "--method mc: isovalue of the Marching Cubes surface (default: the splats' epsilon)")
      ->capture_default_str()
      ->check(real_range(-INFINITY, INFINITY));
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  add_device_option(sub, o->device);
  sub->callback([&action, o, sub] {
    for (const CLI::Option* opt : sub->get_options())
      if (opt->count() > 0) o->given.insert("--" + opt->get_single_name());
    action = [o] { return run_render(*o); };
  });
}

}  // namespace softshell::cli
