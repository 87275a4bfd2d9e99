// `softshell phantom --shape face|spine|sphere --size N --seed S -o DIR`: a
// simulated 3D ultrasound volume with its ground truth (host/phantom.hpp).
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <system_error>

#include "cl_runtime.hpp"
#include "cli_common.hpp"
#include "error.hpp"
#include "image.hpp"
#include "io.hpp"
#include "phantom.hpp"
#include "text.hpp"

namespace softshell::cli {
namespace {

namespace fs = std::filesystem;

struct PhantomOptions {
  std::string shape = "face", out, speckle, slices, device, dims;
  PhantomParams params;
  bool quiet = false;
};

// "AXIAL,LATERAL": two numbers, PSF standard deviations in voxels.
void parse_speckle(const std::string& text, PhantomParams& p) {
  const auto bad = [&] {
    return InputError("--speckle '" + text + "': expected AXIAL,LATERAL PSF sigmas in voxels, e.g. 0.6,1.5");
  };
  const std::size_t comma = text.find(',');
  if (comma == std::string::npos || text.find(',', comma + 1) != std::string::npos) throw bad();
  double v[2];
  const std::string parts[2] = {text.substr(0, comma), text.substr(comma + 1)};
  for (int i = 0; i < 2; ++i) {
    const std::string s = trim(parts[i]);
    char* end = nullptr;
    errno = 0;
    v[i] = std::strtod(s.c_str(), &end);
    if (s.empty() || *end != '\0' || errno != 0 || !std::isfinite(v[i])) throw bad();
  }
  p.psf_axial = v[0];
  p.psf_lateral = v[1];
}

void write_text_atomically(const std::string& path, const std::string& text) {
  io_detail::AtomicFile f(path);
  f.write(text.data(), text.size());
  f.commit();
}

int run_phantom(PhantomOptions o) {
  const auto t0 = Clock::now();
  if (!parse_phantom_shape(o.shape, o.params.shape))
    throw InputError("--shape '" + o.shape + "' is not one of face, spine, sphere");
  if (!o.speckle.empty()) parse_speckle(o.speckle, o.params);
  if (!o.dims.empty()) {
    const Dims3 d = parse_dims(o.dims, "--dims");
    for (int a = 0; a < 3; ++a)
      o.params.dims[a] = static_cast<int>(std::min<std::size_t>(d[a], 1u << 20));  // range checked below
  }
  validate_phantom_params(o.params);  // before anything touches the disk or the device

  const fs::path dir(o.out);
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    throw InputError("-o " + o.out + ": exists and is not a directory");

  Runtime rt(o.device);  // a missing device leaves nothing behind
  const Phantom p = make_phantom(rt, o.params);

  const auto t1 = Clock::now();
  fs::create_directories(dir, ec);
  if (ec) throw InputError("-o " + o.out + ": cannot create directory: " + ec.message());
  write_volume((dir / "volume.nrrd").string(), p.volume);
  write_volume((dir / "truth_sdf.nrrd").string(), p.truth_sdf);
  write_text_atomically((dir / "phantom.json").string(), phantom_json(o.params, p));
  Image slices;
  if (!o.slices.empty()) {
    slices = phantom_slices(p);
    write_png(o.slices, slices);
  }
  const double t_write = seconds_since(t1);

  if (!o.quiet) {
    auto median = [](double m) { return std::isfinite(m) ? std::to_string(static_cast<int>(std::lround(m))) : "n/a"; };
    const double h = p.volume.spacing[0];
    std::cout << std::fixed << std::setprecision(3) << "phantom " << phantom_shape_name(o.params.shape) << ' '
              << dims_text(p.volume.dims) << " uint8, seed " << o.params.seed << " -> " << o.out << '\n'
              << "  spacing  " << h << " mm (fov " << std::setprecision(1) << p.fov_mm
              << " mm), transducer at z = 0, beams along +z\n"
              << std::setprecision(2) << "  psf      sigma axial " << o.params.psf_axial << ", lateral "
              << o.params.psf_lateral << " voxels; dynamic range " << std::setprecision(1) << o.params.dynamic_range_db
              << " dB; noise " << std::setprecision(3) << o.params.noise << '\n'
              << "  medians  fluid " << median(p.fluid_median) << " (sdf > 3), tissue " << median(p.tissue_median)
              << " (sdf < -3)\n"
              << "  device   " << p.device << '\n'
              << "  time     generate " << p.seconds << " s (kernels " << p.device_seconds << " s), write " << t_write
              << " s, total " << seconds_since(t0) << " s\n";
    if (!o.slices.empty())
      std::cout << "  slices   " << slices.width << 'x' << slices.height << " -> " << o.slices << '\n';
  }
  return 0;
}

}  // namespace

void add_phantom_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<PhantomOptions>();
  auto* sub = app.add_subcommand(
      "phantom", "Simulate a 3D ultrasound volume with ground truth (B-mode uint8 + true signed distance)");
  sub->description(
      "Simulate a 3D ultrasound volume with ground truth.\n"
      "Writes DIR/volume.nrrd (uint8 B-mode, isotropic spacing FOV/N mm), DIR/truth_sdf.nrrd (float signed\n"
      "distance in voxels to the true tissue boundary, negative inside tissue) and DIR/phantom.json (parameters,\n"
      "medians of fluid and tissue grey levels, timing). The transducer lies on the z = 0 face and every beam runs\n"
      "along +z (depth). Image formation: scatterers + angle-dependent boundary echoes, depth attenuation and\n"
      "shadowing, anisotropic Gaussian PSF (speckle), electronic noise, envelope, log compression (docs/phantom.md).");
  sub->add_option("--shape", o->shape,
                  "face: fetal face in amniotic fluid with the uterine wall behind; spine: vertebrae in soft "
                  "tissue (tissue = bone); sphere: one sphere of tissue in fluid")
      ->capture_default_str();
  auto* size = sub->add_option("--size", o->params.size, "Voxels along each axis, in [16, 512]")->capture_default_str();
  sub->add_option("--dims", o->dims,
                  "X,Y,Z: a non-cubic volume (e.g. 314,85,43, the paper's largest), each in [16, 512]; isotropic "
                  "voxels of FOV / max(X,Y,Z) mm, the centred crop of the cubic phantom")
      ->type_name("X,Y,Z")
      ->excludes(size);
  sub->add_option("--seed", o->params.seed, "Random seed (speckle, texture, noise; the geometry is fixed)")
      ->check(CLI::Validator(
          [](std::string& v) {
            return trim(v).rfind('-', 0) == 0 ? std::string("must be a non-negative integer") : "";
          },
          "", "non-negative"))
      ->capture_default_str();
  sub->add_option("-o,--output", o->out, "Output directory (created if missing)")->required();
  sub->add_option("--speckle", o->speckle,
                  "AXIAL,LATERAL: PSF standard deviations in voxels, each in [0.2, 8] (default 0.6,1.5)");
  sub->add_option("--dynamic-range", o->params.dynamic_range_db, "Log compression range in dB, in [10, 100]")
      ->capture_default_str();
  sub->add_option("--noise", o->params.noise, "Electronic noise rms relative to the mean tissue echo, >= 0")
      ->capture_default_str();
  sub->add_option("--attenuation", o->params.attenuation,
                  "Depth attenuation relative to the default (0.2 dB/mm two-way in soft tissue), >= 0")
      ->capture_default_str();
  sub->add_option("--specular", o->params.specular, "Strength of boundary echoes relative to the default, >= 0")
      ->capture_default_str();
  sub->add_option("--fov", o->params.fov_mm, "Field of view in mm (default: face 100, spine 60, sphere 80)");
  sub->add_option("--slices", o->slices,
                  "Also write a PNG of the axial | coronal | sagittal mid-slices, second row with the true "
                  "boundary in orange");
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  add_device_option(sub, o->device);
  sub->callback([&action, o] { action = [o] { return run_phantom(*o); }; });
}

}  // namespace softshell::cli
