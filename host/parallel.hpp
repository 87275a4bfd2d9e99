// Splitting host loops over threads (std::thread): contiguous, ordered
// ranges, so a caller that keeps per-range results and combines them in
// range order gets the same bits for any thread count.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <new>
#include <stdexcept>
#include <memory>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

namespace softshell {

// The threads to use: `requested` when positive, else every core.
inline int host_threads(int requested) {
  if (requested > 0) return requested;
  return int(std::max(1u, std::thread::hardware_concurrency()));
}

// The number of ranges parallel_ranges() makes of n items for `parts`.
inline int range_count(std::size_t n, int parts) {
  return int(std::max<std::size_t>(1, std::min<std::size_t>(std::size_t(std::max(parts, 1)), n)));
}

// Calls f(k, begin, end) for range_count(n, parts) contiguous ranges of
// [0, n), range k = [n k / count, n (k + 1) / count) on its own thread (k = 0
// on the caller's), and waits for all of them.
template <class F>
void parallel_ranges_indexed(std::size_t n, int parts, F&& f) {
  const int count = range_count(n, parts);
  const std::size_t c = std::size_t(count);
  if (count == 1) {
    f(0, std::size_t(0), n);
    return;
  }
  std::vector<std::thread> pool;
  pool.reserve(c - 1);
  for (int k = 1; k < count; ++k)
    pool.emplace_back([&f, n, c, k] { f(k, n * std::size_t(k) / c, n * std::size_t(k + 1) / c); });
  f(0, std::size_t(0), n / c);
  for (std::thread& t : pool) t.join();
}

// Calls f(k, begin, end) for `chunks` contiguous ranges of [0, n) (at most
// n; range k = [n k / count, n (k + 1) / count)), handed out in order to
// `parts` threads as they become free: for work that is uneven over the
// range (a split into `parts` equal ranges leaves the threads waiting on the
// busiest). Keep per-chunk results and combine them in chunk order for the
// same bits for any thread count.
template <class F>
void parallel_chunks(std::size_t n, int parts, int chunks, F&& f) {
  const int count = range_count(n, chunks);
  const std::size_t c = std::size_t(count);
  std::atomic<int> next{0};
  auto work = [&] {
    for (int k; (k = next.fetch_add(1)) < count;) f(k, n * std::size_t(k) / c, n * std::size_t(k + 1) / c);
  };
  const int threads = std::min(range_count(n, parts), count);
  std::vector<std::thread> pool;
  pool.reserve(std::size_t(threads > 0 ? threads - 1 : 0));
  for (int t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
}

// As above, f(begin, end).
template <class F>
void parallel_ranges(std::size_t n, int parts, F&& f) {
  parallel_ranges_indexed(n, parts, [&f](int, std::size_t b, std::size_t e) { f(b, e); });
}

// The k-th smallest (k from 0) of the values that value(i, out) yields for i
// in [0, n) (it returns false for an i that has none; no NaN), for each k of
// ks: what std::nth_element over them gives, without gathering them all.
// Floats order as a key made of their bits (sign flipped for positives, all
// bits for negatives; -0 taken as +0): count the values per top 16 bits of
// their key on every thread, find the bucket that holds each rank, gather
// those buckets' values in one more pass and select within each (a serial
// gather and nth_element of 8 M values took 0.06-0.08 s at 256^3; two ranks
// in one call count and gather once). Throws std::invalid_argument when a k
// is not below their count.
template <class Value>
std::vector<float> kth_smallest_of_where(std::size_t n, const std::vector<std::size_t>& ks, int threads, Value value) {
  constexpr std::size_t kBuckets = 1u << 16;
  auto bucket_of = [](float f) {
    f += 0.0f;  // -0 as +0
    std::uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return std::size_t(((u >> 31) ? ~u : (u | 0x80000000u)) >> 16);
  };
  threads = host_threads(threads);
  const int parts = range_count(n, threads);
  std::vector<std::vector<std::size_t>> counts(std::size_t(parts), std::vector<std::size_t>(kBuckets, 0));
  parallel_ranges_indexed(n, threads, [&](int t, std::size_t i0, std::size_t i1) {
    std::vector<std::size_t>& c = counts[std::size_t(t)];
    float f;
    for (std::size_t i = i0; i < i1; ++i)
      if (value(i, f)) ++c[bucket_of(f)];
  });
  std::vector<std::size_t> total(kBuckets, 0);
  for (const auto& part : counts)
    for (std::size_t b = 0; b < kBuckets; ++b) total[b] += part[b];
  // Each rank's bucket, how many values lie in the buckets below it, and
  // its slot: where its bucket's values are gathered (ranks in one bucket
  // share the slot of the first of them; -1: a bucket no rank is in).
  std::vector<std::size_t> below(ks.size());
  std::vector<int> slot(ks.size()), slot_of(kBuckets, -1);
  for (std::size_t j = 0; j < ks.size(); ++j) {
    std::size_t b = 0, under = 0;
    for (;; ++b) {
      if (b == kBuckets) throw std::invalid_argument("kth_smallest_where: k is not below the count");
      if (under + total[b] > ks[j]) break;
      under += total[b];
    }
    if (slot_of[b] < 0) slot_of[b] = int(j);
    below[j] = under, slot[j] = slot_of[b];
  }
  std::vector<std::vector<std::vector<float>>> found(std::size_t(parts), std::vector<std::vector<float>>(ks.size()));
  parallel_ranges_indexed(n, threads, [&](int t, std::size_t i0, std::size_t i1) {
    float f;
    for (std::size_t i = i0; i < i1; ++i)
      if (value(i, f)) {
        const int s = slot_of[bucket_of(f)];
        if (s >= 0) found[std::size_t(t)][std::size_t(s)].push_back(f);
      }
  });
  std::vector<float> out(ks.size());
  for (std::size_t j = 0; j < ks.size(); ++j) {
    std::vector<float> in_bucket;
    for (const auto& part : found) in_bucket.insert(in_bucket.end(), part[std::size_t(slot[j])].begin(), part[std::size_t(slot[j])].end());
    std::nth_element(in_bucket.begin(), in_bucket.begin() + long(ks[j] - below[j]), in_bucket.end());
    out[j] = in_bucket[ks[j] - below[j]];
  }
  return out;
}

// The same for one rank.
template <class Value>
float kth_smallest_where(std::size_t n, std::size_t k, int threads, Value value) {
  return kth_smallest_of_where(n, std::vector<std::size_t>{k}, threads, value)[0];
}

// x's element of rank x.size() / 2 (its upper median), as nth_element gives
// it, selected on the threads. x must not be empty.
inline float median_of(const std::vector<float>& x, int threads) {
  return kth_smallest_where(x.size(), x.size() / 2, threads, [&x](std::size_t i, float& f) {
    f = x[i];
    return true;
  });
}

// A std::vector whose constructor and resize leave new floats (or other
// trivial types) uninitialised, so the threads that fill it are the first to
// touch its pages: std::vector's value-initialisation touches them all on the
// calling thread (a page's first touch costs a fault, about 2 ms per 4 MB on
// this kind of VM, 36 ms for a 256^3 float array) before the threads that
// fill it in parallel start.
//
// Its blocks come from the C library's allocator, in 4 KiB pages: on this
// kind of VM a 2 MiB page's first touch is slower (docs/benchmarks.md, "Huge
// pages: first touch on a VM"), and a block aligned to 2 MiB cannot reuse
// the freed block of the same size that a KeepFreedMemory scope keeps
// (host/host_memory.hpp).
template <class T, class A = std::allocator<T>>
class DefaultInitAllocator : public A {
  using traits = std::allocator_traits<A>;

 public:
  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U, typename traits::template rebind_alloc<U>>;
  };
  using A::A;
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible<U>::value) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    traits::construct(static_cast<A&>(*this), p, std::forward<Args>(args)...);
  }
};
template <class T>
using HostVector = std::vector<T, DefaultInitAllocator<T>>;


}  // namespace softshell
