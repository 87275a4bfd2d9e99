/* Splat orientation by the structure tensor of the opacity u.
 *
 * Why (docs/rendering.md, "Splat normals"): the variational classifier's u
 * is a shell a few voxels thick around each surface. Across the shell u rises
 * and falls again, so on its middle sheet -- where u, hence a splat's alpha,
 * is largest -- grad u vanishes and its central difference is dominated by the
 * small variation *along* the surface: the paper's splat orientation
 * "perpendicular to grad u" is least reliable exactly where it matters most.
 * The structure tensor
 *
 *     J(p) = sum_k w_k g_k g_k^T,   w_k = exp(-|x_k - p|^2 / (2 sigma^2)),
 *
 * over the voxels x_k of the box of radius ceil(2 sigma) (voxel units) around
 * the voxel nearest p, with g_k the central-difference gradient of u per mm
 * (the rule of gradient.cl), does not care about the sign of g: the two
 * flanks of the shell, with opposite gradients, reinforce each other, and
 * its principal eigenvector is the shell's normal on the middle sheet too.
 *
 * tensor_orientation returns that eigenvector (power iteration) scaled by
 * sqrt(lambda_max / sum_k w_k), the rms gradient along it, so callers can
 * tell a flat spot (0) from a surface. Sign: the start vector is the weighted
 * mean gradient sum_k w_k g_k when it is not negligible (then the result
 * points up the gradient like grad u), otherwise the axis of J's largest
 * diagonal entry; power iteration keeps the start vector's side.
 *
 * The host reference with the same definition in double precision is
 * host/orientation.cpp (tensor_orientation_reference). Needs grid.h.
 */
#ifndef SOFTSHELL_ORIENTATION_H
#define SOFTSHELL_ORIENTATION_H

#define ORIENTATION_POWER_ITERATIONS 32
#define ORIENTATION_MAX_RADIUS 16 /* ceil(2 sigma) for sigma <= 8 voxels */

/* p in voxel coordinates (voxel centres at integers), sigma in voxels (> 0). */
inline float3 tensor_orientation(__global const float* restrict u, const GridDesc g, const float3 p,
                                 const float sigma) {
  const int r = (int)ceil(2.0f * sigma);
  const int cx = clamp((int)floor(p.x + 0.5f), 0, g.nx - 1);
  const int cy = clamp((int)floor(p.y + 0.5f), 0, g.ny - 1);
  const int cz = clamp((int)floor(p.z + 0.5f), 0, g.nz - 1);
  const float inv2s2 = 1.0f / (2.0f * sigma * sigma);
  /* The Gaussian is separable: w = wx[x] wy[y] wz[z], 3 (2r + 1) exps
   * instead of (2r + 1)^3. r <= ORIENTATION_MAX_RADIUS (sigma <= 8). */
  float wx[2 * ORIENTATION_MAX_RADIUS + 1], wy[2 * ORIENTATION_MAX_RADIUS + 1], wz[2 * ORIENTATION_MAX_RADIUS + 1];
  for (int k = -r; k <= r; ++k) {
    const float dx = (float)(cx + k) - p.x, dy = (float)(cy + k) - p.y, dz = (float)(cz + k) - p.z;
    wx[k + r] = exp(-dx * dx * inv2s2);
    wy[k + r] = exp(-dy * dy * inv2s2);
    wz[k + r] = exp(-dz * dz * inv2s2);
  }
  float j00 = 0.0f, j01 = 0.0f, j02 = 0.0f, j11 = 0.0f, j12 = 0.0f, j22 = 0.0f;
  float3 mean = (float3)(0.0f);
  float wsum = 0.0f;
  for (int z = max(cz - r, 0); z <= min(cz + r, g.nz - 1); ++z) {
    for (int y = max(cy - r, 0); y <= min(cy + r, g.ny - 1); ++y) {
      const float wyz = wy[y - cy + r] * wz[z - cz + r];
      for (int x = max(cx - r, 0); x <= min(cx + r, g.nx - 1); ++x) {
        const float w = wx[x - cx + r] * wyz;
        const size_t idx = grid_index(g, x, y, z);
        const float3 gk = grid_gradient(u, g, idx, x, y, z);
        j00 += w * gk.x * gk.x;
        j01 += w * gk.x * gk.y;
        j02 += w * gk.x * gk.z;
        j11 += w * gk.y * gk.y;
        j12 += w * gk.y * gk.z;
        j22 += w * gk.z * gk.z;
        mean += w * gk;
        wsum += w;
      }
    }
  }
  const float trace = j00 + j11 + j22;
  if (!(trace > 0.0f)) return (float3)(0.0f);
  float3 v;
  /* The mean gradient counts as a start vector when it carries at least 1 %
   * of the rms gradient (|mean|^2 vs trace, both weighted by wsum). */
  if (dot(mean, mean) > 1e-4f * trace * wsum) {
    v = mean;
  } else {
    v = (j00 >= j11 && j00 >= j22) ? (float3)(1.0f, 0.0f, 0.0f)
                                   : (j11 >= j22 ? (float3)(0.0f, 1.0f, 0.0f) : (float3)(0.0f, 0.0f, 1.0f));
  }
  v = normalize(v);
  float lambda = 0.0f;
  for (int it = 0; it < ORIENTATION_POWER_ITERATIONS; ++it) {
    const float3 w = (float3)(j00 * v.x + j01 * v.y + j02 * v.z, j01 * v.x + j11 * v.y + j12 * v.z,
                              j02 * v.x + j12 * v.y + j22 * v.z);
    lambda = length(w);
    if (!(lambda > 0.0f)) return (float3)(0.0f);
    v = w / lambda;
  }
  return v * sqrt(lambda / wsum);
}

#endif /* SOFTSHELL_ORIENTATION_H */
