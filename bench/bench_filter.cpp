// Lowpass filter bandwidth against the device's own copy bandwidth, in one run.
//
// Byte model: a copy moves 8 bytes per voxel (read 4, write 4). Each 1-D pass
// of the separable Gaussian ideally moves the same 8 bytes per voxel (its
// 2r+1 taps along a line come from cache), so a 3-pass lowpass moves 24 bytes
// per voxel; "effective GB/s" uses that model and the fraction of copy
// bandwidth says how close the filter gets to the memory limit.
//
//   softshell_bench_filter [--size N] [--sigma MM] [--reps R] [--device D]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "error.hpp"
#include "filter.hpp"
#include "stream.hpp"

using namespace softshell;

namespace {

struct Stat {
  double min = 0, median = 0;
};

Stat summarise(std::vector<double> t) {
  std::sort(t.begin(), t.end());
  return {t.front(), t[t.size() / 2]};
}

int usage() {
  std::cerr << "usage: softshell_bench_filter [--size N] [--sigma MM] [--reps R] [--device I|NAME]\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  int size = 256, reps = 10;
  double sigma = 1.5;
  std::string device;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") return usage(), 0;
    if (i + 1 >= argc) return usage();
    if (a == "--size") size = std::atoi(argv[++i]);
    else if (a == "--sigma") sigma = std::atof(argv[++i]);
    else if (a == "--reps") reps = std::atoi(argv[++i]);
    else if (a == "--device") device = argv[++i];
    else return usage();
  }
  if (size < 8 || reps < 1 || !(sigma >= 0)) return usage();
  try {
    Runtime rt(device);
    const std::size_t n = std::size_t(size) * size * size;
    const std::size_t bytes = n * sizeof(float);
    std::vector<float> host(n);
    std::mt19937 rng(1);
    for (float& f : host) f = float(rng() % 256);
    cl::Buffer a = rt.buffer(bytes), b = rt.buffer(bytes), c = rt.buffer(bytes);
    rt.queue().enqueueWriteBuffer(a, CL_TRUE, 0, bytes, host.data());
    rt.queue().enqueueWriteBuffer(b, CL_TRUE, 0, bytes, host.data());

    Stream stream(rt);
    const GridDesc g = make_grid({std::size_t(size), std::size_t(size), std::size_t(size)}, {1.0, 1.0, 1.0});
    Lowpass lowpass(rt, g, {sigma, 3.0});

    // The copy as contiguous chunks per work-item (kernels/stream.cl), one
    // work-item per 64 KiB: what PoCL moves when each thread streams.
    cl::Kernel chunks = rt.kernel("stream.cl", "stream_copy_chunks");
    const cl_ulong chunk = 16384;
    const std::size_t items = (n + chunk - 1) / chunk;
    auto copy_chunks = [&] {
      Runtime::set_args(chunks, a, c, static_cast<cl_ulong>(n), chunk);
      cl::Event e;
      rt.queue().enqueueNDRangeKernel(chunks, cl::NullRange, cl::NDRange(items), cl::NDRange(1), nullptr, &e);
      return e;
    };
    // Warm-up (first launches pay for kernel preparation).
    copy_chunks().wait();
    stream.copy(a, c, n).wait();
    lowpass.apply(a, c).back().wait();

    std::vector<double> t_copy, t_triad, t_pass[3], t_total, t_chunks;
    bool chunks_ok = true;
    for (int r = 0; r < reps; ++r) {
      auto e = copy_chunks();
      e.wait();
      t_chunks.push_back(event_seconds(e));
      if (r == 0) {
        std::vector<float> got(n);
        rt.queue().enqueueReadBuffer(c, CL_TRUE, 0, bytes, got.data());
        chunks_ok = std::memcmp(got.data(), host.data(), bytes) == 0;
      }
      e = stream.copy(a, c, n);
      e.wait();
      t_copy.push_back(event_seconds(e));
      e = stream.triad(a, b, c, 0.5f, n);
      e.wait();
      t_triad.push_back(event_seconds(e));
      const auto ev = lowpass.apply(a, c);
      ev.back().wait();
      for (int p = 0; p < 3; ++p) t_pass[p].push_back(event_seconds(ev[p]));
      t_total.push_back(event_span_seconds(ev.front(), ev.back()));
    }

    // Check the timed result at sample voxels against a direct CPU sum.
    std::vector<float> out(n);
    rt.queue().enqueueReadBuffer(c, CL_TRUE, 0, bytes, out.data());
    const auto w = gaussian_weights(sigma, 3.0);
    const long r = long(w.size() / 2);
    double worst = 0;
    for (int s = 0; s < 64; ++s) {
      const long x = rng() % size, y = rng() % size, z = rng() % size;
      double acc = 0;
      for (long k = -r; k <= r; ++k)
        for (long j = -r; j <= r; ++j)
          for (long i = -r; i <= r; ++i) {
            auto cl = [&](long v) { return std::clamp(v, 0L, long(size) - 1); };
            acc += double(w[i + r]) * w[j + r] * w[k + r] * host[cl(x + i) + size * (cl(y + j) + size * cl(z + k))];
          }
      worst = std::max(worst, std::abs(acc - out[x + size * (y + size * z)]));
    }
    const bool ok = worst < 1e-2 && chunks_ok;
    // The host's own copy, same size, every core (host/stream.hpp).
    const HostStream hs = host_stream(n, reps);

    const Stat copy = summarise(t_copy), triad = summarise(t_triad), total = summarise(t_total);
    auto gbps = [&](double bytes_per_voxel, double s) { return bytes_per_voxel * n / s * 1e-9; };
    std::printf("device     %s\n", rt.info().label().c_str());
    std::printf("volume     %d^3 float (%.1f MiB), sigma %.2f voxels, radius %ld, %d reps (min / median)\n", size,
                bytes / 1048576.0, sigma, r, reps);
    std::printf("%-14s %10s %10s %12s %10s\n", "kernel", "min ms", "median ms", "GB/s (min)", "of copy");
    auto row = [&](const char* name, Stat s, double bpv) {
      std::printf("%-14s %10.3f %10.3f %12.2f %9.0f%%\n", name, s.min * 1e3, s.median * 1e3, gbps(bpv, s.min),
                  100.0 * gbps(bpv, s.min) / gbps(8, copy.min));
    };
    row("copy", copy, 8);
    row("copy (chunks)", summarise(t_chunks), 8);
    row("host copy", {hs.copy_min_s, hs.copy_median_s}, 8);
    row("triad", triad, 12);
    const char* pass_names[3] = {"lowpass x", "lowpass y", "lowpass z"};
    for (int p = 0; p < 3; ++p) row(pass_names[p], summarise(t_pass[p]), 8);
    row("lowpass total", total, 24);
    std::printf("check      max |device - cpu| at 64 voxels = %.2e, chunked copy %s, host stream %s  %s\n", worst,
                chunks_ok ? "exact" : "WRONG", hs.ok ? "ok" : "WRONG", ok && hs.ok ? "ok" : "FAILED");
    return ok && hs.ok ? 0 : 1;
  } catch (const DeviceError& e) {
    std::fprintf(stderr, "softshell_bench_filter: skipped: %s\n", e.what());
    return 2;
  }
}
