/* Splat generation for oriented splatting (paper Section 4.1).
 *
 * Every voxel with opacity u > threshold becomes one splat triangle centred
 * at the voxel, lying in the plane perpendicular to the splat normal. Two
 * passes over x-rows (one work-item per (y, z) row) make the compaction
 * deterministic: splat_count counts each row's splats, the host turns the
 * counts into exclusive offsets, and splat_emit writes each row's splats at
 * its offset in x order. The output is therefore in voxel-index order
 * (x fastest), bit-identical from run to run.
 *
 * Output record, 7 float4 per splat (host/splats.hpp, struct Splat):
 *   [0] centre in mm (origin + h * index), alpha = u
 *   [1] unit normal (mm space), w = |normal field| before normalising (per
 *       mm, in the units of the field that orients: u or the data)
 *   [2] S, [3] T: the triangle's half-axes in mm; the vertices are
 *       centre + S, centre - (S + sqrt3 T) / 2, centre - (S - sqrt3 T) / 2
 *   [4..6] unit normals midway between the centre and vertex 0, 1, 2 (the
 *       paper's "three normals" shading), sign-aligned with [1]; [4].w and
 *       [5].w the ambient occlusion on the side n points to and the other
 *       (0 without -D SPLAT_OCCLUSION=1)
 *
 * S and T are a * h * s and a * h * t (componentwise h) for an orthonormal
 * pair s, t perpendicular to the normal field in voxel coordinates: the
 * triangle then lies in the plane perpendicular to the mm-space normal and
 * covers one voxel's share of the surface at any voxel spacing.
 *
 * The normal field is ONE function, splat_normal, chosen by -D SPLAT_NORMALS:
 *   0  gradient: central-difference grad u per mm (the paper), trilinearly
 *      interpolated between voxels for the three-normal points.
 *   1  tensor (the default): the principal eigenvector of the structure
 *      tensor of u with Gaussian sigma -D TENSOR_SIGMA (voxels), evaluated at
 *      the point itself (orientation.h, which says why: on the middle sheet
 *      of a shell grad u has no reliable direction).
 *   2  data: the same tensor of the data's orientation field (the B-mode
 *      volume lowpassed by a voxel, host/orientation.hpp) instead of u.
 * splat_emit takes the field as `f`: u itself for 0 and 1. Everything else
 * (which voxels, alpha, the shell centre, the occlusion) reads u.
 *
 * The splat centre, chosen by -D SPLAT_CENTRES:
 *   0  voxel: the voxel's centre (the paper).
 *   1  shell (the default): the voxel's centre moved along the splat normal
 *      n (unit, voxel coordinates) to u's local mass centre: the offset
 *      sum w (d . n) / sum w over the voxels within 3 of it, d their offset,
 *      w = u exp(-|d|^2 / (2 CENTRE_SIGMA^2)); at most one voxel. A sharpened
 *      u is a slab a few voxels thick whose faces are voxel staircases;
 *      splats on the voxel centres draw the staircase as bands on a tilted
 *      surface (docs/rendering.md, "Banding"). The neighbourhood spans a
 *      step of the staircase, so the mass centre lies on the slab's
 *      mid-surface whatever the step's phase; one column alone would not.
 */
#include "grid.h"

#define SPLAT_CENTRES_VOXEL 0
#define SPLAT_CENTRES_SHELL 1
#ifndef SPLAT_CENTRES
#define SPLAT_CENTRES SPLAT_CENTRES_SHELL
#endif
#ifndef SPLAT_OCCLUSION
#define SPLAT_OCCLUSION 0
#endif
#ifndef CENTRE_SIGMA
#define CENTRE_SIGMA 1.5f
#endif

#define SPLAT_NORMALS_GRADIENT 0
#define SPLAT_NORMALS_TENSOR 1
#define SPLAT_NORMALS_DATA 2
#ifndef SPLAT_NORMALS
#define SPLAT_NORMALS SPLAT_NORMALS_TENSOR
#endif
#if SPLAT_NORMALS == SPLAT_NORMALS_TENSOR || SPLAT_NORMALS == SPLAT_NORMALS_DATA
#include "orientation.h"
#ifndef TENSOR_SIGMA
#define TENSOR_SIGMA 1.5f
#endif
#endif

inline float3 splat_gradient_at(__global const float* restrict u, const GridDesc g, const int x, const int y,
                                const int z) {
  return grid_gradient(u, g, grid_index(g, x, y, z), x, y, z);
}

/* The splat normal field at a point p in voxel coordinates (p = index at
 * voxel centres; clamped into the grid), in mm space, not normalised, from
 * the field f (u, or the data's orientation field). This is the one place
 * that decides splat orientation and shading normals. */
inline float3 splat_normal(__global const float* restrict f, const GridDesc g, float3 p) {
#if SPLAT_NORMALS == SPLAT_NORMALS_GRADIENT
  p = clamp(p, (float3)(0.0f), (float3)((float)(g.nx - 1), (float)(g.ny - 1), (float)(g.nz - 1)));
  const float3 f0 = floor(p);
  const float3 w = p - f0;
  const int x0 = (int)f0.x, y0 = (int)f0.y, z0 = (int)f0.z;
  const int x1 = min(x0 + 1, g.nx - 1), y1 = min(y0 + 1, g.ny - 1), z1 = min(z0 + 1, g.nz - 1);
  /* At a voxel centre every weight but one is 0: skip the other corners so
   * the centre normal is exactly the voxel's central difference. */
  if (w.x == 0.0f && w.y == 0.0f && w.z == 0.0f) return splat_gradient_at(f, g, x0, y0, z0);
  const float3 c00 = mix(splat_gradient_at(f, g, x0, y0, z0), splat_gradient_at(f, g, x1, y0, z0), w.x);
  const float3 c10 = mix(splat_gradient_at(f, g, x0, y1, z0), splat_gradient_at(f, g, x1, y1, z0), w.x);
  const float3 c01 = mix(splat_gradient_at(f, g, x0, y0, z1), splat_gradient_at(f, g, x1, y0, z1), w.x);
  const float3 c11 = mix(splat_gradient_at(f, g, x0, y1, z1), splat_gradient_at(f, g, x1, y1, z1), w.x);
  return mix(mix(c00, c10, w.y), mix(c01, c11, w.y), w.z);
#elif SPLAT_NORMALS == SPLAT_NORMALS_TENSOR || SPLAT_NORMALS == SPLAT_NORMALS_DATA
  return tensor_orientation(f, g, p, TENSOR_SIGMA);  /* handles points outside the grid */
#else
#error "unknown SPLAT_NORMALS"
#endif
}

/* u at a point in voxel coordinates, trilinear; 0 outside the grid. */
inline float splat_u_at(__global const float* restrict u, const GridDesc g, const float3 p) {
  if (p.x < 0.0f || p.y < 0.0f || p.z < 0.0f || p.x > (float)(g.nx - 1) || p.y > (float)(g.ny - 1) ||
      p.z > (float)(g.nz - 1))
    return 0.0f;
  const float3 f0 = floor(p);
  const float3 w = p - f0;
  const int x0 = (int)f0.x, y0 = (int)f0.y, z0 = (int)f0.z;
  const int x1 = min(x0 + 1, g.nx - 1), y1 = min(y0 + 1, g.ny - 1), z1 = min(z0 + 1, g.nz - 1);
  const float c00 = mix(u[grid_index(g, x0, y0, z0)], u[grid_index(g, x1, y0, z0)], w.x);
  const float c10 = mix(u[grid_index(g, x0, y1, z0)], u[grid_index(g, x1, y1, z0)], w.x);
  const float c01 = mix(u[grid_index(g, x0, y0, z1)], u[grid_index(g, x1, y0, z1)], w.x);
  const float c11 = mix(u[grid_index(g, x0, y1, z1)], u[grid_index(g, x1, y1, z1)], w.x);
  return mix(mix(c00, c10, w.y), mix(c01, c11, w.y), w.z);
}

/* Ambient occlusion from the opacity (-D SPLAT_OCCLUSION=1) on the side
 * `side` (+1: along nv, -1: against it) of a splat: nine rays in a cone of
 * 45 degrees about side * nv (voxel coordinates, s and t the plane's
 * basis), each sampling u at 3, 5, 8 and 12 voxels (clear of the splat's
 * own shell) and absorbing as alpha compositing does; the rays' mean
 * absorbed share. 0: open, 1: enclosed. The renderer uses the side that
 * faces the viewer. */
inline float splat_occlusion(__global const float* restrict u, const GridDesc g, const float3 p, const float3 nv,
                             const float3 s, const float3 t, const int side) {
  const float3 axis = (float)side * nv;
  const float steps[4] = {3.0f, 5.0f, 8.0f, 12.0f};
  float sum = 0.0f;
  for (int r = 0; r < 9; ++r) {
    float3 d = axis;
    if (r > 0) {
      const float phi = 0.785398163f * (float)(r - 1);
      d = normalize(0.70710678f * axis + 0.70710678f * (cos(phi) * s + sin(phi) * t));
    }
    float through = 1.0f;
    for (int k = 0; k < 4; ++k) through *= 1.0f - clamp(splat_u_at(u, g, p + steps[k] * d), 0.0f, 1.0f);
    sum += 1.0f - through;
  }
  return sum / 9.0f;
}

/* Unit vector of v, or `fallback` where v vanishes (a flat spot of u). */
inline float3 splat_unit(const float3 v, const float3 fallback) {
  const float n = length(v);
  return n > 1e-20f ? v / n : fallback;
}

/* Number of splats in each x-row: counts[y + ny * z]. */
__kernel void splat_count(__global const float* restrict u, __global uint* restrict counts, const GridDesc g,
                          const float threshold) {
  const size_t row = get_global_id(0);
  if (row >= (size_t)g.ny * (size_t)g.nz) return;
  __global const float* r = u + row * (size_t)g.nx;
  uint n = 0;
  for (int x = 0; x < g.nx; ++x) n += r[x] > threshold ? 1u : 0u;
  counts[row] = n;
}

/* Writes each row's splats at offsets[row] (exclusive prefix sum of counts).
 * origin.xyz is the position of voxel (0, 0, 0) in mm; a is the triangle
 * size in voxels (paper: a = sqrt(1 / lambda)). */
__kernel void splat_emit(__global const float* restrict u, __global const float* restrict f,
                         __global const uint* restrict offsets,
                         __global float4* restrict out, const GridDesc g, const float4 origin, const float threshold,
                         const float a) {
  const size_t row = get_global_id(0);
  if (row >= (size_t)g.ny * (size_t)g.nz) return;
  const int y = (int)(row % (size_t)g.ny), z = (int)(row / (size_t)g.ny);
  const float3 h = (float3)(g.hx, g.hy, g.hz);
  const float sqrt3 = 1.7320508f;
  /* Texture-space corners of the triangle (paper Figure 4), in (s, t). */
  const float2 corner[3] = {(float2)(1.0f, 0.0f), (float2)(-0.5f, -0.5f * sqrt3), (float2)(-0.5f, 0.5f * sqrt3)};
  size_t k = offsets[row];
  __global const float* r = u + row * (size_t)g.nx;
  for (int x = 0; x < g.nx; ++x) {
    const float alpha = r[x];
    if (!(alpha > threshold)) continue;
    float3 p = (float3)((float)x, (float)y, (float)z);
    float3 grad = splat_normal(f, g, p);
    /* A flat spot has no orientation; face the transducer (-z). */
    float3 n = splat_unit(grad, (float3)(0.0f, 0.0f, -1.0f));
    /* Plane basis in voxel coordinates, perpendicular to the covector n h. */
    float3 nv = splat_unit(n * h, n);
#if SPLAT_CENTRES == SPLAT_CENTRES_SHELL
    {
      /* The offset along nv of u's mass centre in a Gaussian neighbourhood
       * (sigma CENTRE_SIGMA voxels, radius 3): the local mid-surface. */
      float mass = 0.0f, moment = 0.0f;
      const float inv2s2 = 0.5f / (CENTRE_SIGMA * CENTRE_SIGMA);
      for (int dz = -3; dz <= 3; ++dz) {
        const int zz = z + dz;
        if (zz < 0 || zz >= g.nz) continue;
        for (int dy = -3; dy <= 3; ++dy) {
          const int yy = y + dy;
          if (yy < 0 || yy >= g.ny) continue;
          for (int dx = -3; dx <= 3; ++dx) {
            const int xx = x + dx;
            if (xx < 0 || xx >= g.nx) continue;
            const float v = u[grid_index(g, xx, yy, zz)];
            if (v <= 0.0f) continue;
            const float3 d = (float3)((float)dx, (float)dy, (float)dz);
            const float w = v * exp(-dot(d, d) * inv2s2);
            mass += w;
            moment += w * dot(d, nv);
          }
        }
      }
      const float c = clamp(mass > 0.0f ? moment / mass : 0.0f, -1.0f, 1.0f);
      if (c != 0.0f) {
        p += c * nv;
        grad = splat_normal(f, g, p);
        const float3 n2 = splat_unit(grad, n);
        n = dot(n2, n) < 0.0f ? -n2 : n2;
        nv = splat_unit(n * h, n);
      }
    }
#endif
    const float3 helper = fabs(nv.x) < 0.9f ? (float3)(1.0f, 0.0f, 0.0f) : (float3)(0.0f, 1.0f, 0.0f);
    const float3 s = normalize(cross(nv, helper));
    const float3 t = cross(nv, s);
    const float3 S = a * h * s, T = a * h * t;
    __global float4* o = out + 7 * k;
    o[0] = (float4)(origin.xyz + h * p, alpha);
    o[1] = (float4)(n, length(grad));
    o[2] = (float4)(S, 0.0f);
    o[3] = (float4)(T, 0.0f);
    for (int c = 0; c < 3; ++c) {
      /* Midway between the centre and vertex c, in voxel coordinates. */
      const float3 q = p + 0.5f * a * (corner[c].x * s + corner[c].y * t);
      float3 m = splat_unit(splat_normal(f, g, q), n);
      if (dot(m, n) < 0.0f) m = -m;
      float w = 0.0f;  /* [4].w, [5].w: the occlusion along and against n; [6].w unused */
#if SPLAT_OCCLUSION
      if (c < 2) w = splat_occlusion(u, g, p, nv, s, t, c == 0 ? 1 : -1);
#endif
      o[4 + c] = (float4)(m, w);
    }
    ++k;
  }
}
