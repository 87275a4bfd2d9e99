// `softshell info FILE`: dims, spacing, type, value range and a histogram.
#include <iostream>
#include <memory>

#include "cli_common.hpp"
#include "io.hpp"
#include "volume.hpp"

namespace softshell::cli {
namespace {

struct InfoOptions {
  std::string path;
  RawOptions raw;
};

int run_info(const std::string& path, const RawOptions& raw) {
  // A 3D+t sequence: its frame count, then frame 0 (or --frame K) in full.
  const VolumeHeader h = read_any_header(path, raw.spec());
  const std::size_t k = raw.frame.value_or(0);
  const Volume v = read_volume(path, raw.spec(), h.frames > 1 ? std::optional<std::size_t>(k) : raw.frame);
  if (h.frames > 1)
    std::cout << "frames:             " << h.frames << " (a 3D+t sequence; below: frame " << k
              << ", --frame K for another)\n";
  std::cout << describe_volume(v, path);
  return 0;
}

}  // namespace

void add_info_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<InfoOptions>();
  auto* sub = app.add_subcommand("info", "Print dims, spacing, type, value range and a histogram of a volume");
  sub->add_option("FILE", o->path, "Volume: .nrrd/.nhdr, .mha/.mhd, or raw with --raw")->required();
  o->raw.add_to(sub);
  sub->callback([&action, o] { action = [o] { return run_info(o->path, o->raw); }; });
}

}  // namespace softshell::cli
