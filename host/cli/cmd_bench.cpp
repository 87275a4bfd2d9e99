// `softshell bench [--json] [--device D]... [--quick] [-o PLOT.png]`: the
// benchmark across OpenCL devices (host/bench.hpp, docs/benchmarks.md).
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>

#include "bench.hpp"
#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "image.hpp"
#include "text.hpp"

namespace softshell::cli {
namespace {

struct BenchCliOptions {
  bool json = false, quick = false;
  std::vector<std::string> devices;
  std::string plot;
  int reps = 0;
};

// Comma-separated and repeated --device values; "all" (or nothing, with
// $SOFTSHELL_DEVICE unset) means every device.
std::vector<std::string> device_requests(const std::vector<std::string>& given) {
  std::vector<std::string> out;
  for (const std::string& g : given) {
    std::size_t start = 0;
    while (start <= g.size()) {
      const std::size_t comma = g.find(',', start);
      const std::string item = trim(g.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
      if (item.empty()) throw InputError("--device: empty device name in '" + g + "'");
      out.push_back(item);
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
  }
  if (given.empty())
    if (const char* env = std::getenv("SOFTSHELL_DEVICE"); env && *env) out.push_back(env);
  for (const std::string& r : out)
    if (lower(r) == "all") return {};
  return out;
}

int run_bench_command(const BenchCliOptions& o) {
  if (o.reps < 0 || o.reps > 100) throw InputError("--reps must be in 1..100, got " + std::to_string(o.reps));
  if (!o.plot.empty()) {
    namespace fs = std::filesystem;
    const fs::path p(o.plot);
    if (lower(p.extension().string()) != ".png") throw InputError(o.plot + ": the plot is written as PNG: name it *.png");
    const fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) throw InputError(o.plot + ": directory " + dir.string() + " does not exist");
    check_output(o.plot, OutputKind::Png);
  }
  BenchOptions bo;
  bo.quick = o.quick;
  bo.devices = device_requests(o.devices);
  bo.reps = o.reps;
  bo.progress = &std::cerr;
#ifdef SOFTSHELL_HAVE_VIEWER
  bo.render_timer = bench_render_seconds;  // Table 1's render columns (cmd_figures.cpp)
#endif
  const BenchReport report = run_bench(bo);
  if (o.json)
    std::cout << bench_json(report);
  else
    std::cout << bench_table(report);
  std::cout.flush();
  if (!o.plot.empty()) {
    write_png(o.plot, bench_plot(report));
    std::cerr << "bench: plot written to " << o.plot << '\n';
  }
  if (!report.all_checks_passed()) {
    std::size_t n = 0;
    for (const DeviceBench& d : report.devices) n += d.failed_checks.size();
    std::cerr << "softshell: error: bench: " << n << " correctness check" << (n == 1 ? "" : "s")
              << " failed (listed in the output)\n";
    return 1;
  }
  return 0;
}

}  // namespace

void add_bench_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<BenchCliOptions>();
  auto* sub = app.add_subcommand(
      "bench",
      "Benchmark on every OpenCL device (or the chosen ones): the paper's Table 1 on phantoms, bandwidth of the "
      "solver's kernels against the device's copy bandwidth, Eigen CG and CPU Gauss-Seidel peers, scaling with the "
      "volume size, warm-start re-solve. Progress goes to stderr; a device that cannot run is skipped with the "
      "reason.");
  sub->add_flag("--json", o->json, "Print one JSON object instead of the tables (keys: docs/benchmarks.md)");
  sub->add_flag("--quick", o->quick, "Smaller sizes and fewer repeats (under a minute on a 2-core CPU)");
  sub->add_option("--device", o->devices,
                  "Device(s) to run on: index or name substring from `softshell devices`, cpu/gpu, or all; "
                  "repeat or separate with commas (default: $SOFTSHELL_DEVICE, else every device)")
      ->type_name("I|NAME")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  sub->add_option("--reps", o->reps, "Repeats of the cheap timings, 1..100 (default: 3 with --quick, else 5)")
      ->type_name("N")
      ->check(int_range(1, 100));
  sub->add_option("-o,--output", o->plot, "Also write a plot of time vs voxels per device (PNG)")
      ->type_name("PLOT.png");
  sub->callback([&action, o] { action = [o] { return run_bench_command(*o); }; });
}

}  // namespace softshell::cli
