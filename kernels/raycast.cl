/* Ray casting (paper Section 5, Figures 5 and 6): one work-item per pixel,
 * front-to-back compositing with early termination, gradient shading.
 *
 * The volume is a plain buffer (no OpenCL images, which some devices lack)
 * of samples already mapped to [0, 1] on the host: the opacity u itself, or a
 * raw volume's normalised intensity. Trilinear interpolation is by hand, in
 * index coordinates (voxel (0,0,0) at 0, voxel n-1 at n-1, the volume's
 * origin and spacing handled on the ray).
 *
 * Transfer function (post-classification, applied to the interpolated
 * sample s): alpha = tf.z * clamp((s - tf.x) / (tf.y - tf.x), 0, 1), and 0
 * below the cut misc.z. With tf = (0, 1, 1) and no cut the opacity is u
 * itself. The opacity of a sample is per
 * reference length (misc.x mm, one voxel): a step of dt mm uses
 * 1 - (1 - alpha)^(dt / ref), so the image does not depend on the step.
 *
 * Shading as the splat renderer's vertex shader (viewer/shaders/splat.vert):
 * normal = the central-difference gradient per mm (one-sided on the border,
 * as gradient.cl and splat.cl) averaged over the voxel's 3x3x3 neighbours
 * (weights (1 2 1) per axis), trilinearly interpolated from the 8 voxels
 * around the sample, flipped towards the viewer (two-sided), ambient +
 * diffuse + Blinn specular. A zero gradient faces the viewer. Each pixel's
 * samples are offset by a hash of the pixel (raycast_render). Both keep thin
 * shells from shading in wood-grain rings.
 *
 * Options: -D RAYCAST_ORTHO=1 for an orthographic camera (parallel rays
 * along `forward`, the image plane `view.zw` mm half-wide / half-high).
 */
#include "grid.h"

#ifndef RAYCAST_ORTHO
#define RAYCAST_ORTHO 0
#endif

/* One axis of a trilinear lookup: lower index, upper index, weight. */
inline void raycast_axis(const float p, const int n, int* i0, int* i1, float* w) {
  const float q = clamp(p, 0.0f, (float)(n - 1));
  int a = (int)floor(q);
  if (a > n - 2) a = max(n - 2, 0);
  *i0 = a;
  *i1 = min(a + 1, n - 1);
  *w = q - (float)a;
}

inline float raycast_sample(__global const float* restrict v, const GridDesc g, const float3 p) {
  int x0, x1, y0, y1, z0, z1;
  float wx, wy, wz;
  raycast_axis(p.x, g.nx, &x0, &x1, &wx);
  raycast_axis(p.y, g.ny, &y0, &y1, &wy);
  raycast_axis(p.z, g.nz, &z0, &z1, &wz);
  const float c00 = mix(v[grid_index(g, x0, y0, z0)], v[grid_index(g, x1, y0, z0)], wx);
  const float c10 = mix(v[grid_index(g, x0, y1, z0)], v[grid_index(g, x1, y1, z0)], wx);
  const float c01 = mix(v[grid_index(g, x0, y0, z1)], v[grid_index(g, x1, y0, z1)], wx);
  const float c11 = mix(v[grid_index(g, x0, y1, z1)], v[grid_index(g, x1, y1, z1)], wx);
  return mix(mix(c00, c10, wy), mix(c01, c11, wy), wz);
}

/* Per-voxel gradient, computed once per volume: shading then costs one
 * trilinear lookup of float4s instead of 8 x 6 volume reads per sample. */
__kernel void raycast_gradients(__global const float* restrict v, const GridDesc g, __global float4* restrict out) {
  const int x = (int)get_global_id(0), y = (int)get_global_id(1), z = (int)get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  /* Central differences averaged over the 3x3 neighbours across each axis
   * with weights (1 2 1) x (1 2 1) / 16 (a Sobel-type gradient): on a thin,
   * sharpened shell the plain central difference changes from voxel layer to
   * voxel layer, and a surface crossing the layers at a shallow angle shades
   * in terraces (wood-grain rings). Borders clamp. */
  float3 acc = (float3)(0.0f);
  float wsum = 0.0f;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int xx = clamp(x + dx, 0, g.nx - 1), yy = clamp(y + dy, 0, g.ny - 1), zz = clamp(z + dz, 0, g.nz - 1);
        const float w = (float)((2 - abs(dx)) * (2 - abs(dy)) * (2 - abs(dz)));
        acc += w * grid_gradient(v, g, grid_index(g, xx, yy, zz), xx, yy, zz);
        wsum += w;
      }
  out[grid_index(g, x, y, z)] = (float4)(acc / wsum, 0.0f);
}

/* The voxels' gradients interpolated trilinearly at p (index coordinates). */
inline float3 raycast_gradient(__global const float4* restrict gv, const GridDesc g, const float3 p) {
  int x0, x1, y0, y1, z0, z1;
  float wx, wy, wz;
  raycast_axis(p.x, g.nx, &x0, &x1, &wx);
  raycast_axis(p.y, g.ny, &y0, &y1, &wy);
  raycast_axis(p.z, g.nz, &z0, &z1, &wz);
  const float4 c00 = mix(gv[grid_index(g, x0, y0, z0)], gv[grid_index(g, x1, y0, z0)], wx);
  const float4 c10 = mix(gv[grid_index(g, x0, y1, z0)], gv[grid_index(g, x1, y1, z0)], wx);
  const float4 c01 = mix(gv[grid_index(g, x0, y0, z1)], gv[grid_index(g, x1, y0, z1)], wx);
  const float4 c11 = mix(gv[grid_index(g, x0, y1, z1)], gv[grid_index(g, x1, y1, z1)], wx);
  return mix(mix(c00, c10, wy), mix(c01, c11, wy), wz).xyz;
}

/* Arguments (all positions in mm unless said otherwise):
 *   origin   volume origin (position of voxel 0,0,0)
 *   eye, forward, right, up   camera (unit axes; eye unused when orthographic)
 *   view     (tan of half the horizontal / vertical field of view, ortho half width / height)
 *   box_lo, box_hi   the part of the volume rays see, index coordinates (crop box)
 *   tf       (lo, hi, max opacity, step mm)
 *   light    unit vector towards the light
 *   colour   surface colour; background in `out` is left to the host
 *   material (ambient, diffuse, specular, shininess)
 *   misc     (reference length mm, termination opacity, cut, -)
 * grad_vol: raycast_gradients of vol.
 * out: premultiplied colour + accumulated opacity per pixel, rows top to bottom. */
__kernel void raycast_render(__global const float* restrict vol, __global const float4* restrict grad_vol,
                             const GridDesc g, const float4 origin,
                             const float4 eye, const float4 forward, const float4 right, const float4 up,
                             const float4 view, const float4 box_lo, const float4 box_hi, const float4 tf,
                             const float4 light, const float4 colour, const float4 material, const float4 misc,
                             const int width, const int height, __global float4* restrict out) {
  const int px = (int)get_global_id(0), py = (int)get_global_id(1);
  if (px >= width || py >= height) return;

  const float sx = 2.0f * ((float)px + 0.5f) / (float)width - 1.0f;
  const float sy = 1.0f - 2.0f * ((float)py + 0.5f) / (float)height;
#if RAYCAST_ORTHO
  const float3 dir = forward.xyz;
  const float3 start = eye.xyz + sx * view.z * right.xyz + sy * view.w * up.xyz;
#else
  const float3 dir = normalize(forward.xyz + sx * view.x * right.xyz + sy * view.y * up.xyz);
  const float3 start = eye.xyz;
#endif
  const float3 h = (float3)(g.hx, g.hy, g.hz);
  /* The ray in index coordinates: q(t) = o + t d, t in mm along the ray. */
  const float3 o = (start - origin.xyz) / h;
  const float3 d = dir / h;

  /* Slab test against the box. */
  float t0 = 0.0f, t1 = INFINITY;
#if RAYCAST_ORTHO
  t0 = -INFINITY;
#endif
  const float oa[3] = {o.x, o.y, o.z}, da[3] = {d.x, d.y, d.z};
  const float lo[3] = {box_lo.x, box_lo.y, box_lo.z}, hi[3] = {box_hi.x, box_hi.y, box_hi.z};
  for (int a = 0; a < 3; ++a) {
    if (fabs(da[a]) < 1e-12f) {
      if (oa[a] < lo[a] || oa[a] > hi[a]) t1 = -INFINITY;
      continue;
    }
    const float ta = (lo[a] - oa[a]) / da[a], tb = (hi[a] - oa[a]) / da[a];
    t0 = fmax(t0, fmin(ta, tb));
    t1 = fmin(t1, fmax(ta, tb));
  }

  float3 c = (float3)(0.0f);
  float acc = 0.0f;
  const float dt = tf.w, ref = misc.x, term = misc.y, cut = misc.z;
  const float inv_range = 1.0f / fmax(tf.y - tf.x, 1e-12f);
  const float3 view_dir = -dir;
  const float3 half_vec = normalize(light.xyz + view_dir);
  /* Samples at (k + j) dt from the eye (the image plane when orthographic),
   * not from where each ray enters the box, with j in [0, 1) a hash of the
   * pixel: sampling a thin shell at the same distances in every ray prints
   * the distance spheres onto it as wood-grain rings (and the box's faces
   * would, were the samples tied to the entry point); a per-pixel offset
   * turns that aliasing into fine noise of the same mean (stochastic
   * jittering), deterministic from frame to frame. */
  uint hsh = (uint)px * 0x9E3779B1u ^ (uint)py * 0x85EBCA77u;
  hsh ^= hsh >> 15;
  hsh *= 0x2C1B3C6Du;
  hsh ^= hsh >> 12;
  hsh *= 0x297A2D39u;
  hsh ^= hsh >> 15;
  const float jit = (float)(hsh >> 8) * (1.0f / 16777216.0f);
  t0 = (ceil(t0 / dt - jit) + jit) * dt;
  if (t0 <= t1) {
    const int steps = (int)floor((t1 - t0) / dt) + 1;
    for (int k = 0; k < steps; ++k) {
      const float3 q = o + (t0 + (float)k * dt) * d;
      const float s = raycast_sample(vol, g, q);
      const float alpha = s < cut ? 0.0f : tf.z * clamp((s - tf.x) * inv_range, 0.0f, 1.0f);
      if (alpha <= 0.0f) continue;
      const float a = alpha >= 1.0f ? 1.0f : 1.0f - pow(1.0f - alpha, dt / ref);
      const float3 grad = raycast_gradient(grad_vol, g, q);
      const float len = length(grad);
      float3 n = len > 1e-12f ? grad / len : view_dir;
      if (dot(n, view_dir) < 0.0f) n = -n;
      const float diffuse = fmax(dot(n, light.xyz), 0.0f);
      const float specular = diffuse > 0.0f ? pow(fmax(dot(n, half_vec), 0.0f), material.w) : 0.0f;
      const float3 shade = colour.xyz * (material.x + material.y * diffuse) + material.z * specular;
      const float wgt = (1.0f - acc) * a;
      c += wgt * shade;
      acc += wgt;
      if (acc >= term) break;
    }
  }
  out[(size_t)py * (size_t)width + (size_t)px] = (float4)(c, acc);
}
