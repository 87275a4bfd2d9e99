/* Structure-tensor splat orientation at a list of points (orientation.h):
 * one work-item per point, points in voxel coordinates, results as float4
 * (x, y, z: the scaled eigenvector, w unused). Used by host/orientation.cpp;
 * the splat generator calls tensor_orientation directly (splat.cl). */
#include "grid.h"
#include "orientation.h"

__kernel void orientation_at_points(__global const float* restrict u, const GridDesc g,
                                    __global const float4* restrict points, __global float4* restrict out,
                                    const uint count, const float sigma) {
  const size_t i = get_global_id(0);
  if (i >= count) return;
  const float3 v = tensor_orientation(u, g, points[i].xyz, sigma);
  out[i] = (float4)(v, 0.0f);
}
