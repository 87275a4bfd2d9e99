// Volume: a 3-D scalar field on a regular grid, held on the host as float
// samples in the file's own intensity units, x fastest:
//   index(x, y, z) = x + nx * (y + ny * z).
// Spacing and origin are in millimetres. The scalar type the data came from is
// remembered so outputs can be written back in it.
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

struct Volume {
  Dims3 dims{0, 0, 0};
  Vec3d spacing{1.0, 1.0, 1.0};  // mm
  Vec3d origin{0.0, 0.0, 0.0};   // mm, position of voxel (0,0,0)
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
  // Same geometry, float32, given samples (moved in).
  Volume with_data(std::vector<float> samples, ScalarType t) const;
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
