// `softshell lowpass IN --sigma MM -o OUT`: the device Gaussian lowpass as a
// command, with a report of the kernel geometry and where the time went.
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>

#include "cl_runtime.hpp"
#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "progress.hpp"
#include "filter.hpp"
#include "io.hpp"
#include "text.hpp"

namespace softshell::cli {
namespace {

struct LowpassOptions {
  std::string in, out, device;
  double sigma = 1.0;
  double truncate = 3.0;
  bool as_float = false, compress = false, quiet = false;
  RawOptions raw;
  NonFiniteOption non_finite;
};

int run_lowpass(const LowpassOptions& o) {
  const auto t0 = Clock::now();
  if (!(o.sigma >= 0) || !std::isfinite(o.sigma)) throw InputError("--sigma must be >= 0 (millimetres)");
  if (!(o.truncate > 0) || o.truncate > 10) throw InputError("--truncate must be in (0, 10]");
  ensure_distinct_output(o.in, o.out);
  check_output(o.out, OutputKind::Volume);
  const auto raw = o.raw.spec();
  // The kernel's width from the header, before the samples are read.
  check_lowpass_sigma(o.sigma, read_volume_header(o.in, raw, o.raw.frame).spacing, "--sigma", o.truncate);
  std::optional<progress::Stage> stage(std::in_place, "lowpass");
  Runtime rt(o.device);  // fail fast on the device before reading a large input
  const double t_device = seconds_since(t0);
  const auto t_read0 = Clock::now();
  Volume in = read_volume(o.in, raw, o.raw.frame);
  o.non_finite.apply(in, o.in);
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
  stage.reset();

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

}  // namespace

void add_lowpass_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<LowpassOptions>();
  auto* sub = app.add_subcommand("lowpass", "Gaussian lowpass (sigma in mm, anisotropic spacing honoured)");
  sub->add_option("IN", o->in, "Input volume")->required();
  sub->add_option("-o,--output", o->out, "Output volume (.nrrd, .mha, .mhd, .nii, .nii.gz, .vti)")->required();
  sub->add_option("--sigma", o->sigma, "Standard deviation in millimetres")
      ->capture_default_str()
      ->check(real_range(0, INFINITY, "mm"));
  sub->add_option("--truncate", o->truncate, "Kernel radius in standard deviations")
      ->capture_default_str()
      ->check(real_range(0, 10, "", Ends::OpenLow));
  sub->add_flag("--float", o->as_float, "Write float samples (default: the input's sample type)");
  sub->add_flag("--compress", o->compress, "Compress the output (gzip/zlib)");
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  add_device_option(sub, o->device);
  o->raw.add_to(sub);
  o->non_finite.add_to(sub);
  sub->callback([&action, o] { action = [o] { return run_lowpass(*o); }; });
}

}  // namespace softshell::cli
