// Host separable Gaussian blurs (host/blur.hpp).
#include "blur.hpp"

#include <cstring>

namespace softshell {

// out[i] = sum_k w[k] rows[k][i] for i < m, the terms added in k order from
// 0 (the order of a per-sample loop over the taps, so the same bits). Blocks
// of 16 outputs keep their sums in registers over all taps (GCC vector
// types; built for AVX2 too, with products and sums as written, no fused
// multiply-add: the same bits in either build); summing each tap into the
// output row in memory was bound by the L1's loads and stores.
__attribute__((target_clones("avx2", "default"))) void weighted_rows(float* out, const float* const* rows,
                                                                  const float* w, std::size_t taps, std::size_t m) {
  typedef float v8f __attribute__((vector_size(32)));
  std::size_t i0 = 0;
  // 32 outputs at a time where the row has them: four sums per tap that do
  // not wait for each other (two spent most of the loop waiting for the
  // adder's latency).
  for (; i0 + 32 <= m; i0 += 32) {
    v8f a0 = {0, 0, 0, 0, 0, 0, 0, 0}, a1 = a0, a2 = a0, a3 = a0;
    for (std::size_t k = 0; k < taps; ++k) {
      v8f f0, f1, f2, f3;
      std::memcpy(&f0, rows[k] + i0, sizeof f0);
      std::memcpy(&f1, rows[k] + i0 + 8, sizeof f1);
      std::memcpy(&f2, rows[k] + i0 + 16, sizeof f2);
      std::memcpy(&f3, rows[k] + i0 + 24, sizeof f3);
      a0 += w[k] * f0, a1 += w[k] * f1, a2 += w[k] * f2, a3 += w[k] * f3;
    }
    std::memcpy(out + i0, &a0, sizeof a0);
    std::memcpy(out + i0 + 8, &a1, sizeof a1);
    std::memcpy(out + i0 + 16, &a2, sizeof a2);
    std::memcpy(out + i0 + 24, &a3, sizeof a3);
  }
  for (; i0 + 16 <= m; i0 += 16) {
    v8f a0 = {0, 0, 0, 0, 0, 0, 0, 0}, a1 = a0;
    for (std::size_t k = 0; k < taps; ++k) {
      v8f f0, f1;
      std::memcpy(&f0, rows[k] + i0, sizeof f0);
      std::memcpy(&f1, rows[k] + i0 + 8, sizeof f1);
      a0 += w[k] * f0, a1 += w[k] * f1;
    }
    std::memcpy(out + i0, &a0, sizeof a0);
    std::memcpy(out + i0 + 8, &a1, sizeof a1);
  }
  std::fill(out + i0, out + m, 0.0f);
  for (std::size_t k = 0; k < taps && i0 < m; ++k) {
    const float wk = w[k];
    const float* src = rows[k];
    for (std::size_t i = i0; i < m; ++i) out[i] += wk * src[i];
  }
}

// Gaussian weights w along x of one row of `len` samples, in place,
// clamp-to-edge like the device lowpass.
void blur_row_x(float* line, std::size_t len, const std::vector<float>& w, BlurScratch& s) {
  const long r = static_cast<long>(w.size() / 2);
  if (r == 0 || len < 2) return;
  s.pad.resize(len + 2 * std::size_t(r));
  s.rows.resize(w.size());
  for (long i = -r; i < long(len) + r; ++i) s.pad[std::size_t(i + r)] = line[std::size_t(std::clamp(i, 0L, long(len) - 1))];
  for (std::size_t k = 0; k < w.size(); ++k) s.rows[k] = s.pad.data() + k;
  weighted_rows(line, s.rows.data(), w.data(), w.size(), len);
}

// The same along y of one plane of nx x ny samples, in place.
void blur_plane_y(float* plane, std::size_t nx, std::size_t ny, const std::vector<float>& w, BlurScratch& s) {
  const long r = static_cast<long>(w.size() / 2);
  if (r == 0 || ny < 2) return;
  s.out.resize(nx * ny);
  s.rows.resize(w.size());
  for (std::size_t y = 0; y < ny; ++y) {
    for (std::size_t k = 0; k < w.size(); ++k)
      s.rows[k] = plane + std::size_t(std::clamp(long(y) + long(k) - r, 0L, long(ny) - 1)) * nx;
    weighted_rows(s.out.data() + y * nx, s.rows.data(), w.data(), w.size(), nx);
  }
  std::copy_n(s.out.data(), nx * ny, plane);
}

}  // namespace softshell
