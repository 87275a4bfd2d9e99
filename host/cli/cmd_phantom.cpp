// `softshell phantom --shape face|spine|sphere --size N --seed S -o DIR`: a
// simulated 3D ultrasound volume with its ground truth (host/phantom.hpp).
#include <optional>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <system_error>
#include <vector>

#include "cl_runtime.hpp"
#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "progress.hpp"
#include "image.hpp"
#include "io.hpp"
#include "phantom.hpp"
#include "text.hpp"

namespace softshell::cli {
namespace {

namespace fs = std::filesystem;

struct PhantomOptions {
  std::string shape = "face", out, speckle, slices, device, dims, physics, physics_set;
  PhantomParams params;
  bool quiet = false;
  // Options of the fixed physics given on the command line (they do not
  // apply to --physics other than default).
  std::vector<std::string> fixed_physics_options;
  bool fov_given = false;
  // 3D+t: frames > 1 writes 4-D sequences of a moving scene.
  int frames = 1;
  double turn_deg = 10, drift_mm = 3;
  std::string frame_speckle = "new";  // new: seed + k per frame; same: the seed for every frame
};

// The pose of frame k of n: the scene turns by `turn` degrees about the
// beam (yaw) and drifts `drift` mm along x over the sequence, centred on
// the base pose, at a constant rate.
PhantomPhysics frame_physics(const PhantomPhysics& base, int k, int n, double turn, double drift) {
  PhantomPhysics p = base;
  const double t = n > 1 ? double(k) / double(n - 1) - 0.5 : 0.0;
  p.yaw_deg = base.yaw_deg + turn * t;
  if (p.yaw_deg > 180) p.yaw_deg -= 360;
  if (p.yaw_deg < -180) p.yaw_deg += 360;
  p.shift_mm[0] = base.shift_mm[0] + drift * t;
  return p;
}

// The physics parameters for the console, a few to a line.
std::string physics_summary(const PhantomPhysics& p) {
  std::ostringstream s;
  s << std::setprecision(3);
  s << "  geometry " << beam_geometry_name(p.geometry) << ", fov " << p.fov_mm << " mm";
  if (p.geometry != BeamGeometry::Linear)
    s << ", probe radius " << p.probe_radius_mm << " mm, sector +-" << p.sector_deg << " deg"
      << (p.geometry == BeamGeometry::Fan3d ? " x +-" + std::to_string(static_cast<int>(std::lround(p.sector_y_deg))) + " deg" : std::string())
      << ", depth " << p.scan_depth_mm << " mm";
  s << ", jitter " << p.jitter_mm << " mm\n"
    << "  psf      sigma lateral " << p.psf_lateral_mm << ", axial " << p.psf_axial_mm << ", elevation "
    << p.psf_elevation_mm << " mm at focus " << p.focus_depth_mm << " mm, spread " << p.beam_spread << '\n'
    << "  scatter  " << p.scatterers_per_cell << " per resolution cell, texture " << p.texture << ", contrast "
    << p.contrast_db << " dB, specular " << p.specular << ", skull " << p.skull_db << " dB, bone "
    << p.bone_atten_db_mm << " dB/mm\n"
    << "  signal   " << p.frequency_mhz << " MHz, " << p.attenuation_db_cm_mhz << " dB/cm/MHz, TGC mismatch slope "
    << p.tgc_slope_db << " dB bow " << p.tgc_bow_db << " dB; range " << p.dynamic_range_db << " dB, tissue grey "
    << p.tissue_grey << ", noise " << p.noise_db << " dB\n"
    << "  near     " << p.near_field_mm << " mm (skin " << p.skin_mm << ", fat " << p.fat_mm << "), "
    << p.near_field_db << " dB, fat " << p.fat_db << " dB, interfaces " << p.near_field_specular << ", wave "
    << p.near_field_wave << " / " << p.near_field_wavelength_mm << " mm, reverb " << p.reverb_db << " dB\n"
    << "  pose     yaw " << p.yaw_deg << ", pitch " << p.pitch_deg << ", roll " << p.roll_deg << " deg, shift ("
    << p.shift_mm[0] << ", " << p.shift_mm[1] << ", " << p.shift_mm[2] << ") mm\n";
  return s.str();
}

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
  if (!o.physics.empty()) {
    o.params.physics_name = o.physics;
    o.params.physics = phantom_physics(o.physics, o.params.shape, o.params.seed);  // unknown names throw
    if (o.params.physics) {
      if (!o.fixed_physics_options.empty())
        throw InputError(o.fixed_physics_options.front() + " applies to the fixed physics only, not to --physics " +
                         o.physics + " (use --physics-set NAME=VALUE; names as in phantom.json)");
      if (!o.dims.empty()) throw InputError("--dims cannot be combined with --physics " + o.physics + " (cubic volumes only)");
      if (o.fov_given) o.params.physics->fov_mm = o.params.fov_mm;
      if (!o.physics_set.empty()) apply_physics_settings(*o.params.physics, o.physics_set);
      validate_phantom_physics(*o.params.physics);
    } else if (!o.physics_set.empty()) {
      throw InputError("--physics-set needs --physics other than default");
    }
  } else if (!o.physics_set.empty()) {
    throw InputError("--physics-set needs --physics NAME");
  }
  if (o.frames > 1) {
    // A moving scene needs the physics in mm (its pose); without --physics
    // the shape's own preset.
    if (!o.params.physics) {
      if (!o.physics.empty() || !o.fixed_physics_options.empty())
        throw InputError("--frames: a moving scene is posed by the physics in mm: use --physics NAME (not default), "
                         "not the fixed physics' options");
      o.physics = o.params.shape == PhantomShape::Face ? "obstetric" : o.params.shape == PhantomShape::Spine ? "spine" : "clean";
      o.params.physics_name = o.physics;
      o.params.physics = phantom_physics(o.physics, o.params.shape, o.params.seed);
      if (!o.dims.empty()) throw InputError("--dims cannot be combined with --frames (cubic volumes only)");
      if (o.fov_given) o.params.physics->fov_mm = o.params.fov_mm;
    }
    if (std::fabs(o.drift_mm) > 0.5 * o.params.physics->fov_mm)
      throw InputError("--drift: at most half the field of view (" + std::to_string(0.5 * o.params.physics->fov_mm) + " mm)");
    for (int k : {0, o.frames - 1})
      validate_phantom_physics(frame_physics(*o.params.physics, k, o.frames, o.turn_deg, o.drift_mm));
  }
  validate_phantom_params(o.params);  // before anything touches the disk or the device

  const fs::path dir(o.out);
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    throw InputError("-o " + o.out + ": exists and is not a directory");
  check_output(o.out, OutputKind::Directory);
  if (!o.slices.empty()) check_output(o.slices, OutputKind::Png, "--slices");

  Runtime rt(o.device);  // a missing device leaves nothing behind
  std::optional<progress::Stage> stage(std::in_place, "phantom");
  Phantom p;
  // 3D+t: every frame, each with its pose and its own speckle (seed + k).
  std::vector<Volume> volumes, truths, labels, shadows;
  std::string poses;
  if (o.frames > 1) {
    const PhantomPhysics base = *o.params.physics;
    for (int k = 0; k < o.frames; ++k) {
      stage.emplace("phantom: frame " + std::to_string(k + 1) + "/" + std::to_string(o.frames));
      PhantomParams fp = o.params;
      fp.seed = o.params.seed + (o.frame_speckle == "new" ? std::uint64_t(k) : 0u);
      fp.physics = frame_physics(base, k, o.frames, o.turn_deg, o.drift_mm);
      Phantom f = make_phantom(rt, fp);
      if (k == 0) p = f;  // frame 0 for phantom.json, the medians and --slices
      std::ostringstream pose;
      pose << (k ? ", " : "") << "{\"frame\": " << k << ", \"seed\": " << fp.seed << ", \"yaw_deg\": " << fp.physics->yaw_deg
           << ", \"shift_x_mm\": " << fp.physics->shift_mm[0] << "}";
      poses += pose.str();
      volumes.push_back(std::move(f.volume));
      truths.push_back(std::move(f.truth_sdf));
      labels.push_back(std::move(f.labels));
      if (!f.shadow_db.data.empty()) shadows.push_back(std::move(f.shadow_db));
    }
  } else {
    p = make_phantom(rt, o.params);
  }
  stage.emplace("phantom: write");

  const auto t1 = Clock::now();
  fs::create_directories(dir, ec);
  if (ec) throw InputError("-o " + o.out + ": cannot create directory: " + ec.message());
  if (o.frames > 1) {
    write_frames((dir / "volume.nrrd").string(), volumes);
    write_frames((dir / "truth_sdf.nrrd").string(), truths);
    write_frames((dir / "labels.nrrd").string(), labels);
    if (shadows.size() == volumes.size()) write_frames((dir / "shadow_db.nrrd").string(), shadows);
    std::string json = phantom_json(o.params, p);
    const std::size_t close = json.rfind('}');
    std::ostringstream seq;
    seq << ",\n  \"frames\": " << o.frames << ",\n  \"turn_deg\": " << o.turn_deg << ",\n  \"drift_mm\": " << o.drift_mm
        << ",\n  \"frame_poses\": [" << poses << "]\n";
    std::size_t end = close;
    while (end > 0 && (json[end - 1] == '\n' || json[end - 1] == ' ')) --end;
    json = json.substr(0, end) + seq.str() + json.substr(close);
    write_text_atomically((dir / "phantom.json").string(), json);
  } else {
    write_volume((dir / "volume.nrrd").string(), p.volume);
    write_volume((dir / "truth_sdf.nrrd").string(), p.truth_sdf);
    if (!o.params.physics_name.empty()) write_volume((dir / "labels.nrrd").string(), p.labels);
    if (!p.shadow_db.data.empty()) write_volume((dir / "shadow_db.nrrd").string(), p.shadow_db);
    write_text_atomically((dir / "phantom.json").string(), phantom_json(o.params, p));
  }
  Image slices;
  if (!o.slices.empty()) {
    slices = phantom_slices(p);
    write_png(o.slices, slices);
  }
  stage.reset();
  const double t_write = seconds_since(t1);

  if (!o.quiet) {
    auto median = [](double m) { return std::isfinite(m) ? std::to_string(static_cast<int>(std::lround(m))) : "n/a"; };
    const double h = p.volume.spacing[0];
    std::cout << std::fixed << std::setprecision(3) << "phantom " << phantom_shape_name(o.params.shape) << ' '
              << dims_text(p.volume.dims) << " uint8, seed " << o.params.seed
              << (o.physics.empty() ? std::string() : ", physics " + o.physics) << " -> " << o.out << '\n';
    if (o.params.physics) {
      std::cout << "  spacing  " << h << " mm (fov " << std::setprecision(1) << p.fov_mm << " mm), probe at z = 0\n"
                << std::defaultfloat << physics_summary(*o.params.physics) << std::fixed << std::setprecision(3);
    } else {
      std::cout << "  spacing  " << h << " mm (fov " << std::setprecision(1) << p.fov_mm
                << " mm), transducer at z = 0, beams along +z\n"
                << std::setprecision(2) << "  psf      sigma axial " << o.params.psf_axial << ", lateral "
                << o.params.psf_lateral << " voxels; dynamic range " << std::setprecision(1)
                << o.params.dynamic_range_db << " dB; noise " << std::setprecision(3) << o.params.noise << '\n';
    }
    std::cout << "  medians  fluid " << median(p.fluid_median) << " (sdf > 3), tissue " << median(p.tissue_median)
              << " (sdf < -3)"
              << (o.params.physics && std::isfinite(p.near_field_median)
                      ? ", near field " + median(p.near_field_median)
                      : std::string())
              << '\n'
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
      "shadowing, anisotropic Gaussian PSF (speckle), electronic noise, envelope, log compression (docs/phantom.md).\n"
      "--physics NAME forms the image from parameters in mm instead (presets, or drawn from the seed: PSF, speckle\n"
      "density, gain, dynamic range, TGC mismatch, shadows, a layered near field, fan geometry, pose) and adds\n"
      "DIR/labels.nrrd.");
  sub->add_option("--shape", o->shape,
                  "face: fetal face in amniotic fluid with the uterine wall behind; spine: vertebrae in soft "
                  "tissue (tissue = bone); sphere: one sphere of tissue in fluid")
      ->capture_default_str();
  auto* size = sub->add_option("--size", o->params.size, "Voxels along each axis")
                   ->capture_default_str()
                   ->check(int_range(16, 512, "voxels"));
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
  sub->add_option("--frames", o->frames,
                  "3D+t: write N frames of a moving scene as 4-D NRRDs (volume, truth_sdf, labels), the scene "
                  "turning by --turn degrees about the beam and drifting --drift mm along x over the sequence, each "
                  "frame's speckle drawn anew (seed + frame); needs the physics in mm (--physics NAME; default "
                  "obstetric for face, spine for spine, clean for sphere)")
      ->capture_default_str()
      ->check(int_range(1, 200));
  sub->add_option("--frame-speckle", o->frame_speckle,
                  "--frames: new, each frame's scatterers drawn anew (seed + frame: speckle fully decorrelated between "
                  "frames); same, every frame from --seed")
      ->capture_default_str()
      ->check(one_of({"new", "same"}));
  sub->add_option("--turn", o->turn_deg, "--frames: the scene's turn about the beam over the sequence, degrees")
      ->capture_default_str()
      ->check(real_range(-90, 90, "degrees"));
  sub->add_option("--drift", o->drift_mm, "--frames: the scene's drift along x over the sequence, mm")
      ->capture_default_str()
      ->check(real_range(-100, 100, "mm"));
  sub->add_option("--physics", o->physics,
                  "Image formation in physical units (mm): default (the fixed physics below, bit for bit; adds "
                  "labels.nrrd), clean, obstetric, spine, curvilinear, harsh (named presets), or random (every "
                  "parameter drawn from --seed). Writes DIR/labels.nrrd (0 fluid/background, 1 object, 2 near-field "
                  "layers, 3 outside the scanned sector) and every parameter to phantom.json (docs/phantom.md)");
  sub->add_option("--physics-set", o->physics_set,
                  "NAME=VALUE[,NAME=VALUE...]: override parameters of --physics (names as in phantom.json's "
                  "physics_parameters, e.g. near_field_mm=0,geometry=fan)");
  std::vector<CLI::Option*> fixed;
  fixed.push_back(sub->add_option(
      "--speckle", o->speckle, "AXIAL,LATERAL: PSF standard deviations in voxels, each in [0.2, 8] (default 0.6,1.5)"));
  fixed.push_back(
      sub->add_option("--dynamic-range", o->params.dynamic_range_db, "Log compression range in dB")
          ->capture_default_str()
          ->check(real_range(10, 100, "dB")));
  fixed.push_back(
      sub->add_option("--noise", o->params.noise, "Electronic noise rms relative to the mean tissue echo")
          ->capture_default_str()
          ->check(real_range(0, 100)));
  fixed.push_back(sub->add_option("--attenuation", o->params.attenuation,
                                  "Depth attenuation relative to the default (0.2 dB/mm two-way in soft tissue)")
                      ->capture_default_str()
                      ->check(real_range(0, 100)));
  fixed.push_back(
      sub->add_option("--specular", o->params.specular, "Strength of boundary echoes relative to the default")
          ->capture_default_str()
          ->check(real_range(0, 100)));
  auto* fov = sub->add_option("--fov", o->params.fov_mm,
                              "Field of view in mm (default: face 100, spine 60, sphere 80; with --physics it "
                              "replaces the preset's or the drawn fov_mm)")
                  ->check(real_range(0, 10000, "mm", Ends::OpenLow));
  sub->add_option("--slices", o->slices,
                  "Also write a PNG of the axial | coronal | sagittal mid-slices, second row with the true "
                  "boundary in orange (and the near-field layers in cyan)");
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  add_device_option(sub, o->device);
  sub->callback([&action, o, fixed, fov] {
    o->fixed_physics_options.clear();
    for (CLI::Option* f : fixed)
      if (f->count() > 0) o->fixed_physics_options.push_back(f->get_name());
    o->fov_given = fov->count() > 0;
    action = [o] { return run_phantom(*o); };
  });
}

}  // namespace softshell::cli
