// The speckle's size across the beam, from the data, and the gradient
// lowpass it asks for (docs/numerics.md, "The gradient's lowpass from the
// speckle"; issue 12). The edge strength |grad v| that weights the shell is
// taken from v lowpassed by --grad-sigma: wide enough to average the speckle
// out, and no wider, since a bone's echo is a thin bright ridge whose
// gradient falls as 1/sigma^2 once sigma passes its width (a step's falls as
// 1/sigma). On the randomised spines the best width followed the size of the
// scanner's point spread function across the beam (correlation 0.8); one
// width for every scan lost the fine-speckled ones. So the default is taken
// from the data: the correlation c of neighbouring samples of the data's fine
// detail (v minus its 1 mm Gaussian lowpass) along each axis across the beam,
// read as a Gaussian speckle of standard deviation s = h / sqrt(-4 ln c) (the
// correlation of a Gaussian-blurred white noise one spacing h apart), the
// smaller of the two (the lateral resolution; the elevation is coarser).
#pragma once

#include <cstdint>
#include <vector>

#include "volume.hpp"

namespace softshell {

struct SpeckleReport {
  bool measured = false;      // false: too few scanned neighbours, or no detail at all
  double sigma_mm = 0;        // the speckle's standard deviation across the beam, mm
  int axis = -1;              // the axis it was measured along (the finer of the two across the beam)
  double lag1[3] = {0, 0, 0};  // the neighbours' correlation along x, y, z (the beam axis's not measured: 0)
};

// The detail's lowpass (mm) and the fewest scanned neighbour pairs along an
// axis for a measurement.
constexpr double kSpeckleDetailMm = 1.0;
constexpr std::size_t kSpeckleMinPairs = 1000;

// Measures the speckle across the beam of `v` over the scanned voxels
// (`scanned`: one byte per voxel, nonzero scanned; null: all), `beam_axis`
// 0 x, 1 y, 2 z. The sums run over whole planes in a fixed order: the result
// does not depend on the thread count.
SpeckleReport speckle_size(const Volume& v, const std::vector<std::uint8_t>* scanned, int beam_axis, int threads = 0);

// --grad-sigma's default from the speckle: kGradSigmaPerSpeckle x its size,
// within [kGradSigmaMinMm, kGradSigmaMaxMm] (docs/parameters.md, "The
// gradient's lowpass from the speckle": chosen on the family's seeds 101-136
// and 801-830), each x `scale` (a small volume's length scales,
// small_volume_scale). Unmeasured: the upper bound, the earlier fixed default.
constexpr double kGradSigmaPerSpeckle = 3.0, kGradSigmaMinMm = 1.25, kGradSigmaMaxMm = 1.5;
double grad_sigma_from_speckle(const SpeckleReport& r, double scale = 1.0);

// The narrower lowpass serves thin echoes (bright over darker along the
// beam: bone over its shadow), not steps from dark to bright (fluid over a
// face or a head, a cyst's far wall): there it only lets more speckle read
// as edges (the cross-check's heads and cysts lost 0.01-0.05 with it). So it
// is taken only where the data's strong edges fall in brightness along the
// beam at least kGradSigmaEchoRatio x as often as they rise (the shares of
// the bone cue's automatic rule, bone_cue_auto; chosen on the family's
// training seeds and the cross-check's seeds 1-36); elsewhere
// kGradSigmaMaxMm.
constexpr double kGradSigmaEchoRatio = 1.25;

struct GradSigmaChoice {
  double sigma_mm = kGradSigmaMaxMm;  // --grad-sigma's default (x scale)
  double falling = 0, rising = 0;      // the strong edges' shares falling / rising along the beam
  bool echoes = false;                 // falling >= kGradSigmaEchoRatio x rising: the speckle measured
  SpeckleReport speckle;               // measured only when `echoes`
};

// --grad-sigma's default for the data the classifier sees (`v`, unscanned
// samples filled), `beam_axis` 0 x, 1 y, 2 z, `scale` a small volume's.
GradSigmaChoice auto_grad_sigma(const Volume& v, const std::vector<std::uint8_t>* scanned, int beam_axis,
                                double scale = 1.0, int threads = 0);

}  // namespace softshell
