// Independent float64 CPU references (see reference.hpp).
#include "reference.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace softshell::test {

// Direct (not separable-by-construction) reference: the full 3-D sum of
// w_x(i) w_y(j) w_z(k) f(clamp(x+i), clamp(y+j), clamp(z+k)) in double, with
// weights computed here from the definition, not from gaussian_weights().
std::vector<double> reference_lowpass(const Volume& v, double sigma_mm, double truncate) {
  std::array<std::vector<double>, 3> w;
  for (int a = 0; a < 3; ++a) {
    const double s = sigma_mm / v.spacing[a];
    if (s <= 1e-6) {
      w[a] = {1.0};
      continue;
    }
    const int r = std::max(1, int(std::ceil(truncate * s)));
    double sum = 0;
    for (int k = -r; k <= r; ++k) w[a].push_back(std::exp(-k * k / (2 * s * s))), sum += w[a].back();
    for (double& x : w[a]) x /= sum;
  }
  const long nx = v.dims[0], ny = v.dims[1], nz = v.dims[2];
  const long rx = w[0].size() / 2, ry = w[1].size() / 2, rz = w[2].size() / 2;
  std::vector<double> out(v.voxels());
  for (long z = 0; z < nz; ++z)
    for (long y = 0; y < ny; ++y)
      for (long x = 0; x < nx; ++x) {
        double acc = 0;
        for (long k = -rz; k <= rz; ++k)
          for (long j = -ry; j <= ry; ++j)
            for (long i = -rx; i <= rx; ++i) {
              const long xx = std::clamp(x + i, 0L, nx - 1), yy = std::clamp(y + j, 0L, ny - 1),
                         zz = std::clamp(z + k, 0L, nz - 1);
              acc += w[0][i + rx] * w[1][j + ry] * w[2][k + rz] * v.at(xx, yy, zz);
            }
        out[v.index(x, y, z)] = acc;
      }
  return out;
}

// d/d(axis) of v at (x, y, z), written independently of the kernel.
double reference_derivative(const Volume& v, long x, long y, long z, int axis) {
  long p[3] = {x, y, z};
  const long n = long(v.dims[axis]);
  const double h = v.spacing[axis];
  if (n < 2) return 0.0;
  auto sample = [&](long c) {
    long q[3] = {p[0], p[1], p[2]};
    q[axis] = c;
    return double(v.at(q[0], q[1], q[2]));
  };
  const long c = p[axis];
  if (c == 0) return (sample(1) - sample(0)) / h;
  if (c == n - 1) return (sample(n - 1) - sample(n - 2)) / h;
  return (sample(c + 1) - sample(c - 1)) / (2 * h);
}

std::array<std::vector<double>, 3> reference_gradient(const Volume& v) {
  std::array<std::vector<double>, 3> g;
  for (auto& c : g) c.resize(v.voxels());
  for (std::size_t z = 0; z < v.dims[2]; ++z)
    for (std::size_t y = 0; y < v.dims[1]; ++y)
      for (std::size_t x = 0; x < v.dims[0]; ++x)
        for (int a = 0; a < 3; ++a) g[a][v.index(x, y, z)] = reference_derivative(v, x, y, z, a);
  return g;
}

}  // namespace softshell::test
