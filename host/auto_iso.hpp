// `--iso auto`: an isovalue picked from the data (docs/real-data.md,
// "Automatic isovalue").
//
// Rule: the value at which the boundaries of the volume lie, found the way
// Kindlmann and Durkin (1998) find boundaries for transfer functions: across
// a boundary blurred by the imaging, |grad v| peaks at the value midway
// between the two materials. On the lowpassed volume v~ (speckle averaged
// out), over the scanned voxels, the mean |grad v~| is taken per value bin,
// and the bin where it peaks is the isovalue: the fluid/tissue midpoint of an
// obstetric scan, the flank of the bright echo of a bone surface.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "volume.hpp"

namespace softshell {

struct AutoIsoParams {
  double sigma_mm = 1.0;        // lowpass of v~, at least 1 voxel per axis
  int bins = 64;                // over the range of v~ in the scanned voxels
  double min_bin_share = 0.001; // bins with fewer voxels than this share are ignored
};

struct AutoIsoReport {
  double iso = 0;                     // file units
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
