// The scanned-region mask of freehand 3D ultrasound (docs/numerics.md,
// "Masked (unscanned) voxels"; docs/real-data.md): which voxels hold data and
// which the probe never swept. One byte per voxel, x fastest like Volume:
// 1 = scanned (free in the classifier), 0 = unscanned (u held at 0).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "parallel.hpp"
#include "volume.hpp"

namespace softshell {

// The rule (docs/real-data.md, "The mask"):
//  1. zero fill: the voxels exactly equal to 0, kept only where a whole
//     (2 solid + 1)^3 cube of them fits (a morphological opening; outside the
//     volume counts as zero). Dark speckle never fills such a cube — the
//     phantoms' fluid, 25-30 % exact zeros, has no 5^3 block — while the
//     unswept part of a freehand reconstruction is solid. Without this step
//     speckle zeros percolate into one boundary-touching region.
//  2. its 6-connected regions that touch the volume boundary and hold at
//     least min_fraction of all voxels are unscanned;
//  3. they reclaim the zero voxels 6-connected to them within `solid`
//     steps (the ragged edge of the fill that no cube fits into), and the
//     zero voxels on the two faces across the beam, solid in the face's
//     plane, connected to them along the face (a fan's arc meeting that face
//     leaves a one-voxel layer of zeros there);
//  3c. with no region from step 2 (and no dark fluid found by 2b): the zeros
//     on the two faces across the beam that are solid in the face's plane
//     (a square of 2 solid + 1 fits) in 4-connected pieces of at least
//     min_fraction of the face (and the square), when on at least 90 % of
//     a piece's lines into the volume the zeros end in 2 solid + 1 samples
//     of data: a scan ending a fraction of a voxel short of the face (or
//     starting one in) leaves one plane of zeros there, too thin for the
//     cube (the family's spine 204 at 256^3: 2 560 voxels on its bottom
//     face, 7 936 on its top, and the step from its last samples to 0 was
//     drawn as a sheet: 23 600 voxels). Dark fluid reaching the face goes
//     on in its pattern of zeros under them;
//  4. then grow by `grow` voxels (6-neighbour dilation) over the
//     partial-volume rim that the reconstruction leaves at the sweep edge:
//     on the PLUS spine sweep the first scanned layer is dim (median 72
//     against 226 deeper, in the bright near field) and the second still
//     partly so, and with a 1-voxel growth the classifiers still draw the
//     lateral sweep edge (docs/real-data.md), so 2.
//  2b. unless dark fluid: when more than max_enclosed of the zero fill lies
//     between nonzero samples along the beam axis (fluid between echoes at
//     the log-compression floor: 11-37 % on low-dynamic-range phantoms,
//     at most 1.7 % on the five PLUS reconstructions), there is no unscanned
//     region. (An object floating in a void of exact zeros with nothing
//     beyond it along the beam has few zeros between echoes: 2b'.)
//     min_faces (off by default) also asks for scanned voxels on 2 % of that
//     many faces: the PLUS reconstructions reach only 0-2 faces so, with
//     their dim edge rim, so it cannot tell them apart.
//  2b'. also dark fluid when more than fluid_enclosed (1 %) of the fill lies
//     between echoes along the beam and more than fluid_inside (5 %) of it
//     inside the data's hull (2c's lines): an object in a void of zeros
//     with nothing above it. A sweep's gaps between frames lie inside its
//     hull too, but with no echo above or below them. 2c follows, with the
//     zeros beyond a line's last sample kept unscanned (a shadow running out
//     to the sector's end), and then step 4's rim (not step 3).
//  2c. unless what lies outside the data: when 2b or 2b' finds dark fluid, the
//     fill's voxels with no nonzero sample on one side or the other along
//     each of 49 lines through them (directions with components in
//     [-2, 2]) lie outside the data's hull -- beyond a scan's convex sector
//     -- and are unscanned if there are min_fraction of them; the rest is
//     fluid or shadow and scanned. Before the first sample of a beam line
//     the fill counts as outside only when the scan meets the face at the
//     probe (kProbeShare of its lines start there): else it is fluid in
//     front of the object. Steps 3 and 4 then take nothing more (after 2b,
//     step 4 does after 2b'): such a fill can border an object in fluid.
struct MaskParams {
  double min_fraction = 0.001;
  int beam_axis = 2;          // the beam's axis (x 0, y 1, z 2)
  double max_enclosed = 0.05;
  // 2b': dark fluid also when more than fluid_enclosed of the fill lies
  // between echoes along the beam and more than fluid_inside of it inside
  // the data's hull (2c's between_data).
  double fluid_enclosed = 0.01, fluid_inside = 0.05;
  int min_faces = 0;
  int solid = 2;  // cube half-width of step 1, voxels (0: every zero voxel, the plain rule)
  int grow = 2;
  int threads = 0;  // host threads (0: every core); the mask is the same for any count
};

struct MaskReport {
  std::size_t zeros = 0;              // voxels exactly 0
  std::size_t regions = 0;            // solid zero regions that touch the boundary
  std::size_t unscanned_regions = 0;  // of those, the ones at least min_fraction large
  std::size_t zero_fill = 0;          // unscanned voxels before growing (all exact zeros)
  std::size_t unscanned = 0;          // after growing
  double enclosed_share = 0;          // of the zero fill, between nonzero samples along the beam (step 2b)
  int faces_with_data = 0;            // faces of the volume with scanned voxels (step 2b)
  bool rejected = false;              // step 2b found dark fluid, not an unscanned region
  bool outside = false;               // step 2c kept the part of such a fill outside the data's hull
  double outside_share = 0;           // step 2c: that part's share of the zero fill
  double inside_share = 0;            // step 2b': the fill's share inside the data's hull (when measured)
  bool fluid_inside = false;          // step 2b' (not 2b) found the dark fluid
  std::size_t face_layers = 0;        // step 3c: zeros taken in thin layers on the faces across the beam
};

// The mask derived from the zero fill; deterministic, iterative (no
// recursion), O(voxels) time and a few bytes per voxel.
std::vector<std::uint8_t> scanned_mask(const Volume& v, const MaskParams& params = {}, MaskReport* report = nullptr);

// Float data's unscanned fill (docs/real-data.md, "A fill other than 0"):
// the mask, the near field and the beam axis take exact zeros for what the
// probe never swept. Float data carry brightness whose zero is arbitrary
// (dB, or any offset), and their fill is often another value (-80 dB, the
// data's minimum, or data shifted by a constant, fill and all).
// unscanned_fill_value(v): for float data with fewer than min_fraction of
// the samples exactly 0 (a zero fill wins, as before), the value, among the
// data's minimum and the eight corners' samples, that the most samples hold
// exactly, when at least min_fraction do and it is no brighter than the
// median of the rest (a fill is dark; a clipped ceiling is not one), and the
// data less it stay finite in float and keep their detail (the rest's
// robust range at least 1e-3 of its distance from the fill); else 0.
// Integer data: 0 (grey levels' black). classify and the viewer subtract it
// from the data before the mask (an exact 0 where the fill was; the
// classification of float data does not change with an added constant
// otherwise) and report isovalues in the file's units.
double unscanned_fill_value(const Volume& v, double min_fraction = MaskParams{}.min_fraction, int threads = 0);
// v's samples less `fill` (in place; nothing when fill is 0).
void move_fill_to_zero(Volume& v, double fill, int threads = 0);
// After move_fill_to_zero and the mask: the samples at 0 that `scanned`
// (1 = scanned; empty: every voxel) still counts as scanned -- the fill's
// ragged edge that the mask's rule does not reach -- set to the smallest
// other scanned sample. A zero fill lies at the data's black; a fill moved
// from -1000 dB would lie far below it and read as a strong edge.
void darken_scanned_fill(Volume& v, const std::vector<std::uint8_t>& scanned);

// beam_axis_of: an axis other than z wins only by this factor over z.
constexpr double kBeamAxisMargin = 1.1;
// ... and only when the data's brightness profile along z (the mean per
// slice, over about 3 mm) does not vary kBeamProfileMargin times as much as
// along that axis, with a total variation of at least kBeamProfileFloor of
// the data's mean (docs/real-data.md, "The beam axis").
constexpr double kBeamProfileMargin = 1.5, kBeamProfileFloor = 0.3;
// ... and only when the sampled data do not widen from one end of z to the
// other by kBeamSectorWidening while as wide at both ends across that axis
// (within kBeamSectorFlat): a fan's sector, opening along its beam, z
// (the ends: the first and last tenth of the slices with samples).
constexpr double kBeamSectorWidening = 1.5, kBeamSectorFlat = 1.1;
// The beam axis of a scan, from the data: speckle is finest along the beam,
// so the mean squared difference between neighbours (per mm, scanned
// nonzero samples) is largest along it. Another axis than z wins only by
// kBeamAxisMargin over z; less is a tie, and ties go to z (the default beam).
// Brightness varies with depth along the beam: a winner other than z whose
// profile varies much less than z's (kBeamProfileMargin) gives z too, and
// so does one across which a sector that opens along z stays as wide.
// `threads` (0: every core) does not change the result.
// `plane_step` > 1 sums every plane_step-th z-plane only (a cheaper estimate).
int beam_axis_of(const Volume& v, const std::vector<std::uint8_t>* scanned, int threads = 0, std::size_t plane_step = 1);

// The data lowpassed across the beam only (a Gaussian of sigma_mm along the
// two axes other than `beam_axis`; beam lines stay lines: speckle averaged,
// depth resolution kept), normalised over the scanned samples: each output
// is sum w_k v_k / sum w_k over the scanned taps inside the volume (the
// sample itself where none is), in double, the terms in tap order. The near
// field and the reverberation rule read it. The same for any thread count.
HostVector<float> lowpass_across_beam(const Volume& v, const std::vector<std::uint8_t>* scanned, int beam_axis,
                                       double sigma_mm, int threads = 0);

namespace mask_detail {
// Tests only: lowpass_across_beam's sums through the portable build of its
// inner loop even where the CPU has AVX2 (both give the same bits).
void use_portable_taps(bool on);
// A binary cube filter of half-width r in place on `a` (0 or 1 per voxel):
// erode (every voxel of the cube around it set, outside the volume counting
// as set) or dilate (any set); scanned_mask opens the exact zeros with it.
void cube_filter(std::vector<std::uint8_t>& a, const Dims3& d, int r, bool erode, int threads);
// lowpass_across_beam(v, &scanned, ax, sigma_mm) written into lp, in place,
// for the planes across the beam (index along ax) from the first to the last
// that holds a voxel set in `changed`; lp elsewhere is kept (remove_near_field:
// the reverberation rule's lowpass of the mask without the band).
void relowpass_planes(const Volume& v, const std::vector<std::uint8_t>& scanned,
                      const std::vector<std::uint8_t>& changed, int ax, double sigma_mm, int threads,
                      HostVector<float>& lp);
}  // namespace mask_detail

// The bright layered near field under the probe (skin, fat, muscle: an
// occluder, not the object; docs/real-data.md, "The near field"). Along the
// beam (params.axis, or the data's own, beam_axis_of), depth is counted
// from each beam line's first scanned voxel (the skin line). `below`: the
// darkest of P(d), the median over the lines of the lowpassed data at depth
// d (0.5 mm steps), from top_mm to search_mm. Per line, its top T (the
// brightest of its first top_mm): when T is brighter than `below` by more
// than min_ratio of T (or, when at least faint_lines of the lines pass this
// test, by faint_ratio of T and by speckle_sds of the speckle's spread: a
// saturated band over bright tissue), the line's band reaches down to where
// it falls below halfway between the two and stays there for stay_mm (a
// layered band dips at the fat and rises again at the muscle). The lines' bottoms
// are smoothed by a separable median over smooth_mm across the beam, and the
// band is each line's bottom plus margin_mm, when at least min_lines of the
// lines have one. Returns 1 for voxels in the band, all 0 when there is none.
// Reverberations of a strong flat reflector (docs/real-data.md,
// "Reverberations"): a specular echo bounces between the reflector and the
// probe (or within a plate), and the scan shows fainter copies of it at equal
// spacing below it along the beam -- ghosts, not surfaces. Per beam line the
// first strong echo (the data lowpassed across the beam rising above lo +
// strong (hi - lo), lo the median and hi the 99th percentile over the scanned
// voxels; then its crest within 1 mm) aligns the line; Q(s), the median over
// the aligned lines s below their echo, is the echo train. Reverberation: Q
// has a copy at s1 in [min_spacing_mm, max_spacing_mm] that rises above the
// trough before it by min_copy of the echo's own rise, a trough that falls
// at least min_gap of the way from the echo down to lo (under a strong
// reflector lies its shadow), and a second, fainter copy within tolerance s1
// of 2 s1 rising by min_second; the echo itself flat (its depth on
// neighbouring lines within max_jump_mm, see ReverbParams). Then, in every line
// with a first strong echo, the voxels below it from where its lower flank
// falls to halfway between the echo and that trough are the reverberation
// region (held at u = 0 like the near field).
struct ReverbParams {
  double strong = 0.5;
  double min_spacing_mm = 1.0, max_spacing_mm = 15.0;
  double min_copy = 0.3, min_second = 0.15;
  double min_gap = 0.6;  // the trough before the first copy: at least this share of the way from the echo to lo
  double tolerance = 0.2;
  double sigma_mm = 1.0;  // lowpass across the beam, as the near field's
  // The echo's depth on neighbouring lines (along the first lateral axis):
  // its 75th percentile jump at most this, or two lateral voxels.
  double max_jump_mm = 1.0;
  // The second copy must be a bump: Q falls back by half its rise within
  // 2 x tolerance x its spacing after it (false: any maximum in its window).
  bool second_peak = true;
  // A reflector at all: hi - lo at least this many of the data's spreads
  // (1.4826 x the median absolute deviation of the lowpassed samples from
  // lo); 0: no test. Found on the cross-check's cysts in a low-contrast
  // texture (hi - lo 1.8-2.0 spreads), whose speckle passed for an echo
  // train on every line and held 74-80 % of the scan at 0; the PLUS flat
  // reflector (IMLiF) stands 8.1 spreads up, the other PLUS volumes 5-28,
  // the family's one reverberation (spine 2414) 4.7 (docs/real-data.md,
  // "A reflector that stands out").
  double min_stand = 3.0;
};
struct ReverbReport {
  bool found = false;
  double spacing_mm = 0;            // s1
  double cut_mm = 0;                // below the echo's crest: where the region starts
  double echo = 0, copy1 = 0, copy2 = 0, trough = 0;  // Q at 0, s1, 2 s1 and the trough before s1 (file units)
  std::size_t lines = 0;            // beam lines with a first strong echo
  double jump_mm = 0;               // 75th percentile of the echo's depth step between neighbouring lines
  std::size_t voxels = 0;           // voxels in the region
  double stand = 0;                 // hi - lo in the data's spreads (ReverbParams::min_stand); 0: not measured
};
// The region (1) below the first strong echo of each line when the echo
// train is a reverberation; all 0 otherwise. `axis` the beam's.
// `lowpass` (optional): lowpass_across_beam(v, scanned, axis,
// params.sigma_mm) when the caller has it (remove_near_field).
std::vector<std::uint8_t> reverberation_region(const Volume& v, const std::vector<std::uint8_t>* scanned, int axis,
                                               const ReverbParams& params = {}, ReverbReport* report = nullptr,
                                               int threads = 0, const HostVector<float>* lowpass = nullptr);

struct NearFieldParams {
  double top_mm = 3.0, search_mm = 25.0, margin_mm = 1.0;
  double stay_mm = 3.0;    // the band ends where the profile stays below halfway this long
  double layer_gap_mm = 6.0;  // a layered band (its lines' median rises again within this under its first layer):
                              // each line's band ends where it stays below halfway this long (0: never)
  // ... or when that median stays above halfway through a dip of layer_dip
  // under the brighter of the layers beside it, the next within layer_gap_mm
  // (a fat layer that only some lines' skin is bright enough to fall below
  // halfway over; 0: the test above alone).
  double layer_dip = 0.2;
  // A layered band's line ends at most this far under the lines' median
  // bottom (along the beam, in a fan): deeper, it ended in the shadow of an
  // object under the band, not at the band (0: no bound).
  double layer_reach_mm = 3.0;
  // In a layered band, a line that never stays below halfway under its
  // layers but has at least fill_crossing of its samples in the
  // fill_reach_mm under them below the mark (tissue near the mark, not an
  // object under the band) ends where the layers end in the lines' median
  // profile (at most at the found lines' median bottom) instead of having no
  // band (false: no band there).
  bool fill_layered = true;
  double fill_reach_mm = 10.0, fill_crossing = 0.2;
  double min_ratio = 0.3;  // the top brighter than below it by this share of the top
  // ... or by this smaller share when that is also speckle_sds of the
  // speckle's spread below the top (NearFieldReport::speckle_sd), on at
  // least faint_lines of the lines under the probe (their skin line
  // deepening by at most 1 mm per mm across the beam: not the lines that
  // enter a sector down its side).
  double faint_ratio = 0.1, speckle_sds = 2.5, faint_lines = 0.25;
  // ... or by faint_ratio alone on lines whose own top is clipped: at least
  // clip_share of their raw samples in their first top_mm at the data's
  // maximum (within 1 % of its range), and twice the share of the samples
  // under the tops. A saturated slab over bright, coarse speckle; the same
  // faint_lines of the lines under the probe must pass.
  bool clipped = true;
  double clip_share = 0.25;
  double sigma_mm = 1.0;   // lowpass across the beam of the profile's samples
  int axis = -1;           // beam axis (0 x, 1 y, 2 z); -1: beam_axis_of the data
  double max_share = 0.5;  // a "band" holding more of the scanned voxels is the object, not a near field
  double profile_mm = 2.0; // the lines' samples: mean over this far either way across the beam, per depth
  double smooth_mm = 5.0;  // the lines' band bottoms: median over this far either way across the beam
  double min_lines = 0.05; // a band: on at least this share of the beam lines (with a skin line)
  int threads = 0;         // host threads (0: every core); the band is the same for any count
  bool band = true;        // remove_near_field: the band (false: only the reverberations, if reverb)
  bool reverb = true;      // remove_near_field: also the reverberations of a flat reflector (below)
  // The band's echo layer (near_field_band): a copy of the band's deepest
  // interface looked for at echo_from ... echo_to x each line's band depth,
  // rising above the gap under the band by echo_rise of the band's top.
  // Up to echo_layers such layers, brightest first (each interface of the
  // band reverberates at its own multiples: a fascia's copy can lie between
  // the band and the deepest interface's); after the first, anywhere under
  // the band, each bounded by the gap on both sides (1: the first alone).
  bool echo_layer = true;
  double echo_from = 1.2, echo_to = 2.4, echo_rise = 0.1;
  int echo_layers = 3;
  // The first layer must end before echo_to as the further ones must (E
  // falls below its halfway mark again); false: it may run to echo_to.
  // Found on an independent simulator's spine scans whose gain rises with
  // depth: the rise was taken for the band's copy and the laminae under it
  // removed (docs/real-data.md, "A gain that rises with depth").
  bool echo_bounded = true;
  // The band's tail (echo_tail): copies overlapping into a dimmer plateau
  // under the band, with no gap, down to the floor (the median of the
  // profile over the deeper half of 1 ... echo_to): joins the band to where
  // the profile falls halfway from the band's bottom to that floor, when the
  // bottom stands echo_rise of the band's top over the floor above it.
  // Off by default: tried and not kept (docs/parameters.md, "The band's
  // tail: tried, not kept"): on the PLUS spine sweeps it took structures 2-3
  // mm under their bands and made one band too deep to remove.
  bool echo_tail = false;
  // The skin line (skin_step): when none of the rules above finds a band, a
  // thin layer at the skin line that the lines' median profile P ends with a
  // sharp step still is one -- the skin (and the probe's ring-down) over
  // tissue nearly as bright, too faint for the speckle test above but
  // plain in P, a median over every line. It counts when P falls, within
  // top_mm of the skin line, from the layer's brightest bin to the
  // brightest of the stay_mm under it by at least faint_ratio of the
  // layer's level and by step_sds times P's own roughness below it
  // (1.4826 x the median absolute change between its 0.5 mm bins), three
  // quarters of that within 1.5 mm, and nothing in search_mm is as bright
  // as the layer. The band then ends where the fall is three quarters done
  // (plus margin_mm), on every line under the probe. Found on an
  // independent simulator's scans of lesions in parenchyma under a 1-3 mm
  // skin (docs/real-data.md, "A thin skin line").
  bool skin_step = true;
  double step_sds = 8.0;
  ReverbParams reverb_params;
};
struct NearFieldReport {
  int axis = 2;                 // the beam axis used
  bool found = false;
  double depth_mm = 0;          // band bottom below the skin line, margin included (median over its lines)
  std::size_t lines = 0;        // beam lines with a band
  double top = 0, below = 0;    // P at the top and below it (file units)
  double speckle_sd = 0;        // robust spread of the samples about the lowpass below the top (file units)
  bool faint = false;           // found by the faint rule (faint_ratio, speckle_sds, faint_lines): its median top is not min_ratio brighter
  bool clipped = false;         // ... and by the clipped tops of its lines, not by the speckle test
  bool layered = false;         // a layered band: its lines ended where they stayed below halfway for layer_gap_mm
  std::size_t reach_lines = 0;  // ... of them, lines that ended deeper than layer_reach_mm under the median, bounded there
  bool skin = false;            // found by the skin-line rule (params.skin_step): a thin layer ended by a sharp step in P
  double step = 0, roughness = 0;  // that rule's fall of P at the step and P's roughness below it (file units)
  std::size_t voxels = 0;       // voxels in the band
  bool too_deep = false;        // a band was found but held more than max_share of the scanned voxels: kept
  ReverbReport reverb;          // remove_near_field with params.reverb
  struct Echo {
    bool found = false;
    double from = 0, to = 0, peak = 0;  // the layer(s) (from the shallowest to the deepest) and the first's peak, in units of each line's band depth
    int layers = 0;                     // layers found (params.echo_layers at most)
    double tail_to = 0;                 // the band's tail (params.echo_tail) to this x each line's band depth; 0: none
    std::size_t tail_voxels = 0;        // voxels the tail added to the band
    double gap = 0, level = 0;          // the echo profile at the gap and at the peak (file units)
    std::size_t voxels = 0;             // voxels it added to the band
  } echo;                       // the band's echo layer (params.echo_layer)
};
// The data's black, from which the near field's ratio tests (min_ratio,
// faint_ratio, layer_dip) measure brightness: 0 for integer data with no
// sample below 0 (the display's grey levels), else the robust minimum (the
// 0.5th percentile, where the float data's intensity normalisation puts 0)
// of the scanned samples (`scanned`, 1 = scanned; null or none scanned:
// every sample): float data, and signed data holding negative samples,
// carry log-compressed brightness whose zero is arbitrary (dB, or any
// offset: a gain change in the log domain), and their unscanned fill is no
// brightness of theirs. The band is then the same for v and v + c.
double brightness_floor(const Volume& v, const std::vector<std::uint8_t>* scanned = nullptr);

// `lowpass_out` (optional) receives the data lowpassed across the beam that
// the band was read from (lowpass_across_beam(v, scanned, the axis,
// params.sigma_mm)); empty where the volume is too thin along the beam.
std::vector<std::uint8_t> near_field_band(const Volume& v, const std::vector<std::uint8_t>* scanned,
                                          const NearFieldParams& params = {}, NearFieldReport* report = nullptr,
                                          HostVector<float>* lowpass_out = nullptr);

// near_field_band() merged into a scanned mask (band voxels become
// unscanned: u held at 0, their samples continued from below before the
// lowpass, so the band's lower edge is no boundary either), then, with
// params.reverb, reverberation_region() of what is left likewise. An empty
// `scanned` means every voxel scanned; it stays empty when neither is found.
NearFieldReport remove_near_field(const Volume& v, std::vector<std::uint8_t>& scanned,
                                  const NearFieldParams& params = {});

// The depth clip that follows the sweep (`classify --depth-clip`): along
// the beam axis `axis`, depth is counted from each beam line's first scanned
// voxel (the skin line, as for the near field); the scanned voxels whose
// depth d (mm, voxel index difference x spacing) is outside [min_mm, max_mm)
// become unscanned. An empty `scanned` means every voxel scanned (it is then
// filled in). Returns the number of voxels clipped.
std::size_t clip_depth(const Volume& v, std::vector<std::uint8_t>& scanned, int axis, double min_mm, double max_mm);

// A mask from a volume file: nonzero voxels are scanned. Throws InputError
// naming `path` when its dims differ from `dims`.
std::vector<std::uint8_t> read_mask(const std::string& path, const Dims3& dims);

// A copy of `v` whose unscanned samples continue the scanned data: each
// unscanned voxel, in order of its 6-neighbour distance to the scanned
// region, takes the mean of its face neighbours one step nearer. The lowpass
// v~ and the gradients then see no step at the edge of the sweep (the zero
// fill would otherwise read as a strong boundary a few voxels into the
// scan); the classifiers still hold u = 0 there. `depth` > 0 stops after
// that many layers (the rest keeps its samples). `threads` (0: every core)
// does not change the result.
Volume fill_unscanned(const Volume& v, const std::vector<std::uint8_t>& mask, int depth = 0, int threads = 0);
// The same, in place: no second copy of the volume (the CLI's classify).
void fill_unscanned_in_place(Volume& v, const std::vector<std::uint8_t>& mask, int depth = 0, int threads = 0);

// Number of unscanned (0) entries.
std::size_t count_unscanned(const std::vector<std::uint8_t>& mask);

// The remnants under a cut (docs/parameters.md, "Crests cut off up the
// beam"; with AutoIsoParams::cut_crest_votes false, not the default): for each voxel of `edges` (AutoIsoReport::cut_edges: edges
// whose crest the automatic isovalue found cut off up the beam), walk up its
// beam line (`axis`, depth growing with the index) over scanned voxels; when
// an unscanned one comes within `reach` voxels, the voxels walked (the edge's
// included) are set unscanned, held at u = 0 like the near field above them.
// Lines that reach the volume's face or stay scanned are left. Returns the
// voxels newly held; the same for any order of `edges`.
std::size_t hold_cut_remnants(std::vector<std::uint8_t>& mask, const Dims3& dims, int axis,
                              const std::vector<std::size_t>& edges, std::size_t reach);
// The reach for a volume: kCutRemnantMm along the beam, at least one voxel.
constexpr double kCutRemnantMm = 6.0;

// The band's underside drawn as a sheet (docs/parameters.md, "The band's
// underside"). Under a removed near-field band the data can stay above the
// isovalue for a few mm (copies of the band's layers overlapping into a
// plateau with no dark gap), and the shell then forms a sheet just under the
// band: a curtain over the object. Anatomy just under a band (a lamina, a
// head's crown) is drawn there too, in pieces. So after a solve, the beam
// lines on which the drawn opacity (u > threshold) reaches into the window
// of window_mm under the band are joined into patches (4-connected across
// the beam); a patch of at least min_patch of the band's lines is a sheet,
// and its lines' windows are held at u = 0 and the classification solved
// again. (The laminae of the real spine sweeps under their bands came in
// pieces of at most 10 % of the band's lines; the phantoms' sheets 15-50 %.)
//
// Deeper, from window_mm to deep_mm under the band, only a flat sheet is
// held: a patch of at least min_patch of the band's lines whose first drawn
// voxel lies at the same depth under the band on its lines (the spread
// between their quartiles at most flat_mm, or one voxel along the beam).
// The fascia under the subcutaneous fat is such a sheet -- a bright line
// parallel to the skin some millimetres under the skin's band, drawn across
// the whole probe --
// while an object near the probe (a head's crown, a spinous process) is
// not flat under it. A flat sheet's lines are held in the deep window and,
// from the sheet on, down its drawn run (u > threshold, to the deep window's
// end at most) and margin_mm more, past the window if need be (the layer's
// lower flank). 0 (deep_mm <= window_mm): the near window alone.
struct BandSheetParams {
  double window_mm = 3.0;
  double min_patch = 0.15;
  float threshold = 0.2f;  // the splat threshold
  double deep_mm = 8.0;
  double flat_mm = 1.0;
  // A deep sheet is held on down its drawn run and this far more (a shell's
  // width: the layer's lower flank).
  double margin_mm = 2.0;
  // The skin window: on the beam lines that have no band held (every line
  // when none was found), the first skin_mm under the skin line. A sheet
  // drawn there that follows the skin line (its drawn runs' starts within
  // one voxel of each other's depth under the skin line from line to
  // neighbouring line, on at least skin_patch of those lines, their
  // quartiles within flat_mm) is a layer under the probe -- the skin's lower
  // edge, a fascia, across the probe -- not the object: held from above_mm
  // over the run to margin_mm under it. An object near the probe follows its
  // own shape, not the skin's, and lies under part of it. 0: off.
  double skin_mm = 12.0;
  double skin_patch = 0.3;
  // ... and its pieces: flat sets on skin_piece of those lines or more
  // whose median depth is within a voxel of a held sheet's (a layer cut into
  // pieces by the lines where a band was removed).
  double skin_piece = 0.01;
  double above_mm = 1.0;
};
// The window under the band (1; 0 elsewhere): on each beam line along `axis`
// (depth growing with the index) whose first voxel scanned in `before` (the
// skin line; empty: every voxel scanned) is unscanned in `after` (the band
// removed, remove_near_field), the voxels scanned in `after` from the end of
// that unscanned run down to window_mm below it; with deep_mm > window_mm,
// the voxels from there down to deep_mm below it are the deep window (2).
// Empty when no line has a band.
// With skin_mm > 0, on each line with no band (its skin line scanned in
// `after`, or `after` empty: every voxel scanned), the voxels scanned in
// `after` from the skin line down to skin_mm below it are the skin window
// (3).
std::vector<std::uint8_t> band_underside(const Dims3& dims, double spacing_mm, int axis,
                                         const std::vector<std::uint8_t>& before,
                                         const std::vector<std::uint8_t>& after, double window_mm,
                                         double deep_mm = 0, double skin_mm = 0);
// The same for the band `nf` found in volume `v` (along nf.axis, at its
// spacing); with skin_mm > 0 also when none was found (then the skin window
// alone); else empty when none was found.
std::vector<std::uint8_t> band_underside(const Volume& v, const NearFieldReport& nf,
                                         const std::vector<std::uint8_t>& before,
                                         const std::vector<std::uint8_t>& after,
                                         double window_mm = BandSheetParams().window_mm,
                                         double deep_mm = BandSheetParams().deep_mm,
                                         double skin_mm = BandSheetParams().skin_mm);
struct BandSheetReport {
  std::size_t lines = 0;       // beam lines with a window
  std::size_t drawn = 0;       // ... on which u > threshold in the window
  double largest = 0;          // the largest patch of drawn lines, as a share of `lines`
  int patches = 0;             // patches held (min_patch of `lines` or more)
  std::size_t held_lines = 0;  // their lines
  // The deep window (BandSheetParams::deep_mm): its flat sheets held, their
  // lines, and the largest patch's share of `lines` and its depth spread (mm).
  int deep_patches = 0;
  std::size_t deep_lines = 0;
  double deep_largest = 0, deep_spread_mm = 0;
  // The skin window (BandSheetParams::skin_mm): its lines, the sheets held
  // there and the lines with one or more of them.
  std::size_t skin_lines = 0;
  int skin_sheets = 0, skin_pieces = 0;
  std::size_t skin_sheet_lines = 0;
  bool held = false;           // patches + deep_patches + skin_sheets > 0
  std::size_t voxels = 0;      // voxels held
};
// Decides on `u` (a solved opacity) and sets the sheets' windows unscanned
// in `scanned` (of the volume's size; empty: every voxel scanned, filled
// with 1 when something is held). `window` from band_underside(); an empty
// one decides nothing. The same for any order of the lines.
BandSheetReport hold_band_sheet(const Volume& u, const std::vector<std::uint8_t>& window, int axis,
                                std::vector<std::uint8_t>& scanned, const BandSheetParams& params = {});

// 6-neighbour dilation of the unscanned set by `voxels` layers (in place);
// with `within`, only into voxels where (*within)[i] != 0.
void grow_unscanned(std::vector<std::uint8_t>& mask, const Dims3& dims, int voxels,
                    const std::vector<std::uint8_t>* within = nullptr, int threads = 0);

}  // namespace softshell
