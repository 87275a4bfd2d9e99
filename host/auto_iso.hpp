// `--iso auto`: an isovalue picked from the data (docs/real-data.md,
// "Automatic isovalue").
//
// Two rules, both on the lowpassed volume v~ (speckle averaged out) over the
// scanned voxels:
//  - EchoRidge (the default, for the variational classifier): ultrasound
//    draws a boundary as a bright echo layer, and the variational shell sits
//    best on its crest (docs/parameters.md). From every strong-edge voxel
//    (|grad v~| in the top 5 %) climb v~ through the 26 neighbours, at most
//    3.5 mm, never fewer than 6 steps (climb_steps_for), to the crest of the echo; the
//    median crest value is v_iso.
//  - Local (the default for the variational classifier since the shell
//    functional): from every strong-edge voxel climb v~ up to the bright
//    side's crest B and down to the dark side's trough D (26 neighbours, at
//    most climb_steps_for's steps each: 3.5 mm, never fewer than 6); the
//    edge's isovalue is D + local_fraction
//    (B - D), near the bright side, where a log-compressed, blurred boundary
//    has its surface (docs/parameters.md, "The automatic isovalue"). Their
//    median is the global v_iso; spread by a normalised Gaussian (falling
//    back to the median where no edge is near) they give an isovalue field
//    that follows depth-dependent gain, attenuation and a mismatched
//    time-gain compensation (the paper's future work: an isovalue that
//    varies across the volume). The Gaussian is long along the beam
//    (field_depth_sigma_mm, 8 mm) and short across it (field_sigma_mm,
//    3 mm): gain drifts slowly with depth, while objects of different
//    brightness lie side by side; a field as short along the beam follows
//    each bone's echo and its shadow beneath and levels the bone's own
//    contrast away (docs/parameters.md, "The isovalue field along the
//    beam").
//  - Edge (for Levoy's contours): the value at which the boundaries lie,
//    found the way Kindlmann and Durkin (1998) find boundaries for transfer
//    functions: across a boundary blurred by the imaging, |grad v| peaks
//    midway between the two materials; the mean |grad v~| is taken per value
//    bin and the bin where it peaks is the isovalue.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "parallel.hpp"
#include "volume.hpp"

namespace softshell {

enum class AutoIsoRule { EchoRidge, Edge, Local };

struct AutoIsoParams {
  AutoIsoRule rule = AutoIsoRule::Local;
  double edge_share = 0.05;  // share of usable voxels, by |grad v~|, that seed the climb to the echo crest
  // How far an edge voxel climbs at most to its crest (and trough): climb_mm
  // over the smallest spacing, and never fewer than climb_steps voxels
  // (docs/parameters.md, "The climb in millimetres"). A count of voxels alone
  // reached 3.5 mm at 0.59 mm but 1.3 mm at 0.22 mm, and the same anatomy
  // scanned finer stopped short of its crests. climb_mm 0: climb_steps only.
  int climb_steps = 6;
  double climb_mm = 3.5;
  double sigma_mm = 1.0;        // lowpass of v~, at least 1 voxel per axis
  int bins = 64;                // over the range of v~ in the scanned voxels
  double min_bin_share = 0.001; // bins with fewer voxels than this share are ignored
  double local_fraction = 0.75; // Local: where between trough and crest the surface lies
  double field_sigma_mm = 3.0;        // Local: spread of the edges' isovalues into a field, across the beam
  double field_depth_sigma_mm = 8.0;  // ... and along it (the beam axis: beam_axis)
  int beam_axis = 2;                  // x 0, y 1, z 2 (the classifier's beam_axis_of or the near field's)
  // Local: weight of the global median in the field, as a share of the
  // volume's mean edge density (edges per scanned voxel). A share, not a
  // count: the edges grow with the voxel count, so a fixed count per
  // Gaussian volume weighed 19x less at 0.22 mm than at 0.59 mm, and the
  // field in edge-free tissue followed the few bright echoes far off
  // (docs/parameters.md, "The isovalue field's prior").
  double field_prior_share = 0.002;
  // Local, clipped echoes: an edge whose crest reaches the data's ceiling
  // takes clip_fraction instead of local_fraction. The data clip when at
  // least clip_share of the scanned samples equal the largest one; a crest
  // (of v~) is clipped within clip_margin of v~'s range below that sample.
  double clip_fraction = 0.9;
  double clip_share = 0.01;
  double clip_margin = 0.03;
  // Local, fluid at the floor (opt-in: `classify --iso-floor-fraction`;
  // docs/parameters.md, "Fluid at the floor"): where the data sit at their
  // floor (the smallest scanned sample) on at least floor_share of the
  // scanned samples, an edge whose trough (of v~) lies within clip_margin of
  // v~'s range above it, and whose crest is not clipped, is floored. When
  // the floored edges' crests are peaks -- v~ floor_reach_mm past the crest,
  // on from the trough, has fallen by at least floor_drop of the edge's
  // contrast, in their median -- they take floor_fraction instead of
  // local_fraction: a peak overstates the level behind the boundary. Equal
  // to local_fraction (the default): off, the same bits as without the rule.
  double floor_fraction = 0.75;
  double floor_share = 0.01;
  double floor_reach_mm = 2.5;
  double floor_drop = 0.2;
  // Local, crests cut off up the beam: an edge whose climb to its crest ends
  // against unusable voxels on the probe's side (the plane above the crest,
  // along beam_axis: the removed near field, unscanned fill or the volume's
  // face) did not reach its own crest; it may be the tail of what was cut
  // away (the near field's band) rather than a boundary of the object. With
  // cut_crest_votes false it gives no isovalue and AutoIsoReport::cut_edges
  // lists it; the study (--set iso_cut_crest_votes=0) then holds its line up
  // to the cut at u = 0 (hold_cut_remnants, host/mask.hpp). classify and the
  // viewer keep the default and do neither. Tried and not kept: the phantoms
  // gained, but on the PLUS sweeps it took bony pieces that lie under the
  // sweep's edge (docs/parameters.md, "Crests cut off up the beam"). true
  // (the default): every edge votes, as before.
  bool cut_crest_votes = true;
  // Local, levelling `level` (docs/parameters.md, "The isovalue above the
  // bulk"): the bulk, the most common brightness of the levelled data (the
  // mode of its bulk_sigma_mm lowpass over the scanned voxels), reaches up
  // to its mode plus bulk_spread times its upper half-width at half
  // maximum. Where the isovalue lies in that upper tail (above the mode,
  // below the bulk's reach) and the edges' median crest (ridge_iso) above
  // it, the isovalue is raised to the bulk's reach: the bulk is then the
  // background the object's echoes stand out of, and an isovalue inside it
  // draws its speckle. Not when the reach lies more than bulk_max_step of
  // the way from the isovalue to the crest (the crests are then the bulk's
  // own highs), nor when the half-width is more than bulk_max_width of the
  // way from the mode to the crest (no distinct bulk: two classes merged in
  // one wide hump, as fluid and tissue in some faces). 0: off.
  double bulk_spread = 1.5;
  double bulk_max_step = 0.8;
  double bulk_max_width = 0.6;
  double bulk_sigma_mm = 1.0;
  bool want_field = false;      // Local: fill AutoIsoReport::field (or level auto_iso's `level`)
  int threads = 0;              // host threads (0: every core); the results are the same for any count
};

struct AutoIsoReport {
  double iso = 0;                     // file units, by the rule asked for
  double edge_iso = 0, ridge_iso = 0; // the Edge rule's (NaN under the others: not binned) and EchoRidge's
  std::size_t crests = 0;             // strong-edge voxels that climbed to a crest
  double lo = 0, hi = 0;              // range of v~ (binned under the Edge rule)
  std::vector<double> mean_gradient;  // Edge: per bin, per mm (NaN where too few voxels); else empty
  std::vector<std::size_t> count;     // Edge: voxels per bin; else empty
  std::size_t voxels = 0;             // voxels that entered
  double local_iso = 0;               // the Local rule's global value (median of the edges' isovalues)
  double clipped_share = 0;           // Local: share of the scanned samples at the largest one
  double clip_level = 0;              // Local: crests from here up count as clipped (+inf: the data do not clip)
  std::size_t clipped_edges = 0;      // Local: edges whose crest was clipped
  double floor_share = 0;             // Local: share of the scanned samples at the smallest one
  double floor_level = 0;             // Local: troughs up to here count as floored (-inf: the data do not floor)
  std::size_t floored_edges = 0;      // Local: edges whose trough lay at the floor (and crest was not clipped)
  double floor_drop = 0;              // Local: their median drop past the crest (share of their contrast)
  std::vector<std::size_t> cut_edges; // Local: edges whose crest was cut off up the beam (voxel indices, z order)
  HostVector<float> field;            // Local, want_field: the isovalue per voxel, file units
  // Local, levelled (AutoIsoParams::bulk_spread): the bulk's mode and
  // upper half-width (file units, levelled data), its reach, and whether the
  // isovalue was raised to it from local_iso.
  double bulk_mode = 0, bulk_half_width = 0, bulk_reach = 0;
  bool bulk_raised = false;
};

// The isovalue the shadow test takes (host/shadow_walls.hpp) when auto_iso
// returned `iso` with report `r`: the edges' (local_iso) where `iso` was
// raised above the bulk -- the shadow lies below the level between tissue
// and shadow, not below the bulk's reach -- else `iso`.
inline double shadow_test_iso(const AutoIsoReport& r, double iso) { return r.bulk_raised ? r.local_iso : iso; }

// The volume with its local isovalue field levelled out: v - field + iso
// (file units, float samples). Log-compressed brightness drifts are additive,
// so a shift, not a gain, is what undoes them; `field` is smooth (tens of mm),
// so gradients are left all but unchanged.
Volume level_isovalue(const Volume& v, const float* field, std::size_t field_size, double iso);
inline Volume level_isovalue(const Volume& v, const HostVector<float>& field, double iso) {
  return level_isovalue(v, field.data(), field.size(), iso);
}
inline Volume level_isovalue(const Volume& v, const std::vector<float>& field, double iso) {
  return level_isovalue(v, field.data(), field.size(), iso);
}

// The most steps an edge voxel climbs on a grid of `spacing` (mm):
// max(climb_steps, ceil(climb_mm / the smallest spacing)).
int climb_steps_for(const AutoIsoParams& p, const Vec3d& spacing);

// p's length scales times f (a small volume's, host/variational.hpp's
// small_volume_scale): the lowpass of v~, the climb, the field's spread
// along and across the beam, and the bulk's lowpass. The classify CLI does the same
// to the ones not given on its command line.
void scale_length_scales(AutoIsoParams& p, double f);

// `classify --iso auto` for the variational classifier in one call: the
// Local rule's isovalue (file units) taken from `v` (the mask as for
// auto_iso), and `target` (v itself when null; with a mask, v with its
// unscanned samples filled, host/mask.hpp) levelled by its field: `data`,
// what the classifier should see. The report's field stays empty.
struct LevelledVolume {
  Volume data;
  double iso = 0;
};
LevelledVolume auto_iso_levelled(const Volume& v, const std::vector<std::uint8_t>* mask, const Volume* target = nullptr,
                                 const AutoIsoParams& params = {}, AutoIsoReport* report = nullptr);
// The same in place: `v` (with a mask, its unscanned samples may be filled
// first: the isovalue reads the scanned ones only) levelled by its own
// field; returns the isovalue (file units).
double auto_iso_level_in_place(Volume& v, const std::vector<std::uint8_t>* mask, const AutoIsoParams& params = {},
                               AutoIsoReport* report = nullptr);

// v_iso in the file's units. `mask` (optional, 1 = scanned) limits the
// statistics to scanned voxels whose six neighbours are scanned too, and the
// lowpass to scanned samples (normalised convolution), so the edge of the
// sweep does not count as a boundary. Throws InputError when no voxel is
// usable (an empty mask, a volume thinner than 3 voxels) or v~ is constant.
//
// `level` (Local rule with want_field; same dims as v): levelled in place by
// the field, level_isovalue's values, row by row as the field is formed;
// the field is then not kept (report->field stays empty): 4 bytes per voxel
// and two passes over the volume less. It may be &v (v's samples are read
// only before the field is formed), v with its unscanned samples filled,
// or any volume on v's grid.
double auto_iso(const Volume& v, const std::vector<std::uint8_t>* mask, const AutoIsoParams& params = {},
                AutoIsoReport* report = nullptr, Volume* level = nullptr);

// The bulk of `v` (AutoIsoParams::bulk_spread): the mode of its Gaussian
// lowpass of sigma_mm over the scanned voxels (`mask`, optional; 1 =
// scanned) and the upper half-width at half maximum of that histogram (128
// bins between the 0.5th and 99.5th percentiles, smoothed over five bins).
// measured false when fewer than 1000 voxels are scanned or their range is
// empty. The same for any thread count.
struct Bulk {
  bool measured = false;
  double mode = 0, half_width = 0;
};
Bulk bulk_of(const Volume& v, const std::vector<std::uint8_t>* mask, double sigma_mm, int threads = 0);
// The isovalue with the bulk's rule applied (AutoIsoParams::bulk_spread):
// raised to mode + spread x half_width where the isovalue lies between the
// mode and that reach, the crest above the reach, the reach at most
// max_step of the way from the isovalue to the crest, and the half-width at
// most max_width of the way from the mode to the crest; else `iso`.
double bulk_raised_iso(double iso, double crest, const Bulk& bulk, double spread, double max_step, double max_width);

// The k-th smallest (k from 0) of the values >= 0 among g[0, n),
// the others ignored: what std::nth_element over them gives. k must be below
// their count. `threads` as AutoIsoParams::threads; the same for any count.
float kth_nonnegative(const float* g, std::size_t n, std::size_t k, int threads = 0);

// The warning (one line, newline-terminated; empty: none) for an explicit
// --iso outside the samples' values [min, max]: no boundary of the data lies
// at that value, so the result is empty (or everything). Not an error: a
// user may mean it. Callers (classify, figure2, and the renderers through
// viewer::load_opacity) print it once the isovalue has passed the checks
// that refuse it.
std::string iso_outside_data(const Volume& in, double iso);

}  // namespace softshell
