// `softshell slices IN... -o OUT.png`: three orthogonal mid-slices per volume,
// labelled (the file names or --labels, the views and slice indices, a scale
// bar), or the bare panels with --plain.
#include <filesystem>
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
  std::vector<std::string> labels;
  int height = 0;
  bool quiet = false, plain = false;
  RawOptions raw;
  NonFiniteOption non_finite;
};

int run_slices(const SlicesOptions& o) {
  const std::vector<std::string>& inputs = o.inputs;
  const std::string& out = o.out;
  const int height = o.height;
  const RawOptions& raw = o.raw;
  const NonFiniteOption& non_finite = o.non_finite;
  const bool quiet = o.quiet;
  if (height < 0 || height > 4096) throw InputError("--height must be in [0, 4096]");
  if (!o.labels.empty() && o.labels.size() != inputs.size())
    throw InputError("--labels: " + std::to_string(o.labels.size()) + " labels for " + std::to_string(inputs.size()) +
                     " inputs (one per input, comma-separated)");
  if (o.plain && !o.labels.empty()) throw InputError("--labels: not drawn with --plain");
  ensure_distinct_outputs(inputs, {out});
  check_output(out, OutputKind::Png);
  std::vector<Volume> volumes;
  for (const auto& in : inputs) {
    volumes.push_back(read_volume(in, raw.spec(), raw.frame));
    non_finite.apply(volumes.back(), in);
  }
  std::vector<const Volume*> ptrs;
  for (const auto& v : volumes) ptrs.push_back(&v);
  std::vector<std::string> labels = o.labels;
  if (labels.empty())
    for (const auto& in : inputs) labels.push_back(std::filesystem::path(in).filename().string());
  const Image img = o.plain ? slice_montage(ptrs, height) : labelled_slice_montage(ptrs, labels, height);
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
  sub->add_option("--labels", o->labels, "Row labels, one per input (default: the file names)")
      ->delimiter(',')
      ->type_name("A,B,..");
  sub->add_flag("--plain", o->plain, "Only the panels: no labels, titles or scale bar (4-pixel gaps)");
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  o->raw.add_to(sub);
  o->non_finite.add_to(sub);
  sub->callback([&action, o] { action = [o] { return run_slices(*o); }; });
}

}  // namespace softshell::cli
