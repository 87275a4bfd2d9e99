// Subcommands of the `softshell` CLI (CLI11). Each parses its options, calls
// the library, and reports what it did; validation failures throw InputError.
#include "commands.hpp"

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <optional>
#include <random>
#include <sstream>

#include "cl_runtime.hpp"
#include "error.hpp"
#include "filter.hpp"
#include "image.hpp"
#include "io.hpp"
#include "text.hpp"
#include "volume.hpp"

namespace softshell::cli {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// --raw / --type / --spacing / --big-endian for headerless input.
struct RawOptions {
  std::string dims, type, spacing;
  bool big_endian = false;

  void add_to(CLI::App* app) {
    app->add_option("--raw", dims, "Read IN as headerless raw data of these dimensions")->type_name("X,Y,Z");
    app->add_option("--type", type, "Sample type of raw data: uint8|uint16|int16|float|double")->type_name("T");
    app->add_option("--spacing", spacing, "Voxel spacing of raw data in mm (default 1,1,1)")->type_name("X,Y,Z");
    app->add_flag("--big-endian", big_endian, "Raw data is big-endian (default little)");
  }

  std::optional<RawSpec> spec() const {
    if (dims.empty()) {
      if (!type.empty() || !spacing.empty() || big_endian)
        throw InputError("--type, --spacing and --big-endian describe raw input and need --raw X,Y,Z");
      return std::nullopt;
    }
    RawSpec r;
    r.dims = parse_dims(dims, "--raw");
    if (type.empty()) throw InputError("--raw needs --type uint8|uint16|int16|float|double");
    const auto t = parse_scalar_type(type);
    if (!t) throw InputError("--type: unknown sample type '" + type + "' (use uint8, uint16, int16, float or double)");
    r.type = *t;
    if (!spacing.empty()) r.spacing = parse_vec3(spacing, "--spacing");
    r.big_endian = big_endian;
    return r;
  }
};

void add_device_option(CLI::App* app, std::string& device) {
  app->add_option("--device", device,
                  "OpenCL device: index or name substring from `softshell devices`, or cpu/gpu "
                  "(default: $SOFTSHELL_DEVICE, else the first GPU, else the first CPU)")
      ->type_name("I|NAME");
}

// ---------------------------------------------------------------- devices
int cmd_devices(bool json) {
  const auto devices = enumerate_devices();
  int chosen = -1;
  std::string why;
  try {
    chosen = select_device("").index;
  } catch (const DeviceError& e) {
    why = e.what();  // $SOFTSHELL_DEVICE names nothing: still list what exists
  }
  if (json) {
    std::cout << "{\"default\": " << chosen << ", \"devices\": [";
    for (const auto& d : devices) {
      std::cout << (d.index ? ", " : "") << "{\"index\": " << d.index << ", \"type\": \"" << d.type
                << "\", \"name\": \"" << d.device_name << "\", \"platform\": \"" << d.platform_name
                << "\", \"vendor\": \"" << d.vendor << "\", \"compute_units\": " << d.compute_units
                << ", \"global_mem_bytes\": " << d.global_mem << ", \"max_alloc_bytes\": " << d.max_alloc
                << ", \"opencl_c\": \"" << d.opencl_c_version << "\", \"driver\": \"" << d.driver_version << "\"}";
    }
    std::cout << "]}\n";
    return 0;
  }
  std::size_t wname = 4, wplat = 8;
  for (const auto& d : devices) {
    wname = std::max(wname, d.device_name.size());
    wplat = std::max(wplat, d.platform_name.size());
  }
  std::cout << std::left << "  " << std::setw(4) << "#" << std::setw(6) << "type" << std::setw(wname + 2) << "name"
            << std::setw(wplat + 2) << "platform" << std::right << std::setw(4) << "CUs" << std::setw(12)
            << "global mem" << std::setw(12) << "max alloc" << "  OpenCL C / driver\n";
  for (const auto& d : devices) {
    std::cout << (d.index == chosen ? "* " : "  ") << std::left << std::setw(4) << d.index << std::setw(6) << d.type
              << std::setw(wname + 2) << d.device_name << std::setw(wplat + 2) << d.platform_name << std::right
              << std::setw(4) << d.compute_units << std::setw(12) << human_bytes(double(d.global_mem))
              << std::setw(12) << human_bytes(double(d.max_alloc)) << "  " << d.opencl_c_version << " / "
              << d.driver_version << '\n';
  }
  if (chosen >= 0)
    std::cout << "* = used by default; choose with --device INDEX|NAME|cpu|gpu or SOFTSHELL_DEVICE\n";
  else
    std::cout << "note: " << why << '\n';
  const std::string cache = ensure_pocl_cache_dir();
  if (!cache.empty()) std::cout << "PoCL kernel cache: " << cache << '\n';
  return 0;
}

// ---------------------------------------------------------------- info
int cmd_info(const std::string& path, const RawOptions& raw) {
  const Volume v = read_volume(path, raw.spec());
  std::cout << describe_volume(v, path);
  return 0;
}

// ---------------------------------------------------------------- lowpass
struct LowpassOptions {
  std::string in, out, device;
  double sigma = 1.0;
  double truncate = 3.0;
  bool as_float = false, compress = false, quiet = false;
  RawOptions raw;
};

int cmd_lowpass(const LowpassOptions& o) {
  const auto t0 = Clock::now();
  if (!(o.sigma >= 0) || !std::isfinite(o.sigma)) throw InputError("--sigma must be >= 0 (millimetres)");
  if (!(o.truncate > 0) || o.truncate > 10) throw InputError("--truncate must be in (0, 10]");
  ensure_distinct_output(o.in, o.out);
  const auto raw = o.raw.spec();
  Runtime rt(o.device);  // fail fast on the device before reading a large input
  const double t_device = seconds_since(t0);
  const auto t_read0 = Clock::now();
  const Volume in = read_volume(o.in, raw);
  const double t_read = seconds_since(t_read0);

  const auto t1 = Clock::now();
  LowpassReport timing;
  Lowpass::Params p;
  p.sigma_mm = o.sigma;
  p.truncate = o.truncate;
  Volume out;
  try {
    out = lowpass_volume(rt, in, p, &timing);
  } catch (const std::invalid_argument& e) {
    throw InputError(std::string("--sigma: ") + e.what());
  }
  const double t_compute = seconds_since(t1);

  const auto t2 = Clock::now();
  WriteOptions w;
  w.type = o.as_float ? ScalarType::Float32 : in.source_type;
  w.compress = o.compress;
  write_volume(o.out, out, w);
  const double t_write = seconds_since(t2);

  if (!o.quiet) {
    const auto& r = timing.radius;
    const auto& s = timing.sigma_voxels;
    std::cout << std::fixed << std::setprecision(3) << "lowpass " << o.in << " -> " << o.out << '\n'
              << "  volume   " << dims_text(in.dims) << ' ' << scalar_type_name(in.source_type) << ", spacing "
              << in.spacing[0] << ',' << in.spacing[1] << ',' << in.spacing[2] << " mm\n"
              << "  sigma    " << o.sigma << " mm = " << s[0] << ',' << s[1] << ',' << s[2]
              << " voxels, radius " << r[0] << ',' << r[1] << ',' << r[2] << '\n'
              << "  device   " << rt.info().label() << '\n'
              << "  time     device " << t_device << " s, read " << t_read << " s, lowpass " << t_compute
              << " s (upload " << timing.upload << ", filter " << timing.filter << ", download " << timing.download
              << "), write " << t_write << " s, total " << seconds_since(t0) << " s\n";
  }
  return 0;
}

// ---------------------------------------------------------------- synthetic
// A quick test input until the realistic phantom simulator lands: a sphere of
// tissue in fluid with a bright boundary echo and multiplicative speckle.
int cmd_synthetic(const std::string& out_path, int size, std::uint64_t seed, bool quiet) {
  if (size < 8 || size > 1024) throw InputError("--size must be in [8, 1024]");
  const std::size_t n = static_cast<std::size_t>(size);
  Volume v({n, n, n}, {1.0, 1.0, 1.0}, ScalarType::UInt8);
  std::mt19937_64 rng(seed);  // mt19937_64's output sequence is fixed by the standard
  auto uniform = [&] { return (static_cast<double>(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0); };
  const double c = 0.5 * (size - 1), radius = 0.3 * size;
  for (std::size_t z = 0; z < n; ++z)
    for (std::size_t y = 0; y < n; ++y)
      for (std::size_t x = 0; x < n; ++x) {
        const double d = std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + (z - c) * (z - c)) - radius;
        const double tissue = d < 0 ? 90.0 : 12.0;
        const double echo = 150.0 * std::exp(-0.5 * d * d / 2.25);
        const double speckle = std::sqrt(-2.0 * std::log(uniform())) * 0.7979;  // Rayleigh, mean 1
        const double val = (tissue + echo) * speckle + 4.0 * (uniform() - 0.5);
        v.at(x, y, z) = static_cast<float>(std::clamp(std::round(val), 0.0, 255.0));
      }
  write_volume(out_path, v, {});
  if (!quiet) std::cout << "synthetic speckled sphere " << dims_text(v.dims) << " uint8 -> " << out_path << '\n';
  return 0;
}

// ---------------------------------------------------------------- slices
int cmd_slices(const std::vector<std::string>& inputs, const std::string& out, int height, const RawOptions& raw,
               bool quiet) {
  if (height < 0 || height > 4096) throw InputError("--height must be in [0, 4096]");
  for (const auto& in : inputs) ensure_distinct_output(in, out);
  std::vector<Volume> volumes;
  for (const auto& in : inputs) volumes.push_back(read_volume(in, raw.spec()));
  std::vector<const Volume*> ptrs;
  for (const auto& v : volumes) ptrs.push_back(&v);
  const Image img = slice_montage(ptrs, height);
  write_png(out, img);
  if (!quiet)
    std::cout << "slices (axial | coronal | sagittal, one row per input) " << img.width << "x" << img.height
              << " -> " << out << '\n';
  return 0;
}

}  // namespace

int run(int argc, char** argv) {
  CLI::App app{
      "softshell: variational opacity classification and oriented-splat rendering of 3D ultrasound on OpenCL "
      "devices.",
      "softshell"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "softshell 0.1.0");
  app.footer("Exit status: 0 ok, 2 bad input or no device, 3 not converged, 1 internal error.");

  bool devices_json = false;
  auto* devices = app.add_subcommand("devices", "List OpenCL platforms and devices with their index");
  devices->add_flag("--json", devices_json, "Machine-readable output");

  std::string info_path;
  RawOptions info_raw;
  auto* info = app.add_subcommand("info", "Print dims, spacing, type, value range and a histogram of a volume");
  info->add_option("FILE", info_path, "Volume: .nrrd/.nhdr, .mha/.mhd, or raw with --raw")->required();
  info_raw.add_to(info);

  LowpassOptions lp;
  auto* lowpass = app.add_subcommand("lowpass", "Gaussian lowpass (sigma in mm, anisotropic spacing honoured)");
  lowpass->add_option("IN", lp.in, "Input volume")->required();
  lowpass->add_option("-o,--output", lp.out, "Output volume (.nrrd, .mha, .mhd)")->required();
  lowpass->add_option("--sigma", lp.sigma, "Standard deviation in millimetres")->capture_default_str();
  lowpass->add_option("--truncate", lp.truncate, "Kernel radius in standard deviations")->capture_default_str();
  lowpass->add_flag("--float", lp.as_float, "Write float samples (default: the input's sample type)");
  lowpass->add_flag("--compress", lp.compress, "Compress the output (gzip/zlib)");
  lowpass->add_flag("-q,--quiet", lp.quiet, "Print nothing on success");
  add_device_option(lowpass, lp.device);
  lp.raw.add_to(lowpass);

  std::string synth_out;
  int synth_size = 64;
  std::uint64_t synth_seed = 1;
  bool synth_quiet = false;
  auto* synth = app.add_subcommand("synthetic", "Write a small speckled-sphere test volume (uint8)");
  synth->add_option("-o,--output", synth_out, "Output volume")->required();
  synth->add_option("--size", synth_size, "Edge length in voxels")->capture_default_str();
  synth->add_option("--seed", synth_seed, "Random seed")->capture_default_str();
  synth->add_flag("-q,--quiet", synth_quiet, "Print nothing on success");

  std::vector<std::string> slices_in;
  std::string slices_out;
  int slices_height = 0;
  bool slices_quiet = false;
  RawOptions slices_raw;
  auto* slices = app.add_subcommand("slices", "Write the three orthogonal mid-slices of volumes to a PNG");
  slices->add_option("IN", slices_in, "Input volumes (one row each)")->required();
  slices->add_option("-o,--output", slices_out, "Output PNG")->required();
  slices->add_option("--height", slices_height, "Row height in pixels (default: one pixel per smallest spacing)");
  slices->add_flag("-q,--quiet", slices_quiet, "Print nothing on success");
  slices_raw.add_to(slices);

  // CLI11 reports a misspelt command as "a subcommand is required"; name it.
  if (argc > 1 && argv[1][0] != '-') {
    std::string known;
    bool found = false;
    for (const CLI::App* sub : app.get_subcommands({})) {
      found = found || sub->get_name() == argv[1];
      known += (known.empty() ? "" : ", ") + sub->get_name();
    }
    if (!found) throw InputError(std::string("unknown command '") + argv[1] + "' (commands: " + known + ")");
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::string msg = e.what();
    for (char& ch : msg)
      if (ch == '\n') ch = ' ';
    throw InputError(msg + " (see softshell --help)");
  }

  if (*devices) return cmd_devices(devices_json);
  if (*info) return cmd_info(info_path, info_raw);
  if (*lowpass) return cmd_lowpass(lp);
  if (*slices) return cmd_slices(slices_in, slices_out, slices_height, slices_raw, slices_quiet);
  if (*synth) return cmd_synthetic(synth_out, synth_size, synth_seed, synth_quiet);
  return 2;
}

}  // namespace softshell::cli
