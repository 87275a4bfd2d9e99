// Options shared by `softshell render` and `softshell view`
// (host/cli/cmd_render.cpp, cmd_view.cpp): splat method, normals, order,
// threshold, input kind; and parsers for sizes, views and crop boxes. Every
// parse failure throws InputError naming the option.
#pragma once

#include <CLI/CLI.hpp>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "opacity_input.hpp"
#include "raycast.hpp"
#include "splat_renderer.hpp"
#include "presets.hpp"
#include "splats.hpp"

namespace softshell::cli {

// u with the voxels outside the crop box set to 0: fractions of the extent
// with half a voxel of slack, the splat renderer's rule (an axis of one
// voxel counts as 0.5). For the renderers that take a volume, not a box.
Volume cropped(const Volume& u, const viewer::RenderSettings& s);

// The ray caster's crop, colours and light from the splat renderer's
// settings, so every renderer draws the same scene the same way.
void apply_render_settings(RaycastParams& p, const viewer::RenderSettings& s);

// --method words: `render` (splat, isosplat, raycast, mc, shearwarp) and
// `view` (splat, isosplat, mc, raycast; shear-warp is not interactive).
const std::vector<std::string>& render_methods();
const std::vector<std::string>& view_methods();

struct SplatViewOptions {
  std::string method = "splat", normals = "three", order = "lists", gaussian = "rim", orientation = "tensor",
              centres = "shell", preset, occlusion = "off";
  float threshold = 0.2f;
  double tensor_sigma = 1.5;
  bool opacity = false, classify = false;

  // `render` offers every renderer (render_methods()), `view` those it can
  // show (view_methods()); help and errors list the same words.
  void add_to(CLI::App* sub, const std::vector<std::string>& methods);
  viewer::RenderSettings settings() const;  // validates method, normals, order
  SplatParams params() const;               // validates the threshold
  viewer::InputKind input_kind() const;
};

// A preset's rendering part (host/presets.hpp) onto the settings and the
// splat parameters, except what `given` (long option names the command
// line or a parameters file set: --threshold, --gaussian, --colour-map,
// --light) holds. Throws InputError naming --preset for an unknown name.
const Preset& preset_or_throw(const std::string& name);
void apply_preset(const Preset& p, viewer::RenderSettings& s, SplatParams& params, const std::set<std::string>& given);
// Orientation by the data without a B-mode volume behind the opacity `in`:
// an InputError when --orientation data was `given`, else (a preset's)
// the tensor of u, and a line for the user saying so; "" when nothing changed.
std::string settle_orientation(SplatParams& params, bool have_bmode, bool given, const std::string& in);
// "AZ,EL" light direction in degrees, each in [-90, 90].
std::pair<float, float> parse_light(const std::string& text, const std::string& what);

// "WxH" -> (W, H), each in [1, 8192].
std::pair<int, int> parse_size(const std::string& text, const std::string& what);
// "AZ,EL" in degrees, elevation in [-89, 89].
std::pair<float, float> parse_view(const std::string& text, const std::string& what);
// "X0,X1,Y0,Y1,Z0,Z1" fractions in [0, 1], X0 < X1 etc., into settings.crop_*.
void parse_crop(const std::string& text, viewer::RenderSettings& settings);
std::string format_number(double v);  // shortest of %g
const char* method_name(const viewer::RenderSettings& s);  // "oriented splats" / "isotropic splats"

}  // namespace softshell::cli
