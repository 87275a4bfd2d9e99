// Surface-quality metrics of an opacity volume against a ground-truth signed
// distance field (`softshell evaluate`). Definitions: docs/metrics.md.
#pragma once

#include <array>
#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "volume.hpp"

namespace softshell {

// The paper's "negligibly small" opacity (Section 4: "typically over 80 percent of the voxels
// are either zero, or have a negligibly small value"): u above it counts as opaque in the
// Table 1 sense (percent_opaque, classify's summary, bench's Table 1). docs/metrics.md.
inline constexpr double kOpaqueLevel = 0.05;

struct MetricsParams {
  double threshold = 0.2;   // splat threshold: u > threshold is drawn
  double tolerance = 2.0;   // voxels: "near a true surface"
  // > 0: the tolerance in mm, overriding `tolerance`; it becomes tolerance_mm / (smallest
  // spacing) voxels. 0: `tolerance` (voxels) is used as given.
  double tolerance_mm = 0;
  double opaque = kOpaqueLevel;  // u > opaque counts toward % opaque
  double u_ind = 1.0;       // the opacity a surface should reach: surface_peak is a fraction of it
  double blob_rel = 0.2;    // 6-connected blobs: u > blob_rel * max(u), in (0, 1]
  double facing_cos = 0.3;  // a surface voxel faces the transducer if n . (-beam) >= facing_cos
  std::array<double, 3> beam{0, 0, 1};
  // How splats are oriented, hence which normal is scored: > 0 = the
  // principal eigenvector of the structure tensor of u with this Gaussian
  // sigma in voxels (the renderer's default, host/orientation.hpp); 0 = grad u
  // by central differences (the paper's orientation).
  double tensor_sigma = 1.5;
  // Orientation by the data (`render --orientation data`): the data's
  // orientation field (host/orientation.hpp, data_orientation_field; same
  // dims as u), whose structure tensor (tensor_sigma > 0) gives the normal
  // instead of u's. Null: u orients.
  const Volume* orientation_field = nullptr;
  // Visibility (recall_visible): a volume of the two-way shadow loss in dB
  // (the phantom's shadow_db.nrrd, same dims as the truth) and the loss
  // below which a surface voxel counts as visible. Null: recall_visible is
  // not computed.
  const Volume* shadow_db = nullptr;
  double visible_db = 20.0;
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
  // With MetricsParams::shadow_db: recall over the facing surface voxels
  // whose shadow loss is below visible_db (ultrasound cannot see a surface in
  // full acoustic shadow); NaN (JSON null) without it, or when none is visible.
  double recall_visible = std::numeric_limits<double>::quiet_NaN();
  std::size_t visible_surface_voxels = 0;
  // The same restriction for surface_peak and f1 (2 precision recall_visible /
  // (precision + recall_visible)); NaN exactly when recall_visible is.
  double surface_peak_visible = std::numeric_limits<double>::quiet_NaN();
  double f1_visible = std::numeric_limits<double>::quiet_NaN();
  std::size_t normal_voxels = 0;    // drawn voxels near a true surface that entered normal_error_deg
  std::size_t spurious_voxels = 0;  // drawn voxels in spurious blobs

  // Metrics that see all of u, not only what exceeds the splat threshold (docs/metrics.md).
  double mass_precision = 0;       // share of all opacity (sum of u, no threshold) near a true surface
  double f1 = 0;                   // 2 precision recall / (precision + recall)
  double f1_mass = 0;              // the same with mass_precision
  double surface_peak = 0;         // median over the facing surface voxels of the profile's peak / u_ind
  double shell_thickness_mm = 0;   // median full width at half maximum of u along the true normal, mm
  std::size_t thickness_points = 0;    // facing surface voxels whose width entered the median
  std::size_t thickness_censored = 0;  // of those, with a half-maximum crossing beyond the window:
                                       // their width entered as the lower bound the window gives
  // Where across the surface the shell lies: the median over the uncensored
  // thickness points of the middle of their half-maximum interval, mm along
  // the true outward normal (toward positive SDF; + outside, - inside).
  // NaN (JSON null) when no point has an uncensored interval.
  double shell_offset_mm = std::numeric_limits<double>::quiet_NaN();
  std::size_t offset_points = 0;   // the points that entered it
  std::size_t blobs6 = 0;          // 6-connected components of u > blob_threshold never near a true surface
  std::size_t components6 = 0;     // all 6-connected components of u > blob_threshold
  double blob6_voxel_share = 0;    // voxels in those blobs / voxels with u > blob_threshold

  // The parameters as resolved against the data.
  double tolerance = 0;            // voxels
  double tolerance_mm = 0;         // tolerance * smallest spacing
  double blob_threshold = 0;       // blob_rel * max(u)
  double profile_radius_mm = 0;    // the thickness profile's half-length R
};

// Throws InputError when the volumes' dims differ, when a parameter is out of
// range (threshold, tolerance, tolerance_mm, opaque finite and >= 0; u_ind
// finite and > 0; blob_rel in (0, 1]; facing_cos in [-1, 1]; beam finite and
// non-zero) or when a sample is not finite. Uses up to
// hardware_concurrency threads; the result does not depend on their number.
Metrics evaluate_opacity(const Volume& opacity, const Volume& truth_sdf, const MetricsParams& params = {});

// One JSON object, one line: the Metrics fields and the parameters used
// (threshold, tolerance and tolerance_mm as resolved, facing_cos, beam as the
// unit vector, ...).
std::string metrics_json(const Metrics& m, const MetricsParams& p);

namespace metrics_detail {
// Exact squared Euclidean distance, in voxels, from every voxel to the
// nearest voxel with mask != 0 (Felzenszwalb-Huttenlocher, separable, O(N));
// +infinity everywhere when the mask is empty. Exposed for tests.
std::vector<float> squared_edt(const std::vector<unsigned char>& mask, const Dims3& dims);
}  // namespace metrics_detail

}  // namespace softshell
