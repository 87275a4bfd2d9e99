// Structure-tensor splat orientation: host reference and device entry point.
// Definition and reasons: kernels/orientation.h.
#include "orientation.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "blur.hpp"
#include "error.hpp"
#include "filter.hpp"
#include "grid.h"

namespace softshell {

Volume data_orientation_field(const Volume& bmode, int threads) {
  if (bmode.voxels() == 0 || bmode.data.size() != bmode.voxels())
    throw InputError("the data orientation field needs a non-empty volume");
  const double finest = std::min({bmode.spacing[0], bmode.spacing[1], bmode.spacing[2]});
  std::array<std::vector<float>, 3> w;
  for (int a = 0; a < 3; ++a)
    w[std::size_t(a)] = gaussian_weights(kDataLowpassVoxels * finest / bmode.spacing[std::size_t(a)], 3.0);
  Volume f = bmode.with_data(bmode.data, ScalarType::Float32);
  blur_3d(f.data.data(), nullptr, f.dims, w[0], w[1], w[2], threads, [](std::size_t) {});
  return f;
}

std::array<double, 3> tensor_orientation_reference(const Volume& u, const std::array<double, 3>& p, double sigma) {
  if (!(sigma > 0)) throw std::invalid_argument("tensor sigma must be > 0");
  if (u.voxels() == 0) throw std::invalid_argument("empty volume");
  const long n[3] = {long(u.dims[0]), long(u.dims[1]), long(u.dims[2])};
  const std::size_t sy = u.dims[0], sz = u.dims[0] * u.dims[1];
  const int r = static_cast<int>(std::ceil(2.0 * sigma));
  long c[3];
  for (int a = 0; a < 3; ++a) c[a] = std::clamp(static_cast<long>(std::floor(p[a] + 0.5)), 0L, n[a] - 1);
  double J[6] = {0, 0, 0, 0, 0, 0}, mean[3] = {0, 0, 0}, wsum = 0;
  const float* f = u.data.data();
  for (long z = std::max(c[2] - r, 0L); z <= std::min(c[2] + r, n[2] - 1); ++z)
    for (long y = std::max(c[1] - r, 0L); y <= std::min(c[1] + r, n[1] - 1); ++y)
      for (long x = std::max(c[0] - r, 0L); x <= std::min(c[0] + r, n[0] - 1); ++x) {
        const double dx = double(x) - p[0], dy = double(y) - p[1], dz = double(z) - p[2];
        const double w = std::exp(-(dx * dx + dy * dy + dz * dz) / (2.0 * sigma * sigma));
        const std::size_t i = std::size_t(x) + std::size_t(y) * sy + std::size_t(z) * sz;
        const double g[3] = {grid_diff(f, i, std::size_t(x), u.dims[0], 1, u.spacing[0]),
                             grid_diff(f, i, std::size_t(y), u.dims[1], sy, u.spacing[1]),
                             grid_diff(f, i, std::size_t(z), u.dims[2], sz, u.spacing[2])};
        J[0] += w * g[0] * g[0], J[1] += w * g[0] * g[1], J[2] += w * g[0] * g[2];
        J[3] += w * g[1] * g[1], J[4] += w * g[1] * g[2], J[5] += w * g[2] * g[2];
        for (int a = 0; a < 3; ++a) mean[a] += w * g[a];
        wsum += w;
      }
  const double trace = J[0] + J[3] + J[5];
  if (!(trace > 0)) return {0, 0, 0};
  double v[3];
  if (mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2] > 1e-4 * trace * wsum) {
    v[0] = mean[0], v[1] = mean[1], v[2] = mean[2];
  } else {
    const int axis = (J[0] >= J[3] && J[0] >= J[5]) ? 0 : (J[3] >= J[5] ? 1 : 2);
    v[0] = v[1] = v[2] = 0;
    v[axis] = 1;
  }
  double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (double& x : v) x /= len;
  double lambda = 0;
  for (int it = 0; it < 32; ++it) {  // ORIENTATION_POWER_ITERATIONS
    const double w0 = J[0] * v[0] + J[1] * v[1] + J[2] * v[2];
    const double w1 = J[1] * v[0] + J[3] * v[1] + J[4] * v[2];
    const double w2 = J[2] * v[0] + J[4] * v[1] + J[5] * v[2];
    lambda = std::sqrt(w0 * w0 + w1 * w1 + w2 * w2);
    if (!(lambda > 0)) return {0, 0, 0};
    v[0] = w0 / lambda, v[1] = w1 / lambda, v[2] = w2 / lambda;
  }
  const double s = std::sqrt(lambda / wsum);
  return {v[0] * s, v[1] * s, v[2] * s};
}

std::vector<std::array<float, 3>> tensor_orientation_device(Runtime& rt, const Volume& u,
                                                            const std::vector<std::array<float, 3>>& points,
                                                            double sigma) {
  if (!(sigma > 0 && sigma <= 8)) throw InputError("tensor sigma must be in (0, 8] voxels");
  if (points.empty()) return {};
  const GridDesc g = make_grid(u.dims, u.spacing);
  const std::size_t n = u.voxels(), count = points.size();
  rt.check_allocation(n * sizeof(float), "opacity volume");
  cl::Buffer d_u(rt.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, n * sizeof(float),
                 const_cast<float*>(u.data.data()));
  std::vector<cl_float4> pts(count);
  for (std::size_t i = 0; i < count; ++i) pts[i] = {{points[i][0], points[i][1], points[i][2], 0.0f}};
  cl::Buffer d_p(rt.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, count * sizeof(cl_float4), pts.data());
  cl::Buffer d_out = rt.buffer(count * sizeof(cl_float4));
  cl::Kernel k = rt.kernel("orientation.cl", "orientation_at_points");
  Runtime::set_args(k, d_u, g, d_p, d_out, static_cast<cl_uint>(count), static_cast<cl_float>(sigma));
  rt.enqueue_1d(k, count);
  std::vector<cl_float4> out(count);
  rt.queue().enqueueReadBuffer(d_out, CL_TRUE, 0, count * sizeof(cl_float4), out.data());
  std::vector<std::array<float, 3>> result(count);
  for (std::size_t i = 0; i < count; ++i) result[i] = {out[i].s[0], out[i].s[1], out[i].s[2]};
  return result;
}

}  // namespace softshell
