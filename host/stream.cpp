// Host wrapper of kernels/stream.cl, and the host's own STREAM.
#include "stream.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <vector>

namespace softshell {

Stream::Stream(Runtime& rt)
    : rt_(rt), copy_(rt.kernel("stream.cl", "stream_copy")), triad_(rt.kernel("stream.cl", "stream_triad")) {}

cl::Event Stream::copy(const cl::Buffer& a, const cl::Buffer& b, std::size_t n) const {
  Runtime::set_args(copy_, a, b, static_cast<cl_ulong>(n));
  return rt_.enqueue_1d(copy_, n);
}

cl::Event Stream::triad(const cl::Buffer& a, const cl::Buffer& b, const cl::Buffer& c, float s,
                        std::size_t n) const {
  Runtime::set_args(triad_, a, b, c, s, static_cast<cl_ulong>(n));
  return rt_.enqueue_1d(triad_, n);
}

namespace {

// A reusable barrier for a fixed number of threads (C++17 has none).
class Barrier {
 public:
  explicit Barrier(int n) : n_(n) {}
  void wait() {
    std::unique_lock<std::mutex> lock(m_);
    const long gen = gen_;
    if (++count_ == n_) {
      count_ = 0, ++gen_;
      cv_.notify_all();
    } else {
      cv_.wait(lock, [&] { return gen_ != gen; });
    }
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  int n_, count_ = 0;
  long gen_ = 0;
};

double median_of(std::vector<double> t) {
  std::sort(t.begin(), t.end());
  return t.size() % 2 ? t[t.size() / 2] : 0.5 * (t[t.size() / 2 - 1] + t[t.size() / 2]);
}

}  // namespace

HostStream host_stream(std::size_t n, int reps, int threads) {
  if (n == 0 || reps < 1) throw std::invalid_argument("host_stream: no elements or no repeats");
  if (threads <= 0) threads = int(std::max(1u, std::thread::hardware_concurrency()));
  HostStream hs;
  hs.elements = n, hs.threads = threads, hs.reps = reps;
  // Uninitialised storage: each thread first-touches its own chunk.
  std::unique_ptr<float[]> a(new float[n]), b(new float[n]), c(new float[n]);
  float* const pa = a.get();
  float* const pb = b.get();
  float* const pc = c.get();
  Barrier barrier(threads);
  std::vector<double> tc, tt;
  std::vector<float> scales;
  bool copy_ok = true;
  using Clock = std::chrono::steady_clock;
  // Each thread's start and end of each pass: a pass lasts from the first
  // start to the last end (a thread descheduled between the barrier and its
  // clock reading cannot shorten it).
  const auto nthreads = static_cast<std::size_t>(threads);
  std::vector<Clock::time_point> start(nthreads), end(nthreads);
  auto span = [&] {
    return std::chrono::duration<double>(*std::max_element(end.begin(), end.end()) -
                                         *std::min_element(start.begin(), start.end()))
        .count();
  };
  auto work = [&](int id) {
    const std::size_t lo = n * std::size_t(id) / std::size_t(threads), hi = n * std::size_t(id + 1) / std::size_t(threads);
    const std::size_t me = std::size_t(id);
    // Values from a bijective hash of the index: no two pages alike (a
    // periodic pattern lets a hypervisor merge identical pages, and a copy
    // from a few merged pages runs from cache: 69 GB/s "copy" on 2 cores).
    for (std::size_t i = lo; i < hi; ++i) {
      const auto h = std::uint32_t(i) * 2654435761u, g = (std::uint32_t(i) ^ 0x9e3779b9u) * 2246822519u;
      pa[i] = float(h >> 8) * 1e-7f, pb[i] = float(g >> 8) * 1e-7f, pc[i] = float(i);
    }
    for (int r = -1; r < reps; ++r) {  // r = -1: the warm-up
      const float s = 0.5f + 0.25f * float(r + 1);
      barrier.wait();
      start[me] = Clock::now();
      for (std::size_t i = lo; i < hi; ++i) pc[i] = pa[i];
      end[me] = Clock::now();
      barrier.wait();
      if (id == 0) {
        if (r >= 0) tc.push_back(span());
        if (r == reps - 1)  // the last copy, checked before the triad overwrites it (untimed)
          for (std::size_t i = 0; i < n && copy_ok; i += 97) copy_ok = pc[i] == pa[i];
      }
      barrier.wait();
      start[me] = Clock::now();
      for (std::size_t i = lo; i < hi; ++i) pc[i] = pa[i] + s * pb[i];
      end[me] = Clock::now();
      barrier.wait();
      if (id == 0 && r >= 0) tt.push_back(span()), scales.push_back(s);
    }
  };
  std::vector<std::thread> pool;
  for (int id = 1; id < threads; ++id) pool.emplace_back(work, id);
  work(0);
  for (std::thread& t : pool) t.join();
  // c holds the last triad.
  const float s = scales.back();
  bool ok = copy_ok;
  for (std::size_t i = 0; i < n && ok; i += 97)
    ok = std::abs(pc[i] - (pa[i] + s * pb[i])) <= 1e-6f * (1.0f + std::abs(pa[i]) + std::abs(s * pb[i]));
  hs.ok = ok;
  hs.copy_min_s = *std::min_element(tc.begin(), tc.end());
  hs.triad_min_s = *std::min_element(tt.begin(), tt.end());
  hs.copy_median_s = median_of(tc);
  hs.triad_median_s = median_of(tt);
  hs.copy_gbps = 8.0 * double(n) / hs.copy_min_s * 1e-9;
  hs.triad_gbps = 12.0 * double(n) / hs.triad_min_s * 1e-9;
  return hs;
}

}  // namespace softshell
