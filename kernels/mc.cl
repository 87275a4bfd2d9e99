/* Marching Cubes (Lorensen & Cline 1987) on a scalar volume at a level, in three passes with a
 * deterministic host scan in between (host/mesh.cpp):
 *
 *   mc_classify   per grid point: which of its +x, +y, +z edges cross the level (3 mask bits) and,
 *                 for the cell whose lowest corner it is, the case index (bit k: corner k solid,
 *                 value > level)
 *   (host)        exclusive scans: vertex offset per point (popcount of the mask), triangle offset
 *                 per cell (mc_tri_count[case]); both in voxel-index order
 *   mc_vertices   one vertex per crossing edge, in mm (origin + h * index), normal from the
 *                 central-difference gradient interpolated along the edge, pointing towards lower
 *                 values
 *   mc_triangles  per cell, its triangles as indices of the shared edge vertices (so the mesh is
 *                 indexed and, with the face-consistent table of mc_tables.h, closed)
 *
 * Edge vertex of point p along axis a: vertex_offset[p] + popcount(mask[p] & ((1 << a) - 1)).
 * "Solid" is value > level everywhere (NaN is never solid), so the classification of an edge is
 * the same in every cell that shares it.
 */
#include "grid.h"
#include "mc_tables.h"

inline bool mc_solid(const float v, const float level) { return v > level; }

inline float3 mc_gradient(__global const float* restrict f, const GridDesc g, const int x, const int y,
                          const int z) {
  return grid_gradient(f, g, grid_index(g, x, y, z), x, y, z);
}

__kernel void mc_classify(__global const float* restrict f, __global uchar* restrict edge_mask,
                          __global uchar* restrict cases, const GridDesc g, const float level) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t idx = grid_index(g, x, y, z);
  const size_t sy = (size_t)g.nx, sz = (size_t)g.nx * (size_t)g.ny;
  const bool s = mc_solid(f[idx], level);
  uint mask = 0;
  if (x + 1 < g.nx && mc_solid(f[idx + 1], level) != s) mask |= 1u;
  if (y + 1 < g.ny && mc_solid(f[idx + sy], level) != s) mask |= 2u;
  if (z + 1 < g.nz && mc_solid(f[idx + sz], level) != s) mask |= 4u;
  edge_mask[idx] = (uchar)mask;
  uint c = 0;
  if (x + 1 < g.nx && y + 1 < g.ny && z + 1 < g.nz) {
    const size_t i0 = idx, i4 = idx + sz;
    c = (mc_solid(f[i0], level) ? 1u : 0u) | (mc_solid(f[i0 + 1], level) ? 2u : 0u) |
        (mc_solid(f[i0 + 1 + sy], level) ? 4u : 0u) | (mc_solid(f[i0 + sy], level) ? 8u : 0u) |
        (mc_solid(f[i4], level) ? 16u : 0u) | (mc_solid(f[i4 + 1], level) ? 32u : 0u) |
        (mc_solid(f[i4 + 1 + sy], level) ? 64u : 0u) | (mc_solid(f[i4 + sy], level) ? 128u : 0u);
  }
  cases[idx] = (uchar)c;
}

__kernel void mc_vertices(__global const float* restrict f, __global const uchar* restrict edge_mask,
                          __global const uint* restrict vertex_offset, const GridDesc g, const float level,
                          const float4 origin, __global float* restrict positions,
                          __global float* restrict normals) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t idx = grid_index(g, x, y, z);
  const uint mask = edge_mask[idx];
  if (mask == 0) return;
  uint out = vertex_offset[idx];
  const float fa = f[idx];
  const float3 ga = mc_gradient(f, g, x, y, z);
  const float3 h = (float3)(g.hx, g.hy, g.hz);
  for (int a = 0; a < 3; ++a) {
    if (!(mask & (1u << a))) continue;
    const int3 d = (int3)(a == 0, a == 1, a == 2);
    const int bx = x + d.x, by = y + d.y, bz = z + d.z;
    const float fb = f[grid_index(g, bx, by, bz)];
    float t = (level - fa) / (fb - fa);  /* fb != fa: the edge crosses the level */
    t = clamp(t, 0.0f, 1.0f);
    const float3 p = origin.xyz + h * ((float3)((float)x, (float)y, (float)z) + t * convert_float3(d));
    const float3 gr = mix(ga, mc_gradient(f, g, bx, by, bz), t);
    const float len = length(gr);
    /* towards lower values; a flat gradient falls back to the edge direction */
    const float3 n = len > 0.0f ? -gr / len : (fb > fa ? -1.0f : 1.0f) * convert_float3(d);
    vstore3(p, out, positions);
    vstore3(n, out, normals);
    ++out;
  }
}

__kernel void mc_triangles(__global const uchar* restrict cases, __global const uchar* restrict edge_mask,
                           __global const uint* restrict vertex_offset, __global const uint* restrict tri_offset,
                           const GridDesc g, __global uint* restrict triangles) {
  const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, x, y, z)) return;
  const size_t idx = grid_index(g, x, y, z);
  const uint c = cases[idx];
  const uint n = mc_tri_count[c];
  if (n == 0) return;
  const size_t base = 3 * (size_t)tri_offset[idx];
  for (uint k = 0; k < 3 * n; ++k) {
    const int e = mc_tri_table[c][k];
    const size_t q = grid_index(g, x + mc_edge_point[e][0], y + mc_edge_point[e][1], z + mc_edge_point[e][2]);
    const uint axis = mc_edge_point[e][3];
    triangles[base + k] = vertex_offset[q] + popcount((uint)edge_mask[q] & ((1u << axis) - 1u));
  }
}
