// Realistic 3D ultrasound phantoms with ground truth (`softshell phantom`).
//
// A smooth implicit geometry (fetal face with a uterine wall, a chain of
// vertebrae, or a sphere) gives the true tissue boundaries as a signed
// distance field; a convolution (Field II-like) image-formation model on the
// device turns its echogenicity into a speckled, log-compressed B-mode volume.
//
// Conventions shared with `softshell evaluate` and the classifier:
//  - the transducer lies on the z = 0 face of the volume and every beam runs
//    along +z (depth): axial = z, lateral = x and y;
//  - the truth SDF is in voxels, negative inside tissue, zero on the boundary;
//  - the volume is uint8 with isotropic spacing fov_mm / size (fov_mm /
//    max(dims) for a non-cubic phantom).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "cl_runtime.hpp"
#include "image.hpp"
#include "volume.hpp"

namespace softshell {

enum class PhantomShape { Face, Spine, Sphere };
const char* phantom_shape_name(PhantomShape s);             // "face", "spine", "sphere"
bool parse_phantom_shape(const std::string& name, PhantomShape& out);

// ---- physics in physical units (`--physics NAME`, docs/phantom.md) --------------------
//
// Every parameter below is in mm, degrees, dB or a plain ratio and does not
// depend on the voxel count: the same parameters at --size 96 and 256 give the
// same physics and anatomy, sampled finer. World frame (mm): x and y centred
// on the volume, z the depth below its top face (where the probe's skin line
// lies); voxel (i, j, k) sits at ((i + 0.5 - nx/2) h, (j + 0.5 - ny/2) h, (k + 0.5) h).

enum class BeamGeometry {
  Linear,  // parallel beams along +z (a linear array swept along y)
  Fan,     // curvilinear array swept along y: beams from an apex line x = 0, z = -R (parallel to y)
  Fan3d,   // volume probe: beams from an apex point (0, 0, -R), a sector in x and in y
};
const char* beam_geometry_name(BeamGeometry g);  // "linear", "fan", "fan3d"
bool parse_beam_geometry(const std::string& name, BeamGeometry& out);

struct PhantomPhysics {
  // Acquisition geometry
  BeamGeometry geometry = BeamGeometry::Linear;
  double fov_mm = 100;           // edge of the cubic volume
  double probe_radius_mm = 40;   // fans: the apex lies this far above the top face; the probe surface is the arc r = R
  double sector_deg = 30;        // fans: half-angle of the sector in x (< 45)
  double sector_y_deg = 25;      // fan3d: half-angle in y (< 45)
  double scan_depth_mm = 100;    // fans: depth of the sector's bottom arc below the probe surface (linear: ignored, the whole depth)
  double jitter_mm = 0;          // freehand sweep: peak in-plane displacement of a slice (value noise along y, period 4 mm)
  // Point-spread function: standard deviations (mm) at the focus, widening away from it:
  // sigma(d) = sigma (1 + beam_spread |d - focus_depth| / depth) laterally, half that spread in
  // elevation; the axial sigma is constant.
  double psf_lateral_mm = 1.0, psf_axial_mm = 0.4, psf_elevation_mm = 1.5;
  double focus_depth_mm = 40, beam_spread = 0.5;
  // Scattering
  double scatterers_per_cell = 20;  // point scatterers per resolution cell (2 pi)^1.5 sl se sa at the focus
  double texture = 0.3;             // amplitude of the echogenicity texture (1 +- texture)
  double contrast_db = 25;          // face, sphere: tissue over fluid; spine: bone over muscle
  double specular = 1;              // boundary echoes and their reflection loss, x the reference strength (0: a plain step)
  double skull_db = 10;             // face: the fetal skull's echo above tissue
  double bone_atten_db_mm = 4;      // two-way attenuation in bone (spine) and the fetal skull
  // Attenuation and time-gain compensation (TGC)
  double frequency_mhz = 5, attenuation_db_cm_mhz = 0.5;  // soft tissue, one-way: two-way dB/mm = alpha f / 5
  double tgc_slope_db = 0, tgc_bow_db = 0;  // TGC mismatch: D(t) = slope t + bow 4 t (1 - t), t = depth / scan depth
  // Display
  double dynamic_range_db = 50;  // log compression range mapped to 0..255
  double tissue_grey = 160;      // overall gain: grey level of the mean soft-tissue echo (power) at the skin line
  double noise_db = -35;         // electronic noise power re the mean tissue echo, after TGC
  // Near field: layers under the probe (skin, fat, muscle), not part of the object
  double near_field_mm = 0;      // total thickness (0: none)
  double skin_mm = 1.5, fat_mm = 3;  // muscle: the rest
  double near_field_db = 6;      // echo of the muscle layer above soft tissue; skin 3 dB more
  double fat_db = -6;            // fat re the muscle layer (plus bright septa)
  double near_field_specular = 1;  // interface (fascia) echoes, x the tissue boundary strength
  double near_field_wave = 0.08;   // relative undulation of the interfaces (<= 0.15)
  double near_field_wavelength_mm = 25;
  double near_field_dir_deg[2] = {20, 110};  // directions of the two undulation waves
  double near_field_phase_deg[8] = {0, 0, 40, 200, 80, 300, 150, 10};  // per interface (surface, 1, 2, 3), two waves
  double reverb_db = -30;        // level of the first reverberation of each interface (the second: twice)
  // Pose of the scene (rigid: the truth stays exact): rotations about z (yaw), x (pitch), y (roll)
  // about the volume's centre, R = Rz Ry Rx, then a shift.
  double yaw_deg = 0, pitch_deg = 0, roll_deg = 0;
  double shift_mm[3] = {0, 0, 0};
};

// Named physics for `--physics`: "default" (the fixed physics of make_phantom
// without `physics`, bit for bit), "clean", "obstetric", "spine",
// "curvilinear", "harsh" and "random" (drawn from the seed).
const std::vector<std::string>& phantom_physics_names();

// The physics of a name for a shape: std::nullopt for "default"; "random"
// draws from the seed (deterministically; distributions in docs/phantom.md);
// a named preset ignores the seed. Throws InputError for an unknown name.
std::optional<PhantomPhysics> phantom_physics(const std::string& name, PhantomShape shape, std::uint64_t seed);

// Throws InputError (one line naming the parameter) for values outside the
// documented ranges.
void validate_phantom_physics(const PhantomPhysics& p);

// Sets one parameter by its phantom.json name ("near_field_mm", "geometry",
// "shift_mm[1]", ...) from text; InputError naming it for an unknown name or a
// malformed value. `apply_physics_settings` takes "name=value,name=value".
void set_physics_parameter(PhantomPhysics& p, const std::string& name, const std::string& value);
void apply_physics_settings(PhantomPhysics& p, const std::string& settings);

// The parameters as the body of a JSON object (one "name": value per line,
// `indent` spaces in, no braces).
std::string phantom_physics_json(const PhantomPhysics& p, int indent);

struct PhantomParams {
  PhantomShape shape = PhantomShape::Face;
  int size = 96;                     // voxels along each axis
  // Non-cubic volumes (the paper's Table 1 shapes, e.g. 314x85x43): when any
  // entry is non-zero all must be, each in [16, 512]; `size` is then ignored.
  // Voxels stay isotropic, h = fov / max(dims): the volume is the centred
  // max(dims)^3 phantom cropped to dims (the transducer on the crop's z = 0
  // face), so the longest axis spans the whole field of view.
  std::array<int, 3> dims{0, 0, 0};
  std::uint64_t seed = 1;
  double fov_mm = 0;                 // field of view; 0: the shape's default
  // Point-spread function, standard deviations in voxels: finer axially.
  double psf_axial = 0.6, psf_lateral = 1.5;
  double dynamic_range_db = 50;      // log compression range mapped to 0..255
  double noise = 0.02;               // electronic noise, relative to tissue echo
  double attenuation = 1.0;          // relative strength of depth attenuation
  double specular = 1.0;             // relative strength of boundary echoes
  double top_db = 18;                // echo level (dB re the mean tissue echo) mapped to 255
  int lanes = 0;                     // voxels per work-item: 0 by device (CPU 8, GPU 1); tests force 1 or 8
  // `--physics NAME`: empty for none (today's output: no labels, no physics
  // fields). With `physics` set the image is formed by phantom_scan.cl from
  // those parameters (the fields above from psf_axial to top_db, fov_mm and
  // dims then do not apply); without it by the fixed physics above.
  std::string physics_name;
  std::optional<PhantomPhysics> physics;
};

// Default field of view of a shape in mm (used when fov_mm is 0): face 100,
// spine 60, sphere 80.
double phantom_default_fov(PhantomShape s);

// The phantom's dims: `dims` when set, else size^3.
std::array<std::size_t, 3> phantom_dims(const PhantomParams& params);

// Throws InputError (one line naming the CLI option) for out-of-range
// parameters: size or a dims entry outside [16, 512], PSF sigmas outside [0.2, 8] voxels,
// dynamic range outside [10, 100] dB, negative noise / attenuation /
// specular, fov negative or above 10 m, lanes other than 0, 1, 8.
void validate_phantom_params(const PhantomParams& params);

struct Phantom {
  Volume volume;      // uint8 B-mode
  Volume truth_sdf;   // float, voxels, < 0 inside tissue
  double fluid_median = 0, tissue_median = 0;  // of `volume`, away from boundaries
                                               // (sdf > 3 / sdf < -3; NaN when no voxel is)
  std::array<double, 3> beam{0, 0, 1};
  double seconds = 0;  // generation time (device work included)
  // Additions: where the time went and on what.
  double device_seconds = 0;  // first kernel start to last kernel end (profiling events)
  double fov_mm = 0;          // the field of view used (params.fov_mm or the shape's default)
  std::string device;         // label of the device that computed it
  std::vector<std::pair<std::string, double>> kernel_seconds;  // per kernel, in order (profiling events)
  // With --physics: labels per voxel (uint8): 0 fluid / background, 1 the
  // object (sdf < 0), 2 near-field layers, 3 outside the scanned region.
  // Without: empty.
  Volume labels;
  // With --physics other than default: per voxel the two-way loss (dB) the
  // echo suffered beyond what the TGC restores (the reference tissue's
  // attenuation over the depth): > 0 in acoustic shadows, < 0 below fluid
  // (enhancement), 0 outside the scanned region; float. Otherwise empty.
  Volume shadow_db;
  double near_field_median = 0;  // grey level over label 2 (NaN when none)
  // The beam grid of a physics phantom (phantom.json "scan"): cells along
  // u, v, w, and the PSF's widths in cells (range over depth) and radii.
  std::array<int, 3> beam_cells{0, 0, 0};
  std::array<double, 2> psf_lateral_cells{0, 0}, psf_elevation_cells{0, 0};
  double psf_axial_cells = 0;
  std::array<int, 3> psf_radius{0, 0, 0};
};

// Deterministic for a given (params, seed) on a device: two runs give
// bit-identical volumes. Throws InputError for out-of-range parameters.
Phantom make_phantom(Runtime& rt, const PhantomParams& params);

// The physics path of make_phantom (params.physics set; host/phantom_scan.cpp).
Phantom make_scan_phantom(Runtime& rt, const PhantomParams& params);

// Beam direction (unit) at a world point (mm, see PhantomPhysics) and whether
// the point lies in the scanned region: the host's reference for the kernels'
// geometry and the rule `softshell evaluate` users apply for fans.
struct BeamAt {
  std::array<double, 3> dir{0, 0, 1};
  double depth_mm = 0;  // along the beam, below the probe surface
  bool scanned = true;
};
BeamAt phantom_beam_at(const PhantomPhysics& p, double x_mm, double y_mm, double z_mm);

// The parameters and medians as a JSON object (phantom.json).
std::string phantom_json(const PhantomParams& params, const Phantom& p);

// Two rows of axial | coronal | sagittal mid-slices: the B-mode volume, and
// the same with the true boundary (sdf = 0) drawn in orange. Panels are
// `panel_height` pixels high (0: max(size, 256)).
Image phantom_slices(const Phantom& p, int panel_height = 0);

// For tests of the distance correction: the raw smooth implicit function of
// the shape (voxels, negative inside; a lower bound on the distance, not the
// distance) at points given in voxel coordinates of a params.size^3 phantom
// (posed as params.physics says when it is set).
std::vector<float> phantom_implicit(Runtime& rt, const PhantomParams& params,
                                    const std::vector<std::array<float, 3>>& points);

}  // namespace softshell
