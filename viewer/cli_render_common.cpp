// Options shared by `render` and `view`.
#include "cli_render_common.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <vector>

#include "error.hpp"
#include "cli_validate.hpp"

namespace softshell::cli {
namespace {

std::vector<double> parse_numbers(const std::string& text, char sep, std::size_t count, const std::string& what,
                                  const std::string& form) {
  const InputError bad(what + ": expected " + form + ", got '" + text + "'");
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, sep)) {
    char* end = nullptr;
    const double d = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !std::isfinite(d)) throw bad;
    v.push_back(d);
  }
  if (v.size() != count || text.back() == sep) throw bad;
  return v;
}

}  // namespace

const std::vector<std::string>& render_methods() {
  static const std::vector<std::string> m{"splat", "isosplat", "raycast", "mc", "shearwarp"};
  return m;
}

const std::vector<std::string>& view_methods() {
  static const std::vector<std::string> m{"splat", "isosplat", "mc", "raycast"};
  return m;
}

void SplatViewOptions::add_to(CLI::App* sub, const std::vector<std::string>& methods) {
  const bool shearwarp = std::find(methods.begin(), methods.end(), "shearwarp") != methods.end();
  sub->add_option("--method", method,
                  std::string("splat: oriented splats (the paper); isosplat: isotropic splats facing the viewer; "
                              "raycast: OpenCL ray casting; mc: Marching Cubes mesh") +
                      (shearwarp ? "; shearwarp: VolPack" : "") + "; docs/renderers.md")
      ->capture_default_str()
      ->check(one_of(methods));
  sub->add_option("--threshold", threshold,
                  "epsilon: voxels with u > epsilon get a splat; the Gaussian falls to epsilon at the splat's rim")
      ->capture_default_str()
      ->check(real_range(0, 1, "", Ends::Open));
  sub->add_option("--normals", normals, "Shading normals per splat: one (at the centre) or three (midway to each vertex)")
      ->capture_default_str()
      ->check(one_of({"one", "three"}));
  sub->add_option("--orientation", orientation,
                  "Splat plane and normals from: tensor (principal direction of the structure tensor of u; right on "
                  "the middle of a shell, where grad u vanishes), data (the same tensor of the B-mode data, lowpassed "
                  "by a voxel: the surface's own orientation, however u drew it; needs the raw volume or --volume) or "
                  "gradient (grad u, the paper); docs/rendering.md")
      ->capture_default_str()
      ->check(one_of({"tensor", "data", "gradient"}));
  sub->add_option("--centres", centres,
                  "Splat centres: shell (each moved along its normal to the centroid of u across the shell: no bands "
                  "on tilted surfaces) or voxel (the voxel's centre, the paper); docs/rendering.md, \"Banding\"")
      ->capture_default_str()
      ->check(one_of({"shell", "voxel"}));
  sub->add_option("--occlusion", occlusion,
                  "Ambient occlusion from the opacity (soft shadows in creases and hollows: on each side of a splat, "
                  "rays through u absorb light as compositing does; docs/rendering.md)")
      ->capture_default_str()
      ->check(one_of({"on", "off"}));
  sub->add_option("--tensor-sigma", tensor_sigma, "Gaussian sigma of the structure tensor in voxels")
      ->capture_default_str()
      ->check(real_range(0, 8, "voxels", Ends::OpenLow));
  sub->add_option("--order", order,
                  "Back to front: lists (the paper's six presorted lists, by the dominant view axis) or sort (exact "
                  "per-view depth sort)")
      ->capture_default_str()
      ->check(one_of({"lists", "sort"}));
  sub->add_option("--gaussian", gaussian,
                  "lambda from epsilon: paper (-0.25 ln eps, as printed) or rim (-0.25 / ln eps, so that G = eps at "
                  "the splat's rim as the paper intends; larger, smoother splats); docs/rendering.md")
      ->capture_default_str()
      ->check(one_of({"paper", "rim"}));
  sub->add_option("--preset", preset,
                  "Settings for a kind of scan, classification and rendering together (docs/rendering.md, "
                  "\"Presets\"): " + preset_names() + "; what the command line gives wins")
      ->type_name("NAME")
      ->check(one_of([] {
        std::vector<std::string> names;
        for (const Preset& p : presets()) names.push_back(p.name);
        return names;
      }()));
  sub->add_flag("--opacity", opacity, "Treat IN as an opacity volume (float in [0, 1]) even if unsure");
  sub->add_flag("--classify", classify, "Classify IN first (with the defaults) even if it looks like an opacity volume");
}

viewer::RenderSettings SplatViewOptions::settings() const {
  viewer::RenderSettings s;
  // --method raycast / mc / shearwarp leave the splat method at its default
  // (the renderers that use splat settings read crop and colours only).
  if (method == "isosplat" || method == "isotropic")
    s.method = viewer::SplatMethod::Isotropic;
  else if (std::find(render_methods().begin(), render_methods().end(), method) == render_methods().end() &&
           method != "oriented")
    throw InputError("--method " + method + ": unknown (expected " + choice_list(render_methods()) + ")");
  else
    s.method = viewer::SplatMethod::Oriented;
  if (normals != "one" && normals != "three") throw InputError("--normals " + normals + ": expected one or three");
  s.three_normals = normals == "three";
  if (order != "lists" && order != "sort") throw InputError("--order " + order + ": expected lists or sort");
  s.order = order == "sort" ? viewer::DrawOrder::Sort : viewer::DrawOrder::Lists;
  return s;
}

SplatParams SplatViewOptions::params() const {
  if (!(threshold > 0.0f && threshold < 1.0f)) throw InputError("--threshold must be in (0, 1)");
  SplatParams p;
  p.threshold = threshold;
  if (gaussian != "paper" && gaussian != "rim") throw InputError("--gaussian " + gaussian + ": expected paper or rim");
  p.gaussian = gaussian == "rim" ? SplatGaussian::Rim : SplatGaussian::Paper;
  if (!parse_splat_normals(orientation, p.normals))
    throw InputError("--orientation " + orientation + ": expected tensor, data or gradient");
  if (!(tensor_sigma > 0 && tensor_sigma <= 8)) throw InputError("--tensor-sigma must be in (0, 8] voxels");
  if (!parse_splat_centres(centres, p.centres)) throw InputError("--centres " + centres + ": expected shell or voxel");
  if (occlusion != "on" && occlusion != "off") throw InputError("--occlusion " + occlusion + ": expected on or off");
  p.occlusion = occlusion == "on";
  p.tensor_sigma = tensor_sigma;
  return p;
}

viewer::InputKind SplatViewOptions::input_kind() const {
  if (opacity && classify) throw InputError("--opacity and --classify exclude each other");
  return opacity ? viewer::InputKind::Opacity : classify ? viewer::InputKind::Raw : viewer::InputKind::Auto;
}

const Preset& preset_or_throw(const std::string& name) {
  const Preset* p = find_preset(name);
  if (!p) throw InputError("--preset " + name + ": unknown (presets: " + preset_names() + ")");
  return *p;
}

void apply_preset(const Preset& p, viewer::RenderSettings& s, SplatParams& params, const std::set<std::string>& given) {
  s.colour = glm::vec3(p.colour[0], p.colour[1], p.colour[2]);
  s.specular = p.specular;
  if (!given.count("--light")) s.light_azimuth = p.light_azimuth, s.light_elevation = p.light_elevation;
  if (!given.count("--colour-map")) s.depth_colour = p.depth_colour;
  if (!given.count("--threshold")) params.threshold = p.threshold;
  if (!given.count("--gaussian")) params.gaussian = p.rim_gaussian ? SplatGaussian::Rim : SplatGaussian::Paper;
  if (!given.count("--orientation")) parse_splat_normals(p.orientation, params.normals);
}

std::string settle_orientation(SplatParams& params, bool have_bmode, bool given, const std::string& in) {
  if (params.normals != SplatNormals::Data || have_bmode) return "";
  if (given)
    throw input_error(in, "--orientation data needs the B-mode volume behind this opacity: give it with --volume V");
  params.normals = SplatNormals::Tensor;
  return "the preset orients splats by the data, and there is no B-mode volume (--volume V): by the tensor of u";
}

std::pair<float, float> parse_light(const std::string& text, const std::string& what) {
  const std::vector<double> v = parse_numbers(text, ',', 2, what, "AZIMUTH,ELEVATION in degrees from the view direction (e.g. -30,30)");
  if (std::abs(v[0]) > 90 || std::abs(v[1]) > 90) throw InputError(what + ": azimuth and elevation must be in [-90, 90]");
  return {float(v[0]), float(v[1])};
}

std::pair<int, int> parse_size(const std::string& text, const std::string& what) {
  const std::vector<double> v = parse_numbers(text, 'x', 2, what, "WxH (e.g. 400x400)");
  for (double d : v)
    if (d < 1 || d > 8192 || d != std::floor(d)) throw InputError(what + ": width and height must be integers in [1, 8192]");
  return {int(v[0]), int(v[1])};
}

std::pair<float, float> parse_view(const std::string& text, const std::string& what) {
  const std::vector<double> v = parse_numbers(text, ',', 2, what, "AZIMUTH,ELEVATION in degrees (e.g. 30,15)");
  if (std::abs(v[1]) > 89) throw InputError(what + ": elevation must be in [-89, 89]");
  return {float(v[0]), float(v[1])};
}

void parse_crop(const std::string& text, viewer::RenderSettings& s) {
  const std::vector<double> v = parse_numbers(text, ',', 6, "--crop", "X0,X1,Y0,Y1,Z0,Z1 fractions in [0, 1]");
  for (int a = 0; a < 3; ++a) {
    if (v[2 * a] < 0 || v[2 * a + 1] > 1 || !(v[2 * a] < v[2 * a + 1]))
      throw InputError("--crop: each pair must satisfy 0 <= lo < hi <= 1, got '" + text + "'");
    s.crop_lo[a] = float(v[2 * a]);
    s.crop_hi[a] = float(v[2 * a + 1]);
  }
}

std::string format_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

const char* method_name(const viewer::RenderSettings& s) {
  return s.method == viewer::SplatMethod::Isotropic ? "isotropic splats" : "oriented splats";
}

Volume cropped(const Volume& u, const viewer::RenderSettings& s) {
  Volume c = u;
  for (std::size_t z = 0; z < u.dims[2]; ++z)
    for (std::size_t y = 0; y < u.dims[1]; ++y)
      for (std::size_t x = 0; x < u.dims[0]; ++x) {
        const std::size_t i[3] = {x, y, z};
        bool in = true;
        for (int a = 0; a < 3; ++a) {
          const double f = u.dims[a] > 1 ? double(i[a]) / double(u.dims[a] - 1) : 0.5;
          const double eps = u.dims[a] > 1 ? 0.5 / double(u.dims[a] - 1) : 0.0;
          in = in && f >= s.crop_lo[a] - eps && f <= s.crop_hi[a] + eps;
        }
        if (!in) c.at(x, y, z) = 0.0f;
      }
  return c;
}

void apply_render_settings(RaycastParams& p, const viewer::RenderSettings& s) {
  for (int a = 0; a < 3; ++a) {
    p.crop_lo[a] = s.crop_lo[a];
    p.crop_hi[a] = s.crop_hi[a];
    p.colour[a] = s.colour[a];
    p.background[a] = s.background[a];
  }
  p.ambient = s.ambient;
  p.diffuse = s.diffuse;
  p.specular = s.specular;
  p.shininess = s.shininess;
  p.light_azimuth = s.light_azimuth;
  p.light_elevation = s.light_elevation;
}

}  // namespace softshell::cli
