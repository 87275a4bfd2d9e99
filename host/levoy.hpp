// Levoy's isovalue-contour opacity classifier on the device
// (kernels/classify_levoy.cl), optionally on the lowpassed volume: the
// baseline the variational classifier is measured against.
#pragma once

#include "cl_runtime.hpp"
#include "volume.hpp"

namespace softshell {

struct LevoyParams {
  double iso = 0.5;        // isovalue, in the volume's own intensity units
  double thickness = 1.0;  // transition thickness r, in voxels (geometric-mean spacing)
  double sigma_mm = 0.0;   // lowpass before classifying (0: the raw volume)
  double alpha = 1.0;      // opacity on the isosurface (Levoy's alpha_v)
};

struct LevoyReport {
  double upload = 0, lowpass = 0, gradient = 0, classify = 0, download = 0;  // seconds
};

// Float opacity volume with the input's geometry. Throws InputError for
// out-of-range parameters.
Volume classify_levoy(Runtime& rt, const Volume& v, const LevoyParams& params, LevoyReport* report = nullptr);

// Levoy's r in millimetres for a thickness in voxels of this spacing.
double levoy_thickness_mm(double thickness_voxels, const Vec3d& spacing);

}  // namespace softshell
