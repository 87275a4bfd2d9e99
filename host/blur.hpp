// Host separable Gaussian blurs in float, clamp-to-edge like the device
// lowpass (kernels/filter.cl): auto_iso's v~ and the data orientation field
// of the splats (host/orientation.hpp). Each output sample sums its taps in a
// fixed order, so results do not depend on the thread count or the build's
// vector width.
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

#include "parallel.hpp"
#include "volume.hpp"

namespace softshell {

// out[i] = sum_k w[k] rows[k][i] for i < m, the terms added in k order from 0.
void weighted_rows(float* out, const float* const* rows, const float* w, std::size_t taps, std::size_t m);

// A thread's scratch for the blurs below.
struct BlurScratch {
  std::vector<float> pad, out;
  std::vector<const float*> rows;
};

// Gaussian weights w along x of one row of `len` samples, in place,
// clamp-to-edge like the device lowpass.
void blur_row_x(float* line, std::size_t len, const std::vector<float>& w, BlurScratch& s);
// The same along y of one plane of nx x ny samples, in place.
void blur_plane_y(float* plane, std::size_t nx, std::size_t ny, const std::vector<float>& w, BlurScratch& s);

// In-place separable Gaussian of one or two fields (b may be null), wx, wy
// and wz the weights along each axis, clamp-to-edge like the device
// lowpass. x and y are blurred a z-plane at a time while the plane is in
// cache (prepare(z) first writes plane z of both fields, or does nothing), then
// z a y-slice at a time. Each output sample sums its taps in a fixed order
// and the work is split by whole planes or slices, so the result does not
// depend on the thread count.
template <class Prepare>
void blur_3d(float* a, float* b, const Dims3& d, const std::vector<float>& wx, const std::vector<float>& wy,
             const std::vector<float>& wz, int max_threads, Prepare&& prepare) {
  const std::size_t nx = d[0], ny = d[1], nz = d[2], plane = nx * ny;
  const int threads = host_threads(max_threads);
  parallel_ranges(nz, threads, [&](std::size_t z0, std::size_t z1) {
    BlurScratch s;
    for (std::size_t z = z0; z < z1; ++z) {
      prepare(z);
      for (float* f : {a, b}) {
        if (!f) continue;
        float* const p = f + z * plane;
        for (std::size_t y = 0; y < ny; ++y) blur_row_x(p + y * nx, nx, wx, s);
        blur_plane_y(p, nx, ny, wy, s);
      }
    }
  });
  const long r = static_cast<long>(wz.size() / 2);
  if (r == 0 || nz < 2) return;
  const std::size_t taps = wz.size();
  parallel_ranges(ny, threads, [&](std::size_t y0, std::size_t y1) {
    std::vector<float> slice(nz * nx);  // the rows (z, y) of one y, z-major
    std::vector<const float*> rows(taps);
    for (float* f : {a, b}) {
      if (!f) continue;
      for (std::size_t y = y0; y < y1; ++y) {
        for (std::size_t z = 0; z < nz; ++z) std::copy_n(f + (z * ny + y) * nx, nx, slice.data() + z * nx);
        for (std::size_t z = 0; z < nz; ++z) {
          for (std::size_t k = 0; k < taps; ++k)
            rows[k] = slice.data() + std::size_t(std::clamp(long(z) + long(k) - r, 0L, long(nz) - 1)) * nx;
          weighted_rows(f + (z * ny + y) * nx, rows.data(), wz.data(), taps, nx);
        }
      }
    }
  });
}

}  // namespace softshell
