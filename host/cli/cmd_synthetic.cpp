// `softshell synthetic`: a small speckled-sphere volume, a quick input for
// trying commands out (the realistic simulator is `softshell phantom`).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <memory>
#include <random>

#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "io.hpp"
#include "text.hpp"

namespace softshell::cli {
namespace {

struct SyntheticOptions {
  std::string out;
  int size = 64;
  std::uint64_t seed = 1;
  bool quiet = false;
};

// A quick test input until the realistic phantom simulator lands: a sphere of
// tissue in fluid with a bright boundary echo and multiplicative speckle.
int run_synthetic(const std::string& out_path, int size, std::uint64_t seed, bool quiet) {
  if (size < 8 || size > 1024) throw InputError("--size must be in [8, 1024]");
  check_output(out_path, OutputKind::Volume);
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

}  // namespace

void add_synthetic_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<SyntheticOptions>();
  auto* sub = app.add_subcommand("synthetic", "Write a small speckled-sphere test volume (uint8)");
  sub->add_option("-o,--output", o->out, "Output volume")->required();
  sub->add_option("--size", o->size, "Edge length in voxels")->capture_default_str()->check(int_range(8, 1024, "voxels"));
  sub->add_option("--seed", o->seed, "Random seed")->capture_default_str();
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  sub->callback([&action, o] { action = [o] { return run_synthetic(o->out, o->size, o->seed, o->quiet); }; });
}

}  // namespace softshell::cli
