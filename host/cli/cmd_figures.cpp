// Ray casting from the command line, and the paper's comparison figures:
//   `softshell render IN --method raycast`  (options and run; cmd_render.cpp dispatches here)
//   `softshell figure5 IN`  ray casting before / after classification (paper Figure 5)
//   `softshell figure6 IN`  ray casting, Marching Cubes, shear-warp, oriented splats (paper Figure 6)
// Every panel uses the same camera (viewer::OrbitCamera framing the voxels
// with u > 0.2 inside the crop box, as `render` frames its splats), so the
// panels line up, and is labelled with its time per frame. Built into the
// viewer library (the splat panel needs OpenGL); docs/renderers.md.
#include <algorithm>
#include <filesystem>
#include <cmath>
#include <functional>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <tuple>
#include <vector>

#include "auto_iso.hpp"
#include "cli_common.hpp"
#include "cli_render_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "progress.hpp"
#include "headless.hpp"
#include "image.hpp"
#include "io.hpp"
#include "mask.hpp"
#include "mesh.hpp"
#include "mesh_renderer.hpp"
#include "raycast.hpp"
#include "shearwarp.hpp"

namespace softshell::cli {

// ---------------------------------------------------------------------------
// Options of the ray caster (on `render`, `figure5`, `figure6`).
struct RaycastRenderOptions {
  std::string tf_lo = "auto", tf_hi = "auto", tf_cut = "auto";
  float tf_max = 1.0f, step = 0.5f;
  bool unclassified = false, no_early_termination = false;
  int repeat = 3;
};

namespace {

void add_raycast_options(CLI::App* sub, RaycastRenderOptions& o, bool with_unclassified) {
  if (with_unclassified)
    sub->add_flag("--unclassified", o.unclassified,
                  "raycast: ray cast a raw volume's normalised intensity through the transfer function instead of "
                  "classifying it first (the paper's Figure 5, left)");
  sub->add_option("--tf-lo", o.tf_lo,
                  "raycast: transfer-function ramp start, normalised intensity in [0, 1] (auto: the isovalue - 0.1 "
                  "for raw data, 0 for an opacity volume)")
      ->capture_default_str();
  sub->add_option("--tf-hi", o.tf_hi,
                  "raycast: ramp end where the opacity reaches --tf-max (auto: the isovalue + 0.1 for raw data, 1 for "
                  "an opacity volume)")
      ->capture_default_str();
  sub->add_option("--tf-cut", o.tf_cut,
                  "raycast: samples below this are transparent (auto: 0.2 for an opacity volume, the splats' epsilon, "
                  "so ray casting shows what the splats show and not the faint haze of u away from surfaces; 0 for "
                  "raw data)")
      ->capture_default_str();
  sub->add_option("--tf-max", o.tf_max, "raycast: largest opacity per voxel length")
      ->capture_default_str()
      ->check(real_range(0, 1, "", Ends::OpenLow));
  sub->add_option("--step", o.step, "raycast: sampling distance along the ray, in voxels (smallest spacing)")
      ->capture_default_str()
      ->check(real_range(0.05, 4, "voxels"));
  sub->add_flag("--no-early-termination", o.no_early_termination,
                "raycast: march every ray through the whole volume (default: stop at opacity 0.99)");
}

double parse_unit(const std::string& text, const std::string& what) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !(v >= 0.0 && v <= 1.0))
    throw InputError(what + ": expected a normalised intensity in [0, 1] or 'auto', got '" + text + "'");
  return v;
}

// Transfer function and sampling from the options; `iso_unit` < 0 for an
// opacity volume (identity ramp by default), else the raw data's normalised
// isovalue.
RaycastParams raycast_params(const RaycastRenderOptions& o, double iso_unit, const viewer::RenderSettings& s) {
  RaycastParams p;
  const bool raw = iso_unit >= 0;
  // Raw data: a ramp 0.2 wide centred on the isovalue (full opacity a
  // little above the boundary value, speckle below it fades out).
  const double lo = o.tf_lo == "auto" ? (raw ? std::max(iso_unit - 0.1, 0.0) : 0.0) : parse_unit(o.tf_lo, "--tf-lo");
  const double hi = o.tf_hi == "auto" ? (raw ? std::min(iso_unit + 0.1, 1.0) : 1.0) : parse_unit(o.tf_hi, "--tf-hi");
  if (!(lo < hi)) throw InputError("--tf-lo must be below --tf-hi (got " + format_number(lo) + ", " + format_number(hi) + ")");
  const double cut = o.tf_cut == "auto" ? (raw ? 0.0 : 0.2) : parse_unit(o.tf_cut, "--tf-cut");
  if (!(cut < 1.0)) throw InputError("--tf-cut must be below 1");
  p.tf_cut = float(cut);
  p.tf_lo = float(lo);
  p.tf_hi = float(hi);
  p.tf_max = o.tf_max;
  p.step = o.step;
  p.termination = o.no_early_termination ? 2.0f : 0.99f;
  apply_render_settings(p, s);
  if (!(p.tf_max > 0 && p.tf_max <= 1)) throw InputError("--tf-max must be in (0, 1]");
  if (!(p.step >= 0.05f && p.step <= 4.0f)) throw InputError("--step must be in [0.05, 4] voxels");
  p.validate();
  return p;
}

// The GL camera as the ray caster's: the same eye, axes and field of view.
RayCamera ray_camera(const viewer::OrbitCamera& c) {
  RayCamera r;
  const glm::vec3 e = c.eye(), f = c.forward(), rt = c.right(), u = c.up();
  for (int a = 0; a < 3; ++a) r.eye[a] = e[a], r.forward[a] = f[a], r.right[a] = rt[a], r.up[a] = u[a];
  r.fov_y = c.fov_y;
  return r;
}

viewer::OrbitCamera framed_camera(const std::array<Vec3d, 2>& box, float az, float el) {
  viewer::OrbitCamera cam;
  cam.fit(box[0], box[1]);
  cam.azimuth = az;
  cam.elevation = el;
  return cam;
}

void check_png_output(const std::string& in, const std::string& out) {
  if (out.size() < 4 || out.substr(out.size() - 4) != ".png") throw InputError("-o " + out + ": expected a .png file");
  ensure_distinct_output(in, out);
  check_output(out, OutputKind::Png);
}

// The isovalue of a raw volume as `classify --iso auto` picks it (scanned
// region only), or the number given; in the file's units.
double raw_iso(const Volume& v, const std::string& iso_text) {
  if (iso_text != "auto") {
    char* end = nullptr;
    const double iso = std::strtod(iso_text.c_str(), &end);
    if (iso_text.empty() || *end != '\0' || !std::isfinite(iso))
      throw InputError("--iso: expected a number in the input's intensity units or 'auto', got '" + iso_text + "'");
    return iso;
  }
  MaskReport mr;
  std::vector<std::uint8_t> mask = scanned_mask(v, MaskParams{}, &mr);
  return auto_iso(v, mr.unscanned == 0 ? nullptr : &mask);
}

// Median seconds of `repeat` calls after one warm-up call (kernel build,
// first-touch allocations).
double time_frames(const std::function<void()>& frame, int repeat) {
  frame();
  std::vector<double> t;
  for (int i = 0; i < std::max(repeat, 1); ++i) {
    const auto t0 = Clock::now();
    frame();
    t.push_back(seconds_since(t0));
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

std::string format_ms(double seconds) {
  std::ostringstream s;
  if (seconds < 0)
    s << "-";
  else if (seconds < 10.0)
    s << std::fixed << std::setprecision(seconds < 0.1 ? 1 : 0) << 1000.0 * seconds << " ms";
  else
    s << std::fixed << std::setprecision(1) << seconds << " s";
  return s.str();
}

// ---------------------------------------------------------------------------
// Figure panels.
struct Panel {
  std::string title;   // "ray casting", ...
  std::string detail;  // second label line
  Image image;
  double seconds = -1;  // per frame; < 0: not available
};

// What every panel of a figure shares.
struct Scene {
  Runtime& rt;
  const Volume& u;  // the classified opacity
  viewer::OrbitCamera camera;
  viewer::RenderSettings settings;  // crop, colours, light (the splat renderer's defaults)
  int width, height, repeat;
};

Panel raycast_panel(const Scene& s, const Volume& samples, const RaycastParams& p, const std::string& title) {
  RayCaster rc(s.rt, samples, p);
  const RayCamera cam = ray_camera(s.camera);
  RaycastImage img;
  Panel panel;
  panel.title = title;
  panel.seconds = time_frames([&] { img = rc.render(cam, s.width, s.height); }, s.repeat);
  panel.image = img.rgb(p.background);
  return panel;
}

Panel splat_panel(const Scene& s) {
  const SplatViewOptions defaults;  // `render`'s defaults
  const SplatSet set = generate_splats(s.rt, s.u, defaults.params());
  Panel panel;
  panel.title = "oriented splats";
  viewer::RenderSettings settings = s.settings;
  viewer::HeadlessRenderer r(s.width, s.height);
  r.upload(set);
  panel.seconds = time_frames([&] { r.render(s.camera, settings); }, std::max(s.repeat, 5));
  panel.image = r.read().rgb();
  panel.detail = std::to_string(set.splats.size()) + " splats";
  return panel;
}

// A grey panel saying why a renderer is missing.
Panel unavailable_panel(const Scene& s, const std::string& title, const std::string& why) {
  Panel panel;
  panel.title = title;
  panel.image = Image(s.width, s.height, 48);
  const std::string text = "not available";
  const int scale = s.width >= 200 ? 2 : 1;
  draw_text(panel.image, (s.width - text_width(text, scale)) / 2, s.height / 2 - 14, text, {220, 220, 220}, scale);
  draw_text(panel.image, std::max(2, (s.width - text_width(why)) / 2), s.height / 2 + 8, why, {170, 170, 170});
  panel.detail = why;
  return panel;
}


bool has_crop(const viewer::RenderSettings& s) {
  for (int a = 0; a < 3; ++a)
    if (s.crop_lo[a] > 0.0f || s.crop_hi[a] < 1.0f) return true;
  return false;
}

// The Marching Cubes surface of u at `level` (host/mesh.hpp), drawn by the GL
// mesh renderer with the splats' light (viewer/mesh_renderer.hpp); the time is
// per drawn frame (extraction once, not counted). Its own hidden window, gone
// before the next panel's.
Panel marching_cubes_panel(const Scene& s, double level) {
  const Mesh mesh = marching_cubes(s.rt, s.u, level);
  if (mesh.empty()) return unavailable_panel(s, "Marching Cubes", "no surface at level " + format_number(level));
  Panel panel;
  panel.title = "Marching Cubes";
  // The crop drops fragments (mm, half a voxel of slack), as `render --method mc`.
  glm::vec3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    const float o = float(s.u.origin[a]), ext = float(s.u.spacing[a] * double(s.u.dims[a] - 1)),
                eps = 0.5f * float(s.u.spacing[a]);
    lo[a] = s.settings.crop_lo[a] <= 0.0f ? -1e30f : o + s.settings.crop_lo[a] * ext - eps;
    hi[a] = s.settings.crop_hi[a] >= 1.0f ? 1e30f : o + s.settings.crop_hi[a] * ext + eps;
  }
  viewer::MeshHeadless gl(s.width, s.height);
  gl.upload(mesh);
  panel.seconds = time_frames([&] { gl.render(s.camera, s.settings, lo, hi); }, std::max(s.repeat, 5));
  panel.image = gl.read().rgb();
  panel.detail = "level " + format_number(level) + ", " + std::to_string(mesh.triangle_count()) + " triangles";
  return panel;
}

// VolPack's shear-warp of u (host/shearwarp.hpp): parallel projection at the
// scale of the perspective camera at its target, framing the same box.
Panel shear_warp_panel(const Scene& s, const std::array<Vec3d, 2>& box, float az, float el) {
  if (!shearwarp_available()) return unavailable_panel(s, "shear-warp", "built without VolPack");
  Panel panel;
  panel.title = "shear-warp";
  ShearWarpRenderer sw(has_crop(s.settings) ? cropped(s.u, s.settings) : s.u);
  ShearWarpView view;
  view.azimuth = az;
  view.elevation = el;
  view.width = s.width;
  view.height = s.height;
  view.box = box;
  ShearWarpImage img;
  panel.seconds = time_frames([&] { img = sw.render(view); }, s.repeat);
  panel.image = img.rgb();
  panel.detail = "VolPack, parallel projection";
  return panel;
}

// Panels side by side, each with a label band below: title (large) and the
// time per frame plus the detail line (small).
Image compose(const std::vector<Panel>& panels) {
  constexpr int gap = 4;
  const int title_h = text_height("Ag", 2), band = 6 + title_h + 2 + text_height("Ag") + 4;
  int width = gap, height = 0;
  for (const Panel& p : panels) width += p.image.width + gap, height = std::max(height, p.image.height);
  Image out(width, height + band + gap, 24);
  int x0 = gap;
  for (const Panel& p : panels) {
    blit(out, p.image, x0, 0);
    const int scale = text_width(p.title, 2) <= p.image.width - 8 ? 2 : 1;
    draw_text(out, x0 + 4, height + 6, p.title, {255, 255, 255}, scale);
    std::string line = p.seconds >= 0 ? format_ms(p.seconds) + " per frame" : "";
    if (!p.detail.empty()) line += (line.empty() ? "" : ", ") + p.detail;
    draw_text(out, x0 + 4, height + 6 + title_h + 2, line, {200, 200, 200});
    x0 += p.image.width + gap;
  }
  return out;
}

void print_panels(const std::string& what, const std::string& out, const std::vector<Panel>& panels, int w, int h) {
  std::cout << what << " -> " << out << '\n';
  for (const Panel& p : panels)
    std::cout << "  " << std::left << std::setw(30) << p.title << std::right
              << (p.seconds >= 0 ? format_ms(p.seconds) + " per " + std::to_string(w) + "x" + std::to_string(h) + " frame"
                                 : "not available")
              << (p.detail.empty() ? "" : " (" + p.detail + ")") << '\n';
}

// ---------------------------------------------------------------------------
// figure5 / figure6 options.
struct FigureOptions {
  // One row per input; --view, --crop, --iso and --labels: one for every
  // row, or one per row.
  std::vector<std::string> ins, views{"0,0"}, crops, isos{"auto"};
  std::vector<std::string> labels;
  std::string out, device, size = "400x400", caption;
  int repeat = 3;
  double level = 0.2;  // figure6: the Marching Cubes level, as `render --method mc`
  bool quiet = false;
  RaycastRenderOptions raycast;
};

void add_figure_options(CLI::App* sub, FigureOptions& o) {
  sub->add_option("--size", o.size, "Size of each panel in pixels")->capture_default_str()->type_name("WxH");
  sub->add_option("--view", o.views,
                  "Camera azimuth,elevation in degrees; 0,0 looks down the beam (+z) from the transducer, x right, -y "
                  "up. Once for every row, or once per input in order")
      ->capture_default_str()
      ->type_name("AZ,EL");
  sub->add_option("--crop", o.crops,
                  "Keep only this box, fractions of the volume's extent per axis. Once for every row, or once per "
                  "input (0,1,0,1,0,1 keeps all)")
      ->type_name("X0,X1,Y0,Y1,Z0,Z1");
  sub->add_option("--iso", o.isos,
                  "Isovalue for classifying a raw volume (its units, or auto). Once for every row, or once per input")
      ->capture_default_str();
  sub->add_option("--labels", o.labels, "Row labels, one per input (default: the file names)")
      ->delimiter(',')
      ->type_name("A,B,..");
  sub->add_option("--caption", o.caption, "Caption under the figure (default: what the figure shows)")
      ->type_name("TEXT");
  sub->add_option("--repeat", o.repeat, "Frames timed per panel (median, after one warm-up frame)")
      ->capture_default_str()
      ->check(int_range(1, 1000));
  add_raycast_options(sub, o.raycast, false);
  sub->add_flag("-q,--quiet", o.quiet, "Print nothing on success");
  add_device_option(sub, o.device);
}

struct FigureSetup {
  int width = 0, height = 0;
  std::vector<float> az, el;                  // per row
  std::vector<viewer::RenderSettings> settings;  // per row (crop)
  std::vector<std::string> isos, labels;      // per row
};

// The value of a per-row option for row k: one for all, or one per input.
const std::string& per_row(const std::vector<std::string>& v, std::size_t k) { return v.size() == 1 ? v[0] : v[k]; }

void check_per_row(const std::vector<std::string>& v, std::size_t rows, const std::string& option, bool optional) {
  if ((optional && v.empty()) || v.size() == 1 || v.size() == rows) return;
  throw InputError(option + ": give it once for every row or once per input (" + std::to_string(rows) +
                   " inputs, " + std::to_string(v.size()) + " given)");
}

FigureSetup figure_setup(const FigureOptions& o) {
  FigureSetup f;
  const std::size_t rows = o.ins.size();
  std::tie(f.width, f.height) = parse_size(o.size, "--size");
  if (o.repeat < 1 || o.repeat > 1000) throw InputError("--repeat must be in [1, 1000]");
  check_per_row(o.views, rows, "--view", false);
  check_per_row(o.crops, rows, "--crop", true);
  check_per_row(o.isos, rows, "--iso", false);
  const std::vector<std::string>& labels = o.labels;
  if (!labels.empty() && labels.size() != rows)
    throw InputError("--labels: " + std::to_string(labels.size()) + " labels for " + std::to_string(rows) +
                     " inputs (one per input)");
  for (std::size_t k = 0; k < rows; ++k) {
    const auto [az, el] = parse_view(per_row(o.views, k), "--view");
    f.az.push_back(az), f.el.push_back(el);
    viewer::RenderSettings s = SplatViewOptions{}.settings();
    if (!o.crops.empty()) parse_crop(per_row(o.crops, k), s);
    f.settings.push_back(s);
    f.isos.push_back(per_row(o.isos, k));
    f.labels.push_back(labels.empty() ? std::filesystem::path(o.ins[k]).filename().string() : labels[k]);
    check_png_output(o.ins[k], o.out);
  }
  return f;
}

// Rows stacked, each headed by its label, and the caption below, wrapped to
// the figure's width.
Image stack_rows(const std::vector<Image>& rows, const std::vector<std::string>& labels, const std::string& caption) {
  constexpr int margin = 6;
  const int label_h = text_height("Ag", 2) + 2 * margin;
  int width = 0, height = 0;
  for (const Image& r : rows) width = std::max(width, r.width), height += label_h + r.height;
  const std::vector<std::string> lines = caption.empty() ? std::vector<std::string>{} : wrap_text(caption, width - 2 * margin);
  const int line_h = text_height("Ag") + 3;
  const int caption_h = lines.empty() ? 0 : int(lines.size()) * line_h + 2 * margin;
  Image out(std::max(width, 1), height + caption_h, 24);
  int y = 0;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    draw_text(out, margin, y + margin, labels[k], {255, 226, 140}, 2);
    y += label_h;
    blit(out, rows[k], 0, y);
    y += rows[k].height;
  }
  for (std::size_t l = 0; l < lines.size(); ++l)
    draw_text(out, margin, y + margin + int(l) * line_h, lines[l], {210, 210, 210});
  return out;
}

RaycastParams opacity_params(const FigureOptions& o, const viewer::RenderSettings& s) {
  RaycastRenderOptions r = o.raycast;
  r.tf_lo = r.tf_hi = "auto";  // the classified panel shows u itself (above --tf-cut)
  return raycast_params(r, -1.0, s);
}

// The progress stage's prefix for row k ("row 2/3, "), empty for one row.
std::string row_stage(const FigureOptions& o, std::size_t k) {
  return o.ins.size() > 1 ? "row " + std::to_string(k + 1) + "/" + std::to_string(o.ins.size()) + ", " : "";
}

// One row of figure5: ray casting of input k before and after classification.
Image figure5_row(Runtime& rt, const FigureOptions& o, const FigureSetup& f, std::size_t k) {
  const std::string& in = o.ins[k];
  const Volume raw = read_volume(in);
  if (viewer::looks_like_opacity(raw))
    throw input_error(in, "figure5 needs the raw volume (before classification); this is an opacity volume");
  const viewer::OpacityInput input = viewer::load_opacity(rt, in, viewer::InputKind::Raw, f.isos[k]);
  const Volume unit = unit_samples(raw);
  const double iso_unit = std::clamp(raw.intensity_map().to_unit(input.iso), 0.0, 1.0);
  const RaycastParams before = raycast_params(o.raycast, iso_unit, f.settings[k]);
  const RaycastParams after = opacity_params(o, f.settings[k]);

  const Scene scene{rt, input.u, framed_camera(visible_box(input.u, after), f.az[k], f.el[k]), f.settings[k],
                    f.width, f.height, o.repeat};
  std::vector<Panel> panels;
  const std::string row = row_stage(o, k);
  std::optional<progress::Stage> panel(std::in_place, row + "panel 1/2: ray casting before classification");
  panels.push_back(raycast_panel(scene, unit, before, "before classification"));
  panel.emplace(row + "panel 2/2: ray casting after classification");
  std::ostringstream ramp;
  ramp << std::fixed << std::setprecision(2) << "ray cast, intensity ramp " << before.tf_lo << "-" << before.tf_hi;
  panels.back().detail = ramp.str();
  panels.push_back(raycast_panel(scene, input.u, after, "after classification"));
  panels.back().detail = "ray cast, opacity u (> " + format_number(after.tf_cut) + ")";
  panel.reset();
  if (!o.quiet) {
    print_panels("figure5 row " + std::to_string(k + 1) + ": " + in, o.out, panels, f.width, f.height);
    std::cout << "  input    " << input.note << '\n';
  }
  return compose(panels);
}

// One row of figure6: the classified input k by four renderers.
Image figure6_row(Runtime& rt, const FigureOptions& o, const FigureSetup& f, std::size_t k) {
  const std::string& in = o.ins[k];
  const viewer::OpacityInput input = viewer::load_opacity(rt, in, viewer::InputKind::Auto, f.isos[k]);
  const RaycastParams p = opacity_params(o, f.settings[k]);
  const auto box = visible_box(input.u, p);
  const Scene scene{rt, input.u, framed_camera(box, f.az[k], f.el[k]), f.settings[k], f.width, f.height, o.repeat};
  std::vector<Panel> panels;
  const std::string row = row_stage(o, k);
  std::optional<progress::Stage> panel(std::in_place, row + "panel 1/4: ray casting");
  panels.push_back(raycast_panel(scene, input.u, p, "ray casting"));
  panel.emplace(row + "panel 2/4: Marching Cubes");
  panels.push_back(marching_cubes_panel(scene, o.level));
  panel.emplace(row + "panel 3/4: shear-warp");
  panels.push_back(shear_warp_panel(scene, box, f.az[k], f.el[k]));
  panel.emplace(row + "panel 4/4: oriented splats");
  panels.push_back(splat_panel(scene));
  panel.reset();
  if (!o.quiet) {
    print_panels("figure6 row " + std::to_string(k + 1) + ": " + in, o.out, panels, f.width, f.height);
    std::cout << "  input    " << input.note << '\n';
  }
  return compose(panels);
}

int run_figure(const FigureOptions& o, const std::string& name, const std::string& caption,
               Image (*row)(Runtime&, const FigureOptions&, const FigureSetup&, std::size_t)) {
  const auto t0 = Clock::now();
  const FigureSetup f = figure_setup(o);
  const progress::Stage command(name);
  Runtime rt(o.device);
  std::vector<Image> rows;
  for (std::size_t k = 0; k < o.ins.size(); ++k) rows.push_back(row(rt, o, f, k));
  write_png(o.out, stack_rows(rows, f.labels, o.caption.empty() ? caption : o.caption));
  if (!o.quiet)
    std::cout << name << " -> " << o.out << "\n  time     " << std::fixed << std::setprecision(2) << seconds_since(t0)
              << " s on " << rt.info().label() << '\n';
  return 0;
}

int run_figure5(const FigureOptions& o) {
  return run_figure(o, "figure5",
                    "Ray casting before (left: the B-mode intensity through a ramp transfer function) and after "
                    "(right: the opacity u) variational classification, as in the paper's Figure 5. Times are per "
                    "frame on this machine.",
                    figure5_row);
}

int run_figure6(const FigureOptions& o) {
  return run_figure(o, "figure6",
                    "One classified volume per row drawn four ways, as in the paper's Figure 6: ray casting of u, "
                    "Marching Cubes of u at the splats' epsilon, shear-warp (VolPack) and oriented splats (one "
                    "Gaussian triangle per voxel, perpendicular to grad u). Times are per frame on this machine.",
                    figure6_row);
}

}  // namespace

// ---------------------------------------------------------------------------
// `render --method raycast`.
std::shared_ptr<RaycastRenderOptions> add_raycast_render_options(CLI::App* sub) {
  auto o = std::make_shared<RaycastRenderOptions>();
  add_raycast_options(sub, *o, true);
  return o;
}

int run_raycast_render(const RaycastRenderOptions& o, const RaycastRenderRequest& req) {
  const auto t0 = Clock::now();
  const auto [width, height] = parse_size(req.size, "--size");
  const auto [az, el] = parse_view(req.view, "--view");
  if (req.turntable != 0) throw InputError("--turntable is not supported with --method raycast");
  if (req.benchmark < 0 || req.benchmark > 100000) throw InputError("--benchmark must be in [0, 100000]");
  check_png_output(req.in, req.out);
  viewer::RenderSettings settings = SplatViewOptions{}.settings();
  if (!req.crop.empty()) parse_crop(req.crop, settings);
  if (o.unclassified && req.opacity) throw InputError("--unclassified and --opacity exclude each other");
  if (o.unclassified && req.classify) throw InputError("--unclassified and --classify exclude each other");

  Runtime rt(req.device);
  Volume samples;
  RaycastParams p;
  std::string note;
  if (o.unclassified) {
    const Volume raw = read_volume(req.in);
    const double iso = raw_iso(raw, req.iso);
    const double iso_unit = std::clamp(raw.intensity_map().to_unit(iso), 0.0, 1.0);
    p = raycast_params(o, iso_unit, settings);
    samples = unit_samples(raw);
    note = "raw " + req.in + " (" + scalar_type_name(raw.source_type) + ", " + raw.intensity_map().describe() +
           "), iso " + format_number(iso) + (req.iso == "auto" ? " (auto)" : "") + ", not classified";
  } else {
    const viewer::InputKind kind = req.opacity    ? viewer::InputKind::Opacity
                                   : req.classify ? viewer::InputKind::Raw
                                                  : viewer::InputKind::Auto;
    viewer::OpacityInput input = viewer::load_opacity(rt, req.in, kind, req.iso);
    p = raycast_params(o, -1.0, settings);
    samples = std::move(input.u);
    note = input.note;
  }
  const auto box = visible_box(samples, p);
  bool any = false;
  for (float v : samples.data) any = any || p.opacity(v) > 0;
  if (!any) throw input_error(req.in, "every sample is transparent under the transfer function; nothing to render");

  RayCaster rc(rt, samples, p);
  const RayCamera cam = ray_camera(framed_camera(box, az, el));
  double kernel_s = 0;
  const RaycastImage img = rc.render(cam, width, height, &kernel_s);
  write_png(req.out, img.rgb(p.background));
  double ms = 0;
  if (req.benchmark > 0) {
    const auto tb = Clock::now();
    for (int i = 0; i < req.benchmark; ++i) rc.render(cam, width, height);
    ms = 1000.0 * seconds_since(tb) / req.benchmark;
  }
  if (!req.quiet) {
    std::cout << std::fixed << std::setprecision(3) << "render (ray casting) " << req.in << " -> " << req.out << '\n'
              << "  input    " << note << '\n'
              << "  opacity  " << format_number(p.tf_max) << " * ramp(" << format_number(p.tf_lo) << ", "
              << format_number(p.tf_hi) << ") per voxel length" << (p.tf_cut > 0 ? ", 0 below " + format_number(p.tf_cut) : "")
              << ", step " << format_number(p.step)
              << " voxel, early termination " << (p.termination < 1 ? "at 0.99" : "off") << '\n'
              << "  image    " << width << "x" << height << ", view " << format_number(az) << "," << format_number(el)
              << ", kernel " << std::setprecision(1) << 1000.0 * kernel_s << " ms on " << rt.info().label() << '\n';
    if (req.benchmark > 0)
      std::cout << "  speed    " << std::setprecision(1) << ms << " ms/frame (kernel + read-back) over "
                << req.benchmark << " frames\n";
    std::cout << std::setprecision(3) << "  time     " << seconds_since(t0) << " s\n";
  }
  return 0;
}

void add_figure5_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<FigureOptions>();
  auto* sub = app.add_subcommand(
      "figure5",
      "The paper's Figure 5: ray casting of a raw ultrasound volume before variational classification (intensity "
      "through a ramp transfer function) and after (the opacity u), side by side, each labelled with its time per "
      "frame. Ray casting only (no OpenGL).");
  sub->add_option("IN", o->ins, "Raw ultrasound volume(s) (not opacity volumes): one row each")->required();
  o->out = "fig5.png";
  sub->add_option("-o,--output", o->out, "Output PNG")->capture_default_str();
  add_figure_options(sub, *o);
  sub->callback([&action, o] { action = [o] { return run_figure5(*o); }; });
}

void add_figure6_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<FigureOptions>();
  auto* sub = app.add_subcommand(
      "figure6",
      "The paper's Figure 6: one classified volume rendered by ray casting, Marching Cubes, shear-warp (VolPack) "
      "and oriented splats, side by side, each labelled with its time per frame. A raw volume is classified first "
      "with the defaults. The splat panel uses OpenGL (run under xvfb-run -a without a display).");
  sub->add_option("IN", o->ins, "Opacity volume(s) (float in [0, 1]) or raw ultrasound volume(s): one row each")
      ->required();
  o->out = "fig6.png";
  sub->add_option("-o,--output", o->out, "Output PNG")->capture_default_str();
  add_figure_options(sub, *o);
  sub->add_option("--level", o->level, "Level of the Marching Cubes surface of u (default: the splats' epsilon, as render --method mc)")
      ->capture_default_str()
      ->check(real_range(-INFINITY, INFINITY));
  sub->callback([&action, o] { action = [o] { return run_figure6(*o); }; });
}

std::optional<double> bench_render_seconds(Runtime& rt, const Volume& u, const std::string& method, int width,
                                           int height) {
  try {
    const viewer::RenderSettings settings;  // the renderers' defaults, no crop
    RaycastParams p;
    apply_render_settings(p, settings);
    const auto box = visible_box(u, p);
    const Scene scene{rt, u, framed_camera(box, 0.0f, 0.0f), settings, width, height, 5};
    if (method == "splat") return splat_panel(scene).seconds;
    if (method == "shearwarp" && shearwarp_available()) return shear_warp_panel(scene, box, 0.0f, 0.0f).seconds;
  } catch (const InputError&) {
    // no display for the splats, or nothing to draw: the column says n/a
  }
  return std::nullopt;
}

}  // namespace softshell::cli
