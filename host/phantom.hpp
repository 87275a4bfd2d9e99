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
};

// Deterministic for a given (params, seed) on a device: two runs give
// bit-identical volumes. Throws InputError for out-of-range parameters.
Phantom make_phantom(Runtime& rt, const PhantomParams& params);

// The parameters and medians as a JSON object (phantom.json).
std::string phantom_json(const PhantomParams& params, const Phantom& p);

// Two rows of axial | coronal | sagittal mid-slices: the B-mode volume, and
// the same with the true boundary (sdf = 0) drawn in orange. Panels are
// `panel_height` pixels high (0: max(size, 256)).
Image phantom_slices(const Phantom& p, int panel_height = 0);

// For tests of the distance correction: the raw smooth implicit function of
// the shape (voxels, negative inside; a lower bound on the distance, not the
// distance) at points given in voxel coordinates of a params.size^3 phantom.
std::vector<float> phantom_implicit(Runtime& rt, const PhantomParams& params,
                                    const std::vector<std::array<float, 3>>& points);

}  // namespace softshell
