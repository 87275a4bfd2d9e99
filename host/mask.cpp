// The scanned-region mask: a morphological opening of the exact zeros,
// flood fill of its boundary-touching regions with a size rule, and
// 6-neighbour growth (host/mask.hpp gives the rule). The passes over all
// voxels run on threads (MaskParams::threads) in ranges whose results are
// combined in order, so the mask is the same for any thread count; the flood
// fill and the growth layers stay serial.
#include "mask.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <utility>

#include <immintrin.h>

#include "error.hpp"
#include "filter.hpp"
#include "io.hpp"
#include "parallel.hpp"
#include "shadow_walls.hpp"
#include "text.hpp"

namespace softshell {
namespace {

// Calls f(neighbour index) for the up to six face neighbours of voxel i.
template <class F>
void for_face_neighbours(const Dims3& d, std::size_t i, F&& f) {
  const std::size_t nx = d[0], nxy = d[0] * d[1];
  const std::size_t x = i % nx, y = (i / nx) % d[1], z = i / nxy;
  if (x > 0) f(i - 1);
  if (x + 1 < d[0]) f(i + 1);
  if (y > 0) f(i - nx);
  if (y + 1 < d[1]) f(i + nx);
  if (z > 0) f(i - nxy);
  if (z + 1 < d[2]) f(i + nxy);
}

// Byte loops over a row, as functions whose pointers are restrict: written
// inline in the lambdas of filter_axis, each byte store might alias the row
// length they captured by reference, which was then loaded again per byte
// and nothing vectorised.
void breaks_of(std::uint8_t* __restrict out, const std::uint8_t* __restrict in, std::size_t n, std::uint8_t flip) {
  for (std::size_t x = 0; x < n; ++x) out[x] = std::uint8_t((in[x] != 0) ^ flip);
}
void or_into(std::uint8_t* __restrict acc, const std::uint8_t* __restrict in, std::size_t n) {
  for (std::size_t x = 0; x < n; ++x) acc[x] |= in[x];
}
void xor_into(std::uint8_t* __restrict out, const std::uint8_t* __restrict in, std::size_t n, std::uint8_t flip) {
  for (std::size_t x = 0; x < n; ++x) out[x] = in[x] ^ flip;
}

// One plane of scanned_mask's step 2b along z: for each of its m voxels (a
// line each), the first depth with data (first still `none`: this one) and
// the last (this one).
void first_last_rows(const float* __restrict data, std::size_t m, std::uint32_t z, std::uint32_t none,
                     std::uint32_t* __restrict first, std::uint32_t* __restrict last) {
  for (std::size_t i = 0; i < m; ++i) {
    const bool set = data[i] != 0.0f;
    first[i] = set && first[i] == none ? z : first[i];
    last[i] = set ? z : last[i];
  }
}

// One axis of a binary cube filter with half-width r, in place on `a`:
// erode (all of [i - r, i + r] set; outside the volume counts as set) or
// dilate (any of them set). Along x a row at a time, the 2r + 1 offsets ORed
// in; along y (the rows of a z-plane) and z (the rows of a y-slice) the
// window's rows ORed for a whole row of x at once, so every read and write
// is a contiguous row (the lines along z wrote a byte per plane: the cube
// filter took 0.24-0.36 s of a 0.40-0.54 s mask at 256^3). Every line is
// read before any of it is written.
void filter_axis(std::vector<std::uint8_t>& a, const Dims3& d, int axis, int r, bool erode, int threads) {
  const std::size_t nx = d[0], ny = d[1], nz = d[2];
  // A voxel that breaks the test: 1 where the byte is 0 (erode) or not 0
  // (dilate); the output is the OR of the window's breaks, flipped back.
  const std::uint8_t flip = erode ? 1 : 0;
  const std::size_t len = d[axis];
  if (axis == 0) {
    // Per row, the breaks at each offset t in [-r, r] ORed in (clamped to
    // the row: the window's part inside the volume), a pass per offset that
    // vectorises (r is the mask's cube half-width, 2 by default).
    parallel_ranges(ny * nz, threads, [&](std::size_t l0, std::size_t l1) {
      const std::size_t w = nx;
      std::vector<std::uint8_t> brk(w), any(w);
      for (std::size_t l = l0; l < l1; ++l) {
        std::uint8_t* const row = a.data() + l * w;
        breaks_of(brk.data(), row, w, flip);
        std::fill(any.begin(), any.end(), std::uint8_t{0});
        for (long t = -long(r); t <= long(r); ++t) {
          const long i0 = std::max(0L, -t), i1 = long(w) - std::max(0L, t);
          if (i1 <= i0) continue;
          or_into(any.data() + i0, brk.data() + (i0 + t), std::size_t(i1 - i0));  // brk[i + t] for i from i0
        }
        xor_into(row, any.data(), w, flip);
      }
    });
    return;
  }
  // The rows along the axis: of z-plane o (y) or of y-slice o (z), their
  // breaks copied first; each output row the OR of the window's rows
  // [k - r, k + r] (clamped), 2r + 1 byte passes that vectorise.
  const std::size_t outer = axis == 1 ? nz : ny, step = axis == 1 ? nx : nx * ny;
  parallel_ranges(outer, threads, [&](std::size_t o0, std::size_t o1) {
    const std::size_t w = nx;
    std::vector<std::uint8_t> rows(len * w), any(w);
    for (std::size_t o = o0; o < o1; ++o) {
      std::uint8_t* const base = a.data() + (axis == 1 ? o * w * ny : o * w);
      for (std::size_t k = 0; k < len; ++k) breaks_of(rows.data() + k * w, base + k * step, w, flip);
      for (std::size_t k = 0; k < len; ++k) {
        const std::size_t q0 = k > std::size_t(r) ? k - std::size_t(r) : 0, q1 = std::min(len - 1, k + std::size_t(r));
        std::copy_n(rows.data() + q0 * w, w, any.data());
        for (std::size_t q = q0 + 1; q <= q1; ++q) or_into(any.data(), rows.data() + q * w, w);
        xor_into(base + k * step, any.data(), w, flip);
      }
    }
  });
}

// The unscanned voxels (mask 0) with a face neighbour that passes `take`, in
// index order.
template <class F>
std::vector<std::size_t> frontier_of(const std::vector<std::uint8_t>& mask, const Dims3& d, int threads, F&& take) {
  const std::size_t n = mask.size();
  std::vector<std::vector<std::size_t>> parts(std::size_t(range_count(n, threads)));
  parallel_ranges_indexed(n, threads, [&](int k, std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) {
      if (mask[i] != 0) continue;
      bool edge = false;
      for_face_neighbours(d, i, [&](std::size_t j) { edge = edge || take(j); });
      if (edge) parts[std::size_t(k)].push_back(i);
    }
  });
  std::vector<std::size_t> out;
  for (const auto& p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

// Step 2c: 1 where a nonzero sample lies on both sides of the voxel along
// one of the lines through it in the 49 directions with components in
// [-2, 2] (axes, face and body diagonals, and the steps of 1 across per 2
// along that a fan's oblique beams come close to), so the voxel lies inside
// the data's hull. Per direction two running flags, "data met before" (bit
// 0) and "after" (bit 1), each a pass that visits p - dir before p; bit 2
// keeps "inside". The directions split over the threads, one byte per
// voxel each, OR-ed at the end (the same for any thread count). Only when
// step 2b finds dark fluid: at 256^3 the mask then takes 1.18 s on one
// thread, 0.69 s on two (0.20 and 0.15 s without this step), and this
// step 1 + threads bytes per voxel while it runs.
constexpr int kHullReach = 2;
// Step 2c: the scan meets its probe's face when at least kProbeShare of the
// beam lines with data start within kProbeRows samples of it.
constexpr std::uint32_t kProbeRows = 3;
constexpr double kProbeShare = 0.05;

// `zero`: 1 where the sample is exactly 0 (scanned_mask's step 1).
std::vector<std::uint8_t> between_data(const Dims3& d, const std::vector<std::uint8_t>& zero, int threads) {
  const std::size_t n = zero.size();
  const long nx = long(d[0]), ny = long(d[1]), nz = long(d[2]);
  std::vector<std::array<long, 3>> dirs;
  const long R = kHullReach;
  for (long dz = 0; dz <= R; ++dz)
    for (long dy = -R; dy <= R; ++dy)
      for (long dx = -R; dx <= R; ++dx) {
        // One of each pair +-dir: dz > 0, or dz = 0 and dy > 0, or dz = dy = 0 and dx > 0.
        if (!(dz > 0 || (dz == 0 && (dy > 0 || (dy == 0 && dx > 0))))) continue;
        if (std::gcd(std::gcd(std::labs(dx), std::labs(dy)), dz) != 1) continue;  // (2, 0, 2) is (1, 0, 1)
        dirs.push_back({dx, dy, dz});
      }
  // One pass along (dx, dy, dz) over `flag`: `after` false sets bit 0 from
  // p - dir (and clears bit 1); true sets bit 1, and bit 2 where both are.
  const auto pass = [&](std::uint8_t* flag, long dx, long dy, long dz, bool after) {
    const long off = dx + nx * (dy + ny * dz);
    const long x_lo = std::max(0L, dx), x_hi = std::min(nx, nx + dx);  // x - dx inside the row
    for (long zi = 0; zi < nz; ++zi) {
      const long z = dz >= 0 ? zi : nz - 1 - zi;
      const bool z_in = z - dz >= 0 && z - dz < nz;
      for (long yi = 0; yi < ny; ++yi) {
        const long y = dy >= 0 ? yi : ny - 1 - yi;
        const bool row_in = z_in && y - dy >= 0 && y - dy < ny;
        std::uint8_t* f = flag + nx * (y + ny * z);
        const std::uint8_t* z0 = zero.data() + nx * (y + ny * z);
        if (!row_in) {
          if (!after)
            for (long x = 0; x < nx; ++x) f[x] &= 4;
          continue;
        }
        if (!after) {
          for (long x = 0; x < x_lo; ++x) f[x] &= 4;
          for (long x = x_hi; x < nx; ++x) f[x] &= 4;
        }
        // The voxels whose p - dir lies in the volume, p - dir first.
        const auto row = [&](auto&& visit) {
          if (dx >= 0)
            for (long x = x_lo; x < x_hi; ++x) visit(x);
          else
            for (long x = x_hi - 1; x >= x_lo; --x) visit(x);
        };
        if (!after)
          row([&](long x) { f[x] = std::uint8_t((f[x] & 4) | ((f[x - off] | (z0[x - off] ^ 1)) & 1)); });
        else
          row([&](long x) {
            const std::uint8_t a = std::uint8_t(((f[x - off] >> 1) | (z0[x - off] ^ 1)) & 1);
            f[x] = std::uint8_t(f[x] | (a << 1) | ((a & f[x]) << 2));
          });
      }
    }
  };
  const int parts = range_count(dirs.size(), threads);
  std::vector<std::vector<std::uint8_t>> flags(static_cast<std::size_t>(parts));
  parallel_ranges_indexed(dirs.size(), threads, [&](int k, std::size_t j0, std::size_t j1) {
    std::vector<std::uint8_t>& flag = flags[std::size_t(k)];
    flag.assign(n, 0);
    for (std::size_t j = j0; j < j1; ++j) {
      const auto [dx, dy, dz] = dirs[j];
      pass(flag.data(), dx, dy, dz, false);
      pass(flag.data(), -dx, -dy, -dz, true);
    }
  });
  std::vector<std::uint8_t> inside(n, 0);
  for (const auto& flag : flags)
    parallel_ranges(n, threads, [&](std::size_t i0, std::size_t i1) {
      for (std::size_t i = i0; i < i1; ++i) inside[i] = std::uint8_t(inside[i] | (flag[i] >> 2));
    });
  return inside;
}

}  // namespace

void mask_detail::cube_filter(std::vector<std::uint8_t>& a, const Dims3& d, int r, bool erode, int threads) {
  for (int axis = 0; axis < 3; ++axis) filter_axis(a, d, axis, r, erode, threads);
}

namespace {

// The 4-connected pieces of the cells of a w x h plane (cell p at
// (p % w, p / w)) for which in(p) holds, in the order of their first cell:
// each piece's cells go into `piece` (in the fill's order), then visit() is
// called.
template <class In, class Visit>
void plane_pieces(std::size_t w, std::size_t h, const In& in, std::vector<std::size_t>& piece, const Visit& visit) {
  std::vector<std::uint8_t> seen(w * h, 0);
  std::vector<std::size_t> todo;
  for (std::size_t s = 0; s < w * h; ++s) {
    if (seen[s] || !in(s)) continue;
    seen[s] = 1, todo.assign(1, s), piece.clear();
    while (!todo.empty()) {
      const std::size_t p = todo.back();
      todo.pop_back();
      piece.push_back(p);
      const std::size_t pa = p % w, pb = p / w;
      const std::size_t nb[4] = {pa > 0 ? p - 1 : p, pa + 1 < w ? p + 1 : p, pb > 0 ? p - w : p,
                                 pb + 1 < h ? p + w : p};
      for (const std::size_t q : nb)
        if (!seen[q] && in(q)) seen[q] = 1, todo.push_back(q);
    }
    visit();
  }
}

// Step 3c (MaskParams, host/mask.hpp): the solid zeros on the volume's two
// faces across the beam, a layer too thin for step 1's cube, in 4-connected
// pieces of at least min_piece voxels on the face: unscanned (mask 0).
// Returns how many it took. The beam's axis is looked for only when some
// face holds such a piece (beam_axis_of reads the volume).
std::size_t take_face_layers(const Volume& v, const std::vector<std::uint8_t>& zero, int solid, double min_fraction,
                             int threads, std::vector<std::uint8_t>& mask) {
  const Dims3& d = v.dims;
  const std::size_t stride[3] = {1, d[0], d[0] * d[1]};
  // The pieces on face `side` of `axis` (index lists, face-plane order).
  const auto pieces = [&](int axis, std::size_t side) {
    const int a0 = axis == 0 ? 1 : 0, a1 = axis == 2 ? 1 : 2;
    const std::size_t w = d[a0], h = d[a1], at = side == 0 ? 0 : d[axis] - 1;
    const auto index = [&](std::size_t p) { return (p % w) * stride[a0] + (p / w) * stride[a1] + at * stride[axis]; };
    std::vector<std::size_t> taken;
    const std::size_t square = std::size_t(2 * solid + 1) * std::size_t(2 * solid + 1);
    if (w < std::size_t(2 * solid + 1) || h < std::size_t(2 * solid + 1)) return taken;
    std::vector<std::uint8_t> plane(w * h);
    std::size_t count = 0;
    for (std::size_t p = 0; p < w * h; ++p) count += plane[p] = zero[index(p)];
    if (count < square) return taken;
    const Dims3 pd{w, h, 1};
    mask_detail::cube_filter(plane, pd, solid, true, threads);  // the square of step 1's cube
    mask_detail::cube_filter(plane, pd, solid, false, threads);
    const std::size_t min_piece =
        std::max(square, std::size_t(std::ceil(min_fraction * double(w) * double(h))));
    std::vector<std::size_t> piece;
    plane_pieces(w, h, [&](std::size_t p) { return plane[p] != 0; }, piece, [&] {
      if (piece.size() < min_piece) return;
      // A layer, not dark fluid at the log-compression floor reaching the
      // face: on at least 90 % of its lines into the volume, the zeros end
      // and the next 2 solid + 1 samples are all data (fluid's zeros, 25-35 %
      // of its samples, rarely leave five in a row).
      std::size_t layered = 0;
      const std::ptrdiff_t step = side == 0 ? std::ptrdiff_t(stride[axis]) : -std::ptrdiff_t(stride[axis]);
      for (const std::size_t p : piece) {
        std::size_t k = 0, i = index(p);
        while (k < d[axis] && zero[i]) ++k, i = std::size_t(std::ptrdiff_t(i) + (k < d[axis] ? step : 0));
        std::size_t data = 0;
        for (int m = 0; m < 2 * solid + 1 && k < d[axis] && !zero[i]; ++m) {
          ++data, ++k;
          if (k < d[axis]) i = std::size_t(std::ptrdiff_t(i) + step);
        }
        layered += data == std::size_t(2 * solid + 1);
      }
      if (double(layered) >= 0.9 * double(piece.size()))
        for (const std::size_t p : piece) taken.push_back(index(p));
    });
    return taken;
  };
  // Each face's pieces, looked for until one holds some; the beam's faces
  // reuse what was found.
  std::array<std::optional<std::vector<std::size_t>>, 6> found;
  const auto pieces_on = [&](int axis, std::size_t side) -> const std::vector<std::size_t>& {
    auto& f = found[2 * std::size_t(axis) + side];
    if (!f) f = pieces(axis, side);
    return *f;
  };
  bool any = false;
  for (int axis = 0; axis < 3 && !any; ++axis)
    for (std::size_t side = 0; side < (d[axis] > 1 ? 2u : 1u) && !any; ++side) any = !pieces_on(axis, side).empty();
  if (!any) return 0;
  const int axis = beam_axis_of(v, nullptr, threads, std::max<std::size_t>(1, d[2] / 64));
  std::size_t took = 0;
  for (std::size_t side = 0; side < (d[axis] > 1 ? 2u : 1u); ++side)
    for (const std::size_t i : pieces_on(axis, side)) took += mask[i] != 0, mask[i] = 0;
  return took;
}

}  // namespace

std::vector<std::uint8_t> scanned_mask(const Volume& v, const MaskParams& params, MaskReport* report) {
  const Dims3& d = v.dims;
  const std::size_t n = v.voxels();
  if (v.data.size() != n) throw std::invalid_argument("scanned_mask: volume data size differs from its dims");
  if (!(params.min_fraction >= 0) || params.solid < 0 || params.grow < 0)
    throw InputError("mask: min_fraction, solid and grow must be >= 0");
  const auto min_size = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(params.min_fraction * double(n))));
  MaskReport rep;

  const int threads = host_threads(params.threads);
  // 1. The exact zeros, opened by the cube.
  std::vector<std::uint8_t> zero(n);
  {
    // Counted while set (a serial count after it read the 16 MB again).
    std::vector<std::size_t> pzeros(std::size_t(range_count(n, threads)), 0);
    parallel_ranges_indexed(n, threads, [&](int k, std::size_t i0, std::size_t i1) {
      std::uint8_t* const z = zero.data();
      const float* const data = v.data.data();
      std::size_t c = 0;
      for (std::size_t i = i0; i < i1; ++i) z[i] = data[i] == 0.0f ? 1 : 0, c += data[i] == 0.0f;
      pzeros[std::size_t(k)] = c;
    });
    rep.zeros = 0;
    for (const std::size_t c : pzeros) rep.zeros += c;
  }
  // Every step below starts from a solid zero region that touches one of
  // the volume's faces (the flood fill's seeds; the rest waits on an
  // unscanned region): without one, the mask is all scanned. (The cube's
  // opening of no zeros, and the flood fill's state over 16 MB with no seed,
  // took 0.1 s at 256^3.)
  const auto ones = [&] {
    std::vector<std::uint8_t> mask(n);
    parallel_ranges(n, threads, [&](std::size_t i0, std::size_t i1) {
      std::fill(mask.data() + i0, mask.data() + i1, std::uint8_t{1});
    });
    return mask;
  };
  const auto all_scanned = [&] {
    if (report) *report = rep;
    return ones();
  };
  if (rep.zeros == 0) return all_scanned();
  std::vector<std::uint8_t> solid = zero;
  if (params.solid > 0) {
    mask_detail::cube_filter(solid, d, params.solid, true, threads);
    mask_detail::cube_filter(solid, d, params.solid, false, threads);
  }
  {
    bool seed = false;
    for (std::size_t z = 0; z < d[2] && !seed; ++z)
      for (std::size_t y = 0; y < d[1] && !seed; ++y) {
        const std::uint8_t* const row = solid.data() + v.index(0, y, z);
        if (z == 0 || y == 0 || z + 1 == d[2] || y + 1 == d[1])
          seed = std::any_of(row, row + d[0], [](std::uint8_t b) { return b != 0; });
        else
          seed = row[0] != 0 || row[d[0] - 1] != 0;
      }
    if (!seed) {
      // No region for step 2: step 3c's thin layers on the faces, then step 4.
      std::vector<std::uint8_t> mask = ones();
      if (params.solid > 0) rep.face_layers = take_face_layers(v, zero, params.solid, params.min_fraction, threads, mask);
      rep.zero_fill = rep.face_layers;
      if (rep.face_layers) grow_unscanned(mask, d, params.grow, nullptr, threads);
      rep.unscanned = rep.face_layers ? count_unscanned(mask) : 0;
      if (report) *report = rep;
      return mask;
    }
  }

  // 2. Flood fill of the solid regions from the volume's faces. state: 0 not
  // visited, 1 visited (region too small or being measured), 2 unscanned.
  enum : std::uint8_t { kFree = 0, kSeen = 1, kUnscanned = 2, kFluid = 3 };  // kFluid: 2c gave it back to the scan
  std::vector<std::uint8_t> state(n, kFree);
  std::vector<std::size_t> stack, region;
  // Marks the solid free region around seed (its six-connected component)
  // as seen; its voxels in `region`. A run along x at a time: a seed taken
  // from the stack extends both ways over the free solid voxels of its row,
  // and the four rows beside the run (y and z one off) are scanned under it,
  // a seed pushed for each stretch of free solid voxels there (marked seen
  // when pushed: a run stops at it, and it starts its own). The same region
  // as a fill voxel by voxel (which took 0.07 s for a fan's fill at 256^3).
  const std::size_t nx = d[0], nxy = d[0] * d[1];
  auto fill = [&](std::size_t seed) {
    stack.clear(), region.clear();
    const auto open = [&](std::size_t j) { return state[j] == kFree && solid[j]; };
    stack.push_back(seed);
    state[seed] = kSeen;
    while (!stack.empty()) {
      const std::size_t i = stack.back();
      stack.pop_back();
      const std::size_t row = i - i % nx;
      std::size_t x0 = i - row, x1 = x0 + 1;  // the run [x0, x1)
      while (x0 > 0 && open(row + x0 - 1)) state[row + --x0] = kSeen;
      while (x1 < nx && open(row + x1)) state[row + x1++] = kSeen;
      for (std::size_t x = x0; x < x1; ++x) region.push_back(row + x);
      const std::size_t y = (row / nx) % d[1], z = row / nxy;
      const auto scan = [&](std::size_t beside) {
        bool in_stretch = false;
        for (std::size_t x = x0; x < x1; ++x) {
          const bool o = open(beside + x);
          if (o && !in_stretch) state[beside + x] = kSeen, stack.push_back(beside + x);
          in_stretch = o;
        }
      };
      if (y > 0) scan(row - nx);
      if (y + 1 < d[1]) scan(row + nx);
      if (z > 0) scan(row - nxy);
      if (z + 1 < d[2]) scan(row + nxy);
    }
    return region.size();
  };
  for (std::size_t z = 0; z < d[2]; ++z)
    for (std::size_t y = 0; y < d[1]; ++y)
      for (std::size_t x = 0; x < d[0]; ++x) {
        const bool face = x == 0 || y == 0 || z == 0 || x + 1 == d[0] || y + 1 == d[1] || z + 1 == d[2];
        if (!face) {
          x = d[0] - 2;  // jump over the interior of the row to its last voxel
          continue;
        }
        const std::size_t i = v.index(x, y, z);
        if (state[i] != kFree || !solid[i]) continue;
        ++rep.regions;
        if (fill(i) >= min_size) {
          ++rep.unscanned_regions;
          for (const std::size_t j : region) state[j] = kUnscanned;  // (a second flood fill before)
        }
      }
  std::vector<std::uint8_t> mask(n);
  const auto mask_from_state = [&] {
    parallel_ranges(n, threads, [&](std::size_t i0, std::size_t i1) {
      for (std::size_t i = i0; i < i1; ++i) mask[i] = state[i] == kUnscanned ? 0 : 1;
    });
  };
  mask_from_state();
  // 2b. Dark fluid at the log-compression floor is exact zeros too. An
  // unswept region lies beside or beyond the scan; a zero region with data
  // on both sides of it along the beam lies inside the scan (fluid between
  // echoes), and a scan reaches the faces of its own bounding box. Unless
  // both hold, there is no unscanned region.
  if (rep.unscanned_regions > 0) {
    const int axis = std::clamp(params.beam_axis, 0, 2);
    const std::size_t len = d[axis];
    // Per beam line: the first and last nonzero sample. With s the beam
    // axis's stride, voxel i lies on line (i % s) + (i / (s len)) s at
    // position (i / s) % len; walked by planes, both come without a division
    // (three integer divisions per voxel: the mask took 0.37-0.39 s at 256^3
    // before, 0.33 s after).
    std::vector<std::uint32_t> first(n / len, std::uint32_t(len)), last(n / len, 0);
    const std::size_t nx = d[0], ny = d[1];
    // Calls f(i, line, pos) for the voxels of planes [z0, z1) in memory order.
    auto each_voxel = [&](std::size_t z0, std::size_t z1, auto&& f) {
      for (std::size_t z = z0; z < z1; ++z)
        for (std::size_t y = 0; y < ny; ++y) {
          const std::size_t row = (z * ny + y) * nx;
          for (std::size_t x = 0; x < nx; ++x) {
            const std::size_t line = axis == 0 ? y + ny * z : axis == 1 ? x + nx * z : x + nx * y;
            const std::size_t pos = axis == 0 ? x : axis == 1 ? y : z;
            f(row + x, line, std::uint32_t(pos));
          }
        }
    };
    {
      // Per range of planes its own first/last, merged (min and max: exact).
      const int parts = range_count(d[2], threads);
      const auto nparts = static_cast<std::size_t>(parts);
      std::vector<std::vector<std::uint32_t>> pf(nparts), pl(nparts);
      parallel_ranges_indexed(d[2], threads, [&](int k, std::size_t z0, std::size_t z1) {
        std::vector<std::uint32_t>& f = pf[std::size_t(k)];
        std::vector<std::uint32_t>& l_ = pl[std::size_t(k)];
        f.assign(n / len, std::uint32_t(len)), l_.assign(n / len, 0);
        if (axis == 2) {
          // The beam along z: a plane's rows are lines x + nx y at depth z,
          // the planes in increasing z (the first depth with data is the
          // first one set, the last the latest): row loops that vectorise.
          for (std::size_t z = z0; z < z1; ++z)
            first_last_rows(v.data.data() + z * nx * ny, nx * ny, std::uint32_t(z), std::uint32_t(len), f.data(),
                            l_.data());
          return;
        }
        each_voxel(z0, z1, [&](std::size_t i, std::size_t l, std::uint32_t pos) {
          if (v.data[i] != 0.0f) f[l] = std::min(f[l], pos), l_[l] = std::max(l_[l], pos);
        });
      });
      for (int k = 0; k < parts; ++k)
        for (std::size_t l = 0; l < first.size(); ++l)
          first[l] = std::min(first[l], pf[std::size_t(k)][l]), last[l] = std::max(last[l], pl[std::size_t(k)][l]);
    }
    std::size_t enclosed = 0, total = 0;
    {
      const int parts = range_count(d[2], threads);
      const auto nparts = static_cast<std::size_t>(parts);
      std::vector<std::size_t> pe(nparts, 0), pt(nparts, 0);
      parallel_ranges_indexed(d[2], threads, [&](int k, std::size_t z0, std::size_t z1) {
        // Counted in locals (in the shared vectors per voxel, the threads'
        // cache lines ping-ponged).
        std::size_t e = 0, t = 0;
        each_voxel(z0, z1, [&](std::size_t i, std::size_t l, std::uint32_t pos) {
          if (state[i] != kUnscanned) return;
          ++t;
          e += first[l] < pos && pos < last[l];
        });
        pe[std::size_t(k)] = e, pt[std::size_t(k)] = t;
      });
      for (int k = 0; k < parts; ++k) enclosed += pe[std::size_t(k)], total += pt[std::size_t(k)];
    }
    rep.enclosed_share = total ? double(enclosed) / double(total) : 0.0;
    // Faces of the volume with scanned voxels on at least 2 % of them.
    int faces = 0;
    for (int a = 0; a < 3; ++a)
      for (int side = 0; side < 2; ++side) {
        const std::size_t u = (a + 1) % 3, w = (a + 2) % 3;
        std::size_t scanned = 0;
        for (std::size_t j = 0; j < d[w]; ++j)
          for (std::size_t k = 0; k < d[u]; ++k) {
            std::size_t c[3];
            c[a] = side ? d[a] - 1 : 0, c[u] = k, c[w] = j;
            scanned += state[v.index(c[0], c[1], c[2])] != kUnscanned;
          }
        faces += double(scanned) >= 0.02 * double(d[u] * d[w]);
      }
    rep.faces_with_data = faces;
    // 2c. The part of a fill that is mostly dark fluid that lies outside the
    // data. On a fan whose acoustic shadows (or dark fluid) clip to exact
    // zeros, the shadows join the unswept wedges and arc into one region,
    // most of it between echoes (randomised spine 601: 8.7 %), and step 2b
    // gave up on all of it, so the fan's edge was drawn as a sheet (8 of the
    // 72 training cases, 8 of 60 diagnosis cases). A scan's sector is convex
    // (a linear probe's box, a curvilinear probe's fan), and nothing beyond
    // it holds data: kept are the fill's voxels with no nonzero sample on
    // one side or the other along each of the 49 lines through them
    // (between_data); the rest (shadow and fluid between echoes, in any
    // of those directions) is scanned.
    //
    // 2b'. Fluid seen two ways. A fill with fewer zeros between echoes along
    // the beam than max_enclosed is still dark fluid when more than
    // fluid_enclosed of it is, and more than fluid_inside of it also lies
    // inside the data's hull: an object in a void of exact zeros with nothing
    // (or little) above it (fresh randomised faces 915, 928 and 1116: 1.2-2.9 %
    // of the fill between echoes, 8.4-20 % inside the hull; the rule as
    // unswept took the fluid over the face and the face's front with it, and
    // 915 drew no face at all). A freehand sweep's gaps between frames lie
    // inside its hull too (IMLiF: 16 %), but they span the frame's whole depth,
    // with no echo above or below (0.0 % between echoes); on the PLUS
    // reconstructions at most 1.7 % of the fill lies between echoes and at
    // most 2.9 % inside the hull where it does.
    bool fluid = rep.enclosed_share > params.max_enclosed;
    std::vector<std::uint8_t> inside;
    if (faces >= params.min_faces && (fluid || rep.enclosed_share > params.fluid_enclosed)) {
      inside = between_data(d, zero, threads);
      std::size_t in_hull = 0;
      for (std::size_t i = 0; i < n; ++i) in_hull += state[i] == kUnscanned && inside[i];
      rep.inside_share = total ? double(in_hull) / double(total) : 0.0;
      if (!fluid && rep.inside_share > params.fluid_inside) fluid = rep.fluid_inside = true;
    }
    if (faces >= params.min_faces && fluid) {
      // Before the first sample of a beam line lies the beam's own path,
      // unless the scan meets its probe's face: then the lines that start
      // deeper begin at the side of a fan (its wedges). Where no line's data
      // starts at that face (fluid under the probe, no skin), a run before
      // the first sample is fluid in front of an object and is scanned
      // (randomised face 403: the fluid over the face, and the face's front
      // with it, masked).
      std::size_t at_face = 0, with_data = 0;
      for (std::size_t l = 0; l < first.size(); ++l)
        if (first[l] < len) ++with_data, at_face += first[l] < kProbeRows;
      const bool probe_seen = double(at_face) >= kProbeShare * double(with_data);
      // After 2b' (few zeros between echoes) the zeros beyond a line's last
      // sample stay unscanned even inside the hull: a shadow that runs out
      // to the sector's end, or what lies under an object with nothing
      // below it, holds no echo to classify, and the rim then takes the
      // shadow's walls at the sector's end as 2b did (fresh randomised spine
      // 915: F1 on the visible surface 0.766 before 2b', 0.643 with those
      // zeros scanned, 0.731 unscanned; spine 1128: 0.565, 0.604, 0.640).
      std::size_t kept = 0;
      each_voxel(0, d[2], [&](std::size_t i, std::size_t l, std::uint32_t pos) {
        if (state[i] != kUnscanned) return;
        const bool beyond = rep.fluid_inside && pos > last[l];
        if ((inside[i] && !beyond) || (!probe_seen && pos < first[l] && first[l] < len)) state[i] = kFluid;
        else ++kept;
      });
      rep.outside_share = total ? double(kept) / double(total) : 0.0;
      if (kept >= min_size) {
        rep.outside = true;
        mask_from_state();
      }
    }
    if (!rep.outside && (fluid || faces < params.min_faces)) {
      rep.rejected = true;
      rep.unscanned_regions = 0;
      std::fill(mask.begin(), mask.end(), std::uint8_t{1});
    }
  }

  // 3. The ragged edge of the fill: zeros within `solid` steps through zeros.
  // Not after 2c: there the fill can border an object in fluid, and the
  // zeros between them stay the fluid they are (randomised face 823, F1 on
  // the visible surface 0.688 with this step, 0.736 without; measured with
  // 2c's first 13 lines).
  if (rep.unscanned_regions > 0 && !rep.outside) grow_unscanned(mask, d, params.solid, &zero, threads);
  // 3b. The thin end of the fill along the volume's faces: where a fan's
  // bottom arc meets the face across the beam, the zeros between the arc and the
  // face thin to one voxel and no cube fits, so step 1 left them, and the
  // data's last samples above them were drawn as a sheet (randomised spine
  // 305: 11 600 of its 18 400 drawn voxels). The zeros on a face that are
  // solid in the face's plane (a square of 2 solid + 1 fits, as the cube of
  // step 1 in 3-D: dark fluid's zeros on a face fill no such square) and
  // connected, on the faces, to the unscanned region join it. Only the two
  // faces across the beam (the data's own axis, beam_axis_of): there the
  // data ends at the scan's depth. On a face along the beam the zeros lie
  // beside the sweep's edge, whose data is the object's (the IMLiF scan is
  // 23 slices of 0.2 mm across its beam, its reflector reaching the slices
  // next to its faces: taking those faces' zeros and their rim took 1.2 of
  // its 4.6 mm, and the plane's opacity with it). After 2b' not the zeros
  // that 2c gave back to the scan: on the probe's face they are the fluid
  // over an object, and the rim would grow from them into it.
  if (rep.unscanned_regions > 0 && params.solid > 0) {
    // The beam from every 4th z-plane of a large volume (a global statistic
    // of the speckle's grain: a quarter of the planes tell the same).
    const int axis = beam_axis_of(v, nullptr, threads, std::max<std::size_t>(1, d[2] / 64));
    const int a0 = axis == 0 ? 1 : 0, a1 = axis == 2 ? 1 : 2;  // the face's two axes
    const std::size_t stride[3] = {1, d[0], d[0] * d[1]};
    const std::size_t w = d[a0], h = d[a1];
    for (std::size_t side = 0; side < (d[axis] > 1 ? 2u : 1u); ++side) {
      const std::size_t at = side == 0 ? 0 : d[axis] - 1;
      const auto index = [&](std::size_t p) { return (p % w) * stride[a0] + (p / w) * stride[a1] + at * stride[axis]; };
      std::vector<std::uint8_t> plane(w * h);  // the face's zeros, opened by the square
      for (std::size_t p = 0; p < w * h; ++p) plane[p] = zero[index(p)];
      const Dims3 pd{w, h, 1};
      mask_detail::cube_filter(plane, pd, params.solid, true, threads);  // one plane: the square of step 1's cube
      mask_detail::cube_filter(plane, pd, params.solid, false, threads);
      // Flood the face from its unscanned voxels through those zeros (the
      // face's plane holds the whole path: a voxel off the face is no zero
      // of it).
      std::vector<std::size_t> todo;
      for (std::size_t p = 0; p < w * h; ++p)
        if (mask[index(p)] == 0) todo.push_back(p);
      while (!todo.empty()) {
        const std::size_t p = todo.back();
        todo.pop_back();
        const std::size_t pa = p % w, pb = p / w;
        const std::size_t nb[4] = {pa > 0 ? p - 1 : p, pa + 1 < w ? p + 1 : p, pb > 0 ? p - w : p, pb + 1 < h ? p + w : p};
        for (std::size_t q : nb)
          if (q != p && plane[q] && mask[index(q)] != 0 && !(rep.fluid_inside && state[index(q)] == kFluid)) {
            mask[index(q)] = 0;
            todo.push_back(q);
          }
      }
    }
  }
  // 3c. The thin layer of zeros that a scan leaves on a face across the beam
  // when it ends a fraction of a voxel short of it (or starts one in), with
  // no unscanned region behind it that step 2 could take (host/mask.hpp).
  if (rep.unscanned_regions == 0 && !rep.rejected && params.solid > 0)
    rep.face_layers = take_face_layers(v, zero, params.solid, params.min_fraction, threads, mask);
  rep.zero_fill = count_unscanned(mask);
  // 4. The partial-volume rim. Not after 2c: a rim there would be taken
  // from that object (randomised faces 102 and 125: F1 on the visible
  // surface 0.888 and 0.724 with it, 0.965 and 0.782 without, with 2c's
  // first 13 lines; the reconstruction's dim rim is a freehand sweep's,
  // which 2b accepts). After 2b' it grows: there few zeros lie between
  // echoes, most of what 2c keeps is beyond a sweep's edge, and the fluid
  // over the object is scanned, so the rim takes no object's front (fresh
  // randomised spines 915 and 917, with all of 2c's inside zeros scanned:
  // 0.604 and 0.687 without it, 0.643 and 0.812 with it, 0.766 and 0.840
  // before 2b').
  if ((rep.unscanned_regions > 0 && (!rep.outside || rep.fluid_inside)) || rep.face_layers > 0)
    grow_unscanned(mask, d, params.grow, nullptr, threads);
  rep.unscanned = count_unscanned(mask);
  if (report) *report = rep;
  return mask;
}

void grow_unscanned(std::vector<std::uint8_t>& mask, const Dims3& d, int voxels, const std::vector<std::uint8_t>* within,
                    int threads) {
  const std::size_t n = d[0] * d[1] * d[2];
  if (mask.size() != n || (within && within->size() != n))
    throw std::invalid_argument("grow_unscanned: mask size differs from dims");
  if (voxels <= 0) return;
  auto may_take = [&](std::size_t j) { return mask[j] != 0 && (!within || (*within)[j] != 0); };
  // Frontier: unscanned voxels with a face neighbour that may be taken; each
  // layer takes the neighbours of the frontier.
  std::vector<std::size_t> frontier = frontier_of(mask, d, host_threads(threads), may_take), next;
  for (int layer = 0; layer < voxels && !frontier.empty(); ++layer) {
    next.clear();
    for (std::size_t i : frontier)
      for_face_neighbours(d, i, [&](std::size_t j) {
        if (may_take(j)) {
          mask[j] = 0;
          next.push_back(j);
        }
      });
    frontier.swap(next);
  }
}

Volume fill_unscanned(const Volume& v, const std::vector<std::uint8_t>& mask, int depth, int threads) {
  Volume out = v;
  fill_unscanned_in_place(out, mask, depth, threads);
  return out;
}

void fill_unscanned_in_place(Volume& out, const std::vector<std::uint8_t>& mask, int depth, int threads) {
  const Dims3& d = out.dims;
  const std::size_t n = out.voxels();
  if (mask.size() != n) throw std::invalid_argument("fill_unscanned: mask size differs from the volume");
  // done: scanned or filled in an earlier layer.
  std::vector<std::uint8_t> done(mask);
  threads = host_threads(threads);
  std::vector<std::size_t> layer = frontier_of(done, d, threads, [&](std::size_t j) { return done[j] != 0; }), next;
  std::vector<float> value(layer.size());
  // Threads only for a layer large enough to pay for starting them.
  const auto parts_for = [threads](std::size_t items) { return items >= 65536 ? threads : 1; };
  for (int k = 0; !layer.empty() && (depth <= 0 || k < depth); ++k) {
    // Values first, from earlier layers only, so the order within a layer
    // does not matter (deterministic).
    value.resize(layer.size());
    const int parts = parts_for(layer.size());
    parallel_ranges(layer.size(), parts, [&](std::size_t a0, std::size_t a1) {
      for (std::size_t a = a0; a < a1; ++a) {
        double s = 0;
        int c = 0;
        for_face_neighbours(d, layer[a], [&](std::size_t j) {
          if (done[j]) s += out.data[j], ++c;
        });
        value[a] = static_cast<float>(s / c);
      }
    });
    parallel_ranges(layer.size(), parts, [&](std::size_t a0, std::size_t a1) {
      for (std::size_t a = a0; a < a1; ++a) out.data[layer[a]] = value[a], done[layer[a]] = 1;
    });
    // The next layer: the not yet done face neighbours, each queued once (2)
    // by whichever range finds it first. Its order may differ from run to
    // run; its values do not (they come from earlier layers only).
    std::vector<std::vector<std::size_t>> found(std::size_t(range_count(layer.size(), parts)));
    parallel_ranges_indexed(layer.size(), parts, [&](int k, std::size_t a0, std::size_t a1) {
      std::vector<std::size_t>& f = found[std::size_t(k)];
      for (std::size_t a = a0; a < a1; ++a)
        for_face_neighbours(d, layer[a], [&](std::size_t j) {
          std::uint8_t expected = 0;
          if (__atomic_load_n(&done[j], __ATOMIC_RELAXED) == 0 &&
              __atomic_compare_exchange_n(&done[j], &expected, std::uint8_t{2}, false, __ATOMIC_RELAXED,
                                          __ATOMIC_RELAXED))
            f.push_back(j);
        });
    });
    next.clear();
    for (const auto& f : found) next.insert(next.end(), f.begin(), f.end());
    parallel_ranges(next.size(), parts_for(next.size()), [&](std::size_t a0, std::size_t a1) {
      for (std::size_t a = a0; a < a1; ++a) done[next[a]] = 0;
    });
    layer.swap(next);
  }
}

std::vector<std::uint8_t> read_mask(const std::string& path, const Dims3& dims) {
  const Volume m = read_volume(path);
  if (m.dims != dims)
    throw input_error(path, "mask has dims " + dims_text(m.dims) + ", the volume " + dims_text(dims));
  std::vector<std::uint8_t> mask(m.voxels());
  for (std::size_t i = 0; i < mask.size(); ++i) mask[i] = m.data[i] != 0.0f ? 1 : 0;
  return mask;
}

std::size_t count_unscanned(const std::vector<std::uint8_t>& mask) {
  return static_cast<std::size_t>(std::count(mask.begin(), mask.end(), std::uint8_t{0}));
}

std::size_t hold_cut_remnants(std::vector<std::uint8_t>& mask, const Dims3& dims, int axis,
                              const std::vector<std::size_t>& edges, std::size_t reach) {
  const std::size_t n = dims[0] * dims[1] * dims[2];
  if (mask.size() != n) throw std::invalid_argument("hold_cut_remnants: mask size differs from the volume");
  if (axis < 0 || axis > 2) throw std::invalid_argument("hold_cut_remnants: beam axis must be 0, 1 or 2");
  const std::size_t stride = axis == 0 ? 1 : axis == 1 ? dims[0] : dims[0] * dims[1];
  // Decide every line on the mask as it came (the holds of one edge do not
  // make another's reach), then hold.
  std::vector<std::pair<std::size_t, std::size_t>> runs;  // edge, the last voxel walked (nearest the cut)
  for (std::size_t i : edges) {
    if (i >= n || !mask[i]) continue;
    std::size_t j = i, steps = 0;
    while (steps < reach && (j / stride) % dims[std::size_t(axis)] > 0 && mask[j - stride]) j -= stride, ++steps;
    if ((j / stride) % dims[std::size_t(axis)] > 0 && !mask[j - stride]) runs.emplace_back(i, j);
  }
  std::size_t held = 0;
  for (const auto& [i, j] : runs)
    for (std::size_t q = i;; q -= stride) {
      held += mask[q] != 0;
      mask[q] = 0;
      if (q == j) break;
    }
  return held;
}

namespace {

// The beam lines of a grid along `axis`: line l = u + nu w over the two
// lateral axes (the first fastest), its voxels `len` steps of `stride` from
// start(l).
struct BeamLines {
  std::size_t stride, su, sw, nu, nw, len;
  BeamLines(const Dims3& d, std::size_t a)
      : stride(a == 0 ? 1 : a == 1 ? d[0] : d[0] * d[1]),
        su(a == 0 ? d[0] : 1),
        sw(a == 2 ? d[0] : d[0] * d[1]),
        nu(d[a == 0 ? 1 : 0]),
        nw(d[a == 2 ? 1 : 2]),
        len(d[a]) {}
  std::size_t count() const { return nu * nw; }
  std::size_t start(std::size_t l) const { return (l % nu) * su + (l / nu) * sw; }
};

// Whether beam line l (lines ordered as BeamLines orders them: nu across,
// then nw rows of those) lies under the probe: its skin line (skin[l], the
// index along the beam of its first scanned sample; < 0: none) deepens by
// at most 1 mm per mm across the beam to each 4-neighbour that has one.
// Not a line that enters a sector down its side (a volume probe's fan cut
// by the top face), whose first sample is the sector's edge, no skin.
// h_along: the spacing along the beam; hu, hw: across it.
bool under_probe(const std::vector<long>& skin, std::size_t l, std::size_t nu, std::size_t nw, double h_along,
                 double hu, double hw) {
  const std::size_t a = l % nu, b = l / nu;
  const auto slope = [&](std::size_t l0, std::size_t l1, double h) {
    if (skin[l0] < 0 || skin[l1] < 0) return 0.0;
    return std::fabs(double(skin[l1] - skin[l0])) * h_along / h;
  };
  double s = 0;
  if (a > 0) s = std::max(s, slope(l - 1, l, hu));
  if (a + 1 < nu) s = std::max(s, slope(l, l + 1, hu));
  if (b > 0) s = std::max(s, slope(l - nu, l, hw));
  if (b + 1 < nw) s = std::max(s, slope(l, l + nu, hw));
  return s <= 1.0;
}

// The skin window's sheets (label 3 of band_underside's window;
// BandSheetParams::skin_mm): the drawn runs (u > threshold) that start in
// it on the lines under the probe (the skin line deepening by at most 1 mm
// per mm across the beam), joined from line to 4-neighbouring line where
// their starts lie within one voxel of the same depth under the skin line.
// A joined set on at least skin_patch of those lines whose starts'
// quartiles lie within flat_mm (or a voxel) follows the skin line, and so
// do the flat sets on skin_piece or more at its median depth (within a
// voxel): each held from above_mm over its runs to margin_mm under them (a
// run cut at the window's end). The same for any order of the lines: the
// sets are the connected components.
void hold_skin_sheets(const Volume& u, const std::vector<std::uint8_t>& window, const BeamLines& lines,
                      double along, double hu, double hw, const BandSheetParams& params,
                      std::vector<std::uint8_t>& scanned, BandSheetReport& rep) {
  struct Run {
    std::size_t line, k0, k1;  // [k0, k1) along the line
    long depth;                // k0 under the line's skin line
  };
  std::vector<Run> runs;
  // Each line's window: from its skin line (top, -1: no window) to end.
  std::vector<std::size_t> first(lines.count() + 1, 0), end(lines.count(), 0);
  std::vector<long> top(lines.count(), -1);
  for (std::size_t l = 0; l < lines.count(); ++l) {
    const std::size_t base = lines.start(l), stride = lines.stride;
    for (std::size_t k = 0; k < lines.len; ++k)
      if (window[base + k * stride] == 3) {
        if (top[l] < 0) top[l] = long(k);
        end[l] = k + 1;
      }
  }
  for (std::size_t l = 0; l < lines.count(); ++l) {
    first[l] = runs.size();
    if (top[l] < 0 || !under_probe(top, l, lines.nu, lines.nw, along, hu, hw)) continue;
    const std::size_t s = std::size_t(top[l]), e = end[l];
    ++rep.skin_lines;
    const std::size_t base = lines.start(l), stride = lines.stride;
    for (std::size_t k = s; k < e;) {
      if (!(u.data[base + k * stride] > params.threshold)) {
        ++k;
        continue;
      }
      std::size_t k1 = k;
      while (k1 < e && u.data[base + k1 * stride] > params.threshold) ++k1;
      runs.push_back({l, k, k1, long(k - s)});
      k = k1;
    }
  }
  first[lines.count()] = runs.size();
  if (runs.empty()) return;
  std::vector<std::size_t> parent(runs.size());
  std::iota(parent.begin(), parent.end(), std::size_t{0});
  const auto root = [&](std::size_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  const auto join = [&](std::size_t l, std::size_t m) {
    for (std::size_t a = first[l]; a < first[l + 1]; ++a)
      for (std::size_t b = first[m]; b < first[m + 1]; ++b)
        if (std::labs(runs[a].depth - runs[b].depth) <= 1) {
          const std::size_t ra = root(a), rb = root(b);
          if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
        }
  };
  for (std::size_t l = 0; l < lines.count(); ++l) {
    if (l % lines.nu + 1 < lines.nu) join(l, l + 1);
    if (l / lines.nu + 1 < lines.nw) join(l, l + lines.nu);
  }
  // The sets: the runs ordered by their root (then by index), each set a
  // stretch [from[j], from[j + 1]) of `order`.
  std::vector<std::size_t> order(runs.size()), from;
  for (std::size_t a = 0; a < runs.size(); ++a) parent[a] = root(a);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return parent[a] < parent[b]; });
  for (std::size_t t = 0; t < order.size(); ++t)
    if (t == 0 || parent[order[t]] != parent[order[t - 1]]) from.push_back(t);
  from.push_back(order.size());
  const std::size_t nsets = from.size() - 1;
  const auto members = [&](std::size_t j) {
    return std::pair<const std::size_t*, const std::size_t*>(order.data() + from[j], order.data() + from[j + 1]);
  };
  const auto above = std::size_t(std::ceil(params.above_mm / along - 1e-9));
  const auto below = std::size_t(std::ceil(params.margin_mm / along - 1e-9));
  std::vector<std::size_t> ls;
  std::vector<long> at;
  std::vector<std::uint8_t> on(lines.count(), 0);  // lines with a sheet held
  // Each set's lines, median depth and whether it is flat; then the sheets
  // (skin_patch of the lines or more), then the pieces of them: smaller flat
  // sets (skin_piece or more) at a sheet's median depth, within a voxel (a
  // layer cut into pieces by the lines where a band was removed).
  struct Set {
    std::size_t lines = 0;
    long depth = 0;
    bool flat = false, held = false;
  };
  std::vector<Set> info(nsets);
  for (std::size_t j = 0; j < nsets; ++j) {
    ls.clear(), at.clear();
    for (auto [a, e] = members(j); a != e; ++a) ls.push_back(runs[*a].line), at.push_back(runs[*a].depth);
    std::sort(ls.begin(), ls.end());
    info[j].lines = std::size_t(std::unique(ls.begin(), ls.end()) - ls.begin());
    std::sort(at.begin(), at.end());
    info[j].depth = at[at.size() / 2];
    info[j].flat = double(at[at.size() * 3 / 4] - at[at.size() / 4]) * along <= std::max(params.flat_mm, along) + 1e-9;
  }
  const auto hold = [&](std::size_t j) {
    info[j].held = true;
    for (auto [a, e] = members(j); a != e; ++a) {
      const Run& r = runs[*a];
      rep.skin_sheet_lines += !on[r.line], on[r.line] = 1;
      const auto t = std::size_t(top[r.line]);
      const std::size_t k0 = r.k0 > t + above ? r.k0 - above : t;
      const std::size_t k1 = std::min(lines.len, r.k1 + below);
      for (std::size_t k = k0; k < k1; ++k) {
        const std::size_t i = lines.start(r.line) + k * lines.stride;
        if (scanned[i]) scanned[i] = 0, ++rep.voxels;
      }
    }
  };
  std::vector<long> depths;
  for (std::size_t j = 0; j < nsets; ++j)
    if (info[j].flat && double(info[j].lines) >= params.skin_patch * double(rep.skin_lines))
      ++rep.skin_sheets, depths.push_back(info[j].depth), hold(j);
  for (std::size_t j = 0; j < nsets; ++j) {
    if (info[j].held || !info[j].flat || double(info[j].lines) < params.skin_piece * double(rep.skin_lines)) continue;
    for (long dd : depths)
      if (std::labs(dd - info[j].depth) <= 1) {
        ++rep.skin_pieces, hold(j);
        break;
      }
  }
}

}  // namespace

std::vector<std::uint8_t> band_underside(const Volume& v, const NearFieldReport& nf,
                                         const std::vector<std::uint8_t>& before,
                                         const std::vector<std::uint8_t>& after, double window_mm,
                                         double deep_mm, double skin_mm) {
  if (!nf.found && !(skin_mm > 0)) return {};
  return band_underside(v.dims, v.spacing[std::size_t(nf.axis)], nf.axis, before, after, window_mm, deep_mm,
                        skin_mm);
}

std::vector<std::uint8_t> band_underside(const Dims3& dims, double spacing_mm, int axis,
                                         const std::vector<std::uint8_t>& before,
                                         const std::vector<std::uint8_t>& after, double window_mm,
                                         double deep_mm, double skin_mm) {
  const std::size_t n = dims[0] * dims[1] * dims[2];
  if (axis < 0 || axis > 2) throw std::invalid_argument("band_underside: beam axis must be 0, 1 or 2");
  if ((!before.empty() && before.size() != n) || (!after.empty() && after.size() != n))
    throw std::invalid_argument("band_underside: mask size differs from the volume");
  const bool skin = skin_mm > 0;
  if (!(spacing_mm > 0) || (!skin && (after.empty() || !(window_mm > 0)))) return {};
  const auto scanned_after = [&](std::size_t i) { return after.empty() || after[i] != 0; };
  const BeamLines lines(dims, std::size_t(axis));
  std::vector<std::uint8_t> window(n, 0);
  bool any = false;
  for (std::size_t l = 0; l < lines.count(); ++l) {
    const std::size_t base = lines.start(l), stride = lines.stride, len = lines.len;
    std::size_t k = 0;
    while (k < len && !before.empty() && !before[base + k * stride]) ++k;  // the skin line
    if (k == len) continue;
    if (scanned_after(base + k * stride)) {  // no band on this line: the skin window
      if (!skin) continue;
      for (const std::size_t s = k; k < len && double(k - s) * spacing_mm < skin_mm - 1e-9; ++k)
        if (scanned_after(base + k * stride)) window[base + k * stride] = 3, any = true;
      continue;
    }
    if (!(window_mm > 0)) continue;
    while (k < len && !after[base + k * stride]) ++k;                         // the band
    const std::size_t b = k;
    for (; k < len && double(k - b) * spacing_mm < window_mm - 1e-9; ++k)
      if (after[base + k * stride]) window[base + k * stride] = 1, any = true;
    for (; k < len && double(k - b) * spacing_mm < deep_mm - 1e-9; ++k)
      if (after[base + k * stride]) window[base + k * stride] = 2, any = true;
  }
  if (!any) window.clear();
  return window;
}

BandSheetReport hold_band_sheet(const Volume& u, const std::vector<std::uint8_t>& window, int axis,
                                std::vector<std::uint8_t>& scanned, const BandSheetParams& params) {
  BandSheetReport rep;
  const std::size_t n = u.voxels();
  if (window.empty()) return rep;
  if (window.size() != n || (!scanned.empty() && scanned.size() != n))
    throw std::invalid_argument("hold_band_sheet: window or mask size differs from the volume");
  if (axis < 0 || axis > 2) throw std::invalid_argument("hold_band_sheet: beam axis must be 0, 1 or 2");
  // An empty mask: every voxel scanned; made explicit while deciding, and
  // emptied again if nothing is held.
  const bool was_empty = scanned.empty();
  if (was_empty) scanned.assign(n, 1);
  const BeamLines lines(u.dims, std::size_t(axis));
  const std::size_t nu = lines.nu, nw = lines.nw;
  const double along = u.spacing[std::size_t(axis)];
  // Per beam line: 0 no window, 1 a window, 2 drawn in it; the same for the
  // deep window (label 2), with the first drawn voxel's place in it.
  std::vector<std::uint8_t> line(lines.count(), 0), deep(lines.count(), 0);
  std::vector<std::size_t> deep_at(lines.count(), 0), deep_k(lines.count(), 0), deep_end(lines.count(), 0);
  for (std::size_t l = 0; l < line.size(); ++l) {
    std::size_t in_deep = 0;
    for (std::size_t k = 0, i = lines.start(l); k < lines.len; ++k, i += lines.stride) {
      if (window[i] == 1) line[l] = std::max<std::uint8_t>(line[l], u.data[i] > params.threshold ? 2 : 1);
      if (window[i] == 2) {
        if (u.data[i] > params.threshold && deep[l] != 2) deep[l] = 2, deep_at[l] = in_deep, deep_k[l] = k;
        deep[l] = std::max<std::uint8_t>(deep[l], 1);
        ++in_deep, deep_end[l] = k + 1;
      }
    }
    rep.lines += line[l] > 0, rep.drawn += line[l] == 2;
  }
  // The drawn lines' patches: 4-connected across the beam. `decide` takes a
  // patch's share of the band's lines (its lines in `members`) and says
  // whether it is held; `label` is the window's part held.
  std::vector<std::size_t> members;
  const auto patches = [&](const std::vector<std::uint8_t>& drawn, std::uint8_t label, const auto& decide) {
    plane_pieces(nu, nw, [&](std::size_t c) { return drawn[c] == 2; }, members, [&] {
      if (!decide(double(members.size()) / double(rep.lines))) return;
      for (std::size_t c : members) {
        for (std::size_t k = 0, i = lines.start(c); k < lines.len; ++k, i += lines.stride)
          if (window[i] == label && scanned[i]) scanned[i] = 0, ++rep.voxels;
        if (label != 2) continue;
        // A deep sheet: also its drawn run (to the deep window's end at
        // most: what is drawn on below it is no sheet's) and margin_mm on.
        std::size_t k = deep_k[c];
        while (k < deep_end[c] && u.data[lines.start(c) + k * lines.stride] > params.threshold) ++k;
        const std::size_t end = std::min(lines.len, k + std::size_t(std::ceil(params.margin_mm / along - 1e-9)));
        for (k = deep_k[c]; k < end; ++k) {
          const std::size_t i = lines.start(c) + k * lines.stride;
          if (scanned[i]) scanned[i] = 0, ++rep.voxels;
        }
      }
    });
  };
  if (rep.lines > 0) patches(line, 1, [&](double share) {
    rep.largest = std::max(rep.largest, share);
    if (share < params.min_patch) return false;
    ++rep.patches, rep.held_lines += members.size();
    return true;
  });
  // The deep window: a patch that is a flat sheet (its first drawn voxels'
  // quartiles within flat_mm of each other).
  std::vector<std::size_t> at;
  if (rep.lines > 0) patches(deep, 2, [&](double share) {
    at.clear();
    for (std::size_t c : members) at.push_back(deep_at[c]);
    std::sort(at.begin(), at.end());
    const double spread = double(at[at.size() * 3 / 4] - at[at.size() / 4]) * along;
    if (share > rep.deep_largest) rep.deep_largest = share, rep.deep_spread_mm = spread;
    if (share < params.min_patch || spread > std::max(params.flat_mm, along) + 1e-9) return false;
    ++rep.deep_patches, rep.deep_lines += members.size();
    return true;
  });
  hold_skin_sheets(u, window, lines, along, u.spacing[axis == 0 ? 1 : 0], u.spacing[axis == 2 ? 1 : 2], params,
                   scanned, rep);
  rep.held = rep.patches > 0 || rep.deep_patches > 0 || rep.skin_sheets > 0;
  if (was_empty && !rep.held) scanned.clear();
  return rep;
}

namespace {

// The float normalisation's robust minimum (the 0.5th percentile,
// Volume::intensity_map) of a set of samples.
double robust_minimum(std::vector<float> samples) {
  Volume s({samples.size(), 1, 1}, {1.0, 1.0, 1.0}, ScalarType::Float32);
  s.data = std::move(samples);
  return s.intensity_map().lo;
}

// Total variation of a brightness profile (the mean of the scanned nonzero
// samples per slice across an axis, slices with samples only, averaged over
// a moving window of about 3 mm), over the data's mean less its floor.
double profile_variation(const std::vector<double>& sum, const std::vector<std::size_t>& count, double slice_mm,
                         double mean) {
  std::vector<double> prof;
  std::size_t total = 0;
  for (std::size_t c : count) total += c;
  if (total == 0 || !(mean > 0)) return 0;
  const double least = 0.01 * double(total) / double(count.size());
  for (std::size_t i = 0; i < sum.size(); ++i)
    if (count[i] > 0 && double(count[i]) >= least) prof.push_back(sum[i] / double(count[i]));
  const auto w = std::size_t(std::max(1.0, std::round(3.0 / std::max(slice_mm, 1e-9))));
  if (prof.size() < w + 2) return 0;
  std::vector<double> avg(prof.size() - w + 1, 0.0);
  double run = 0;
  for (std::size_t i = 0; i < prof.size(); ++i) {
    run += prof[i];
    if (i >= w) run -= prof[i - w];
    if (i + 1 >= w) avg[i + 1 - w] = run / double(w);
  }
  double tv = 0;
  for (std::size_t i = 1; i < avg.size(); ++i) tv += std::fabs(avg[i] - avg[i - 1]);
  return tv / mean;
}

// How much a sector widens across the slices of an axis: the sampled count
// per slice (slices from the first to the last with a sample), the mean of
// the last tenth over the first tenth's or the other way round, whichever is
// larger (1: as wide at both ends). A fan's scanned sector opens along its
// beam and stays as wide at both ends across it.
double sector_widening(const std::vector<std::size_t>& count) {
  std::size_t first = 0, last = count.size();
  while (first < count.size() && count[first] == 0) ++first;
  while (last > first && count[last - 1] == 0) --last;
  const std::size_t n = last - first;
  if (n < 10) return 1.0;
  const std::size_t k = std::max<std::size_t>(1, n / 10);
  double a = 0, b = 0;
  for (std::size_t i = 0; i < k; ++i) a += double(count[first + i]), b += double(count[last - 1 - i]);
  const double lo = std::min(a, b), hi = std::max(a, b);
  return lo > 0 ? hi / lo : std::numeric_limits<double>::infinity();
}

struct BeamProfiles {
  double tv_axis = 0, tv_z = 0;        // profile_variation() across `axis`'s slices and z's
  double widen_axis = 1, widen_z = 1;  // sector_widening() of the same slices
};

// profile_variation() and sector_widening() of the slices across `axis` and
// across z (every `step`-th z-plane): one pass, sums per z-plane added in z
// order, so the same for any thread count.
BeamProfiles brightness_variation(const Volume& v, const std::vector<std::uint8_t>* scanned, int axis, int threads,
                                  std::size_t step) {
  const Dims3& d = v.dims;
  const std::size_t plane = d[0] * d[1];
  const std::size_t na = d[std::size_t(axis)];  // axis 0 or 1
  std::vector<double> zsum(d[2], 0.0), asum(d[2] * na, 0.0);
  std::vector<std::size_t> zcount(d[2], 0), acount(d[2] * na, 0);
  parallel_ranges(d[2], host_threads(threads), [&](std::size_t z0, std::size_t z1) {
    for (std::size_t z = z0; z < z1; ++z) {
      if (z % step != 0) continue;
      for (std::size_t y = 0; y < d[1]; ++y)
        for (std::size_t x = 0, i = z * plane + y * d[0]; x < d[0]; ++x, ++i) {
          if (v.data[i] == 0.0f || (scanned && !(*scanned)[i])) continue;
          const double s = v.data[i];
          const std::size_t k = z * na + (axis == 0 ? x : y);
          zsum[z] += s, ++zcount[z];
          asum[k] += s, ++acount[k];
        }
    }
  });
  std::vector<double> zs, as(na, 0.0);
  std::vector<std::size_t> zc, ac(na, 0);
  double all = 0;
  std::size_t n_all = 0;
  for (std::size_t z = 0; z < d[2]; z += step) {
    zs.push_back(zsum[z]), zc.push_back(zcount[z]);
    all += zsum[z], n_all += zcount[z];
    for (std::size_t k = 0; k < na; ++k) as[k] += asum[z * na + k], ac[k] += acount[z * na + k];
  }
  // The mean brightness counted from the data's black (brightness_floor
  // over the same samples: 0 for integer grey levels), so that float data
  // offset by a constant give the same answer.
  double floor = 0;
  if (!scalar_type_is_integer(v.source_type) || std::any_of(v.data.begin(), v.data.end(), [](float x) { return x < 0.0f; })) {
    std::vector<float> samples;
    for (std::size_t z = 0; z < d[2]; z += step)
      for (std::size_t i = z * plane; i < (z + 1) * plane; ++i)
        if (v.data[i] != 0.0f && (!scanned || (*scanned)[i])) samples.push_back(v.data[i]);
    if (!samples.empty()) floor = robust_minimum(std::move(samples));
  }
  const double mean = n_all ? all / double(n_all) - floor : 0;
  BeamProfiles out;
  out.tv_axis = profile_variation(as, ac, v.spacing[std::size_t(axis)], mean);
  out.tv_z = profile_variation(zs, zc, v.spacing[2] * double(step), mean);
  out.widen_axis = sector_widening(ac);
  out.widen_z = sector_widening(zc);
  return out;
}

}  // namespace

namespace {

// sq[x] = ((q[x] - p[x]) / h)^2 in double where both samples are nonzero
// (not unscanned fill or the floor) and, with a mask m, both scanned
// (m[x], m[x + m_step]); else 0. Returns how many pairs counted. Four at a
// time in GCC vector types (built for AVX2 too, no fused multiply-add: the
// same bits as one at a time).
__attribute__((target_clones("avx2", "default"))) std::size_t neighbour_squares(const float* p, const float* q,
                                                                               const std::uint8_t* m,
                                                                               std::size_t m_step, double h,
                                                                               std::size_t n, double* sq) {
  typedef float v4f __attribute__((vector_size(16)));
  typedef double v4d __attribute__((vector_size(32)));
  typedef long long v4l __attribute__((vector_size(32)));
  static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the mask bytes are read as a little-endian integer");
  const v4l lanes = {0xffLL, 0xffLL << 8, 0xffLL << 16, 0xffLL << 24};  // lane j's byte of 4
  const v4d zero = {0, 0, 0, 0}, hv = {h, h, h, h};
  std::size_t count = 0, x = 0;
  for (; x + 4 <= n; x += 4) {
    v4f a, b;
    std::memcpy(&a, p + x, sizeof a);
    std::memcpy(&b, q + x, sizeof b);
    const v4d ad = __builtin_convertvector(a, v4d), bd = __builtin_convertvector(b, v4d);
    v4l ok = (ad != zero) & (bd != zero);
    if (m) {
      // 4 mask bytes as one integer in every lane, each lane testing its own
      // byte (as normalised_taps does).
      std::uint32_t m0, m1;
      std::memcpy(&m0, m + x, sizeof m0);
      std::memcpy(&m1, m + x + m_step, sizeof m1);
      const v4l b0 = {m0, m0, m0, m0}, b1 = {m1, m1, m1, m1};
      ok &= ((b0 & lanes) != 0) & ((b1 & lanes) != 0);
    }
    const v4d g = (bd - ad) / hv;
    const v4d s = ok ? g * g : zero;
    std::memcpy(sq + x, &s, sizeof s);
    count += std::size_t(-(ok[0] + ok[1] + ok[2] + ok[3]));
  }
  for (; x < n; ++x) {
    const bool ok = p[x] != 0.0f && q[x] != 0.0f && (!m || (m[x] && m[x + m_step]));
    const double g = (double(q[x]) - double(p[x])) / h;
    sq[x] = ok ? g * g : 0.0, count += ok;
  }
  return count;
}

}  // namespace

int beam_axis_of(const Volume& v, const std::vector<std::uint8_t>* scanned, int threads, std::size_t plane_step) {
  // Speckle is finest along the beam (the axial resolution is the best of
  // the three), so the data's mean squared difference between neighbours, per
  // mm, is largest along it.
  const Dims3& d = v.dims;
  const std::size_t stride[3] = {1, d[0], d[0] * d[1]};
  double energy[3] = {0, 0, 0};
  // Sums per z-plane, added in z order: the same for any thread count.
  const std::size_t plane = d[0] * d[1];
  std::vector<double> psum(3 * d[2], 0.0);
  std::vector<std::size_t> pcount(3 * d[2], 0);
  parallel_ranges(d[2], host_threads(threads), [&](std::size_t z0, std::size_t z1) {
    std::array<std::vector<double>, 3> sq;
    for (auto& s : sq) s.assign(d[0], 0.0);
    for (std::size_t z = z0; z < z1; ++z) {
      if (z % std::max<std::size_t>(1, plane_step) != 0) continue;
      // The axes taken: along each one with a neighbour in this plane's
      // rows (z: not the last plane).
      bool take[3];
      for (int a = 0; a < 3; ++a) take[a] = d[a] >= 2 && !(a == 2 && z + 1 >= d[2]);
      double sum[3] = {0, 0, 0};
      std::size_t count[3] = {0, 0, 0};
      for (std::size_t y = 0; y < d[1]; ++y) {
        // A row's squares along each axis first (without branches: the
        // zeros of dark speckle made them unpredictable; a skipped pair's
        // square is 0, as is every square of an axis not taken here), then
        // the three sums side by side, each in ascending i as before (one
        // axis after the other, each sum a chain of dependent additions).
        std::size_t x_end[3] = {0, 0, 0};
        for (int a = 0; a < 3; ++a) {
          if (!take[a] || (a == 1 && y + 1 >= d[1])) {
            std::fill(sq[std::size_t(a)].begin(), sq[std::size_t(a)].end(), 0.0);
            continue;
          }
          x_end[a] = a == 0 ? d[0] - 1 : d[0];
          const float* p = v.data.data() + z * plane + y * d[0];
          const float* q = p + stride[a];
          const std::uint8_t* m = scanned ? scanned->data() + z * plane + y * d[0] : nullptr;
          count[a] += neighbour_squares(p, q, m, stride[a], v.spacing[a], x_end[a], sq[std::size_t(a)].data());
        }
        // Adding 0.0 to a sum leaves it as it is (it cannot be -0: it
        // starts at +0 and adds squares), so the axes not taken and x's
        // last voxel add nothing.
        const double *s0 = sq[0].data(), *s1 = sq[1].data(), *s2 = sq[2].data();
        if (x_end[0] < d[0]) sq[0][d[0] - 1] = 0.0;
        for (std::size_t x = 0; x < d[0]; ++x) sum[0] += s0[x], sum[1] += s1[x], sum[2] += s2[x];
      }
      for (int a = 0; a < 3; ++a)
        if (take[a]) psum[3 * z + std::size_t(a)] = sum[a], pcount[3 * z + std::size_t(a)] = count[a];
    }
  });
  for (int a = 0; a < 3; ++a) {
    double sum = 0;
    std::size_t count = 0;
    for (std::size_t z = 0; z < d[2]; ++z) sum += psum[3 * z + std::size_t(a)], count += pcount[3 * z + std::size_t(a)];
    energy[a] = count ? sum / double(count) : 0;
  }
  const int best = int(std::max_element(energy, energy + 3) - energy);
  if (best == 2) return best;
  // A PSF finer than the voxels along two axes leaves their grain alike
  // (white speckle at the voxel scale): when z ties with the winner, the
  // data does not tell, and the beam is the classifier's default, +z
  // (docs/real-data.md, "The beam axis").
  if (!(energy[best] >= kBeamAxisMargin * energy[2])) return 2;
  // An almost isotropic PSF can give another axis the finer grain by more
  // than the margin (a fan phantom: 0.22 mm axial, 0.35 lateral, 0.37
  // elevation). Brightness changes with depth along the beam (the near-field
  // band, attenuation, gain drifting with depth), much less across it: when
  // the profile across z's slices varies kBeamProfileMargin as much as
  // across the winner's, and clearly more than noise, the beam stays z.
  const BeamProfiles prof = brightness_variation(v, scanned, best, threads, std::max<std::size_t>(1, plane_step));
  if (prof.tv_z >= kBeamProfileFloor && prof.tv_z >= kBeamProfileMargin * prof.tv_axis) return 2;
  // A fan's sector opens with depth along its beam: sampled data that widen
  // from one end of z to the other (kBeamSectorWidening) and stay as wide
  // at both ends across the winner (kBeamSectorFlat) are a fan with its
  // beam along z, whatever the grain says (a linear scan, or a fan's
  // winner, is not touched).
  if (prof.widen_z >= kBeamSectorWidening && prof.widen_axis <= kBeamSectorFlat) return 2;
  return best;
}

namespace {

// Whether every tap's mask bytes [at, at + bytes) are non-zero (bytes a
// multiple of 8; each 8 read as one integer, a high bit left where a byte
// is 0): a block of outputs that sees only scanned taps.
bool every_tap_scanned(const std::uint8_t* const* mask, std::size_t taps, std::size_t at, std::size_t bytes) {
  constexpr std::uint64_t kOnes = 0x0101010101010101ULL, kHighs = 0x8080808080808080ULL;
  std::uint64_t zero_byte = 0;
  for (std::size_t t = 0; t < taps; ++t)
    for (std::size_t b = 0; b < bytes; b += 8) {
      std::uint64_t m;
      std::memcpy(&m, mask[t] + at + b, sizeof m);
      zero_byte |= (m - kOnes) & ~m & kHighs;
    }
  return zero_byte == 0;
}

// One output row of a normalised lowpass whose taps are whole rows: out[x] =
// sum_t w[t] src[t][x] over the scanned taps (mask[t][x] != 0; every tap when
// mask is null) / the sum of their weights, or fallback[x] when none is
// scanned. Each output's terms are added in tap order in double, an
// unscanned tap adding 0 (which leaves a sum that started at +0 unchanged:
// the same bits as skipping it), products in float. Two builds of it give
// the same bits: the portable one below (GCC vector types) and an AVX2 one
// (intrinsics: GCC's vector types converted each 4 floats to doubles in two
// halves and an insert, a third of the loop), chosen once by the CPU.
//
// Blocks of 8 outputs keep their sums in registers over all taps (per tap
// and output a loop over taps in memory loads and stores two doubles: bound
// by the L1's load/store rate). A block whose outputs see only scanned taps
// (the mask's interior: most blocks) adds every term and takes the weights'
// sum over every tap, added in tap order (the same additions as each lane's).
void normalised_taps_portable(float* out, const float* const* src, const std::uint8_t* const* mask, const float* w,
                              std::size_t taps, std::size_t width, double* acc, double* wsum, const float* fallback,
                              double all_taps, std::size_t x0) {
  // Two lanes per SSE2 register.
  typedef float v4f __attribute__((vector_size(16)));
  typedef double v4d __attribute__((vector_size(32)));
  typedef long long v4l __attribute__((vector_size(32)));
  typedef int v4i __attribute__((vector_size(16)));
  // Output x0 + j's mask byte within 8 bytes read as a little-endian integer.
  static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the mask bytes are read as a little-endian integer");
  const v4l lanes_lo = {0xffLL, 0xffLL << 8, 0xffLL << 16, 0xffLL << 24},
            lanes_hi = {0xffLL << 32, 0xffLL << 40, 0xffLL << 48, (long long)(0xffULL << 56)};
  const v4d all_v = {all_taps, all_taps, all_taps, all_taps};
  for (; x0 + 8 <= width; x0 += 8) {
    v4d a0 = {0, 0, 0, 0}, a1 = a0, s0 = a0, s1 = a0;
    const v4d zero = a0;
    if (!mask || every_tap_scanned(mask, taps, x0, 8)) {
      for (std::size_t t = 0; t < taps; ++t) {
        const float wk = w[t];
        v4f f0, f1;
        std::memcpy(&f0, src[t] + x0, sizeof f0);
        std::memcpy(&f1, src[t] + x0 + 4, sizeof f1);
        a0 += __builtin_convertvector(wk * f0, v4d), a1 += __builtin_convertvector(wk * f1, v4d);
      }
      s0 = all_v, s1 = all_v;
    } else {
      for (std::size_t t = 0; t < taps; ++t) {
        const float wk = w[t];
        const double wd = wk;
        const v4d wv = {wd, wd, wd, wd};
        v4f f0, f1;
        std::memcpy(&f0, src[t] + x0, sizeof f0);
        std::memcpy(&f1, src[t] + x0 + 4, sizeof f1);
        const v4d p0 = __builtin_convertvector(wk * f0, v4d), p1 = __builtin_convertvector(wk * f1, v4d);
        // The 8 mask bytes as one integer in every lane, each lane testing
        // its own byte.
        long long m;
        std::memcpy(&m, mask[t] + x0, sizeof m);
        const v4l mv = {m, m, m, m};
        const v4l c0 = (mv & lanes_lo) != 0, c1 = (mv & lanes_hi) != 0;
        a0 += c0 ? p0 : zero, a1 += c1 ? p1 : zero;
        s0 += c0 ? wv : zero, s1 += c1 ? wv : zero;
      }
    }
    // The quotients four at a time (division and narrowing round as the
    // scalar ones do); an output without a scanned tap keeps its fallback.
    v4f fb0, fb1;
    std::memcpy(&fb0, fallback + x0, sizeof fb0);
    std::memcpy(&fb1, fallback + x0 + 4, sizeof fb1);
    const v4f q0 = __builtin_convertvector(a0 / s0, v4f), q1 = __builtin_convertvector(a1 / s1, v4f);
    const v4i k0 = __builtin_convertvector(s0 > zero, v4i), k1 = __builtin_convertvector(s1 > zero, v4i);
    const v4f o0 = k0 ? q0 : fb0, o1 = k1 ? q1 : fb1;
    std::memcpy(out + x0, &o0, sizeof o0);
    std::memcpy(out + x0 + 4, &o1, sizeof o1);
  }
  // The tail, output by output.
  std::fill(acc + x0, acc + width, 0.0), std::fill(wsum + x0, wsum + width, 0.0);
  for (std::size_t t = 0; t < taps && x0 < width; ++t) {
    const float wk = w[t];
    const float* s = src[t];
    if (mask) {
      const std::uint8_t* m = mask[t];
      for (std::size_t x = x0; x < width; ++x) {
        acc[x] += m[x] ? wk * s[x] : 0.0;
        wsum[x] += m[x] ? wk : 0.0;
      }
    } else {
      for (std::size_t x = x0; x < width; ++x) acc[x] += wk * s[x], wsum[x] += wk;
    }
  }
  for (std::size_t x = x0; x < width; ++x) out[x] = wsum[x] > 0 ? float(acc[x] / wsum[x]) : fallback[x];
}

// 8 outputs a0 / s0 (the first 4), a1 / s1, narrowed to float, or the
// fallback where a weight sum is 0 (the comparison's all-ones lanes narrow
// to a float with its sign bit set, which is what the blend tests).
__attribute__((target("avx2"))) inline void store_quotients(float* out, const float* fallback, __m256d a0,
                                                            __m256d a1, __m256d s0, __m256d s1) {
  const __m256d zero = _mm256_setzero_pd();
  const __m256 q = _mm256_set_m128(_mm256_cvtpd_ps(_mm256_div_pd(a1, s1)), _mm256_cvtpd_ps(_mm256_div_pd(a0, s0)));
  const __m256 keep = _mm256_set_m128(_mm256_cvtpd_ps(_mm256_cmp_pd(s1, zero, _CMP_GT_OQ)),
                                      _mm256_cvtpd_ps(_mm256_cmp_pd(s0, zero, _CMP_GT_OQ)));
  _mm256_storeu_ps(out, _mm256_blendv_ps(_mm256_loadu_ps(fallback), q, keep));
}

// The AVX2 build's blocks (no fused multiply-add: products and sums as the
// portable build rounds them); returns where the tail starts.
__attribute__((target("avx2"))) std::size_t normalised_taps_avx2(float* out, const float* const* src,
                                                                 const std::uint8_t* const* mask, const float* w,
                                                                 std::size_t taps, std::size_t width,
                                                                 double all_taps, const float* fallback) {
  const __m256d zero = _mm256_setzero_pd(), all_v = _mm256_set1_pd(all_taps);
  const __m256i zero_i = _mm256_setzero_si256();
  std::size_t x0 = 0;
  while (x0 + 8 <= width) {
    // 16 outputs whose taps are all scanned: four sums per tap that do not
    // wait for each other.
    if (x0 + 16 <= width && (!mask || every_tap_scanned(mask, taps, x0, 16))) {
      __m256d a0 = zero, a1 = zero, a2 = zero, a3 = zero;
      for (std::size_t t = 0; t < taps; ++t) {
        const __m256 wk = _mm256_set1_ps(w[t]);
        const __m256 p = _mm256_mul_ps(wk, _mm256_loadu_ps(src[t] + x0));
        const __m256 p2 = _mm256_mul_ps(wk, _mm256_loadu_ps(src[t] + x0 + 8));
        a0 = _mm256_add_pd(a0, _mm256_cvtps_pd(_mm256_castps256_ps128(p)));
        a1 = _mm256_add_pd(a1, _mm256_cvtps_pd(_mm256_extractf128_ps(p, 1)));
        a2 = _mm256_add_pd(a2, _mm256_cvtps_pd(_mm256_castps256_ps128(p2)));
        a3 = _mm256_add_pd(a3, _mm256_cvtps_pd(_mm256_extractf128_ps(p2, 1)));
      }
      store_quotients(out + x0, fallback + x0, a0, a1, all_v, all_v);
      store_quotients(out + x0 + 8, fallback + x0 + 8, a2, a3, all_v, all_v);
      x0 += 16;
      continue;
    }
    // 8 outputs, their taps all scanned or not.
    __m256d a0 = zero, a1 = zero, s0 = zero, s1 = zero;
    if (!mask || every_tap_scanned(mask, taps, x0, 8)) {
      for (std::size_t t = 0; t < taps; ++t) {
        const __m256 p = _mm256_mul_ps(_mm256_set1_ps(w[t]), _mm256_loadu_ps(src[t] + x0));
        a0 = _mm256_add_pd(a0, _mm256_cvtps_pd(_mm256_castps256_ps128(p)));
        a1 = _mm256_add_pd(a1, _mm256_cvtps_pd(_mm256_extractf128_ps(p, 1)));
      }
      s0 = all_v, s1 = all_v;
    } else {
      for (std::size_t t = 0; t < taps; ++t) {
        const __m256 p = _mm256_mul_ps(_mm256_set1_ps(w[t]), _mm256_loadu_ps(src[t] + x0));
        const __m256d wv = _mm256_set1_pd(double(w[t]));
        // All ones in a lane whose mask byte is 0: that lane adds +0.
        const __m128i m8 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(mask[t] + x0));
        const __m256d u0 = _mm256_castsi256_pd(_mm256_cmpeq_epi64(_mm256_cvtepu8_epi64(m8), zero_i));
        const __m256d u1 = _mm256_castsi256_pd(_mm256_cmpeq_epi64(_mm256_cvtepu8_epi64(_mm_srli_si128(m8, 4)), zero_i));
        a0 = _mm256_add_pd(a0, _mm256_andnot_pd(u0, _mm256_cvtps_pd(_mm256_castps256_ps128(p))));
        a1 = _mm256_add_pd(a1, _mm256_andnot_pd(u1, _mm256_cvtps_pd(_mm256_extractf128_ps(p, 1))));
        s0 = _mm256_add_pd(s0, _mm256_andnot_pd(u0, wv));
        s1 = _mm256_add_pd(s1, _mm256_andnot_pd(u1, wv));
      }
    }
    store_quotients(out + x0, fallback + x0, a0, a1, s0, s1);
    x0 += 8;
  }
  return x0;
}

std::atomic<bool> g_portable_taps{false};  // mask_detail::use_portable_taps

void normalised_taps(float* out, const float* const* src, const std::uint8_t* const* mask, const float* w,
                     std::size_t taps, std::size_t width, double* acc, double* wsum, const float* fallback) {
  double all_taps = 0;
  for (std::size_t t = 0; t < taps; ++t) all_taps += double(w[t]);
  static const bool avx2 = __builtin_cpu_supports("avx2");
  std::size_t x0 = 0;
  if (avx2 && !g_portable_taps.load(std::memory_order_relaxed))
    x0 = normalised_taps_avx2(out, src, mask, w, taps, width, all_taps, fallback);
  normalised_taps_portable(out, src, mask, w, taps, width, acc, wsum, fallback, all_taps, x0);
}

// Filters along the rows' index of a len x width array (row p at
// base + p * stride): out row p from the rows p + k, k in [-r, r] clamped to
// the array (only taps inside are visited).
void filter_rows(float* out, const float* src, const std::uint8_t* mask, std::size_t len, std::size_t width,
                 std::size_t stride, const std::vector<float>& w, std::vector<const float*>& rows,
                 std::vector<const std::uint8_t*>& mrows, std::vector<double>& acc, std::vector<double>& wsum) {
  const long r = long(w.size() / 2);
  for (std::size_t pos = 0; pos < len; ++pos) {
    const long k0 = std::max(-r, -long(pos)), k1 = std::min(r, long(len) - 1 - long(pos));
    std::size_t t = 0;
    for (long k = k0; k <= k1; ++k, ++t) {
      const std::size_t row = std::size_t(long(pos) + k) * stride;
      rows[t] = src + row;
      if (mask) mrows[t] = mask + row;
    }
    normalised_taps(out + pos * stride, rows.data(), mask ? mrows.data() : nullptr, w.data() + (k0 + r), t, width,
                    acc.data(), wsum.data(), src + pos * stride);
  }
}

// Filters one row along itself (the taps x + k, k in [-r, r] clamped to the
// row), the same sums as filter_rows on the row's transpose: one call of
// normalised_taps whose tap rows are the row shifted, padded with r
// unscanned samples either side (a tap outside adds 0 to both sums: the
// same bits as not visiting it). pad and mpad hold len + 2r + 8.
void filter_along_row(float* out, const float* src, const std::uint8_t* mask, std::size_t len,
                      const std::vector<float>& w, std::vector<const float*>& rows,
                      std::vector<const std::uint8_t*>& mrows, std::vector<double>& acc, std::vector<double>& wsum,
                      std::vector<float>& pad, std::vector<std::uint8_t>& mpad) {
  const std::size_t r = w.size() / 2;
  std::copy(src, src + len, pad.begin() + long(r));
  if (mask)
    std::copy(mask, mask + len, mpad.begin() + long(r));
  else
    std::fill(mpad.begin() + long(r), mpad.begin() + long(r + len), std::uint8_t(1));
  for (std::size_t t = 0; t < w.size(); ++t) rows[t] = pad.data() + t, mrows[t] = mpad.data() + t;
  normalised_taps(out, rows.data(), mrows.data(), w.data(), w.size(), len, acc.data(), wsum.data(), src);
}

}  // namespace

void mask_detail::use_portable_taps(bool on) { g_portable_taps.store(on); }

namespace {

// lowpass_across_beam of the planes [k0, k1) across the beam (indices along
// ax) into out, a whole volume's array; the rest of out untouched. The
// passes filter across the beam only, so a plane's values do not depend on
// the others: the same bits as filtering the whole volume.
//
// Every pass filters whole rows at a time, vectorised across them: along y
// (z) the rows of a z-plane (y-slice); along x each row along itself, its
// taps the row shifted (it went through a transpose of each plane, of its
// mask and back: a fifth of the pass). Split by z-planes or y-rows, the
// result does not depend on the thread count. (Along x it ran voxel by
// voxel, with a branch per tap: 0.4 s of the near field's 1.3 s at 256^3;
// now the same bits in a fraction.)
void lowpass_planes(const Volume& v, const std::uint8_t* mask, int ax, double sigma_mm, int threads, float* out,
                    std::size_t k0, std::size_t k1) {
  const Dims3& d = v.dims;
  const int u_ax = ax == 0 ? 1 : 0, w_ax = ax == 2 ? 1 : 2;  // the two lateral axes
  const std::size_t nx = d[0], ny = d[1], nz = d[2];
  // Each axis's range: [k0, k1) along the beam, all of the others.
  std::size_t lo[3] = {0, 0, 0}, hi[3] = {nx, ny, nz};
  lo[ax] = k0, hi[ax] = k1;
  const std::size_t xw = hi[0] - lo[0];  // the x-rows' part filtered
  for (const int axis : {u_ax, w_ax}) {
    const bool in_place = axis == w_ax;
    const float* src = in_place ? out : v.data.data();
    float* const dst = out;
    // At most as wide as the axis (wider is flat across it anyway: a
    // spacing in the wrong unit made it 30000 taps, O(n r) for nothing).
    const double sigma_vox = std::clamp(sigma_mm / v.spacing[axis], 0.5, std::max(0.5, double(d[axis])));
    const std::vector<float> w = gaussian_weights(sigma_vox, 3.0);
    const std::size_t taps = w.size();
    if (axis == 0) {
      // Always the first pass (the second is y or z); each row is copied
      // into its padded scratch before it is written.
      parallel_ranges(hi[2] - lo[2], threads, [&](std::size_t z0, std::size_t z1) {
        std::vector<const float*> rows(taps);
        std::vector<const std::uint8_t*> mrows(taps);
        std::vector<double> acc(nx), wsum(nx);
        // The row padded with taps / 2 unscanned samples either side.
        std::vector<float> pad(nx + taps + 8, 0.0f);
        std::vector<std::uint8_t> mpad(nx + taps + 8, 0);
        for (std::size_t z = lo[2] + z0; z < lo[2] + z1; ++z)
          for (std::size_t y = lo[1]; y < hi[1]; ++y) {
            const std::size_t at = (z * ny + y) * nx;
            filter_along_row(dst + at, src + at, mask ? mask + at : nullptr, nx, w, rows, mrows, acc, wsum, pad,
                             mpad);
          }
      });
    } else if (axis == 1) {
      // A z-plane's rows, their part [lo[0], hi[0]) in x.
      parallel_ranges(hi[2] - lo[2], threads, [&](std::size_t z0, std::size_t z1) {
        std::vector<const float*> rows(taps);
        std::vector<const std::uint8_t*> mrows(taps);
        std::vector<double> acc(nx), wsum(nx);
        std::vector<float> copy(in_place ? nx * ny : 0);
        for (std::size_t z = lo[2] + z0; z < lo[2] + z1; ++z) {
          const std::size_t plane = z * nx * ny + lo[0];
          const float* from = src + plane;
          if (in_place) {
            std::copy_n(from, nx * ny - lo[0], copy.data());
            from = copy.data();
          }
          filter_rows(dst + plane, from, mask ? mask + plane : nullptr, ny, xw, nx, w, rows, mrows, acc, wsum);
        }
      });
    } else {
      // Always the second pass, in place: the y-slice's rows (z, y), their
      // part [lo[0], hi[0]) in x, gathered z-major, filtered there and
      // written back.
      parallel_ranges(hi[1] - lo[1], threads, [&](std::size_t y0, std::size_t y1) {
        std::vector<const float*> rows(taps);
        std::vector<const std::uint8_t*> mrows(taps);
        std::vector<double> acc(xw), wsum(xw);
        std::vector<float> slice(nz * xw), filtered(slice.size());
        std::vector<std::uint8_t> mslice(mask ? nz * xw : 0);
        for (std::size_t y = lo[1] + y0; y < lo[1] + y1; ++y) {
          const std::size_t at = y * nx + lo[0];
          for (std::size_t z = 0; z < nz; ++z) {
            std::copy_n(src + at + z * nx * ny, xw, slice.data() + z * xw);
            if (mask) std::copy_n(mask + at + z * nx * ny, xw, mslice.data() + z * xw);
          }
          filter_rows(filtered.data(), slice.data(), mask ? mslice.data() : nullptr, nz, xw, xw, w, rows, mrows, acc,
                      wsum);
          for (std::size_t z = 0; z < nz; ++z) std::copy_n(filtered.data() + z * xw, xw, dst + at + z * nx * ny);
        }
      });
    }
  }
}

}  // namespace

HostVector<float> lowpass_across_beam(const Volume& v, const std::vector<std::uint8_t>* scanned, int ax, double sigma_mm,
                                       int threads) {
  // One array: the first pass reads the data and writes it, the second
  // filters it in place, each plane (along y) or slice (along z) copied out
  // first (a second array's first touch cost more than the copies).
  HostVector<float> out(v.voxels());
  lowpass_planes(v, scanned ? scanned->data() : nullptr, ax, sigma_mm, host_threads(threads), out.data(), 0,
                 v.dims[ax]);
  return out;
}

namespace {

// The band's echo layer (docs/real-data.md, "The near field's echo"): the
// band's interfaces (skin, fat, fascia) reverberate between themselves and
// the probe, and the scan shows a fainter copy of the band's deepest
// interface at about twice its depth, under the dark gap below the band: a
// layer that follows the skin line as the band does, not a surface. Each
// band line is read (the data lowpassed across the beam, as for the band)
// at depths scaled by its own band bottom, t = depth / bottom (a wavy
// band's copy is as wavy, twice as deep), and E(t), the median over the
// band lines' scanned samples, is the band's echo profile. A layer: E's
// highest point at t_peak in [echo_from, echo_to] rising above the lowest
// point between the band and it (the gap, from t = 1) by at least
// echo_rise of the band's top over that gap. Then, in every band line, the
// voxels from where E rises above halfway between the gap and the peak to
// where it falls below it again, margin_mm either way, join the band. Each
// interface has its own copy (the fat's bottom at twice its depth lies
// between the band and the deepest interface's copy), so up to
// echo_layers - 1 further layers are looked for the same way anywhere under
// the band, each bounded by the gap on both sides ("Every echo layer").
template <class Voxel>
void echo_layer(const HostVector<float>& lp, const std::vector<long>& skin,
                const std::vector<double>& bottom_mm, NearFieldReport& rep, std::vector<std::uint8_t>& band,
                const Voxel& voxel, const std::vector<std::uint8_t>* scanned, std::size_t n_u, std::size_t n_w,
                std::size_t n_ax, double hz, const NearFieldParams& params, int threads) {
  const std::size_t lines = n_u * n_w;
  std::vector<std::size_t> band_lines;
  for (std::size_t l = 0; l < lines; ++l)
    if (skin[l] >= 0 && bottom_mm[l] > 0) band_lines.push_back(l);
  if (band_lines.empty() || !(rep.top > 0)) return;
  // E(t) in steps of dt (0.5 mm at the band's median depth), t from 1 to echo_to.
  const double B = rep.depth_mm - params.margin_mm;
  if (!(B > 0)) return;
  const double dt = 0.5 / B;
  const auto steps = std::size_t(std::floor((params.echo_to - 1.0) / dt)) + 1;
  std::vector<double> E(steps, std::nan(""));
  parallel_ranges(steps, threads, [&](std::size_t s0, std::size_t s1) {
    std::vector<float> x;
    for (std::size_t s = s0; s < s1; ++s) {
      const double t = 1.0 + double(s) * dt;
      x.clear();
      for (std::size_t l : band_lines) {
        const long z = skin[l] + std::lround(t * bottom_mm[l] / hz);
        if (z >= 0 && std::size_t(z) < n_ax) {
          const std::size_t i = voxel(l % n_u, l / n_u, std::size_t(z));
          if (!scanned || (*scanned)[i]) x.push_back(lp[i]);
        }
      }
      // Only where most band lines still have samples at this depth.
      if (x.size() * 2 < band_lines.size()) continue;
      std::nth_element(x.begin(), x.begin() + long(x.size() / 2), x.end());
      E[s] = x[x.size() / 2];
    }
  });
  // Joins t in [from_t, to_t] of every band line (margin_mm either way) to
  // the band; returns the voxels added.
  const auto join = [&](double from_t, double to_t) {
    std::size_t added = 0;
    for (std::size_t l : band_lines) {
      const std::size_t a = l % n_u, bb = l / n_u;
      const double from = from_t * bottom_mm[l] - params.margin_mm;
      const double to = to_t * bottom_mm[l] + params.margin_mm;
      for (std::size_t z = std::size_t(skin[l]); z < n_ax; ++z) {
        const double depth = double(long(z) - skin[l]) * hz;
        if (depth >= to) break;
        if (depth < from) continue;
        std::uint8_t& b = band[voxel(a, bb, z)];
        if (!b) b = 1, ++added, ++rep.voxels;
      }
    }
    return added;
  };
  std::vector<std::uint8_t> taken(steps, 0), tried(steps, 0);
  // The band's tail: under a band whose interfaces' copies overlap (no dark
  // gap between them), E falls from the band's bottom (t = 1) through a
  // dimmer plateau to the floor under it, the median of E over the deeper
  // half of t = 1 ... echo_to. When E at the bottom stands echo_rise of the
  // band's top over that floor above it, the band reaches down to where E
  // first falls halfway from its bottom to the floor.
  if (params.echo_tail && !std::isnan(E[0])) {
    std::vector<double> deep;
    for (std::size_t s = steps / 2; s < steps; ++s)
      if (!std::isnan(E[s])) deep.push_back(E[s]);
    if (!deep.empty()) {
      std::nth_element(deep.begin(), deep.begin() + long(deep.size() / 2), deep.end());
      const double floor_level = deep[deep.size() / 2];
      const double drop = E[0] - floor_level;
      if (drop > 0 && drop >= params.echo_rise * (rep.top - floor_level)) {
        std::size_t end = 0;
        while (end + 1 < steps / 2 && !std::isnan(E[end + 1]) && E[end + 1] > floor_level + 0.5 * drop) ++end;
        if (end > 0) {
          for (std::size_t s = 0; s <= end; ++s) taken[s] = 1;
          rep.echo.tail_to = 1.0 + double(end) * dt;
          rep.echo.tail_voxels = join(1.0, rep.echo.tail_to);
        }
      }
    }
  }
  // The layers, brightest first: the first at t >= echo_from, each further
  // one anywhere under the band (t > 1) outside the layers already taken,
  // and bounded on both sides (E below its halfway mark before and after
  // it: a layer, not a rising trend).
  // A candidate that fails as a further layer is passed over (the band's
  // own flank just under it, say) and the next brightest tried.
  for (int k = 0; k < std::max(params.echo_layers, 0);) {
    std::size_t peak = steps;
    for (std::size_t s = 0; s < steps; ++s) {
      const double t = 1.0 + double(s) * dt;
      if ((k == 0 && t < params.echo_from) || (k > 0 && s == 0) || taken[s] || tried[s] || std::isnan(E[s])) continue;
      if (peak == steps || E[s] > E[peak]) peak = s;
    }
    if (peak == steps) return;
    tried[peak] = 1;
    std::size_t gap = 0;
    bool any = false;
    for (std::size_t s = 0; s < peak; ++s)
      if (!std::isnan(E[s]) && (!any || E[s] < E[gap])) gap = s, any = true;
    const double rise = any ? E[peak] - E[gap] : 0.0;
    const bool rises = any && rise >= params.echo_rise * (rep.top - E[gap]) && rise > 0;
    if (k == 0 && !rises) return;
    if (!rises) continue;
    // The layer's extent in t: halfway between the gap and the peak.
    const double half = E[gap] + 0.5 * rise;
    std::size_t lo = peak, hi = peak;
    while (lo > gap && !taken[lo - 1] && !std::isnan(E[lo - 1]) && E[lo - 1] >= half) --lo;
    while (hi + 1 < steps && !taken[hi + 1] && !std::isnan(E[hi + 1]) && E[hi + 1] >= half) ++hi;
    if (k > 0 && (lo == gap || hi + 1 >= steps || std::isnan(E[hi + 1]) || taken[hi + 1] || taken[lo - 1])) continue;
    // The first layer, too, must end inside the window: E that stays above
    // halfway to echo_to is the gain rising with depth (a time-gain
    // compensation stronger than the attenuation), not a copy of the band.
    if (k == 0 && params.echo_bounded && (hi + 1 >= steps || std::isnan(E[hi + 1]))) return;
    for (std::size_t s = lo; s <= hi; ++s) taken[s] = 1;
    const double from_t = 1.0 + double(lo) * dt, to_t = 1.0 + double(hi) * dt;
    if (k == 0) {
      rep.echo.found = true;
      rep.echo.from = from_t, rep.echo.to = to_t;
      rep.echo.peak = 1.0 + double(peak) * dt;
      rep.echo.gap = E[gap], rep.echo.level = E[peak];
    } else {
      rep.echo.from = std::min(rep.echo.from, from_t), rep.echo.to = std::max(rep.echo.to, to_t);
    }
    ++rep.echo.layers, ++k;
    rep.echo.voxels += join(from_t, to_t);
  }
}

// The skin-line rule (NearFieldParams::skin_step) on P, the lines' median
// profile in 0.5 mm bins below the skin line: the depth (mm) where a thin
// bright layer at the top ends in a sharp step, or 0. Fills rep.step and
// rep.roughness for the step it looked at.
double skin_step(const std::vector<double>& P, const NearFieldParams& params, double floor, NearFieldReport& rep) {
  const std::size_t bins = P.size();
  const auto top_bins = std::size_t(std::ceil(params.top_mm / 0.5));
  const auto stay_bins = std::max<std::size_t>(1, std::size_t(std::ceil(params.stay_mm / 0.5)));
  constexpr std::size_t kSharp = 3;  // bins after the layer the fall must be done in (1.5 mm)
  // The step: the bin s (the first under the layer) where P falls most both
  // ways: from the layer's brightest bin (P[0, s)) to the brightest of the
  // stay_mm under it (P(s, s + stay]) -- the fall -- and, within kSharp bins,
  // from the layer's last bin -- the drop. (Bins without a sample, where the
  // voxels are coarser than 0.5 mm, are NaN and skipped.)
  const auto extreme = [&](std::size_t b0, std::size_t b1, bool high) {  // of P[b0, b1); NaN if none
    double x = std::nan("");
    for (std::size_t b = b0; b < std::min(b1, bins); ++b)
      if (!std::isnan(P[b]) && (std::isnan(x) || (high ? P[b] > x : P[b] < x))) x = P[b];
    return x;
  };
  std::size_t best = 0;
  double fall = 0, drop = 0, level = 0, after = 0;
  for (std::size_t s = 1; s <= top_bins && s + stay_bins < bins; ++s) {
    if (std::isnan(P[s - 1])) continue;
    const double l = extreme(0, s, true), a = extreme(s + 1, s + stay_bins + 1, true);
    const double dr = P[s - 1] - extreme(s, s + kSharp, false);
    if (std::isnan(a) || std::isnan(dr)) continue;
    if (std::min(l - a, dr) > std::min(fall, drop)) best = s, fall = l - a, drop = dr, level = l, after = a;
  }
  if (best == 0 || !(fall > 0)) return 0;
  // P's roughness under the step: the robust spread of its bin-to-bin changes.
  std::vector<double> dP;
  double last = std::nan("");
  for (std::size_t b = best + kSharp; b < bins; ++b)
    if (!std::isnan(P[b])) {
      if (!std::isnan(last)) dP.push_back(std::fabs(P[b] - last));
      last = P[b];
    }
  if (dP.size() < 8) return 0;
  std::nth_element(dP.begin(), dP.begin() + long(dP.size() / 2), dP.end());
  const double roughness = 1.4826 * dP[dP.size() / 2];
  rep.step = fall, rep.roughness = roughness;
  const bool sharp = drop >= 0.75 * fall;  // most of the fall is the drop
  bool brightest = true;  // nothing deeper within the search is as bright as the layer
  for (std::size_t b = best; b < bins; ++b) brightest &= std::isnan(P[b]) || P[b] < level;
  const bool found = sharp && brightest && fall >= params.faint_ratio * (level - floor) &&
                     fall >= params.step_sds * roughness;
  if (!found) return 0.0;
  // The band ends where the fall is three quarters done.
  std::size_t end = best;
  while (end < bins && !(P[end] <= after + 0.25 * fall)) ++end;
  return 0.5 * double(end);
}

}  // namespace

double unscanned_fill_value(const Volume& v, double min_fraction, int threads) {
  if (scalar_type_is_integer(v.source_type) || v.data.empty()) return 0.0;
  const std::size_t n = v.data.size();
  const Dims3& d = v.dims;
  threads = host_threads(threads);
  // The candidates: the data's minimum and the eight corners' samples (a
  // fill the mask takes touches the volume's border; a fan's or a sweep's
  // reaches its corners).
  const int parts = range_count(n, threads);
  std::vector<float> mins(std::size_t(parts), INFINITY), maxs(std::size_t(parts), -INFINITY);
  parallel_ranges_indexed(n, threads, [&](int k, std::size_t i0, std::size_t i1) {
    float m = INFINITY, M = -INFINITY;
    for (std::size_t i = i0; i < i1; ++i) m = std::min(m, v.data[i]), M = std::max(M, v.data[i]);
    mins[std::size_t(k)] = m, maxs[std::size_t(k)] = M;
  });
  const float top = *std::max_element(maxs.begin(), maxs.end());
  std::vector<float> cand{0.0f, *std::min_element(mins.begin(), mins.end())};
  for (int c = 0; c < 8; ++c) {
    const std::size_t x = c & 1 ? d[0] - 1 : 0, y = c & 2 ? d[1] - 1 : 0, z = c & 4 ? d[2] - 1 : 0;
    cand.push_back(v.data[x + d[0] * (y + d[1] * z)]);
  }
  std::sort(cand.begin() + 1, cand.end());
  cand.erase(std::unique(cand.begin() + 1, cand.end()), cand.end());
  cand.erase(std::remove_if(cand.begin() + 1, cand.end(), [](float x) { return x == 0.0f || !std::isfinite(x); }),
             cand.end());
  if (cand.size() < 2) return 0.0;
  // Exact samples at each (cand[0] is 0), over threads (the same for any split).
  const std::size_t nc = cand.size();
  std::vector<std::size_t> counts(std::size_t(parts) * nc, 0);
  parallel_ranges_indexed(n, threads, [&](int k, std::size_t i0, std::size_t i1) {
    std::size_t* const c = counts.data() + std::size_t(k) * nc;
    for (std::size_t i = i0; i < i1; ++i)
      for (std::size_t j = 0; j < nc; ++j) c[j] += v.data[i] == cand[j];
  });
  std::vector<std::size_t> total(nc, 0);
  for (int k = 0; k < parts; ++k)
    for (std::size_t j = 0; j < nc; ++j) total[j] += counts[std::size_t(k) * nc + j];
  const double need = min_fraction * double(n);
  if (double(total[0]) >= need) return 0.0;  // a zero fill: as always
  std::size_t best = 0;
  for (std::size_t j = 1; j < nc; ++j)
    if (double(total[j]) >= need && (best == 0 || total[j] > total[best])) best = j;
  if (best == 0) return 0.0;
  // A fill is dark: at most the median of the other samples (a clipped
  // ceiling, repeated as often, is not one). From every stride-th sample.
  const float f = cand[best];
  const std::size_t stride = std::max<std::size_t>(1, n / 1000000);
  std::vector<float> rest;
  rest.reserve(n / stride + 1);
  for (std::size_t i = 0; i < n; i += stride)
    if (v.data[i] != f) rest.push_back(v.data[i]);
  if (rest.empty()) return 0.0;
  std::nth_element(rest.begin(), rest.begin() + long(rest.size() / 2), rest.end());
  if (!(f <= rest[rest.size() / 2])) return 0.0;
  // The data less the fill must stay finite in float (data spanning +-3e38)
  // and keep its detail: the rest's robust range at least a thousandth of
  // its distance from the fill (float's 24 bits then leave it 2^14 steps; a
  // fill at -1e30 under data in 10-20 would round every sample to one).
  if (!(double(top) - double(f) <= double(std::numeric_limits<float>::max()))) return 0.0;
  const auto at = [&](double q) {
    const auto k = long(q * double(rest.size() - 1));
    std::nth_element(rest.begin(), rest.begin() + k, rest.end());
    return double(rest[std::size_t(k)]);
  };
  const double hi = at(0.995), lo = at(0.005);
  return hi - lo >= 1e-3 * (hi - double(f)) ? double(f) : 0.0;
}

void move_fill_to_zero(Volume& v, double fill, int threads) {
  if (fill == 0.0) return;
  const float f = float(fill);
  parallel_ranges(v.data.size(), host_threads(threads), [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) v.data[i] -= f;
  });
}

void darken_scanned_fill(Volume& v, const std::vector<std::uint8_t>& scanned) {
  const std::size_t n = v.data.size();
  const bool all = scanned.size() != n;
  float lo = INFINITY;
  for (std::size_t i = 0; i < n; ++i)
    if ((all || scanned[i]) && v.data[i] != 0.0f) lo = std::min(lo, v.data[i]);
  if (!std::isfinite(lo)) return;
  for (std::size_t i = 0; i < n; ++i)
    if ((all || scanned[i]) && v.data[i] == 0.0f) v.data[i] = lo;
}

double brightness_floor(const Volume& v, const std::vector<std::uint8_t>* scanned) {
  if (scalar_type_is_integer(v.source_type) &&
      std::none_of(v.data.begin(), v.data.end(), [](float x) { return x < 0.0f; }))
    return 0.0;  // grey levels (no sample below 0): black is 0
  // Float data, and signed data holding negative samples (dB): the robust
  // minimum of the scanned samples (the fill is no brightness of the data).
  std::vector<float> samples;
  if (scanned && scanned->size() == v.data.size()) {
    for (std::size_t i = 0; i < v.data.size(); ++i)
      if ((*scanned)[i]) samples.push_back(v.data[i]);
  }
  if (samples.empty()) return v.with_data(v.data, ScalarType::Float32).intensity_map().lo;
  return robust_minimum(std::move(samples));
}

std::vector<std::uint8_t> near_field_band(const Volume& v, const std::vector<std::uint8_t>* scanned,
                                          const NearFieldParams& params, NearFieldReport* report,
                                          HostVector<float>* lowpass_out) {
  const Dims3& d = v.dims;
  const std::size_t n = v.voxels();
  if (scanned && scanned->size() != n) throw std::invalid_argument("near_field_band: mask size differs from the volume");
  NearFieldReport rep;
  const int threads = host_threads(params.threads);
  rep.axis = params.axis >= 0 && params.axis < 3 ? params.axis : beam_axis_of(v, scanned, threads);
  std::vector<std::uint8_t> band(n, 0);
  const int ax = rep.axis, u_ax = ax == 0 ? 1 : 0, w_ax = ax == 2 ? 1 : 2;  // the two lateral axes
  const std::size_t stride[3] = {1, d[0], d[0] * d[1]};
  const double hz = v.spacing[ax];
  const auto bins = std::size_t(std::ceil(params.search_mm / 0.5)) + 1;
  if (d[ax] < 4) {
    if (report) *report = rep;
    return band;
  }
  HostVector<float> own_lp;
  HostVector<float>& lp = lowpass_out ? *lowpass_out : own_lp;
  lp = lowpass_across_beam(v, scanned, ax, params.sigma_mm, threads);
  // Brightness in the ratio tests below counts from the data's black
  // (brightness_floor): the same band for data offset by a constant.
  const double floor = brightness_floor(v, scanned);
  // Skin line per beam line (its first scanned voxel).
  auto voxel = [&](std::size_t a, std::size_t b, std::size_t z) {
    return a * stride[u_ax] + b * stride[w_ax] + z * stride[ax];
  };
  const std::size_t lines = d[u_ax] * d[w_ax];
  // Without a mask every line starts at depth 0.
  std::vector<long> skin(lines, scanned ? -1 : 0);
  if (scanned) {
    // In memory order (z-planes over threads): the skin line of every beam
    // line (its first scanned voxel, the minimum depth: exact).
    const std::size_t nx = d[0], ny = d[1], nz = d[2];
    const int parts = range_count(nz, threads);
    std::vector<std::vector<long>> pskin(static_cast<std::size_t>(parts), std::vector<long>(lines, -1));
    parallel_ranges_indexed(nz, threads, [&](int k, std::size_t z0, std::size_t z1) {
      std::vector<long>& sk = pskin[std::size_t(k)];
      const std::uint8_t* const in = scanned->data();
      if (ax == 2) {
        // The beam along z: a line is (x, y), and a thread's planes come in
        // ascending z, so a line's first scanned voxel is its first depth
        // (row loops without branches).
        long* const s = sk.data();
        for (std::size_t z = z0; z < z1; ++z)
          for (std::size_t y = 0; y < ny; ++y) {
            const std::uint8_t* const m = in + (z * ny + y) * nx;
            long* const sr = s + y * nx;
            for (std::size_t x = 0; x < nx; ++x) sr[x] = sr[x] < 0 && m[x] ? long(z) : sr[x];
          }
        return;
      }
      for (std::size_t z = z0; z < z1; ++z)
        for (std::size_t y = 0; y < ny; ++y)
          for (std::size_t x = 0; x < nx; ++x) {
            const std::size_t i = (z * ny + y) * nx + x;
            if (!in[i]) continue;
            const std::size_t c[3] = {x, y, z};
            const std::size_t l = c[u_ax] + c[w_ax] * d[u_ax];
            if (sk[l] < 0 || long(c[ax]) < sk[l]) sk[l] = long(c[ax]);
          }
    });
    for (const auto& sk : pskin)
      for (std::size_t l = 0; l < lines; ++l)
        if (sk[l] >= 0 && (skin[l] < 0 || sk[l] < skin[l])) skin[l] = sk[l];
  }
  // The lines' samples by depth below their skin line, A[l K + k] (NaN where
  // unscanned or past the volume): deep enough for the profile's depth bins
  // (0.5 mm each, `bins` of them), which reach past search_mm. One pass over
  // the volume serves the profile below and the per-line band after it.
  // (At most the lines' length: on a spacing given in the wrong unit, 0.1 um
  // voxels, 25 mm were 250 000 samples a line, and A alone 4 GB.)
  const auto K = std::min<std::size_t>(d[ax], std::size_t(std::ceil(0.5 * double(bins) / hz)) + 1);
  const auto K_search = std::min(K, std::size_t(std::ceil(params.search_mm / hz)));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // Uninitialised: each thread of the pass below sets its own lines' part
  // to NaN first (its pages first touched there, in parallel).
  HostVector<float> A(lines * K);
  // The speckle's own spread (below) from R: each scanned sample's departure
  // from the lowpass, at depths top_mm ... search_mm below the skin line
  // (gathered per thread; only their median and spread are used).
  const auto top_k = std::size_t(std::ceil(params.top_mm / hz));
  std::vector<float> R;
  std::size_t all = 0;  // scanned voxels
  // The scanned samples' range (the clipped rule below).
  double vmax = -std::numeric_limits<double>::infinity(), vmin = std::numeric_limits<double>::infinity();
  {
    // The scanned voxels' count and range, in memory order (a pass of
    // loops without branches: exact in any order).
    const int parts = range_count(n, threads);
    std::vector<std::size_t> pall(static_cast<std::size_t>(parts), 0);
    std::vector<float> phi(static_cast<std::size_t>(parts)), plo(static_cast<std::size_t>(parts));
    parallel_ranges_indexed(n, threads, [&](int part, std::size_t i0, std::size_t i1) {
      constexpr float inf = std::numeric_limits<float>::infinity();
      const float* const data = v.data.data();
      std::size_t count = 0;
      float hi = -inf, lo = inf;
      if (scanned) {
        const std::uint8_t* const in = scanned->data();
        for (std::size_t i = i0; i < i1; ++i) {
          const bool s = in[i] != 0;
          count += s;
          hi = std::max(hi, s ? data[i] : -inf), lo = std::min(lo, s ? data[i] : inf);
        }
      } else {
        count = i1 - i0;
        for (std::size_t i = i0; i < i1; ++i) hi = std::max(hi, data[i]), lo = std::min(lo, data[i]);
      }
      pall[std::size_t(part)] = count;
      phi[std::size_t(part)] = hi, plo[std::size_t(part)] = lo;
    });
    for (int k = 0; k < parts; ++k) {
      all += pall[std::size_t(k)];
      if (pall[std::size_t(k)] > 0)
        vmax = std::max(vmax, double(phi[std::size_t(k)])), vmin = std::min(vmin, double(plo[std::size_t(k)]));
    }
  }
  {
    const int parts = range_count(d[w_ax], threads);
    std::vector<std::vector<float>> presid(static_cast<std::size_t>(parts));
    parallel_ranges_indexed(d[w_ax], threads, [&](int part, std::size_t b0, std::size_t b1) {
      std::vector<float>& resid = presid[std::size_t(part)];
      // At most every line's samples in the window: reserved (not touched),
      // so the pushes below never move what they gathered.
      if (K_search > top_k) resid.reserve((b1 - b0) * d[u_ax] * (K_search - top_k));
      const float* data = v.data.data();
      const float* low = lp.data();
      const std::uint8_t* in = scanned ? scanned->data() : nullptr;
      // Line by line, each down from its skin line to K below it: a line's
      // stretch of A is written in order, and the neighbouring lines read
      // the same cache lines of the volume while they are in cache (depth by
      // depth across the lines, every store went to another cache line of
      // A). The residuals' median does not depend on the order.
      for (std::size_t bb = b0; bb < b1; ++bb)
        for (std::size_t a = 0; a < d[u_ax]; ++a) {
          const std::size_t l = a + bb * d[u_ax];
          float* const line = A.data() + l * K;
          std::fill(line, line + K, nan);
          const long s0 = skin[l];
          if (s0 < 0) continue;  // no scanned voxel on the line
          const auto z_end = std::size_t(std::min(long(d[ax]), s0 + long(K)));
          for (std::size_t z = std::size_t(s0); z < z_end; ++z) {
            const std::size_t i = voxel(a, bb, z);
            if (in && !in[i]) continue;
            const std::size_t k = z - std::size_t(s0);
            line[k] = low[i];
            if (k >= top_k && k < K_search) resid.push_back(data[i] - low[i]);
          }
        }
    });
    for (const auto& pr : presid) R.insert(R.end(), pr.begin(), pr.end());
  }
  if (all < 100) {
    if (report) *report = rep;
    return band;
  }
  auto median = [](auto& x) {
    if (x.empty()) return std::nan("");
    std::nth_element(x.begin(), x.begin() + long(x.size() / 2), x.end());
    return double(x[x.size() / 2]);
  };
  // P(d): the median over the lines of their samples in each depth bin.
  std::vector<double> P(bins);
  {
    // Bins over threads: each gathers its bins' samples (line by line, as
    // one serial pass did) and takes their medians.
    const auto bin_of = [&](std::size_t k) { return std::size_t(double(k) * hz / 0.5); };  // nondecreasing in k
    std::vector<std::size_t> k_of_bin(bins + 1, K);  // the first k of bin b or beyond (K: none)
    for (std::size_t k = 0, b = 0; k < K; ++k)
      for (; b <= std::min(bin_of(k), bins); ++b) k_of_bin[b] = k;
    parallel_ranges(bins, threads, [&](std::size_t b0, std::size_t b1) {
      std::vector<std::vector<float>> at_depth(b1 - b0);
      // k in [k0, k1) lies in exactly the bins [b0, b1).
      const std::size_t k0 = k_of_bin[b0], k1 = k_of_bin[b1];
      // Each bin's bound reserved (its depths' samples on every line): no
      // copies as they grow.
      for (std::size_t b = b0; b < b1; ++b) at_depth[b - b0].reserve(lines * (k_of_bin[b + 1] - k_of_bin[b]));
      for (std::size_t l = 0; l < lines; ++l)
        for (std::size_t k = k0; k < k1; ++k)
          if (!std::isnan(A[l * K + k])) at_depth[bin_of(k) - b0].push_back(A[l * K + k]);
      for (std::size_t b = b0; b < b1; ++b) P[b] = median(at_depth[b - b0]);
    });
  }
  const auto top_bins = std::size_t(std::ceil(params.top_mm / 0.5));
  double top = -1e300, below = 1e300;
  for (std::size_t b = 0; b < bins && b < top_bins; ++b)
    if (!std::isnan(P[b]) && P[b] > top) top = P[b];
  for (std::size_t b = top_bins; b < bins; ++b)
    if (!std::isnan(P[b])) below = std::min(below, P[b]);
  rep.top = top, rep.below = below;
  if (!(below < 1e300)) {
    if (report) *report = rep;
    return band;
  }
  // The speckle's spread: 1.4826 x the median absolute deviation of the
  // residuals R (a robust standard deviation: the objects' edges in R are
  // few). A faint band (brighter than `below` by faint_ratio of its top but
  // not by min_ratio) counts when it stands out of the speckle by
  // speckle_sds of it: on bright tissue (grey levels near the top of the
  // range) a saturated band can never be min_ratio brighter.
  if (R.size() >= 100) {
    // The medians by the threads' selection (the same order statistics as
    // nth_element's).
    const double m = median_of(R, threads);
    for (float& x : R) x = float(std::fabs(double(x) - m));
    rep.speckle_sd = 1.4826 * double(median_of(R, threads));
  }
  std::vector<float>().swap(R);
  // Per beam line (docs/real-data.md, "The near field"): the line's own top,
  // T (the brightest of its first top_mm), and, when T is at least min_ratio
  // brighter than `below` (relative to T), the band's bottom on this line:
  // where the line falls below halfway between T and `below` and stays there
  // for stay_mm (a layered band dips at the fat), within search_mm. A line
  // that never falls (bright all the way) has no band. The profile above,
  // over all lines, sets only `below`: on a fan whose top the volume's top
  // face cuts, or on a volume probe whose cap is a small part of the top,
  // most lines enter the scan below the band, and their median hid it.
  //
  // The lines' samples (A, to search_mm) are averaged across the beam over
  // profile_mm either way (a separable box over the lines, per depth): one
  // line's maximum over a few speckle samples is biased bright, and the
  // local mean is not.
  // The two passes share a scratch array: the second writes into the first's
  // input, whose pages are touched already (not a second fresh 17.6 MB
  // array at 256^3).
  HostVector<float> box_out;
  const auto box_across = [&](int lat, double h_lat) {
    const std::size_t n_along = lat == 0 ? d[u_ax] : d[w_ax], n_other = lat == 0 ? d[w_ax] : d[u_ax];
    const long r = std::max(0L, long(std::lround(params.profile_mm / h_lat)));
    HostVector<float>& out = box_out;
    out.resize(A.size());
    // Each line's depths side by side: per depth k the same additions and
    // subtractions in the same order as one depth at a time (which read a
    // cache line per sample and divided one at a time), in loops over k that
    // vectorise. A NaN sample adds +0.0 to the sum and 0 to the count: the
    // same values (a sum that starts at +0 is never -0).
    parallel_ranges(n_other, threads, [&](std::size_t o0, std::size_t o1) {
      std::vector<double> sum(K_search), count(K_search);
      for (std::size_t o = o0; o < o1; ++o) {
        const auto line = [&](long t) { return lat == 0 ? std::size_t(t) + o * d[u_ax] : o + std::size_t(t) * d[u_ax]; };
        std::fill(sum.begin(), sum.end(), 0.0);
        std::fill(count.begin(), count.end(), 0.0);
        double* const sm = sum.data();
        double* const cn = count.data();
        const auto add = [&](long t, double sign) {
          if (t < 0 || t >= long(n_along)) return;
          const float* const x = A.data() + line(t) * K;
          for (std::size_t k = 0; k < K_search; ++k) {
            const bool ok = !std::isnan(x[k]);
            sm[k] += ok ? sign * double(x[k]) : 0.0;
            cn[k] += ok ? sign : 0.0;
          }
        };
        for (long t = 0; t < r && t < long(n_along); ++t) add(t, 1.0);
        for (long t = 0; t < long(n_along); ++t) {
          add(t + r, 1.0);
          add(t - r - 1, -1.0);
          const float* const x = A.data() + line(t) * K;
          float* const y = out.data() + line(t) * K;
          for (std::size_t k = 0; k < K_search; ++k)
            y[k] = !std::isnan(x[k]) && cn[k] > 0 ? float(sm[k] / cn[k]) : nan;
          std::fill(y + K_search, y + K, nan);
        }
      }
    });
    A.swap(out);
  };
  // The line's own top before the mean across: the median of its first
  // top_mm. A line is a candidate only when this is bright too, so that the
  // mean across does not carry a band past its lateral edge (where the
  // volume's top face cuts a fan's band) onto dark lines beside it.
  std::vector<float> own_top(lines, nan);
  parallel_ranges(lines, threads, [&](std::size_t l0, std::size_t l1) {
    std::vector<float> x;
    for (std::size_t l = l0; l < l1; ++l) {
      x.clear();
      for (std::size_t k = 0; k < top_k && k < K_search; ++k)
        if (!std::isnan(A[l * K + k])) x.push_back(A[l * K + k]);
      if (!x.empty()) own_top[l] = float(median(x));
    }
  });
  box_across(0, v.spacing[u_ax]);
  box_across(1, v.spacing[w_ax]);
  std::vector<float> ltop(lines, -std::numeric_limits<float>::infinity());
  std::vector<long> ltop_at(lines, -1), lbottom(lines, 0), run(lines, -1);
  // A faint band (faint_ratio, speckle_sds) must lie under faint_lines of the
  // lines under the probe: a layer across the probe. A few lines brighter at
  // their top than the deep median (tissue on a gain that drifts with depth,
  // an object near the skin) are no near field unless min_ratio brighter.
  bool faint = false;
  const auto bright = [&](double t) {
    return t - below > params.min_ratio * (t - floor) ||
           (faint && t - below > params.faint_ratio * (t - floor) && rep.speckle_sd > 0 &&
            t - below > params.speckle_sds * rep.speckle_sd);
  };
  // ... or a clipped one (its own top at the data's maximum: a slab
  // saturated at the top of the range over bright, coarse speckle, which can
  // be neither min_ratio brighter nor speckle_sds out of the speckle).
  const double clip_level = vmax - 0.01 * (vmax - vmin);
  // Per line: clip_share of its raw samples in its first top_mm at that
  // maximum, and at least twice the share of the samples under the tops
  // (top_mm to search_mm below the skin line, every line) at it: the band is
  // clipped, the tissue under it much less (tissue that saturates as often
  // is no clipped band over it). One pass over the lines counts both.
  std::vector<std::uint8_t> clipped_top(lines, 0);
  if (params.clipped && vmax > vmin) {
    std::vector<std::uint32_t> top_at_max(lines, 0), top_count(lines, 0);
    const int parts = range_count(lines, threads);
    std::vector<std::size_t> pat(static_cast<std::size_t>(parts), 0), pcount(static_cast<std::size_t>(parts), 0);
    // In memory order, as A above (line by line, a cache miss per sample;
    // integer counts: the same for any order), each thread's sums in locals.
    const long k_end = long(std::max(top_k, K_search));
    long z_end = 0;
    for (std::size_t l = 0; l < lines; ++l) z_end = std::max(z_end, skin[l] + k_end);
    z_end = std::min(z_end, long(d[ax]));
    parallel_ranges_indexed(d[w_ax], threads, [&](int part, std::size_t b0, std::size_t b1) {
      std::size_t at = 0, count = 0;
      for (std::size_t z = 0; z < std::size_t(z_end); ++z)
        for (std::size_t bb = b0; bb < b1; ++bb)
          for (std::size_t a = 0; a < d[u_ax]; ++a) {
            const std::size_t l = a + bb * d[u_ax];
            const long k = long(z) - skin[l];
            if (skin[l] < 0 || k < 0 || k >= k_end) continue;
            const std::size_t i = voxel(a, bb, z);
            if (scanned && !(*scanned)[i]) continue;
            const bool at_max = double(v.data[i]) >= clip_level;
            if (std::size_t(k) < top_k) ++top_count[l], top_at_max[l] += at_max;
            else if (std::size_t(k) < K_search) ++count, at += at_max;
          }
      pat[std::size_t(part)] = at, pcount[std::size_t(part)] = count;
    });
    std::size_t at_max = 0, count = 0;
    for (int k = 0; k < parts; ++k) at_max += pat[std::size_t(k)], count += pcount[std::size_t(k)];
    const double under_share = count ? double(at_max) / double(count) : 1.0;
    const double clip_share = std::max(params.clip_share, 2.0 * under_share);
    if (clip_share <= 1.0)
      for (std::size_t l = 0; l < lines; ++l)
        clipped_top[l] = top_count[l] > 0 && double(top_at_max[l]) >= clip_share * double(top_count[l]);
  }
  const auto clipped = [&](std::size_t l) {
    return clipped_top[l] && double(ltop[l]) - below > params.faint_ratio * (double(ltop[l]) - floor);
  };
  const auto candidate = [&](std::size_t l) {
    return ltop_at[l] >= 0 && ((bright(double(ltop[l])) && !std::isnan(own_top[l]) && bright(double(own_top[l]))) ||
                               (faint && clipped(l)));
  };
  parallel_ranges(lines, threads, [&](std::size_t l0, std::size_t l1) {
    for (std::size_t l = l0; l < l1; ++l) {
      const float* x = &A[l * K];
      for (std::size_t k = 0; k < top_k && k < K_search; ++k)
        if (!std::isnan(x[k]) && x[k] > ltop[l]) ltop[l] = x[k], ltop_at[l] = long(k);
    }
  });
  // The lines under the probe: where the skin line runs across the beam (it
  // deepens by at most 1 mm per mm across it), not down the side of a
  // sector, whose lines enter the scan below the band (a volume probe's fan
  // cut by the top face: two thirds of the lines).
  const auto under_probe_line = [&](std::size_t l) {
    return under_probe(skin, l, d[u_ax], d[w_ax], hz, v.spacing[u_ax], v.spacing[w_ax]);
  };
  if (params.faint_ratio < params.min_ratio) {
    faint = true;  // count the lines that pass with the faint rule in force, then keep it only if enough do
    std::size_t faint_lines = 0, probe_lines = 0;
    for (std::size_t l = 0; l < lines; ++l)
      if (skin[l] >= 0 && under_probe_line(l)) ++probe_lines, faint_lines += candidate(l);
    faint = probe_lines > 0 && double(faint_lines) >= params.faint_lines * double(probe_lines);
  }
  // A layered band (skin, a dark fat layer up to a few mm thick, then bright
  // muscle or fascia): Pc(k), the median over the candidate lines of their
  // samples k below the skin line, falls below halfway and rises above it
  // again within layer_gap_mm, and then falls for good. Then each line's
  // band ends only where it stays below halfway for layer_gap_mm (not
  // stay_mm): the fat's dip is no bottom. A median over the lines decides:
  // an object close under the band on some of them (a bone) is no layer.
  double stay_mm = params.stay_mm;
  std::size_t layers_end_k = 0;  // a layered band: where its layers end in Pc (samples below the skin line)
  if (params.layer_gap_mm > params.stay_mm) {
    std::vector<std::size_t> cand;
    std::vector<float> x;
    for (std::size_t l = 0; l < lines; ++l)
      if (candidate(l)) cand.push_back(l), x.push_back(ltop[l]);
    const double half = 0.5 * (median(x) + below);
    // Pc(k): the candidates' median at depth k, up to the first depth where
    // fewer than half of them have a sample (the depths over the threads,
    // each its own gather and selection; then cut at that depth).
    std::vector<double> Pc(cand.empty() ? 0 : K_search);
    std::vector<std::uint8_t> few(Pc.size(), 0);
    parallel_ranges(Pc.size(), threads, [&](std::size_t k0, std::size_t k1) {
      std::vector<float> xs;
      for (std::size_t k = k0; k < k1; ++k) {
        xs.clear();
        for (std::size_t l : cand)
          if (!std::isnan(A[l * K + k])) xs.push_back(A[l * K + k]);
        if (double(xs.size()) < 0.5 * double(cand.size())) few[k] = 1;
        else Pc[k] = median(xs);
      }
    });
    Pc.resize(std::size_t(std::find(few.begin(), few.end(), std::uint8_t{1}) - few.begin()));
    const auto gap_k = std::size_t(std::floor(params.layer_gap_mm / hz));
    const auto stay_k = std::max<std::size_t>(1, std::size_t(std::ceil(params.stay_mm / hz)));
    std::size_t k = 0;
    while (k < Pc.size() && top_k > k && Pc[k] < half) ++k;  // the top
    while (k < Pc.size() && Pc[k] >= half) ++k;               // the first layer
    const std::size_t fall = k;
    while (k < Pc.size() && Pc[k] < half) ++k;                // the gap under it
    bool gap = k < Pc.size() && k - fall >= 1 && k - fall <= gap_k;
    if (!gap && params.layer_dip > 0) {
      // A fat layer that the median does not take below halfway: a dip of
      // layer_dip under the brighter of the peaks beside it, the next peak
      // within layer_gap_mm, both above halfway. Under a skin bright on some
      // lines, those lines fall below their own halfway through the fat and
      // ended there (fresh randomised face 1308: Pc's fat at 80-85 between
      // 113 and 108, halfway 69; 7.1 mm of an 11 mm band removed).
      k = 0;
      while (k < Pc.size() && top_k > k && Pc[k] < half) ++k;
      const double keep = 1.0 - params.layer_dip;  // a dip is at most this share of a layer beside it
      double peak = -std::numeric_limits<double>::infinity();
      for (; k < Pc.size() && Pc[k] >= half; ++k) {
        peak = std::max(peak, Pc[k]);
        if (Pc[k] - floor > keep * (peak - floor)) continue;
        std::size_t j = k + 1;  // the next layer: the first sample the dip is that far under
        while (j < Pc.size() && j <= k + gap_k && Pc[j] >= half && Pc[k] - floor > keep * (Pc[j] - floor)) ++j;
        if (j < Pc.size() && j <= k + gap_k && Pc[j] >= half) {
          gap = true;
          k = j;
          break;
        }
      }
      while (gap && k < Pc.size() && Pc[k] >= half) ++k;  // to the end of the next layer
    }
    if (gap) {
      std::size_t end = k;  // the end of the next layer in Pc
      while (end < Pc.size() && Pc[end] >= half) ++end;
      std::size_t run = 0;                                    // the next layer, then a fall that stays
      for (; k < Pc.size() && run < stay_k; ++k) run = Pc[k] < half ? run + 1 : 0;
      if (run >= stay_k) stay_mm = params.layer_gap_mm, rep.layered = true, layers_end_k = end;
    }
  }
  parallel_ranges(lines, threads, [&](std::size_t l0, std::size_t l1) {
    for (std::size_t l = l0; l < l1; ++l) {
      const float* x = &A[l * K];
      if (!candidate(l)) continue;
      const double half = 0.5 * (double(ltop[l]) + below);
      for (std::size_t k = std::size_t(ltop_at[l]); k < K_search; ++k) {
        if (std::isnan(x[k])) continue;
        if (double(x[k]) >= half) {
          run[l] = -1;
          continue;
        }
        if (run[l] < 0) run[l] = long(k);
        if (double(long(k) - run[l] + 1) * hz >= stay_mm) {
          lbottom[l] = run[l];
          break;
        }
      }
    }
  });
  // A line that fell below halfway and ended (or left the search window)
  // before stay_mm: its band ends where it fell.
  for (std::size_t l = 0; l < lines; ++l)
    if (candidate(l) && lbottom[l] == 0 && run[l] > 0) lbottom[l] = run[l];
  // The band is a layer across the probe: its bottom varies slowly across the
  // lines. A separable median over smooth_mm either way across the beam (over
  // the lines with a skin line; 0 where a line has no band) keeps that and
  // drops single lines that speckle or an object under the band carried
  // deeper (or cut short).
  std::vector<double> bottom_mm(lines, -1.0);
  for (std::size_t l = 0; l < lines; ++l)
    if (skin[l] >= 0) bottom_mm[l] = double(lbottom[l]) * hz;
  // In a layered band, a candidate line that never stays below halfway under
  // its layers has no bottom of its own. Where the tissue under the band
  // lies about at the halfway mark (which comes from `below`, the fat's dark
  // dip), it crosses the mark back and forth: such a line ends where the
  // layers end in Pc, at most at the found lines' median bottom
  // (NearFieldParams::fill_layered). A line over an object right under the
  // band stays above the mark: it keeps no band.
  if (params.fill_layered && rep.layered && layers_end_k > 0) {
    std::vector<double> found;
    for (std::size_t l = 0; l < lines; ++l)
      if (bottom_mm[l] > 0) found.push_back(bottom_mm[l]);
    double fill = double(layers_end_k) * hz;
    if (!found.empty()) fill = std::min(fill, median(found));
    const auto reach = std::min(K_search, layers_end_k + std::size_t(std::ceil(params.fill_reach_mm / hz)));
    for (std::size_t l = 0; l < lines; ++l) {
      if (skin[l] < 0 || !candidate(l) || lbottom[l] != 0 || run[l] >= 0) continue;
      const float* x = &A[l * K];
      const double half = 0.5 * (double(ltop[l]) + below);
      std::size_t n = 0, under = 0;
      for (std::size_t k = layers_end_k; k < reach; ++k)
        if (!std::isnan(x[k])) ++n, under += double(x[k]) < half;
      if (n > 0 && double(under) >= params.fill_crossing * double(n)) bottom_mm[l] = fill;
    }
  }
  // A layered band is a layer across the probe, about as deep on every
  // line. Where the tissue under it hovers about the halfway mark, a line
  // stays under the mark for layer_gap_mm only in an acoustic shadow, so a
  // line over a bone ended under the bone; where many lines do so, the
  // median across the beam below keeps them, and the bone's top went with
  // the band (an independent simulator's bones: up to 48 % of their visible
  // surface). So a line's band ends at most layer_reach_mm under the lines'
  // median bottom (docs/parameters.md, "A layered band's reach") -- unless
  // the line stayed under the mark for stay_mm in between: then what lies
  // deeper is a layer of the band's own over a dark gap (a deep fascia, the
  // band's echo merged into it), not tissue over a shadow. In a fan a line
  // along the axis crosses the band at its beam's angle, so both depths are
  // taken along the beam: each bottom divided by its line's stretch (the
  // beam's length per unit along the axis, from the fan's apex; 1 without a
  // fan) before the median, the bound multiplied by it. The band's echo
  // (echo_layer) is looked for on the lines not bounded.
  std::vector<std::uint8_t> bounded;  // 1: the line's band was bounded (empty: none was)
  if (rep.layered && params.layer_reach_mm > 0) {
    const FanBeams fan = scanned ? fan_beams(*scanned, d, v.spacing, ax) : FanBeams{};
    std::vector<double> stretch(lines, 1.0);
    if (fan.found)
      for (std::size_t bb = 0; bb < d[w_ax]; ++bb)
        for (std::size_t a = 0; a < d[u_ax]; ++a) {
          const std::size_t l = a + bb * d[u_ax];
          if (skin[l] < 0) continue;
          const double along = (double(skin[l]) - fan.apex[ax]) * hz;
          double len2 = along * along;
          for (const int k : {u_ax, w_ax})
            if (fan.spreads[k]) {
              const double c = (double(k == u_ax ? a : bb) - fan.apex[k]) * v.spacing[std::size_t(k)];
              len2 += c * c;
            }
          if (along > 0) stretch[l] = std::sqrt(len2) / along;
        }
    std::vector<double> found;
    for (std::size_t l = 0; l < lines; ++l)
      if (bottom_mm[l] > 0) found.push_back(bottom_mm[l] / stretch[l]);
    if (!found.empty()) {
      const double med = median(found);
      const auto stay_k = std::max<long>(1, long(std::ceil(params.stay_mm / hz)));
      for (std::size_t l = 0; l < lines; ++l)
        if (bottom_mm[l] > (med + params.layer_reach_mm) * stretch[l]) {
          // A line that stayed under the mark for stay_mm between the
          // median bottom and its own has a further layer of its own there
          // (the band's deep fascia, or its echo over a dark gap): kept.
          const float* x = &A[l * K];
          const double half = 0.5 * (double(ltop[l]) + below);
          long longest = 0, r = 0;
          for (long k = std::max(0L, long(std::floor(med * stretch[l] / hz))); k < lbottom[l] && longest < stay_k; ++k) {
            r = !std::isnan(x[k]) && double(x[k]) < half ? r + 1 : 0;
            longest = std::max(longest, r);
          }
          if (longest >= stay_k) continue;
          if (bounded.empty()) bounded.assign(lines, 0);
          bottom_mm[l] = (med + params.layer_reach_mm) * stretch[l];
          bounded[l] = 1;
          ++rep.reach_lines;
        }
    }
  }
  const auto median_along = [&](int axis_lat, std::size_t n_along, std::size_t n_other, double h_lat) {
    const long r = std::max(1L, long(std::lround(params.smooth_mm / h_lat)));
    std::vector<double> out(bottom_mm);
    parallel_ranges(n_other, threads, [&](std::size_t o0, std::size_t o1) {
      std::vector<double> win;
      for (std::size_t o = o0; o < o1; ++o)
        for (std::size_t t = 0; t < n_along; ++t) {
          const auto line = [&](std::size_t s) { return axis_lat == 0 ? s + o * d[u_ax] : o + s * d[u_ax]; };
          if (bottom_mm[line(t)] < 0) continue;
          win.clear();
          // Symmetric about t, also at the volume's sides (a one-sided window
          // there would carry the inner lines' value out to the edge).
          const long rt = std::min({r, long(t), long(n_along) - 1 - long(t)});
          for (long s = long(t) - rt; s <= long(t) + rt; ++s)
            if (bottom_mm[line(std::size_t(s))] >= 0) win.push_back(bottom_mm[line(std::size_t(s))]);
          std::nth_element(win.begin(), win.begin() + long(win.size() / 2), win.end());
          out[line(t)] = win[win.size() / 2];
        }
    });
    bottom_mm.swap(out);
  };
  median_along(0, d[u_ax], d[w_ax], v.spacing[u_ax]);
  median_along(1, d[w_ax], d[u_ax], v.spacing[w_ax]);
  // The band's echo lies at multiples of a line's own band depth, which a
  // bounded line does not show (it lies over an object): the echo is looked
  // for, and joined, on the other lines.
  std::vector<double> echo_bottom;
  if (!bounded.empty()) {
    echo_bottom = bottom_mm;
    for (std::size_t l = 0; l < lines; ++l)
      if (bounded[l]) echo_bottom[l] = 0;
  }
  std::size_t with_skin = 0, band_lines = 0;
  std::vector<double> depths, tops;
  for (std::size_t l = 0; l < lines; ++l) {
    if (skin[l] < 0) continue;
    ++with_skin;
    if (bottom_mm[l] > 0) {
      ++band_lines;
      depths.push_back(bottom_mm[l] + params.margin_mm);
      if (ltop_at[l] >= 0) tops.push_back(double(ltop[l]));
    }
  }
  if (band_lines > 0 && double(band_lines) >= params.min_lines * double(with_skin)) {
    rep.found = true;
    rep.lines = band_lines;
    rep.depth_mm = median(depths);
    if (!tops.empty()) rep.top = median(tops);
    rep.faint = faint && !(rep.top - below > params.min_ratio * (rep.top - floor));
    // Clipped: the faint rule's speckle test fails, so its lines came in by
    // their clipped tops.
    rep.clipped = rep.faint && !(rep.speckle_sd > 0 && rep.top - below > params.speckle_sds * rep.speckle_sd);
    for (std::size_t bb = 0; bb < d[w_ax]; ++bb)
      for (std::size_t a = 0; a < d[u_ax]; ++a) {
        const std::size_t l = a + bb * d[u_ax];
        const long s0 = skin[l];
        if (s0 < 0 || !(bottom_mm[l] > 0)) continue;
        const double bottom = bottom_mm[l] + params.margin_mm;
        for (std::size_t z = std::size_t(s0); z < d[ax]; ++z) {
          if (double(long(z) - s0) * hz >= bottom) break;
          band[voxel(a, bb, z)] = 1;
          ++rep.voxels;
        }
      }
    if (params.echo_layer)
      echo_layer(lp, skin, echo_bottom.empty() ? bottom_mm : echo_bottom, rep, band, voxel, scanned, d[u_ax], d[w_ax], d[ax], hz,
                 params, threads);
  } else if (params.skin_step) {
    // The skin line (NearFieldParams::skin_step): a thin layer at the skin
    // line ended by a sharp step in P.
    const double step_mm = skin_step(P, params, floor, rep);
    if (step_mm > 0) {
      rep.found = rep.skin = true;
      rep.depth_mm = step_mm + params.margin_mm;
      for (std::size_t bb = 0; bb < d[w_ax]; ++bb)
        for (std::size_t a = 0; a < d[u_ax]; ++a) {
          const std::size_t l = a + bb * d[u_ax];
          const long s0 = skin[l];
          if (s0 < 0 || !under_probe_line(l)) continue;
          ++rep.lines;
          for (std::size_t z = std::size_t(s0); z < d[ax] && double(long(z) - s0) * hz < rep.depth_mm; ++z) {
            band[voxel(a, bb, z)] = 1;
            ++rep.voxels;
          }
        }
      if (rep.lines == 0) rep.found = rep.skin = false;
    }
  }
  if (rep.found) {
    // On a small or shallow volume the "band" may be most of it: that is
    // the object (removing it would leave nothing to classify), not an
    // occluder above it.
    if (double(rep.voxels) > params.max_share * double(all)) {
      rep.found = false, rep.too_deep = true, rep.voxels = 0;
      std::fill(band.begin(), band.end(), std::uint8_t{0});
    }
  }
  if (report) *report = rep;
  return band;
}

std::vector<std::uint8_t> reverberation_region(const Volume& v, const std::vector<std::uint8_t>* scanned, int ax,
                                               const ReverbParams& params, ReverbReport* report, int threads,
                                               const HostVector<float>* lowpass) {
  const Dims3& d = v.dims;
  const std::size_t n = v.voxels();
  if (scanned && scanned->size() != n) throw std::invalid_argument("reverberation_region: mask size differs from the volume");
  if (ax < 0 || ax > 2) throw std::invalid_argument("reverberation_region: beam axis must be 0, 1 or 2");
  ReverbReport rep;
  std::vector<std::uint8_t> region(n, 0);
  const auto done = [&] {
    if (report) *report = rep;
    return region;
  };
  const double h = v.spacing[ax];
  if (d[ax] < 8 || !(h > 0)) return done();
  threads = host_threads(threads);
  if (lowpass && lowpass->size() != n) throw std::invalid_argument("reverberation_region: lowpass size differs from the volume");
  HostVector<float> own_lp;
  if (!lowpass) own_lp = lowpass_across_beam(v, scanned, ax, params.sigma_mm, threads);
  const HostVector<float>& lp = lowpass ? *lowpass : own_lp;
  const auto is_scanned = [&](std::size_t i) { return !scanned || (*scanned)[i] != 0; };
  // lo (median) and hi (99th percentile) of the scanned samples.
  const std::size_t count = scanned ? std::size_t(std::count_if(scanned->begin(), scanned->end(),
                                                                [](std::uint8_t m) { return m != 0; }))
                                    : n;
  if (count < 100) return done();
  // The q-quantile of value(lowpassed sample) over the scanned voxels.
  const auto quantile_of = [&](double q, const auto& value) {
    const auto k = std::size_t(q * double(count - 1));
    return double(kth_smallest_where(n, k, threads, [&](std::size_t i, float& f) {
      f = value(lp[i]);
      return is_scanned(i);
    }));
  };
  // lo and hi in one call (one count and one gather for both).
  const std::vector<float> lo_hi = kth_smallest_of_where(
      n, {std::size_t(0.5 * double(count - 1)), std::size_t(0.99 * double(count - 1))}, threads,
      [&](std::size_t i, float& f) {
        f = lp[i];
        return is_scanned(i);
      });
  const double lo = lo_hi[0], hi = lo_hi[1];
  if (!(hi > lo)) return done();
  // The strong echoes must stand out of the data's spread (1.4826 x the
  // median absolute deviation from lo): in a texture without a reflector
  // the 99th percentile is only a few spreads up, and its "first strong
  // echo" is speckle on every line.
  if (params.min_stand > 0) {
    const double spread = 1.4826 * quantile_of(0.5, [lo](float x) { return float(std::fabs(double(x) - lo)); });
    rep.stand = spread > 0 ? (hi - lo) / spread : std::numeric_limits<double>::infinity();
    if (rep.stand < params.min_stand) return done();
  }
  const double strong = lo + params.strong * (hi - lo);
  const int u_ax = ax == 0 ? 1 : 0, w_ax = ax == 2 ? 1 : 2;
  const std::size_t stride[3] = {1, d[0], d[0] * d[1]};
  const std::size_t lines = d[u_ax] * d[w_ax];
  const auto at = [&](std::size_t l, std::size_t p) {
    return (l % d[u_ax]) * stride[u_ax] + (l / d[u_ax]) * stride[w_ax] + p * stride[ax];
  };
  // The first strong echo of each line, at its crest (within 1 mm below the
  // crossing).
  const auto crest_reach = std::size_t(std::ceil(1.0 / h));
  std::vector<long> echo(lines, -1);
  std::size_t with_data = 0;
  {
    // Lines over threads (each line's search is its own; the counts are
    // sums), each thread's lines walked a plane across the beam at a time
    // (in memory order where the beam is z; line by line down the beam it
    // read a cache line per sample): per line the first scanned sample not
    // below `strong`, then the brightest scanned one up to crest_reach below
    // it (the first of equals), as a search down each line finds them.
    const int parts = range_count(lines, threads);
    std::vector<std::size_t> pechoes(std::size_t(parts), 0), pdata(std::size_t(parts), 0);
    parallel_ranges_indexed(lines, threads, [&](int k, std::size_t l0, std::size_t l1) {
      const std::size_t m = l1 - l0;
      std::vector<std::size_t> base(m);
      for (std::size_t j = 0; j < m; ++j) base[j] = at(l0 + j, 0);
      std::vector<long> first(m, -1);  // the first strong sample's position
      std::vector<float> crest(m);     // the brightest from there
      std::vector<std::uint8_t> any(m, 0);
      const std::size_t step = stride[ax];
      for (std::size_t p = 0; p < d[ax]; ++p)
        for (std::size_t j = 0; j < m; ++j) {
          const std::size_t i = base[j] + p * step;
          if (!is_scanned(i)) continue;
          any[j] = 1;
          if (first[j] < 0) {
            if (!(lp[i] < strong)) first[j] = long(p), echo[l0 + j] = long(p), crest[j] = lp[i];
          } else if (p <= std::size_t(first[j]) + crest_reach && lp[i] > crest[j]) {
            echo[l0 + j] = long(p), crest[j] = lp[i];
          }
        }
      std::size_t echoes = 0, data = 0;
      for (std::size_t j = 0; j < m; ++j) echoes += first[j] >= 0, data += any[j];
      pechoes[std::size_t(k)] = echoes, pdata[std::size_t(k)] = data;
    });
    for (int k = 0; k < parts; ++k) rep.lines += pechoes[std::size_t(k)], with_data += pdata[std::size_t(k)];
  }
  if (rep.lines < 16 || double(rep.lines) < 0.05 * double(with_data)) return done();
  // A flat reflector: its echo lies at nearly the same depth on neighbouring
  // lines (a tilted one moves by about a lateral step per line). On bright
  // speckle every line has a "first strong echo", at whatever depth its
  // first bright grain lies: 3 mm apart on a quarter of the neighbouring
  // lines (randomised spine 106), none on the flat reflector of IMLiF.
  {
    std::vector<double> jumps;
    for (std::size_t l = 0; l + 1 < lines; ++l)
      if ((l + 1) % d[u_ax] != 0 && echo[l] >= 0 && echo[l + 1] >= 0)
        jumps.push_back(std::fabs(double(echo[l + 1] - echo[l])) * h);
    if (jumps.empty()) return done();
    const auto q = jumps.begin() + long(3 * (jumps.size() - 1) / 4);
    std::nth_element(jumps.begin(), q, jumps.end());
    rep.jump_mm = *q;
    if (rep.jump_mm > std::max(params.max_jump_mm, 2.0 * v.spacing[u_ax])) return done();
  }
  // The echo train: Q(s), the median over the aligned lines.
  const auto smax = std::size_t(std::min(1e9, std::floor(params.max_spacing_mm / h)));
  const auto smin = std::max<std::size_t>(1, std::size_t(std::ceil(params.min_spacing_mm / h)));
  if (!(params.max_spacing_mm / h >= double(smin)) || smax < smin) return done();
  // At most the beam lines' length (a spacing in the wrong unit made smax huge).
  const std::size_t S = std::min<std::size_t>(d[ax], std::size_t(std::ceil(double(smax) * (2.0 + params.tolerance))) + 1);
  // Depths over threads: each gathers its depths' samples, line by line,
  // and takes their medians.
  std::vector<double> median_at(S, 0.0);
  std::vector<std::size_t> lines_at(S, 0);
  parallel_ranges(S, threads, [&](std::size_t s0, std::size_t s1) {
    std::vector<std::vector<float>> at_s(s1 - s0);
    for (auto& x : at_s) x.reserve(rep.lines);  // at most a sample per line with an echo
    for (std::size_t l = 0; l < lines; ++l) {
      if (echo[l] < 0) continue;
      for (std::size_t s = s0; s < s1 && std::size_t(echo[l]) + s < d[ax]; ++s) {
        const std::size_t i = at(l, std::size_t(echo[l]) + s);
        if (is_scanned(i)) at_s[s - s0].push_back(lp[i]);
      }
    }
    for (std::size_t s = s0; s < s1; ++s) {
      auto& x = at_s[s - s0];
      lines_at[s] = x.size();
      if (x.empty()) continue;
      std::nth_element(x.begin(), x.begin() + long(x.size() / 2), x.end());
      median_at[s] = double(x[x.size() / 2]);
    }
  });
  std::vector<double> Q;  // up to the first depth too few lines reach
  for (std::size_t s = 0; s < S; ++s) {
    if (double(lines_at[s]) < 0.25 * double(rep.lines)) break;
    Q.push_back(median_at[s]);
  }
  const auto argext = [&](std::size_t a, std::size_t b, bool max) {  // [a, b], b < Q.size()
    std::size_t k = a;
    for (std::size_t s = a + 1; s <= b; ++s)
      if (max ? Q[s] > Q[k] : Q[s] < Q[k]) k = s;
    return k;
  };
  if (Q.size() <= smin + 1) return done();
  const std::size_t s1 = argext(smin, std::min(smax, Q.size() - 1), true);
  const std::size_t t1 = argext(1, s1 - 1, false);
  rep.echo = Q[0], rep.copy1 = Q[s1], rep.trough = Q[t1], rep.spacing_mm = double(s1) * h;
  const double rise = Q[0] - Q[t1];
  if (!(rise > 0) || Q[s1] - Q[t1] < params.min_copy * rise) return done();
  // Between an echo and its first copy the line goes dark: what lies under a
  // strong specular reflector is in its shadow. Bright texture under the
  // first echo (the inside of an object) has bumps of any spacing but no
  // such gap (randomised face 106: trough 0.43 of the way from the echo down
  // to the median, the flat reflector of IMLiF 0.81).
  if (rise < params.min_gap * (Q[0] - lo)) return done();
  const auto lo2 = std::size_t(std::lround(double(s1) * (2.0 - params.tolerance)));
  const auto hi2 = std::min(Q.size() - 1, std::size_t(std::lround(double(s1) * (2.0 + params.tolerance))));
  if (lo2 <= s1 + 1 || lo2 > hi2) return done();
  const std::size_t s2 = argext(lo2, hi2, true);
  const std::size_t t2 = argext(s1 + 1, s2 - 1, false);
  rep.copy2 = Q[s2];
  if (Q[s2] > Q[s1] || Q[s2] - Q[t2] < params.min_second * (Q[0] - Q[t2])) return done();
  // The second copy is a bump, as the first is: within 2 x tolerance x s1
  // after it Q falls back by half its rise. A profile still rising there is
  // the gain rising with depth (a time-gain compensation stronger than the
  // attenuation), and skin, fat and fascia over it make a train of an echo,
  // a gap and a "copy" (found on an independent simulator's spine scans:
  // the whole volume under the skin was removed, bones and all).
  if (params.second_peak) {
    const auto after = std::max<std::size_t>(2, std::size_t(std::lround(2.0 * params.tolerance * double(s1))));
    const std::size_t reach = std::min(Q.size() - 1, s2 + after);
    if (reach <= s2 || Q[argext(s2 + 1, reach, false)] > Q[s2] - 0.5 * (Q[s2] - Q[t2])) return done();
  }
  // Found: the region starts where the echo's lower flank falls halfway to
  // the trough.
  std::size_t cut = 1;
  while (cut < t1 && Q[cut] >= Q[t1] + 0.5 * rise) ++cut;
  rep.found = true;
  rep.cut_mm = double(cut) * h;
  for (std::size_t l = 0; l < lines; ++l) {
    if (echo[l] < 0) continue;
    for (std::size_t p = std::size_t(echo[l]) + cut; p < d[ax]; ++p) {
      const std::size_t i = at(l, p);
      if (is_scanned(i)) region[i] = 1, ++rep.voxels;
    }
  }
  return done();
}

std::size_t clip_depth(const Volume& v, std::vector<std::uint8_t>& scanned, int ax, double min_mm, double max_mm) {
  const Dims3& d = v.dims;
  const std::size_t n = v.voxels();
  if (ax < 0 || ax > 2) throw std::invalid_argument("clip_depth: beam axis must be 0, 1 or 2");
  if (scanned.empty()) scanned.assign(n, 1);
  if (scanned.size() != n) throw std::invalid_argument("clip_depth: mask size differs from the volume");
  const int u_ax = ax == 0 ? 1 : 0, w_ax = ax == 2 ? 1 : 2;
  const std::size_t stride[3] = {1, d[0], d[0] * d[1]};
  const double h = v.spacing[ax];
  std::size_t clipped = 0;
  for (std::size_t b = 0; b < d[w_ax]; ++b)
    for (std::size_t a = 0; a < d[u_ax]; ++a) {
      const std::size_t base = a * stride[u_ax] + b * stride[w_ax];
      long skin = -1;
      for (std::size_t p = 0; p < d[ax]; ++p) {
        const std::size_t i = base + p * stride[ax];
        if (!scanned[i]) continue;
        if (skin < 0) skin = long(p);
        const double depth = double(long(p) - skin) * h;
        if (depth < min_mm || depth >= max_mm) scanned[i] = 0, ++clipped;
      }
    }
  return clipped;
}

void mask_detail::relowpass_planes(const Volume& v, const std::vector<std::uint8_t>& scanned,
                      const std::vector<std::uint8_t>& changed, int ax, double sigma_mm, int threads,
                      HostVector<float>& lp) {
  const Dims3& d = v.dims;
  // The planes [k0, k1) along ax that hold a changed voxel (per z-plane in
  // memory order over the threads, a plane's own extent along ax joined).
  const int parts = range_count(d[2], host_threads(threads));
  std::vector<std::size_t> pk0(std::size_t(parts), d[ax]), pk1(std::size_t(parts), 0);
  parallel_ranges_indexed(d[2], host_threads(threads), [&](int k, std::size_t z0, std::size_t z1) {
    std::size_t a = d[ax], b = 0;
    for (std::size_t z = z0; z < z1; ++z)
      for (std::size_t y = 0; y < d[1]; ++y) {
        const std::uint8_t* row = changed.data() + (z * d[1] + y) * d[0];
        std::size_t x0 = 0;
        while (x0 < d[0] && !row[x0]) ++x0;
        if (x0 == d[0]) continue;
        std::size_t x1 = d[0];
        while (!row[x1 - 1]) --x1;
        const std::size_t c0[3] = {x0, y, z}, c1[3] = {x1 - 1, y, z};
        a = std::min(a, c0[ax]), b = std::max(b, c1[ax] + 1);
      }
    pk0[std::size_t(k)] = a, pk1[std::size_t(k)] = b;
  });
  const std::size_t k0 = *std::min_element(pk0.begin(), pk0.end()), k1 = *std::max_element(pk1.begin(), pk1.end());
  if (k0 >= k1) return;
  // In place in lp (it was a slab of the volume copied out, filtered and
  // copied back: three serial copies and two arrays more).
  lowpass_planes(v, scanned.data(), ax, sigma_mm, host_threads(threads), lp.data(), k0, k1);
}

NearFieldReport remove_near_field(const Volume& v, std::vector<std::uint8_t>& scanned, const NearFieldParams& params) {
  NearFieldReport rep;
  std::vector<std::uint8_t> band;
  // The reverberation rule reads the same lowpass across the beam as the
  // band, of the mask without the band. It never mixes depths along the
  // beam, so only the planes across the beam that hold band voxels change:
  // those are lowpassed again, in place (the same sums per voxel, the same
  // bits), and the rest is the band's. Only with the same sigma. Without a
  // mask (every voxel scanned) the lowpass adds the same terms in the same
  // order as under a mask of ones (normalised_taps), so the band's lowpass
  // serves there too, and a band found then makes the mask a plane at a
  // time as before.
  HostVector<float> lp;
  const bool share = params.band && params.reverb && params.reverb_params.sigma_mm == params.sigma_mm;
  if (params.band)
    band = near_field_band(v, scanned.empty() ? nullptr : &scanned, params, &rep, share ? &lp : nullptr);
  else
    rep.axis = params.axis >= 0 && params.axis < 3 ? params.axis
                                                   : beam_axis_of(v, scanned.empty() ? nullptr : &scanned, params.threads);
  if (rep.found) {
    if (scanned.empty()) scanned.assign(v.voxels(), 1);
    for (std::size_t i = 0; i < band.size(); ++i)
      if (band[i]) scanned[i] = 0;
    if (!lp.empty()) mask_detail::relowpass_planes(v, scanned, band, rep.axis, params.sigma_mm, params.threads, lp);
  }
  if (params.reverb) {
    const std::vector<std::uint8_t> region =
        reverberation_region(v, scanned.empty() ? nullptr : &scanned, rep.axis, params.reverb_params, &rep.reverb,
                             params.threads, lp.empty() ? nullptr : &lp);
    if (rep.reverb.found) {
      if (scanned.empty()) scanned.assign(v.voxels(), 1);
      for (std::size_t i = 0; i < region.size(); ++i)
        if (region[i]) scanned[i] = 0;
    }
  }
  return rep;
}

}  // namespace softshell
