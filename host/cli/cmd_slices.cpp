// `softshell slices IN... -o OUT.png`: three orthogonal mid-slices per volume.
#include <iostream>
#include <memory>
#include <vector>

#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "image.hpp"
#include "io.hpp"

namespace softshell::cli {
namespace {

struct SlicesOptions {
  std::vector<std::string> inputs;
  std::string out;
  int height = 0;
  bool quiet = false;
  RawOptions raw;
  NonFiniteOption non_finite;
};

int run_slices(const std::vector<std::string>& inputs, const std::string& out, int height, const RawOptions& raw,
               const NonFiniteOption& non_finite, bool quiet) {
  if (height < 0 || height > 4096) throw InputError("--height must be in [0, 4096]");
  ensure_distinct_outputs(inputs, {out});
  check_output(out, OutputKind::Png);
  std::vector<Volume> volumes;
  for (const auto& in : inputs) {
    volumes.push_back(read_volume(in, raw.spec()));
    non_finite.apply(volumes.back(), in);
  }
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

void add_slices_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<SlicesOptions>();
  auto* sub = app.add_subcommand("slices", "Write the three orthogonal mid-slices of volumes to a PNG");
  sub->add_option("IN", o->inputs, "Input volumes (one row each)")->required();
  sub->add_option("-o,--output", o->out, "Output PNG")->required();
  sub->add_option("--height", o->height, "Row height in pixels (default 0: one pixel per smallest spacing)")
      ->check(int_range(0, 4096, "pixels"));
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  o->raw.add_to(sub);
  o->non_finite.add_to(sub);
  sub->callback([&action, o] { action = [o] { return run_slices(o->inputs, o->out, o->height, o->raw, o->non_finite, o->quiet); }; });
}

}  // namespace softshell::cli
