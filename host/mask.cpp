// The scanned-region mask: a morphological opening of the exact zeros,
// flood fill of its boundary-touching regions with a size rule, and
// 6-neighbour growth (host/mask.hpp gives the rule).
#include "mask.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "error.hpp"
#include "io.hpp"
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

// One axis of a binary cube filter with half-width r, in place on `a`:
// erode (all of [i - r, i + r] set; outside the volume counts as set) or
// dilate (any of them set). Running counts along each line, O(voxels).
void filter_axis(std::vector<std::uint8_t>& a, const Dims3& d, int axis, int r, bool erode) {
  const std::size_t stride = axis == 0 ? 1 : (axis == 1 ? d[0] : d[0] * d[1]);
  const std::size_t len = d[axis];
  std::vector<std::uint8_t> line(len);
  std::vector<std::size_t> prefix(len + 1);
  const std::size_t lines = a.size() / len;
  for (std::size_t l = 0; l < lines; ++l) {
    // Start of line l: enumerate the voxels with coordinate 0 along `axis`.
    std::size_t start;
    if (axis == 0) start = l * d[0];
    else if (axis == 1) start = (l % d[0]) + (l / d[0]) * d[0] * d[1];
    else start = l;
    for (std::size_t i = 0; i < len; ++i) {
      line[i] = a[start + i * stride];
      // count of voxels that break the test: unset ones for erosion, set for dilation
      prefix[i + 1] = prefix[i] + ((line[i] != 0) != erode ? 1 : 0);
    }
    for (std::size_t i = 0; i < len; ++i) {
      const std::size_t lo = i >= std::size_t(r) ? i - r : 0, hi = std::min(len, i + r + 1);
      const bool any_break = prefix[hi] - prefix[lo] > 0;
      a[start + i * stride] = erode ? !any_break : any_break;
    }
  }
}

void cube_filter(std::vector<std::uint8_t>& a, const Dims3& d, int r, bool erode) {
  for (int axis = 0; axis < 3; ++axis) filter_axis(a, d, axis, r, erode);
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

  // 1. The exact zeros, opened by the cube.
  std::vector<std::uint8_t> zero(n);
  for (std::size_t i = 0; i < n; ++i) zero[i] = v.data[i] == 0.0f ? 1 : 0;
  rep.zeros = static_cast<std::size_t>(std::count(zero.begin(), zero.end(), std::uint8_t{1}));
  std::vector<std::uint8_t> solid = zero;
  if (params.solid > 0) {
    cube_filter(solid, d, params.solid, true);
    cube_filter(solid, d, params.solid, false);
  }

  // 2. Flood fill of the solid regions from the volume's faces. state: 0 not
  // visited, 1 visited (region too small or being measured), 2 unscanned.
  enum : std::uint8_t { kFree = 0, kSeen = 1, kUnscanned = 2 };
  std::vector<std::uint8_t> state(n, kFree);
  std::vector<std::size_t> stack;
  auto fill = [&](std::size_t seed, std::uint8_t from, std::uint8_t to) {
    std::size_t size = 0;
    stack.clear();
    stack.push_back(seed);
    state[seed] = to;
    while (!stack.empty()) {
      const std::size_t i = stack.back();
      stack.pop_back();
      ++size;
      for_face_neighbours(d, i, [&](std::size_t j) {
        if (state[j] == from && solid[j]) {
          state[j] = to;
          stack.push_back(j);
        }
      });
    }
    return size;
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
        if (fill(i, kFree, kSeen) >= min_size) {
          ++rep.unscanned_regions;
          fill(i, kSeen, kUnscanned);
        }
      }
  std::vector<std::uint8_t> mask(n);
  for (std::size_t i = 0; i < n; ++i) mask[i] = state[i] == kUnscanned ? 0 : 1;

  // 3. The ragged edge of the fill: zeros within `solid` steps through zeros.
  if (rep.unscanned_regions > 0) grow_unscanned(mask, d, params.solid, &zero);
  rep.zero_fill = count_unscanned(mask);
  // 4. The partial-volume rim.
  if (rep.unscanned_regions > 0) grow_unscanned(mask, d, params.grow);
  rep.unscanned = count_unscanned(mask);
  if (report) *report = rep;
  return mask;
}

void grow_unscanned(std::vector<std::uint8_t>& mask, const Dims3& d, int voxels, const std::vector<std::uint8_t>* within) {
  const std::size_t n = d[0] * d[1] * d[2];
  if (mask.size() != n || (within && within->size() != n))
    throw std::invalid_argument("grow_unscanned: mask size differs from dims");
  if (voxels <= 0) return;
  auto may_take = [&](std::size_t j) { return mask[j] != 0 && (!within || (*within)[j] != 0); };
  // Frontier: unscanned voxels with a face neighbour that may be taken; each
  // layer takes the neighbours of the frontier.
  std::vector<std::size_t> frontier, next;
  for (std::size_t i = 0; i < n; ++i) {
    if (mask[i] != 0) continue;
    bool edge = false;
    for_face_neighbours(d, i, [&](std::size_t j) { edge = edge || may_take(j); });
    if (edge) frontier.push_back(i);
  }
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

Volume fill_unscanned(const Volume& v, const std::vector<std::uint8_t>& mask, int depth) {
  Volume out = v;
  fill_unscanned_in_place(out, mask, depth);
  return out;
}

void fill_unscanned_in_place(Volume& out, const std::vector<std::uint8_t>& mask, int depth) {
  const Dims3& d = out.dims;
  const std::size_t n = out.voxels();
  if (mask.size() != n) throw std::invalid_argument("fill_unscanned: mask size differs from the volume");
  // done: scanned or filled in an earlier layer.
  std::vector<std::uint8_t> done(mask);
  std::vector<std::size_t> layer, next;
  for (std::size_t i = 0; i < n; ++i) {
    if (done[i]) continue;
    bool edge = false;
    for_face_neighbours(d, i, [&](std::size_t j) { edge = edge || done[j]; });
    if (edge) layer.push_back(i);
  }
  std::vector<float> value(layer.size());
  for (int k = 0; !layer.empty() && (depth <= 0 || k < depth); ++k) {
    // Values first, from earlier layers only, so the order within a layer
    // does not matter (deterministic).
    value.resize(layer.size());
    for (std::size_t a = 0; a < layer.size(); ++a) {
      double s = 0;
      int c = 0;
      for_face_neighbours(d, layer[a], [&](std::size_t j) {
        if (done[j]) s += out.data[j], ++c;
      });
      value[a] = static_cast<float>(s / c);
    }
    for (std::size_t a = 0; a < layer.size(); ++a) out.data[layer[a]] = value[a], done[layer[a]] = 1;
    next.clear();
    for (std::size_t i : layer)
      for_face_neighbours(d, i, [&](std::size_t j) {
        if (!done[j]) done[j] = 2, next.push_back(j);  // 2: queued
      });
    for (std::size_t j : next) done[j] = 0;
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

}  // namespace softshell
