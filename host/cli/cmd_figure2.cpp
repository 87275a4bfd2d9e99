// `softshell figure2 IN -o fig2.png`: the paper's Figure 2 on one slice of a
// volume — (a) the input, (b) Levoy's classifier, (c)-(f) the variational
// classifier with omega in {1, 0.6} and beta in {0, B} — to show what each
// term of the functional does (paper Section 3.5).
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "auto_iso.hpp"
#include "filter.hpp"
#include "cl_runtime.hpp"
#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "progress.hpp"
#include "image.hpp"
#include "io.hpp"
#include "levoy.hpp"
#include "mask.hpp"
#include "text.hpp"
#include "variational.hpp"

namespace softshell::cli {
namespace {

namespace fs = std::filesystem;

// Layout (documented in --help; tests rely on it): panels are grey (r = g = b),
// everything else is not: background kBackground, captions kLabel.
constexpr Rgb kBackground{24, 26, 40};
constexpr Rgb kLabel{255, 230, 120};
constexpr int kGap = 8;  // around and between cells

// Beta of panels (e) and (f): the paper's 0.03 was for 0-255 intensities,
// and F_tan scales with the square of the intensity unit.
constexpr double kFigureBeta = 0.03 * 255.0 * 255.0;  // the paper's 0.03 on 0-255 data

struct Figure2Options {
  std::string in, out, device, slice = "y", iso = "auto", mask = "auto";
  double beta = std::numeric_limits<double>::quiet_NaN();  // not given: the rule above
  int zoom = 0;      // 0: automatic
  double levoy_sigma = 0;  // mm; 0: the raw volume, as in the paper
  bool quiet = false;
  RawOptions raw;
  NonFiniteOption non_finite;
};

struct SliceSpec {
  int axis = 1;       // the fixed axis: 0 x, 1 y, 2 z
  long index = -1;    // -1: the middle
};

SliceSpec parse_slice(const std::string& text) {
  const auto bad = [&] {
    return InputError("--slice '" + text + "': expected x, y or z, optionally with :INDEX (e.g. y:40)");
  };
  SliceSpec s;
  if (text.empty()) throw bad();
  const std::string axis = text.substr(0, text.find(':'));
  if (axis == "x") s.axis = 0;
  else if (axis == "y") s.axis = 1;
  else if (axis == "z") s.axis = 2;
  else throw bad();
  if (text.size() > 1) {
    if (text[1] != ':' || text.size() == 2) throw bad();
    const std::string num = text.substr(2);
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(num.c_str(), &end, 10);
    if (*end != '\0' || errno != 0 || v < 0 || !std::isdigit(static_cast<unsigned char>(num[0]))) throw bad();
    s.index = v;
  }
  return s;
}

// The in-plane axes of a slice: image x runs along u, image y along v
// (as in `softshell slices`: z slice x right y down; y slice x right z down;
// x slice y right z down — for phantoms the y slice has the transducer on top).
void plane_axes(int fixed, int& u, int& v) {
  u = fixed == 0 ? 1 : 0;
  v = fixed == 2 ? 1 : 2;
}

// Samples of one slice as grey levels in [0, 1] (through `to_grey`), nearest
// neighbour onto square pixels of the smaller in-plane spacing, times zoom.
template <class F>
Image slice_panel(const Volume& vol, int fixed, std::size_t index, int zoom, F&& to_grey) {
  int au, av;
  plane_axes(fixed, au, av);
  const double h = std::min(vol.spacing[au], vol.spacing[av]);
  const int w = std::max(1, int(std::lround(vol.dims[au] * vol.spacing[au] / h))) * zoom;
  const int ht = std::max(1, int(std::lround(vol.dims[av] * vol.spacing[av] / h))) * zoom;
  Image p(w, ht);
  std::size_t c[3];
  c[fixed] = index;
  for (int py = 0; py < ht; ++py)
    for (int px = 0; px < w; ++px) {
      c[au] = std::min(vol.dims[au] - 1, std::size_t((px + 0.5) * vol.dims[au] / w));
      c[av] = std::min(vol.dims[av] - 1, std::size_t((py + 0.5) * vol.dims[av] / ht));
      const double g = std::clamp(to_grey(vol.at(c[0], c[1], c[2])), 0.0, 1.0);
      std::uint8_t* q = p.pixel(px, py);
      q[0] = q[1] = q[2] = static_cast<std::uint8_t>(std::lround(255.0 * g));
    }
  return p;
}

std::string number(double v) {
  std::ostringstream s;
  s << std::setprecision(4) << v;
  return s.str();
}

// What Figure 2 is about, per opacity panel, on the slice shown
// (docs/real-data.md, "Figure 2"): the drawn set is u above half the
// slice's maximum; `blobs` counts its 8-connected pieces of fewer than
// kBlobPixels pixels (speckle-sized debris); `roughness` is the length of
// its boundary (pixel edges between drawn and not drawn) over that of the
// slice blurred by a Gaussian of 2 pixels and cut at half its own maximum:
// about 1 for a smooth contour, more for a ragged one.
struct SliceStats {
  int blobs = 0;
  double roughness = 0;
};
constexpr int kBlobPixels = 20;

SliceStats slice_stats(const Volume& u, int fixed, std::size_t index) {
  int au, av;
  plane_axes(fixed, au, av);
  const int w = int(u.dims[au]), h = int(u.dims[av]);
  std::vector<float> s(std::size_t(w) * h);
  std::size_t c[3];
  c[fixed] = index;
  float top = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      c[au] = std::size_t(x), c[av] = std::size_t(y);
      s[std::size_t(y) * w + x] = u.at(c[0], c[1], c[2]);
      top = std::max(top, s[std::size_t(y) * w + x]);
    }
  SliceStats st;
  if (!(top > 0)) return st;
  const float t = 0.5f * top;
  auto boundary = [&](const std::vector<float>& f, float thr) {
    long edges = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const bool in = f[std::size_t(y) * w + x] > thr;
        if (x + 1 < w) edges += in != (f[std::size_t(y) * w + x + 1] > thr);
        if (y + 1 < h) edges += in != (f[std::size_t(y + 1) * w + x] > thr);
      }
    return double(edges);
  };
  // Gaussian sigma 2 pixels, separable, clamped at the border.
  std::vector<float> g = s, tmp(s.size());
  const std::vector<float> k = gaussian_weights(2.0, 3.0);
  const int r = int(k.size() / 2);
  for (int pass = 0; pass < 2; ++pass) {
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        double acc = 0;
        for (int j = -r; j <= r; ++j) {
          const int xx = pass == 0 ? std::clamp(x + j, 0, w - 1) : x, yy = pass == 1 ? std::clamp(y + j, 0, h - 1) : y;
          acc += k[std::size_t(j + r)] * g[std::size_t(yy) * w + xx];
        }
        tmp[std::size_t(y) * w + x] = float(acc);
      }
    g.swap(tmp);
  }
  // Each set at half its own maximum (the blur lowers a thin shell's peak).
  const float gtop = *std::max_element(g.begin(), g.end());
  const double rough = boundary(s, t), smooth = boundary(g, 0.5f * gtop);
  st.roughness = smooth > 0 ? rough / smooth : 0.0;
  // 8-connected pieces of the drawn set, by flood fill.
  std::vector<std::uint8_t> seen(s.size(), 0);
  std::vector<int> stack;
  for (int i0 = 0; i0 < w * h; ++i0) {
    if (seen[std::size_t(i0)] || !(s[std::size_t(i0)] > t)) continue;
    int size = 0;
    stack.assign(1, i0);
    seen[std::size_t(i0)] = 1;
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      ++size;
      const int x = i % w, y = i / w;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
          const int j = yy * w + xx;
          if (!seen[std::size_t(j)] && s[std::size_t(j)] > t) seen[std::size_t(j)] = 1, stack.push_back(j);
        }
    }
    st.blobs += size < kBlobPixels;
  }
  return st;
}

// Six captioned panels, 3 across and 2 down, and a footer line.
Image compose(const std::vector<Image>& panels, const std::vector<std::string>& long_labels,
              const std::vector<std::string>& short_labels, const std::string& footer) {
  const int pw = panels[0].width, ph = panels[0].height;
  // Caption scale: 2 when every long label fits the panel width, else 1;
  // short labels when even that does not fit.
  int scale = 2;
  bool use_long = true;
  auto fits = [&](const std::vector<std::string>& labels, int s) {
    return std::all_of(labels.begin(), labels.end(), [&](const std::string& l) { return text_width(l, s) <= pw; });
  };
  if (!fits(long_labels, 2)) {
    scale = 1;
    if (!fits(long_labels, 1)) use_long = false;
  }
  const int caption = text_height("A", scale) + 6;
  // The footer: lines separated by '\n'.
  std::vector<std::string> lines;
  if (!footer.empty()) lines = wrap_text(footer, 3 * pw + 2 * kGap, 1);
  const int line_h = text_height("A", 1) + 4;
  const int footer_h = lines.empty() ? 0 : int(lines.size()) * line_h + kGap;
  const int cell_h = caption + ph;
  Image img(4 * kGap + 3 * pw, 3 * kGap + 2 * cell_h + footer_h);
  fill_rect(img, 0, 0, img.width, img.height, kBackground);
  for (int k = 0; k < 6; ++k) {
    const int x0 = kGap + (k % 3) * (pw + kGap), y0 = kGap + (k / 3) * (cell_h + kGap);
    draw_text(img, x0, y0 + 2, use_long ? long_labels[k] : short_labels[k], kLabel, scale);
    blit(img, panels[k], x0, y0 + caption);  // every panel is pw x ph
  }
  for (std::size_t l = 0; l < lines.size(); ++l)
    draw_text(img, kGap, img.height - footer_h + int(l) * line_h, lines[l], kLabel, 1);
  return img;
}

int run_figure2(const Figure2Options& o) {
  const auto t0 = Clock::now();
  const SliceSpec spec = parse_slice(o.slice);
  std::optional<double> given_iso;
  AutoIsoParams auto_params;  // auto / auto-ridge: the echo crest; auto-edge: the edge midpoint
  auto_params.rule = o.iso == "auto-edge" ? AutoIsoRule::Edge : AutoIsoRule::EchoRidge;
  if (o.iso != "auto" && o.iso != "auto-ridge" && o.iso != "auto-edge") {
    char* end = nullptr;
    const double v = std::strtod(o.iso.c_str(), &end);
    if (o.iso.empty() || *end != '\0' || !std::isfinite(v))
      throw InputError("--iso: expected a number in the input's intensity units, auto, auto-ridge or auto-edge, got '" +
                       o.iso + "'");
    given_iso = v;
  }
  if (o.zoom < 0 || o.zoom > 64) throw InputError("--zoom must be in [0, 64] (0: automatic)");
  if (!(o.levoy_sigma >= 0) || !std::isfinite(o.levoy_sigma)) throw InputError("--levoy-sigma must be >= 0 (mm)");
  const bool beta_given = !std::isnan(o.beta);
  if (beta_given && !(o.beta >= 0 && std::isfinite(o.beta))) throw InputError("--beta must be a finite number >= 0");
  if (o.mask.empty()) throw InputError("--mask: expected FILE, auto or none");
  ensure_distinct_output(o.in, o.out);
  check_output(o.out, OutputKind::Png);

  Runtime rt(o.device);
  Volume in = read_volume(o.in, o.raw.spec(), o.raw.frame);
  o.non_finite.apply(in, o.in);
  if (spec.index >= 0 && std::size_t(spec.index) >= in.dims[spec.axis])
    throw InputError("--slice " + o.slice + ": index out of range, the volume has " +
                     std::to_string(in.dims[spec.axis]) + " slices along " + "xyz"[spec.axis]);
  const std::size_t index = spec.index >= 0 ? std::size_t(spec.index) : in.dims[spec.axis] / 2;

  // A given isovalue's warning in the file's units, before the fill moves.
  const std::string iso_warning = given_iso ? iso_outside_data(in, *given_iso) : "";
  // Data region, as in `classify` (host/mask.hpp): float data whose fill is
  // not 0 have it moved to 0 first; isovalues are shown in the file's units.
  const double fill = o.mask == "auto" ? unscanned_fill_value(in) : 0.0;
  move_fill_to_zero(in, fill);
  std::vector<std::uint8_t> mask;
  if (o.mask == "auto") mask = scanned_mask(in);
  else if (o.mask != "none") {
    try {
      mask = read_mask(o.mask, in.dims);
    } catch (const InputError& e) {
      throw InputError(std::string("--mask ") + e.what());
    }
  }
  const std::size_t unscanned = mask.empty() ? 0 : count_unscanned(mask);
  if (unscanned == 0) mask.clear();
  if (fill != 0.0) darken_scanned_fill(in, mask);
  const std::vector<std::uint8_t>* mask_ptr = mask.empty() ? nullptr : &mask;
  const double iso = given_iso ? *given_iso - fill : auto_iso(in, mask_ptr, auto_params);
  const Volume filled = mask.empty() ? Volume() : fill_unscanned(in, mask);
  const Volume& data = mask.empty() ? in : filled;
  auto apply_mask = [&](Volume& u) {
    for (std::size_t i = 0; i < mask.size(); ++i)
      if (!mask[i]) u.data[i] = 0.0f;
  };

  // The paper's functional exactly (--literal), at the paper's omega and
  // beta: its beta = 0.03 was for 0-255 intensities, and F_tan scales with
  // the square of the intensity unit, so on [0, 1] data it is 0.03 x 255^2.
  const VariationalParams defaults = VariationalParams::literal_defaults();
  const double beta = beta_given ? o.beta : kFigureBeta;

  std::vector<Volume> opacities;
  LevoyParams lp;
  lp.iso = iso;
  lp.sigma_mm = o.levoy_sigma;
  const progress::Stage command("figure2");
  std::optional<progress::Stage> panel(std::in_place, "panel (b): levoy");
  opacities.push_back(classify_levoy(rt, data, lp));
  apply_mask(opacities.back());
  // v_iso normalised the way classify_variational normalises `data` (for
  // float volumes the robust range of the filled copy, not of the input).
  const IntensityMap data_map = data.intensity_map();
  const double runs[4][2] = {{1.0, 0.0}, {0.6, 0.0}, {1.0, beta}, {0.6, beta}};  // omega, beta
  for (const auto& r : runs) {
    panel.emplace("panel (" + std::string(1, char('c' + (&r - runs))) + "): variational");
    VariationalParams p = defaults;
    p.v_iso = data_map.to_unit(iso);
    p.omega = r[0];
    p.beta = r[1];
    SolveReport report;
    opacities.push_back(classify_variational(rt, data, p, SolverParams{}, &report, nullptr, mask_ptr));
    if (!report.converged) {
      std::ostringstream msg;
      msg << "figure2: the variational classifier (omega " << r[0] << ", beta " << r[1]
          << ") did not converge: relative residual " << std::scientific << std::setprecision(2)
          << report.residuals.back() << " after " << report.cycles << " iterations; nothing written";
      throw NotConvergedError(msg.str());
    }
  }

  panel.reset();
  std::cerr << iso_warning;  // after every check of the isovalue passed
  int au, av;
  plane_axes(spec.axis, au, av);
  int zoom = o.zoom;
  if (zoom == 0) {
    const double h = std::min(in.spacing[au], in.spacing[av]);
    const double longest = std::max(in.dims[au] * in.spacing[au], in.dims[av] * in.spacing[av]) / h;
    zoom = std::clamp(int(std::ceil(256.0 / std::max(longest, 1.0))), 1, 64);
  }
  std::vector<Image> panels;
  const IntensityMap map = in.intensity_map();
  panels.push_back(slice_panel(in, spec.axis, index, zoom, [&](double v) { return map.to_unit(v); }));
  for (const Volume& u : opacities) panels.push_back(slice_panel(u, spec.axis, index, zoom, [](double v) { return v; }));

  const std::string b = number(beta);
  std::vector<SliceStats> stats;
  for (const Volume& u : opacities) stats.push_back(slice_stats(u, spec.axis, index));
  const std::string levoy_label = o.levoy_sigma > 0 ? "(b) Levoy, sigma " + number(o.levoy_sigma) + " mm" : "(b) Levoy";
  const std::vector<std::string> long_labels = {
      "(a) input",         levoy_label,         "(c) omega 1, beta 0", "(d) omega 0.6, beta 0",
      "(e) omega 1, beta " + b, "(f) omega 0.6, beta " + b};
  const std::vector<std::string> short_labels = {"(a)", "(b)", "(c)", "(d)", "(e)", "(f)"};
  // "auto", "none" or the mask file's name, and how much it fixed.
  const std::string mask_name = o.mask == "auto" || o.mask == "none" ? o.mask : fs::path(o.mask).filename().string();
  const std::string mask_label = o.mask == "none" ? mask_name : mask_name + " (" + std::to_string(unscanned) + " unscanned)";
  std::ostringstream footer;
  footer << "slice " << "xyz"[spec.axis] << '=' << index << "  iso " << number(iso + fill) << (given_iso ? "" : " (auto)")
         << "  mask " << mask_label << "  beta " << b << "\nblobs / contour roughness:";
  for (std::size_t k = 0; k < stats.size(); ++k)
    footer << "  (" << char('b' + k) << ") " << stats[k].blobs << " / " << std::fixed << std::setprecision(2)
           << stats[k].roughness;
  const Image img = compose(panels, long_labels, short_labels, footer.str());
  write_png(o.out, img);
  if (!o.quiet) {
    std::cout << std::fixed << std::setprecision(3) << "figure2 " << o.in << " -> " << o.out << " (" << img.width
              << "x" << img.height << ", panels " << panels[0].width << "x" << panels[0].height << ", zoom " << zoom
              << ")\n"
              << "  slice    " << "xyz"[spec.axis] << " = " << index << " of " << in.dims[spec.axis] << '\n'
              << "  iso      " << iso + fill << (given_iso ? "" : " (auto)") << '\n'
              << "  mask     " << (o.mask == "none" ? "none" : o.mask) << ", " << unscanned << " voxels unscanned\n"
              << "  panels   (a) input, (b) Levoy (thickness 1 voxel, lowpass " << number(o.levoy_sigma)
              << " mm), (c) omega 1 beta 0, (d) omega 0.6 beta 0, "
                 "(e) omega 1 beta "
              << b << ", (f) omega 0.6 beta " << b << "; the paper's functional (--literal)\n";
    std::cout << "  slice    blobs (pieces under " << kBlobPixels << " pixels of u > half the slice's max) / "
              << "contour roughness (boundary length over that after a 2-pixel Gaussian):";
    for (std::size_t k = 0; k < stats.size(); ++k)
      std::cout << " (" << char('b' + k) << ") " << stats[k].blobs << " / " << std::setprecision(2) << stats[k].roughness;
    std::cout << std::setprecision(3) << '\n'
              << "  device   " << rt.info().label() << '\n'
              << "  time     " << seconds_since(t0) << " s\n";
  }
  return 0;
}

}  // namespace

void add_figure2_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<Figure2Options>();
  auto* sub = app.add_subcommand(
      "figure2",
      "The paper's Figure 2 on one slice: (a) input, (b) Levoy, (c)-(f) variational with omega 1 / 0.6 and beta 0 / B");
  sub->add_option("IN", o->in, "Input volume")->required();
  sub->add_option("-o,--output", o->out, "Output PNG: 3 x 2 captioned grey panels (opacity 0..1 as black..white)")
      ->required();
  sub->add_option("--slice", o->slice, "Slice: x, y or z (the middle one) or AXIS:INDEX")
      ->capture_default_str()
      ->type_name("z|y|x[:INDEX]");
  sub->add_option("--iso", o->iso, "Isovalue in the input's units, or auto|auto-ridge|auto-edge (as in classify)")
      ->capture_default_str()
      ->type_name("V|auto");
  sub->add_option("--mask", o->mask, "Scanned region: auto, none or FILE (as in classify)")
      ->capture_default_str()
      ->type_name("FILE|auto|none");
  sub->add_option("--beta", o->beta,
                  "Beta of panels (e) and (f), on intensities normalised to [0, 1] (default: the paper's 0.03 on "
                  "0-255 data, i.e. 0.03 x 255^2 = 1951; the panels use the paper's functional, --literal)")
      ->check(real_range(0, 1e6));
  sub->add_option("--levoy-sigma", o->levoy_sigma, "Lowpass of panel (b) in mm (0: the raw volume, as in the paper)")
      ->capture_default_str()
      ->check(real_range(0, INFINITY, "mm"));
  sub->add_option("--zoom", o->zoom, "Pixels per voxel (default 0: panels about 256 pixels on their long side)")
      ->check(int_range(0, 64));
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  add_device_option(sub, o->device);
  o->raw.add_to(sub);
  o->non_finite.add_to(sub);
  sub->callback([&action, o] { action = [o] { return run_figure2(*o); }; });
}

}  // namespace softshell::cli
