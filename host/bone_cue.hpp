// The bone cue (docs/numerics.md, "The bone cue"; issue 13): in ultrasound a
// bone surface is a bright ridge with an acoustic shadow beneath it along the
// beam. Per voxel, the score compares the lowpassed data with the mean of the
// lowpassed data a few mm further down the beam, in units of the data's
// robust spread; the classifier's edge strength |grad v| is then weighted by
// a smooth step of that score (VariationalParams::edge_weight), so F_ind pulls
// u toward u_ind only on bright echoes with a shadow beneath them, and the
// walls of the shadows, muscle fascia and speckle are not drawn.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "volume.hpp"

namespace softshell {

struct BoneCueParams {
  int axis = 2;                  // beam axis (0 x, 1 y, 2 z); depth grows with the index along it
  double sigma_mm = 1.0;         // Gaussian lowpass (mm) of the data before the comparison
  // The window below the voxel along the beam, from ... to ... mm: the
  // voxel is compared with the mean of v~ there.
  double below_from_mm = 1.5;
  double below_to_mm = 10.0;
  // Also compare the voxel with its surroundings at the same depth: the
  // mean of v~ over a square of half-width lateral_mm across the beam; the
  // score is the smaller of the two differences.
  bool depth_term = true;
  double lateral_mm = 10.0;
  // The weight: floor below score_lo, 1 above score_hi, a smooth step
  // between (scores in units of the spread, the data's q90 - q10).
  double score_lo = 0.12, score_hi = 0.4;
  double floor = 0.0;
  double reach_mm = 3.0;         // the weight reaches this far up the beam from a scored voxel
  // The automatic rule (bone_cue_auto): among the strong-edge voxels (the
  // top auto_edge_share of |grad v~|), those whose gradient lies within
  // acos(auto_beam_cos) of the beam are counted as falling (brighter above:
  // an echo over a shadow) or rising (darker above: fluid over tissue); the
  // cue is on when falling >= auto_ratio x rising.
  double auto_edge_share = 0.03;
  double auto_beam_cos = 0.5;
  double auto_ratio = 2.0;
  int threads = 0;               // host threads (0: every core); the result is the same for any count
};

struct BoneCueReport {
  double spread = 0;             // q90 - q10 of the lowpassed scanned data (file units)
  double falling_share = 0;      // of the strong-edge voxels, brightness falling along the beam
  double rising_share = 0;       // ... rising along the beam
  std::size_t edge_voxels = 0;   // strong-edge voxels counted
  double weighted_share = 0;     // of the scanned voxels, the share with weight >= 0.5
  bool on = false;               // bone_cue_auto's decision
};

// The score per voxel (0 for unscanned voxels and where less than half of
// the window below lies in the scanned volume). `scanned` (optional, 1 =
// scanned) limits the window's samples and the spread to scanned voxels.
std::vector<float> bone_cue_score(const Volume& v, const std::vector<std::uint8_t>* scanned,
                                  const BoneCueParams& params = {}, BoneCueReport* report = nullptr);

// The weight of a score: floor + (1 - floor) smoothstep((s - lo) / (hi - lo)).
float bone_cue_weight_of(float score, const BoneCueParams& params);
// Per voxel, the largest weight of the scores within reach_mm below it
// along the beam (the shell sits on the echo's front flank, above its crest).
std::vector<float> bone_cue_weight(const Volume& v, const std::vector<float>& score, const BoneCueParams& params);

// The automatic rule: among the strong-edge voxels of the data (|grad v~|,
// central differences per mm, in the top auto_edge_share of the scanned
// voxels whose six neighbours are scanned; voxels with odd indices only, a
// subsample of one in eight), the shares whose gradient points
// up the beam (brightness falling with depth: a bright echo over a shadow,
// what bone looks like) and down it (rising: fluid over tissue, what a face
// looks like); on when falling >= auto_ratio x rising. Fills report.
bool bone_cue_auto(const Volume& v, const std::vector<std::uint8_t>* scanned, const BoneCueParams& params,
                   BoneCueReport* report);

// `--bone-cue off|on|auto` (classify, view, the studies).
enum class BoneCueMode { Off, On, Auto };
// false for an unknown name.
bool parse_bone_cue_mode(const std::string& name, BoneCueMode& mode);

// What classify does with the mode: Off -> null; On -> the weights of the
// score; Auto -> the weights when bone_cue_auto says so, else null. `v` is
// the data the classifier sees (unscanned samples filled, levelled).
std::shared_ptr<const std::vector<float>> bone_cue_weights(const Volume& v, const std::vector<std::uint8_t>* scanned,
                                                           BoneCueMode mode, const BoneCueParams& params = {},
                                                           BoneCueReport* report = nullptr);

namespace bone_cue_detail {
// Separable Gaussian lowpass on the host (clamped at the border, radius
// ceil(3 sigma) voxels per axis), used by the score. Exposed for tests.
std::vector<float> gaussian(const Volume& v, double sigma_mm, int threads = 0);
}  // namespace bone_cue_detail

}  // namespace softshell
