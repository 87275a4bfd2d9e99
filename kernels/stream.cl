/* Bandwidth probes: the yardstick every memory-bound kernel is measured
 * against in the same run (STREAM's copy and triad). */

__kernel void stream_copy(__global const float* restrict a, __global float* restrict b, const ulong n) {
  const size_t i = get_global_id(0);
  if (i < n) b[i] = a[i];
}

__kernel void stream_triad(__global const float* restrict a, __global const float* restrict b,
                           __global float* restrict c, const float s, const ulong n) {
  const size_t i = get_global_id(0);
  if (i < n) c[i] = fma(s, b[i], a[i]);
}

/* The copy as CPUs like it (a diagnostic, bench/bench_filter.cpp): work-item
 * i copies the contiguous chunk [i c, (i + 1) c) of n (c a multiple of 8) in
 * 8-lane loads and stores, each hardware thread streaming its own stretch of
 * memory as memcpy does, instead of PoCL's work-group loops over single
 * elements. */
__kernel void stream_copy_chunks(__global const float* restrict a, __global float* restrict b, const ulong n,
                                 const ulong chunk) {
  const ulong start = get_global_id(0) * chunk;
  const ulong end = min(start + chunk, n);
  ulong i = start;
  for (; i + 8 <= end; i += 8) vstore8(vload8(0, a + i), 0, b + i);
  for (; i < end; ++i) b[i] = a[i];
}
