// Surface-quality metrics of an opacity volume against a ground-truth signed
// distance field (`softshell evaluate`). Definitions: docs/metrics.md.
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "volume.hpp"

namespace softshell {

struct MetricsParams {
  double threshold = 0.2;   // splat threshold: u > threshold is drawn
  double tolerance = 2.0;   // voxels: "near a true surface"
  double opaque = 0.01;     // u > opaque counts toward % opaque
  double facing_cos = 0.3;  // a surface voxel faces the transducer if n . (-beam) >= facing_cos
  std::array<double, 3> beam{0, 0, 1};
  // How splats are oriented, hence which normal is scored: > 0 = the
  // principal eigenvector of the structure tensor of u with this Gaussian
  // sigma in voxels (the renderer's default, host/orientation.hpp); 0 = grad u
  // by central differences (the paper's orientation).
  double tensor_sigma = 1.5;
};

struct Metrics {
  double precision = 0;        // opacity-weighted share of drawn opacity near a true surface
  double recall = 0;           // share of facing surface voxels with a drawn voxel within tolerance
  std::size_t spurious_blobs = 0;  // drawn 26-connected components never near a true surface
  std::size_t components = 0;      // all drawn components
  double normal_error_deg = 0;     // opacity-weighted mean angle between grad u and the true normal
  double percent_opaque = 0;       // 100 * share of voxels with u > opaque
  std::size_t splats = 0;          // voxels with u > threshold
  std::size_t facing_surface_voxels = 0;
  std::size_t normal_voxels = 0;    // drawn voxels near a true surface that entered normal_error_deg
  std::size_t spurious_voxels = 0;  // drawn voxels in spurious blobs
};

// Throws InputError when the volumes' dims differ, when a parameter is out of
// range (threshold, tolerance, opaque finite and >= 0; facing_cos in [-1, 1];
// beam finite and non-zero) or when a sample is not finite. Uses up to
// hardware_concurrency threads; the result does not depend on their number.
Metrics evaluate_opacity(const Volume& opacity, const Volume& truth_sdf, const MetricsParams& params = {});

// One JSON object, one line: the Metrics fields and the parameters used
// (threshold, tolerance, facing_cos, beam as the unit vector).
std::string metrics_json(const Metrics& m, const MetricsParams& p);

namespace metrics_detail {
// Exact squared Euclidean distance, in voxels, from every voxel to the
// nearest voxel with mask != 0 (Felzenszwalb-Huttenlocher, separable, O(N));
// +infinity everywhere when the mask is empty. Exposed for tests.
std::vector<float> squared_edt(const std::vector<unsigned char>& mask, const Dims3& dims);
}  // namespace metrics_detail

}  // namespace softshell
