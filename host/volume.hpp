// Volume: a 3-D scalar field on a regular grid, held on the host as float
// samples in the file's own intensity units, x fastest:
//   index(x, y, z) = x + nx * (y + ny * z).
// Spacing and origin are in millimetres; `frame` places the grid in the
// world (orientation, the world's name). The scalar type the data came from
// is remembered so outputs can be written back in it.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace softshell {

enum class ScalarType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Int64, UInt64, Float32, Float64 };

const char* scalar_type_name(ScalarType t);           // "uint8", "float", ...
std::size_t scalar_type_size(ScalarType t);           // bytes per sample
bool scalar_type_is_integer(ScalarType t);
// Parses "int8|uint8|int16|uint16|int32|uint32|int64|uint64|float|double"
// (also "float32"/"float64"); nullopt when unknown.
std::optional<ScalarType> parse_scalar_type(std::string_view name);
// Lowest / highest representable value of an integer type (for clamping and
// for the type-range normalisation); for float types +-FLT_MAX / +-DBL_MAX.
double scalar_type_min(ScalarType t);
double scalar_type_max(ScalarType t);

using Dims3 = std::array<std::size_t, 3>;
using Vec3d = std::array<double, 3>;
using Mat3 = std::array<Vec3d, 3>;  // three vectors (rows in code, axes in meaning: see WorldFrame)

inline constexpr Mat3 kIdentityAxes{{{1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, {0.0, 0.0, 1.0}}};

// Where the voxel grid lies in the world (the scanner's or the patient's
// coordinates), the index-to-world transform of ITK, Slicer and NRRD:
//   world(i, j, k) = origin + i * spacing[0] * axes[0] + j * spacing[1] * axes[1] + k * spacing[2] * axes[2]
// axes[a] is the unit vector of index axis a in world coordinates (NRRD's
// "space directions" divided by their lengths; MetaImage's TransformMatrix
// lists the same three vectors in the same order; ITK's direction matrix has
// them as columns). The classifier works on the grid (spacing only); the
// frame is carried from input to output and used where geometry is written
// in world terms (meshes). docs/formats.md, "Orientation".
struct WorldFrame {
  Mat3 axes = kIdentityAxes;
  // The world's name in NRRD's words: "left-posterior-superior" (ITK,
  // DICOM, MetaImage), "right-anterior-superior" (NIfTI, Slicer's display),
  // "left-anterior-superior", "scanner-xyz", "3D-right-handed",
  // "3D-left-handed"; empty when the file names none (MetaImage, raw,
  // phantoms): written as left-posterior-superior, ITK's physical space.
  std::string space;
  // NRRD's "measurement frame", as Teem holds it, kept only to be written
  // back (softshell's samples are scalars; it does not apply to them).
  std::optional<Mat3> measurement_frame;
  // MetaImage's AnatomicalOrientation as read (e.g. "RAI"); empty: derived
  // from the axes when written.
  std::string anatomical_orientation;
  // The file's own direction vectors (NRRD's space directions, spacing
  // times axis), written back as they were while spacing and axes are
  // unchanged: unit axes times spacing can differ from them in the last bit.
  struct Exact {
    Vec3d spacing;
    Mat3 axes, directions;
  };
  std::optional<Exact> as_read;

  bool axes_are_identity() const { return axes == kIdentityAxes; }
  // True when the world is LPS, RAS or LAS (a patient space), or unnamed
  // (taken as LPS).
  bool anatomical() const;
  // The frame with the same physical meaning in LPS coordinates (axes and
  // `origin` flipped as RAS/LAS require); `origin` is updated in place. Other
  // spaces are returned as they are (ITK's rule: no conversion defined).
  WorldFrame to_lps(Vec3d& origin) const;
};

// "RAI"-style code of ITK's AnatomicalOrientation for axes given in LPS
// coordinates: per index axis, the letter of the side it comes *from*
// (identity axes -> "RAI"), by the dominant component of each axis.
std::string lps_orientation_code(const Mat3& axes_lps);
// Determinant of the three axes (rows); < 0: a left-handed grid.
double determinant(const Mat3& m);
// Inverse of m (rows); throws std::invalid_argument when |det| < 1e-12.
Mat3 inverse(const Mat3& m);

// Maps file intensities to [0, 1] for classification and back, so parameters
// such as v_iso carry across 8-bit, 16-bit and float data.
//  - integer data: by the type's range, unit = (v - type_min) / (type_max - type_min)
//  - float data: by robust min/max, the 0.5th and 99.5th percentiles of the
//    samples, clamped to [0, 1] (a constant volume maps to 0).
struct IntensityMap {
  double lo = 0.0;  // file value that maps to 0
  double hi = 1.0;  // file value that maps to 1
  bool clamp = false;
  double to_unit(double v) const;
  double from_unit(double u) const;
  std::string describe() const;  // e.g. "type range [0, 255]"
  std::string rule;              // "type range" or "robust min/max (0.5%, 99.5%)"
};

struct Volume;
// Empty when `a` and `b` (of the same dims) place their voxels at the same
// world positions (spacing within 1e-4 relative, origin within 1e-3 voxel,
// axes within 1e-4); else what differs, for a message: "spacing 0.5,0.5,1
// mm against 1,1,1 mm", "origin (...) against (...) mm", "axes differ".
std::string grid_mismatch(const Volume& a, const Volume& b);

struct Volume {
  Dims3 dims{0, 0, 0};
  Vec3d spacing{1.0, 1.0, 1.0};  // mm
  Vec3d origin{0.0, 0.0, 0.0};   // mm, world position of voxel (0,0,0)'s centre
  WorldFrame frame;              // orientation of the grid in the world (identity: axis-aligned)
  ScalarType source_type = ScalarType::Float32;
  std::vector<float> data;       // dims[0]*dims[1]*dims[2] samples

  Volume() = default;
  Volume(Dims3 d, Vec3d s = {1.0, 1.0, 1.0}, ScalarType t = ScalarType::Float32);

  std::size_t voxels() const { return dims[0] * dims[1] * dims[2]; }
  std::size_t index(std::size_t x, std::size_t y, std::size_t z) const {
    return x + dims[0] * (y + dims[1] * z);
  }
  float& at(std::size_t x, std::size_t y, std::size_t z) { return data[index(x, y, z)]; }
  float at(std::size_t x, std::size_t y, std::size_t z) const { return data[index(x, y, z)]; }

  IntensityMap intensity_map() const;
  // Same geometry (dims, spacing, origin, frame), given samples (moved in).
  Volume with_data(std::vector<float> samples, ScalarType t) const;

  // World position (mm) of a continuous index (voxel centres at integers).
  Vec3d index_to_world(const Vec3d& ijk) const;
  // Continuous index of a world position (the inverse).
  Vec3d world_to_index(const Vec3d& xyz) const;
  // World position of a point given in grid millimetres, origin + spacing *
  // index: what softshell's grid-based code (Marching Cubes, renderers)
  // produces. Equals the input when the axes are the identity.
  Vec3d grid_to_world(const Vec3d& grid_mm) const;
};

// Summary statistics for `softshell info` and for tests.
struct VolumeStats {
  double min = 0, max = 0, mean = 0, stddev = 0;
  double zero_fraction = 0;                    // share of samples exactly 0
  std::array<double, 7> percentiles{};         // 1, 5, 25, 50, 75, 95, 99 %
  std::vector<std::size_t> histogram;          // equal-width bins over [min, max]
};
VolumeStats compute_stats(const Volume& v, std::size_t bins = 16);

// Multi-line human-readable description of a volume (dims, spacing, origin,
// type, value range, intensity normalisation, percentiles, histogram bars).
std::string describe_volume(const Volume& v, const std::string& path);

}  // namespace softshell
