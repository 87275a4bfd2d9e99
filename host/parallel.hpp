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
// in one call count and gather once). value is called twice per i and must
// give the same both times (the gather fills arrays of the counted sizes).
// Throws std::invalid_argument when a k is not below their count.
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
  // Four 32-bit counts per bucket and thread, a value's into the one of its
  // index mod 4 (neighbouring values mostly share a bucket: one count made a
  // chain of stores and reloads through memory); a range of 2^32 values or
  // more counts in 64 bits. count(t, b): thread t's values in bucket b.
  constexpr std::size_t kWays = 4;
  std::vector<std::vector<std::uint32_t>> counts(static_cast<std::size_t>(parts));
  std::vector<std::vector<std::size_t>> wide(static_cast<std::size_t>(parts));
  parallel_ranges_indexed(n, threads, [&](int t, std::size_t i0, std::size_t i1) {
    float f;
    if (i1 - i0 >= (std::size_t(1) << 32)) {
      std::vector<std::size_t>& c = wide[std::size_t(t)];
      c.assign(kBuckets, 0);
      for (std::size_t i = i0; i < i1; ++i)
        if (value(i, f)) ++c[bucket_of(f)];
      return;
    }
    std::vector<std::uint32_t>& c = counts[std::size_t(t)];
    c.assign(kWays * kBuckets, 0);
    std::uint32_t* const c0 = c.data();
    std::size_t i = i0;
    for (; i + kWays <= i1; i += kWays)
      for (std::size_t w = 0; w < kWays; ++w)
        if (value(i + w, f)) ++c0[w * kBuckets + bucket_of(f)];
    for (; i < i1; ++i)
      if (value(i, f)) ++c0[bucket_of(f)];
  });
  const auto count = [&](int t, std::size_t b) {
    const auto& c = counts[std::size_t(t)];
    std::size_t sum = wide[std::size_t(t)].empty() ? 0 : wide[std::size_t(t)][b];
    if (!c.empty())
      for (std::size_t w = 0; w < kWays; ++w) sum += c[w * kBuckets + b];
    return sum;
  };
  std::vector<std::size_t> total(kBuckets, 0);
  for (int t = 0; t < parts; ++t)
    for (std::size_t b = 0; b < kBuckets; ++b) total[b] += count(t, b);
  // Each rank's bucket, how many values lie in the buckets below it, and
  // its slot: which of the distinct buckets the ranks fall in (`target`)
  // holds it, where that bucket's values are gathered.
  std::vector<std::size_t> below(ks.size()), target;
  std::vector<int> slot(ks.size());
  for (std::size_t j = 0; j < ks.size(); ++j) {
    std::size_t b = 0, under = 0;
    for (;; ++b) {
      if (b == kBuckets) throw std::invalid_argument("kth_smallest_where: k is not below the count");
      if (under + total[b] > ks[j]) break;
      under += total[b];
    }
    const auto at = std::find(target.begin(), target.end(), b);
    slot[j] = int(at - target.begin());
    if (at == target.end()) target.push_back(b);
    below[j] = under;
  }
  // Gathered into arrays of the counted size (one slot spare), each value
  // stored at every target's next slot and kept where its bucket is that
  // one: no branch on the bucket (a table of every bucket's slot missed the
  // cache where the buckets scatter, as |x - median|'s do over many
  // exponents, and a push_back per kept value cost as much).
  const std::size_t m = target.size();
  std::vector<std::vector<float>> found(std::size_t(parts) * m);
  for (int t = 0; t < parts; ++t)
    for (std::size_t s = 0; s < m; ++s) found[std::size_t(t) * m + s].resize(count(t, target[s]) + 1);
  parallel_ranges_indexed(n, threads, [&](int t, std::size_t i0, std::size_t i1) {
    float f;
    std::vector<float*> out(m);
    std::vector<std::size_t> kept(m, 0);
    for (std::size_t s = 0; s < m; ++s) out[s] = found[std::size_t(t) * m + s].data();
    if (m == 1) {
      float* const o = out[0];
      const std::size_t b0 = target[0];
      std::size_t k = 0;
      for (std::size_t i = i0; i < i1; ++i)
        if (value(i, f)) o[k] = f, k += bucket_of(f) == b0;
      kept[0] = k;
    } else if (m == 2) {
      float *const o0 = out[0], *const o1 = out[1];
      const std::size_t b0 = target[0], b1 = target[1];
      std::size_t k0 = 0, k1 = 0;
      for (std::size_t i = i0; i < i1; ++i)
        if (value(i, f)) {
          const std::size_t b = bucket_of(f);
          o0[k0] = f, o1[k1] = f;
          k0 += b == b0, k1 += b == b1;
        }
      kept[0] = k0, kept[1] = k1;
    } else {
      for (std::size_t i = i0; i < i1; ++i)
        if (value(i, f)) {
          const std::size_t b = bucket_of(f);
          for (std::size_t s = 0; s < m; ++s) out[s][kept[s]] = f, kept[s] += b == target[s];
        }
    }
    for (std::size_t s = 0; s < m; ++s) found[std::size_t(t) * m + s].resize(kept[s]);
  });
  std::vector<float> out(ks.size());
  for (std::size_t j = 0; j < ks.size(); ++j) {
    std::vector<float> in_bucket;
    for (int t = 0; t < parts; ++t) {
      const std::vector<float>& part = found[std::size_t(t) * m + std::size_t(slot[j])];
      in_bucket.insert(in_bucket.end(), part.begin(), part.end());
    }
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
