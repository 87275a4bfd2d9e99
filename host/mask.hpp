// The scanned-region mask of freehand 3D ultrasound (docs/numerics.md,
// "Masked (unscanned) voxels"; docs/real-data.md): which voxels hold data and
// which the probe never swept. One byte per voxel, x fastest like Volume:
// 1 = scanned (free in the classifier), 0 = unscanned (u held at 0).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "volume.hpp"

namespace softshell {

// The rule (docs/real-data.md, "The mask"):
//  1. zero fill: the voxels exactly equal to 0, kept only where a whole
//     (2 solid + 1)^3 cube of them fits (a morphological opening; outside the
//     volume counts as zero). Dark speckle never fills such a cube — the
//     phantoms' fluid, 25-30 % exact zeros, has no 5^3 block — while the
//     unswept part of a freehand reconstruction is solid. Without this step
//     speckle zeros percolate into one boundary-touching region.
//  2. its 6-connected regions that touch the volume boundary and hold at
//     least min_fraction of all voxels are unscanned;
//  3. they reclaim the zero voxels 6-connected to them within `solid`
//     steps (the ragged edge of the fill that no cube fits into);
//  4. then grow by `grow` voxels (6-neighbour dilation) over the
//     partial-volume rim that the reconstruction leaves at the sweep edge:
//     on the PLUS spine sweep the first scanned layer is dim (median 72
//     against 226 deeper, in the bright near field) and the second still
//     partly so, and with a 1-voxel growth the classifiers still draw the
//     lateral sweep edge (docs/real-data.md), so 2.
struct MaskParams {
  double min_fraction = 0.01;
  int solid = 2;  // cube half-width of step 1, voxels (0: every zero voxel, the plain rule)
  int grow = 2;
};

struct MaskReport {
  std::size_t zeros = 0;              // voxels exactly 0
  std::size_t regions = 0;            // solid zero regions that touch the boundary
  std::size_t unscanned_regions = 0;  // of those, the ones at least min_fraction large
  std::size_t zero_fill = 0;          // unscanned voxels before growing (all exact zeros)
  std::size_t unscanned = 0;          // after growing
};

// The mask derived from the zero fill; deterministic, iterative (no
// recursion), O(voxels) time and a few bytes per voxel.
std::vector<std::uint8_t> scanned_mask(const Volume& v, const MaskParams& params = {}, MaskReport* report = nullptr);

// A mask from a volume file: nonzero voxels are scanned. Throws InputError
// naming `path` when its dims differ from `dims`.
std::vector<std::uint8_t> read_mask(const std::string& path, const Dims3& dims);

// A copy of `v` whose unscanned samples continue the scanned data: each
// unscanned voxel, in order of its 6-neighbour distance to the scanned
// region, takes the mean of its face neighbours one step nearer. The lowpass
// v~ and the gradients then see no step at the edge of the sweep (the zero
// fill would otherwise read as a strong boundary a few voxels into the
// scan); the classifiers still hold u = 0 there. `depth` > 0 stops after
// that many layers (the rest keeps its samples).
Volume fill_unscanned(const Volume& v, const std::vector<std::uint8_t>& mask, int depth = 0);
// The same, in place: no second copy of the volume (the CLI's classify).
void fill_unscanned_in_place(Volume& v, const std::vector<std::uint8_t>& mask, int depth = 0);

// Number of unscanned (0) entries.
std::size_t count_unscanned(const std::vector<std::uint8_t>& mask);

// 6-neighbour dilation of the unscanned set by `voxels` layers (in place);
// with `within`, only into voxels where (*within)[i] != 0.
void grow_unscanned(std::vector<std::uint8_t>& mask, const Dims3& dims, int voxels,
                    const std::vector<std::uint8_t>* within = nullptr);

}  // namespace softshell
