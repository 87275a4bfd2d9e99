// `softshell render IN --method mc|shearwarp`: the Marching Cubes mesh drawn by the GL renderer
// (viewer/mesh_renderer.hpp) and VolPack's shear-warp (host/shearwarp.hpp), dispatched from
// cmd_render.cpp with render's common options. Both frame what the splats frame (the voxels with
// u > 0.2 inside the crop box), so the same --view and --size give images that line up.
#include <algorithm>
#include <chrono>
#include <iomanip>
#include <iostream>

#include "cli_common.hpp"
#include "cli_render_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "image.hpp"
#include "mesh.hpp"
#include "mesh_renderer.hpp"
#include "opacity_input.hpp"
#include "shearwarp.hpp"

namespace softshell::cli {
namespace {

constexpr float kFrameThreshold = 0.2f;  // the splats' default epsilon: what `render` frames

struct Common {
  int width = 0, height = 0;
  float az = 0, el = 0;
  viewer::RenderSettings settings;  // crop fractions, colours, light
  viewer::InputKind kind = viewer::InputKind::Auto;
};

Common validate(const RaycastRenderRequest& r, const char* method) {
  Common c;
  std::tie(c.width, c.height) = parse_size(r.size, "--size");
  std::tie(c.az, c.el) = parse_view(r.view, "--view");
  if (r.turntable != 0) throw InputError(std::string("--turntable is not available with --method ") + method);
  if (r.benchmark < 0 || r.benchmark > 100000) throw InputError("--benchmark must be in [0, 100000]");
  if (r.out.size() < 4 || r.out.substr(r.out.size() - 4) != ".png") throw InputError("-o " + r.out + ": expected a .png file");
  if (!r.crop.empty()) parse_crop(r.crop, c.settings);
  if (r.opacity && r.classify) throw InputError("--opacity and --classify exclude each other");
  c.kind = r.opacity ? viewer::InputKind::Opacity : r.classify ? viewer::InputKind::Raw : viewer::InputKind::Auto;
  ensure_distinct_output(r.in, r.out);
  check_output(r.out, OutputKind::Png);
  return c;
}


double seconds(Clock::time_point t0) { return seconds_since(t0); }

}  // namespace

int run_mesh_render(double level, const RaycastRenderRequest& r) {
  const auto t0 = Clock::now();
  const Common c = validate(r, "mc");
  if (!std::isfinite(level)) throw InputError("--level must be a finite number");
  Runtime rt(r.device);
  const viewer::OpacityInput input = viewer::load_opacity(rt, r.in, c.kind, r.iso);
  MeshTiming mt;
  const Mesh mesh = marching_cubes(rt, input.u, level, &mt);
  if (mesh.empty()) throw input_error(r.in, "no surface at level " + format_number(level) + "; nothing to render");

  // Camera as the splats': fit the box of u > 0.2 inside the crop, then the view.
  const Volume& u = input.u;
  viewer::OrbitCamera cam;
  const auto box = opacity_box(cropped(u, c.settings), kFrameThreshold);
  cam.fit(box[0], box[1]);
  cam.azimuth = c.az;
  cam.elevation = c.el;
  glm::vec3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    const float o = float(u.origin[a]), ext = float(u.spacing[a] * double(u.dims[a] - 1)), eps = 0.5f * float(u.spacing[a]);
    lo[a] = c.settings.crop_lo[a] <= 0.0f ? -1e30f : o + c.settings.crop_lo[a] * ext - eps;
    hi[a] = c.settings.crop_hi[a] >= 1.0f ? 1e30f : o + c.settings.crop_hi[a] * ext + eps;
  }

  viewer::MeshHeadless gl(c.width, c.height);
  const auto tu = Clock::now();
  gl.upload(mesh);
  glFinish();
  const double upload_s = seconds(tu);
  const double first_s = gl.render(cam, c.settings, lo, hi);
  write_png(r.out, gl.read().rgb());
  double frame_ms = 0;
  if (r.benchmark > 0) {
    gl.render(cam, c.settings, lo, hi);  // warm
    viewer::OrbitCamera turn = cam;
    const auto tb = Clock::now();
    for (int i = 0; i < r.benchmark; ++i) {
      turn.azimuth = c.az + 0.5f * float(i);
      gl.render(turn, c.settings, lo, hi);
    }
    frame_ms = 1e3 * seconds(tb) / r.benchmark;
  }
  if (!r.quiet) {
    std::cout << std::fixed << std::setprecision(1) << "render (Marching Cubes) " << r.in << " -> " << r.out << '\n'
              << "  input    " << input.note << '\n'
              << "  mesh     level " << format_number(level) << ": " << mesh.vertex_count() << " vertices, "
              << mesh.triangle_count() << " triangles, extracted in " << 1e3 * mt.total << " ms on "
              << rt.info().label() << " (classify " << 1e3 * mt.classify << ", scan " << 1e3 * mt.scan
              << ", generate " << 1e3 * mt.generate << ", read-back " << 1e3 * mt.read << ")\n"
              << "  image    " << c.width << "x" << c.height << ", view " << format_number(c.az) << ","
              << format_number(c.el) << "; upload " << 1e3 * upload_s << " ms, first frame " << 1e3 * first_s
              << " ms\n"
              << "  gl       " << gl.description() << '\n';
    if (r.benchmark > 0)
      std::cout << "  speed    " << std::setprecision(2) << frame_ms << " ms/frame (" << std::setprecision(1)
                << 1000.0 / frame_ms << " fps) over " << r.benchmark << " frames\n";
    std::cout << std::setprecision(3) << "  time     " << seconds(t0) << " s\n";
  }
  return 0;
}

int run_shearwarp_render(const RaycastRenderRequest& r) {
  const auto t0 = Clock::now();
  const Common c = validate(r, "shearwarp");
  if (!shearwarp_available())
    throw InputError("--method shearwarp: softshell was built without VolPack (install libvolpack1-dev and rebuild)");
  Runtime rt(r.device);
  const viewer::OpacityInput input = viewer::load_opacity(rt, r.in, c.kind, r.iso);
  const Volume u = r.crop.empty() ? input.u : cropped(input.u, c.settings);
  ShearWarpRenderer sw(u);
  ShearWarpView view;
  view.azimuth = c.az;
  view.elevation = c.el;
  view.width = c.width;
  view.height = c.height;
  view.box = opacity_box(u, kFrameThreshold);
  const ShearWarpImage img = sw.render(view);
  const ShearWarpTiming first = sw.timing();
  write_png(r.out, img.rgb());
  double frame_ms = 0, render_ms = 0;
  if (r.benchmark > 0) {
    const auto tb = Clock::now();
    for (int i = 0; i < r.benchmark; ++i) {
      view.azimuth = c.az + 0.5f * float(i);
      sw.render(view);
      render_ms += 1e3 * sw.timing().render / r.benchmark;
    }
    frame_ms = 1e3 * seconds(tb) / r.benchmark;
  }
  if (!r.quiet) {
    std::cout << std::fixed << std::setprecision(1) << "render (shear-warp, VolPack) " << r.in << " -> " << r.out
              << '\n'
              << "  input    " << input.note << '\n'
              << "  volume   " << u.dims[0] << "x" << u.dims[1] << "x" << u.dims[2] << ", " << sw.voxels_kept()
              << " voxels with u >= 0.05 classified (run-length encoded) in " << 1e3 * first.preprocess << " ms\n"
              << "  image    " << c.width << "x" << c.height << ", view " << format_number(c.az) << ","
              << format_number(c.el) << " (parallel projection); shading table " << 1e3 * first.shade
              << " ms, render " << 1e3 * first.render << " ms\n";
    if (r.benchmark > 0)
      std::cout << "  speed    " << std::setprecision(2) << frame_ms << " ms/frame (" << std::setprecision(1)
                << 1000.0 / frame_ms << " fps; vpRenderClassifiedVolume " << std::setprecision(2) << render_ms
                << " ms) over " << r.benchmark << " frames\n";
    std::cout << std::setprecision(3) << "  time     " << seconds(t0) << " s\n";
  }
  return 0;
}

}  // namespace softshell::cli
