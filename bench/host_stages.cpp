// Where a classification's time goes: the host stages of `softshell classify
// --iso auto --mask auto` (mask, near field, fill of the unscanned samples,
// automatic isovalue with its levelling, the speckle's size for the gradient
// lowpass) against the device
// classification, in one run, as shares of the whole (docs/benchmarks.md,
// "Host stages").
//
//   softshell_host_stages VOLUME [--reps R] [--threads T] [--device D] [--reverb keep] [--bulk-spread X] [--host-only]
//
// --bulk-spread 0 times the automatic isovalue without its bulk rule (host/auto_iso.hpp).
// --host-only skips the device classification (its row 0, the shares of the
// host stages alone): quick rounds for comparing two builds' host stages.
//
// T (0: every core) is passed to the multi-threaded host stages; 1 gives
// the single-threaded baseline. Each stage's time is the minimum of R runs,
// and beside it the first run's: the later runs find the pages the earlier
// ones freed, so only the first pays the first touch of its memory, as a
// one-shot `softshell classify` does (docs/benchmarks.md, "Host stages",
// fourth round).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "auto_iso.hpp"
#include "cl_runtime.hpp"
#include "error.hpp"
#include "host_memory.hpp"
#include "io.hpp"
#include "mask.hpp"
#include "speckle.hpp"
#include "variational.hpp"

using namespace softshell;

namespace {
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }
}  // namespace

int main(int argc, char** argv) {
  const char* const kUsage =
      "usage: softshell_host_stages VOLUME [--reps R] [--threads T] [--device D] [--reverb keep] [--bulk-spread X] [--host-only]\n";
  std::string in, device;
  int reps = 3, threads = 0;
  bool host_only = false;
  bool reverb = true;
  double bulk_spread = AutoIsoParams().bulk_spread;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--reps" && i + 1 < argc) reps = std::atoi(argv[++i]);
    else if (a == "--threads" && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (a == "--device" && i + 1 < argc) device = argv[++i];
    else if (a == "--reverb" && i + 1 < argc) reverb = std::string(argv[++i]) != "keep";
    else if (a == "--bulk-spread" && i + 1 < argc) bulk_spread = std::atof(argv[++i]);
    else if (a == "--host-only") host_only = true;
    else if (in.empty() && a[0] != '-') in = a;
    else {
      std::cerr << kUsage;
      return 2;
    }
  }
  if (in.empty() || reps < 1 || threads < 0) {
    std::cerr << kUsage;
    return 2;
  }
  try {
    Runtime rt(device);
    const Volume v0 = read_volume(in);
    const char* names[] = {"mask", "near field", "fill unscanned", "auto iso + level", "speckle size",
                           "classify (device)"};
    constexpr int kStages = 6;
    std::vector<double> best(kStages, 1e300), first(kStages, 0.0);
    for (int r = 0; r < reps; ++r) {
      Volume v = v0;
      std::vector<double> t(kStages);
      // As classify: the host stages reuse each other's freed blocks (host/host_memory.hpp).
      std::optional<KeepFreedMemory> keep_freed(std::in_place);
      auto t0 = Clock::now();
      MaskParams mp;
      mp.threads = threads;
      MaskReport mr;
      std::vector<std::uint8_t> mask = scanned_mask(v, mp, &mr);
      if (mr.rejected || mr.unscanned == 0) mask.clear();
      t[0] = since(t0);
      t0 = Clock::now();
      NearFieldParams np;
      np.threads = threads;
      np.reverb = reverb;
      remove_near_field(v, mask, np);
      t[1] = since(t0);
      t0 = Clock::now();
      if (!mask.empty()) fill_unscanned_in_place(v, mask, 0, threads);
      t[2] = since(t0);
      t0 = Clock::now();
      AutoIsoParams ap;
      ap.rule = AutoIsoRule::Local;
      ap.want_field = true;
      ap.threads = threads;
      ap.bulk_spread = bulk_spread;  // 0: without the isovalue above the bulk
      AutoIsoReport rep;
      const double iso = auto_iso(v, mask.empty() ? nullptr : &mask, ap, &rep, &v);  // as classify: levels v
      t[3] = since(t0);
      t0 = Clock::now();
      VariationalParams p;
      p.grad_sigma_mm = auto_grad_sigma(v, mask.empty() ? nullptr : &mask, 2, 1.0, threads).sigma_mm;
      t[4] = since(t0);
      keep_freed.reset();
      if (host_only) {
        for (int k = 0; k < kStages; ++k) best[k] = std::min(best[k], t[k]);
        if (r == 0) first = t;
        continue;
      }
      t0 = Clock::now();
      p.v_iso = v.intensity_map().to_unit(iso);
      SolveReport sr;
      classify_variational(rt, v, p, SolverParams{}, &sr, nullptr, mask.empty() ? nullptr : &mask);
      t[5] = since(t0);
      for (int k = 0; k < kStages; ++k) best[k] = std::min(best[k], t[k]);
      if (r == 0) first = t;
    }
    double total = 0, first_total = 0;
    for (double b : best) total += b;
    for (double f : first) first_total += f;
    std::printf("%s: %zux%zux%zu, threads %d (0: every core), min of %d runs | the first run\n", in.c_str(),
                v0.dims[0], v0.dims[1], v0.dims[2], threads, reps);
    for (int k = 0; k < kStages; ++k) {
      if (host_only && k == kStages - 1) {
        std::printf("  %-18s   skipped (--host-only)\n", names[k]);
        continue;
      }
      std::printf("  %-18s %8.3f s  %5.1f %%  | %8.3f s  %5.1f %%\n", names[k], best[k], 100 * best[k] / total, first[k],
                  100 * first[k] / first_total);
    }
    std::printf("  %-18s %8.3f s          | %8.3f s\n", "total", total, first_total);
  } catch (const std::exception& e) {
    std::cerr << "softshell_host_stages: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
