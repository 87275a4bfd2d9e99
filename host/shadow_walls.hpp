// Shadow walls (docs/numerics.md, "Shadow walls"; issue 12): under a bright
// occluder (bone, a calcified or dense layer) ultrasound leaves an acoustic
// shadow, a dark column along the beam whose sides are strong edges across
// the beam. Those sides are no tissue boundary: on the randomised spines they
// were most of what the classifier drew (docs/parameters.md). Per voxel the
// weight is 1 - (smoothed) "wall": an edge whose gradient lies across the
// beam and whose dark side, a short step down the gradient, is in shadow --
// below the isovalue, some way below a voxel above the isovalue further up
// its beam line -- while its bright side, the same step up, is not, and is
// above the isovalue (where the classifier would draw the edge). It
// multiplies the classifier's edge strength like the bone cue's
// (VariationalParams::edge_weight); the reference edge gradient is then taken
// from the weighted edges (EdgeReference::Weighted, set_edge_weights below)
// unless the bone cue is on. The side of an object seen in fluid is no wall (the fluid
// beside it has nothing bright above it), nor is a bone's top (its gradient
// lies along the beam).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "cl_runtime.hpp"
#include "variational.hpp"
#include "volume.hpp"

namespace softshell {

struct ShadowWallParams {
  int axis = 2;                // the beam axis (0 x, 1 y, 2 z); depth grows with the index
  double sigma_mm = 1.5;       // the data lowpassed for the shadow test
  double grad_sigma_mm = 1.5;  // ... and for the edges' direction (as --grad-sigma; one lowpass when equal)
  double beam_cos = 0.5;       // an edge across the beam: |cos(grad, beam)| below this
  double reach_mm = 1.5;       // the dark side is probed this far down the gradient
  double smooth_mm = 0.5;      // the wall indicator's lowpass before the weight is taken
  double gap_mm = 6.0;         // shadow only this far below the deepest bright voxel above
  // ... or this far, where the shadow lasts: its beam stays under the
  // isovalue from the voxel to the end (in a fan along the fan's beams),
  // as under a bone; a cyst's inside has its far wall below. Chosen on the
  // cross-check's seeds 1-12 (docs/parameters.md, "A shadow that lasts").
  // At least gap_mm: the rule off (the shadow from gap_mm everywhere).
  double lasting_gap_mm = 3.0;
  // The bright side at most this far under the isovalue by the gradient
  // (its value above iso - bright_mm |grad v|). 0 (the default): above the
  // isovalue. Half the shell (1 mm) was tried and not kept
  // (docs/parameters.md, "Shadow walls beside tissue under the isovalue").
  double bright_mm = 0.0;
  // The bright side is probed at reach_mm and also at this share of it
  // (0 or 1: at reach_mm only). It counts as out of shadow, and as above
  // the isovalue, where either probe is: a strip of tissue narrower than
  // the reach between two shadows (the beam passing between two bones, a
  // spine's processes) had both its sides read as "shadow on the bright
  // side too", and its walls were drawn (docs/parameters.md, "Walls of a
  // strip between two shadows").
  double bright_near = 0.5;
  // Follow a fan's beams (fan_beams below: the scanned region's sides
  // spread out with depth, as a curvilinear or phased array's sector does):
  // the shadow is walked down each beam from the apex, and "across the beam"
  // is across the local beam. Without a fan (or with false) the beams run
  // along `axis`, as before.
  bool fan = true;
  // In a fan, a bright voxel occludes only from this far (mm, along its
  // beam) below the beam's first scanned voxel: the beams meet under the
  // probe, and the near field's bright remnants there lie on every one of
  // them (they shaded two thirds of some phantoms' sectors).
  double fan_skip_mm = 6.0;
  // The underside of a thin echo (docs/parameters.md, "The underside of a
  // thin echo"): with `underside` on, an edge falling in brightness along
  // the beam (|cos(grad, beam)| at least beam_cos) whose bright side
  // (reach_mm up its gradient) is above the isovalue and its dark side below,
  // and whose bright side falls under the isovalue again within
  // underside_mm up the beam, is marked like a wall. It is the far side of a
  // thin bright layer seen from dark fluid (a skull's echo over the brain),
  // not a surface. Off for bone echoes, where the layer's far side may be all
  // that can be drawn (underside_applies below decides).
  bool underside = false;
  double underside_mm = 3.0;
};

// Whether the data's strong edges are steps up from dark fluid (fluid over
// a head or a face) rather than echoes over darker data (bone over its
// shadow): they fall in brightness along the beam at most
// kUndersideFallRatio x as often as they rise (`falling`, `rising`: the
// shares of GradSigmaChoice, host/speckle.hpp). Chosen on the cross-check's
// seeds 1-12, 301-324 and 349-396 (heads 0.02-0.45, bones from 0.26) and the
// family's faces (0.09-0.34) and spines (from 0.74).
constexpr double kUndersideFallRatio = 0.2;
bool underside_applies(double falling, double rising);

// The beams of a fan: the apex (voxel coordinates, usually above the volume)
// and the axes across the beam along which the sector spreads. A beam runs
// from the apex through each voxel (the spreading axes' components; the
// others as along the beam axis).
struct FanBeams {
  bool found = false;
  double apex[3] = {0.0, 0.0, 0.0};
  bool spreads[3] = {false, false, false};
  double rms_voxels = 0.0;  // the sides' fit, the worse of the two on the axes that spread
};

// A fan from the scanned region (1 = scanned): per plane across the beam
// axis `axis`, the scanned voxels' first and last coordinate along each other
// axis; on the planes where a side lies inside the volume (off its faces),
// each side's coordinate is fitted by a line in depth (robustly: a shadow
// or a gap reaching the side on some planes is left out). An axis spreads
// when on both sides at least kFanMinPlanes planes, and half of the side's,
// lie on its line, within kFanMaxRms voxels of it; both sides widen with
// depth by at least kFanMinSlope (mm per mm), neither more than kFanMaxSkew
// times the other (a probe's sector is symmetric about its middle beam);
// and they meet (the apex) above the first scanned plane. A sweep's ragged
// edge fits no line; a linear array's sides run straight down.
FanBeams fan_beams(const std::vector<std::uint8_t>& scanned, const Dims3& dims, const Vec3d& spacing, int axis);
constexpr int kFanMinPlanes = 6;
constexpr double kFanMinSlope = 0.05, kFanMaxRms = 1.5, kFanMaxSkew = 2.0;

// The constants for a classification with `p`: both lowpasses are p's
// gradient lowpass (grad_sigma_mm; sigma_mm when that is 0), and the lengths
// above (given for sigma 1 mm) scale with p.sigma_mm, so a small volume's
// shrunken lowpasses, or sigmas given in another unit, shrink them too.
ShadowWallParams shadow_wall_params(const VariationalParams& p, int axis);

struct ShadowWallReport {
  double shadow_share = 0;  // of the scanned voxels, in shadow
  double wall_share = 0;    // of the scanned voxels, weight below 1/2
  double underside_share = 0;  // of the scanned voxels, marked as a thin echo's underside
  FanBeams fan;             // the fan followed (found false: beams along the axis)
};

// The weights (one per voxel, in [0, 1]) for the data the classifier sees
// (unscanned samples filled, levelled) at isovalue `iso` (its units);
// `scanned` (optional, 1 = scanned): only scanned voxels occlude or lie in
// shadow. The lowpasses run on `rt`'s device.
std::vector<float> shadow_wall_weight(Runtime& rt, const Volume& v, const std::vector<std::uint8_t>* scanned,
                                      double iso, const ShadowWallParams& params = {},
                                      ShadowWallReport* report = nullptr);

// Two per-voxel weights as one (their product); either may be null.
std::shared_ptr<const std::vector<float>> combine_edge_weights(std::shared_ptr<const std::vector<float>> a,
                                                               std::shared_ptr<const std::vector<float>> b);

// p.edge_weight: the bone cue's weights `cue` times the shadow walls'
// `walls` (either may be null), and p.edge_reference to go with them: the
// cue's rule when the cue is on, else the walls' (the strongest weighted
// edges). The one rule classify, the viewer, the study and the fuzz
// harness share.
void set_edge_weights(VariationalParams& p, std::shared_ptr<const std::vector<float>> cue,
                      std::shared_ptr<const std::vector<float>> walls);

}  // namespace softshell
