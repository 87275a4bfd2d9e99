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
