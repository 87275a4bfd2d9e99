// Shells on a bright echo's crest (docs/parameters.md, "The echo's crest";
// `classify --echo-crest`, on by default in classify and view):
// a bone (or any hard reflector) seen from above is a bright ridge along the
// beam whose lower flank falls into its shadow. The levelled isovalue is
// crossed twice, on the ridge's rise and on its fall, and the fall -- the
// steeper, longer edge into the shadow -- draws the shell a millimetre or
// two under the surface, which lies at the crest or above it. Where a ridge
// stands out from the data (its crest among the brightest voxels, rising from
// above by a share of its fall, standing above the isovalue by a share of
// the fall's depth under it, the fall crossing the isovalue within reach into
// a shadow that lasts to the end of the line, and as strong an edge as the
// data's strong ones), F_iso is re-centred on
// the crest: its lowpassed v and |grad v| are replaced, over the ridge, by a
// ramp whose zero (after the shell shift) lies at the crest, so F_iso's
// squared distance is the distance to the crest along the beam.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "volume.hpp"

namespace softshell {

// classify's and view's default ridge (--echo-crest): chosen on the
// cross-check's seeds 1-12 and 541-552 (docs/parameters.md, "The echo's
// crest"). The library's VariationalParams keep the rule off.
constexpr double kEchoCrestRidge = 0.25;

struct CrestParams {
  double ridge = 0.25;      // the rise from above at least this x the fall below (0: the rule off)
  double quantile = 0.97;   // the crest at least this quantile of the scanned voxels' lowpassed v
  double reach_mm = 3.0;    // the fall crosses the isovalue within this far under the crest
  double above_mm = 2.0;    // the rise is measured over this far above the crest
  double pad_mm = 1.5;      // the ramp reaches this far above the crest and below the crossing
  double min_edge = 0.5;    // the fall's steepest |grad v| at least this x g_ref
  // The fall leads into a shadow: the line stays under the isovalue from
  // the crossing to the end of its scanned part. A cyst's top wall has its
  // far wall (and the brighter tissue behind it) below; a bone its shadow.
  bool shadow = true;
  // The crest stands above the isovalue by at least this x the fall's
  // depth under it (crest - iso >= lift (iso - low)): an echo, not a
  // speckle grain that just reaches the isovalue. 0: not asked.
  double lift = 0.5;
  int axis = 2;             // the beam axis (0 x, 1 y, 2 z); depth grows with the index
};

struct CrestReport {
  std::size_t crests = 0;   // beam-line crests re-centred
  std::size_t voxels = 0;   // voxels whose F_iso terms were replaced
  double threshold = 0;     // the quantile's lowpassed v (normalised)
};

// vs: the lowpassed v (v~, normalised); grad2: |grad v|^2 as the densities
// take it (per mm^2); fixed: 1 where u is held at 0. Both are changed in
// place over each ridge: vs = v_iso + shift_mm G + G d, grad2 = max(grad2, G^2),
// with d the signed distance (mm) from the crest along the beam and G the
// fall's steepest |grad v|. threads: host threads (0: every core); the
// result is the same for any count.
//
// changed (optional): the voxels whose values were replaced, with their
// values before (index, v~, |grad v|^2), so a caller can restore them; in
// the order of the lines, the same for any thread count.
struct CrestChanges {
  std::vector<std::size_t> index;
  std::vector<float> vs, grad2;
};
CrestReport crest_shells(std::vector<float>& vs, std::vector<float>& grad2, const std::vector<std::uint8_t>& fixed,
                         const Dims3& dims, const Vec3d& spacing, double v_iso, double shift_mm, double g_ref,
                         const CrestParams& p, int threads = 0, CrestChanges* changed = nullptr);

}  // namespace softshell
