/* Levoy's isovalue-contour opacity (M. Levoy, "Display of Surfaces from Volume
 * Data", 1988; the paper's Figure 2b), for one isovalue f_v:
 *
 *   alpha(x) = alpha_v                                 if |grad f| = 0 and f = f_v
 *            = alpha_v (1 - |f_v - f| / (r |grad f|))   if |grad f| > 0 and
 *                                                         |f_v - f| <= r |grad f|
 *            = 0                                       otherwise
 *
 * |f_v - f| / |grad f| is the first-order distance (mm) from x to the
 * isosurface, so the opacity falls linearly from alpha_v on the surface to 0
 * at distance r (mm; the host converts the thickness from voxels). f and its
 * gradient come in the same intensity units as f_v.
 */

__kernel void classify_levoy(__global const float* restrict f, __global const float* restrict gx,
                             __global const float* restrict gy, __global const float* restrict gz,
                             __global float* restrict alpha, const float iso, const float r_mm,
                             const float alpha_v, const ulong n) {
  const size_t i = get_global_id(0);
  if (i >= n) return;
  const float d = fabs(iso - f[i]);
  const float g = sqrt(gx[i] * gx[i] + gy[i] * gy[i] + gz[i] * gz[i]);
  float a = 0.0f;
  if (g > 0.0f) {
    if (d <= r_mm * g) a = alpha_v * (1.0f - d / (r_mm * g));
  } else if (d == 0.0f) {
    a = alpha_v;
  }
  alpha[i] = a;
}
