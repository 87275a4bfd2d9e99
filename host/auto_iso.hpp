// `--iso auto`: an isovalue picked from the data (docs/real-data.md,
// "Automatic isovalue").
//
// Two rules, both on the lowpassed volume v~ (speckle averaged out) over the
// scanned voxels:
//  - EchoRidge (the default, for the variational classifier): ultrasound
//    draws a boundary as a bright echo layer, and the variational shell sits
//    best on its crest (docs/parameters.md). From every strong-edge voxel
//    (|grad v~| in the top 5 %) climb v~ through the 26 neighbours, at most 6
//    steps, to the crest of the echo; the median crest value is v_iso.
//  - Edge (for Levoy's contours): the value at which the boundaries lie,
//    found the way Kindlmann and Durkin (1998) find boundaries for transfer
//    functions: across a boundary blurred by the imaging, |grad v| peaks
//    midway between the two materials; the mean |grad v~| is taken per value
//    bin and the bin where it peaks is the isovalue.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "volume.hpp"

namespace softshell {

enum class AutoIsoRule { EchoRidge, Edge };

struct AutoIsoParams {
  AutoIsoRule rule = AutoIsoRule::EchoRidge;
  double edge_share = 0.05;  // share of usable voxels, by |grad v~|, that seed the climb to the echo crest
  int climb_steps = 6;       // voxels climbed at most from an edge voxel to its crest
  double sigma_mm = 1.0;        // lowpass of v~, at least 1 voxel per axis
  int bins = 64;                // over the range of v~ in the scanned voxels
  double min_bin_share = 0.001; // bins with fewer voxels than this share are ignored
};

struct AutoIsoReport {
  double iso = 0;                     // file units, by the rule asked for
  double edge_iso = 0, ridge_iso = 0; // both rules' values
  std::size_t crests = 0;             // strong-edge voxels that climbed to a crest
  double lo = 0, hi = 0;              // range of v~ binned
  std::vector<double> mean_gradient;  // per bin, per mm (NaN where too few voxels)
  std::vector<std::size_t> count;     // voxels per bin
  std::size_t voxels = 0;             // voxels that entered
};

// v_iso in the file's units. `mask` (optional, 1 = scanned) limits the
// statistics to scanned voxels whose six neighbours are scanned too, and the
// lowpass to scanned samples (normalised convolution), so the edge of the
// sweep does not count as a boundary. Throws InputError when no voxel is
// usable (an empty mask, a volume thinner than 3 voxels) or v~ is constant.
double auto_iso(const Volume& v, const std::vector<std::uint8_t>* mask, const AutoIsoParams& params = {},
                AutoIsoReport* report = nullptr);

}  // namespace softshell
