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
  const Volume v = read_volume(path, raw.spec());
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
