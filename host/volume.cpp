// Volume, scalar-type helpers, intensity normalisation and the summary
// statistics / text report behind `softshell info`.
#include "volume.hpp"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace softshell {

const char* scalar_type_name(ScalarType t) {
  switch (t) {
    case ScalarType::Int8: return "int8";
    case ScalarType::UInt8: return "uint8";
    case ScalarType::Int16: return "int16";
    case ScalarType::UInt16: return "uint16";
    case ScalarType::Int32: return "int32";
    case ScalarType::UInt32: return "uint32";
    case ScalarType::Int64: return "int64";
    case ScalarType::UInt64: return "uint64";
    case ScalarType::Float32: return "float";
    case ScalarType::Float64: return "double";
  }
  return "unknown";
}

std::size_t scalar_type_size(ScalarType t) {
  switch (t) {
    case ScalarType::Int8:
    case ScalarType::UInt8: return 1;
    case ScalarType::Int16:
    case ScalarType::UInt16: return 2;
    case ScalarType::Int32:
    case ScalarType::UInt32:
    case ScalarType::Float32: return 4;
    case ScalarType::Int64:
    case ScalarType::UInt64:
    case ScalarType::Float64: return 8;
  }
  return 0;
}

bool scalar_type_is_integer(ScalarType t) {
  return t != ScalarType::Float32 && t != ScalarType::Float64;
}

std::optional<ScalarType> parse_scalar_type(std::string_view name) {
  struct Entry {
    std::string_view name;
    ScalarType type;
  };
  static constexpr Entry kNames[] = {
      {"int8", ScalarType::Int8},       {"uint8", ScalarType::UInt8},
      {"int16", ScalarType::Int16},     {"uint16", ScalarType::UInt16},
      {"int32", ScalarType::Int32},     {"uint32", ScalarType::UInt32},
      {"int64", ScalarType::Int64},     {"uint64", ScalarType::UInt64},
      {"float", ScalarType::Float32},   {"float32", ScalarType::Float32},
      {"double", ScalarType::Float64},  {"float64", ScalarType::Float64},
  };
  for (const Entry& e : kNames) {
    if (e.name == name) return e.type;
  }
  return std::nullopt;
}

namespace {
template <typename T>
double lowest() { return static_cast<double>(std::numeric_limits<T>::lowest()); }
template <typename T>
double highest() { return static_cast<double>(std::numeric_limits<T>::max()); }
}  // namespace

double scalar_type_min(ScalarType t) {
  switch (t) {
    case ScalarType::Int8: return lowest<std::int8_t>();
    case ScalarType::UInt8: return 0.0;
    case ScalarType::Int16: return lowest<std::int16_t>();
    case ScalarType::UInt16: return 0.0;
    case ScalarType::Int32: return lowest<std::int32_t>();
    case ScalarType::UInt32: return 0.0;
    case ScalarType::Int64: return lowest<std::int64_t>();
    case ScalarType::UInt64: return 0.0;
    case ScalarType::Float32: return -FLT_MAX;
    case ScalarType::Float64: return -DBL_MAX;
  }
  return 0.0;
}

double scalar_type_max(ScalarType t) {
  switch (t) {
    case ScalarType::Int8: return highest<std::int8_t>();
    case ScalarType::UInt8: return highest<std::uint8_t>();
    case ScalarType::Int16: return highest<std::int16_t>();
    case ScalarType::UInt16: return highest<std::uint16_t>();
    case ScalarType::Int32: return highest<std::int32_t>();
    case ScalarType::UInt32: return highest<std::uint32_t>();
    case ScalarType::Int64: return highest<std::int64_t>();
    case ScalarType::UInt64: return highest<std::uint64_t>();
    case ScalarType::Float32: return FLT_MAX;
    case ScalarType::Float64: return DBL_MAX;
  }
  return 0.0;
}

// ---- IntensityMap ------------------------------------------------------------

double IntensityMap::to_unit(double v) const {
  // A constant volume (hi == lo) maps to 0 rather than dividing by zero.
  if (!(hi > lo)) return 0.0;
  double u = (v - lo) / (hi - lo);
  if (clamp) u = std::clamp(u, 0.0, 1.0);
  return u;
}

double IntensityMap::from_unit(double u) const { return lo + u * (hi - lo); }

namespace {
std::string format_number(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}
}  // namespace

std::string IntensityMap::describe() const {
  std::string s = rule.empty() ? std::string("linear") : rule;
  s += " [" + format_number(lo) + ", " + format_number(hi) + "] -> [0, 1]";
  if (clamp) s += ", clamped";
  if (!(hi > lo)) s += " (constant volume: everything maps to 0)";
  return s;
}

// ---- percentiles ---------------------------------------------------------------

namespace {

// Percentiles (in %) of the finite values, linearly interpolated
// between order statistics. Consumes `values`; O(n) per percentile via
// nth_element on a shrinking range instead of a full sort.
std::vector<double> percentiles_of(std::vector<float> values, const std::vector<double>& pcts) {
  // NaN would break nth_element's strict weak ordering; infinities would
  // make the interpolation meaningless.
  values.erase(std::remove_if(values.begin(), values.end(),
                              [](float x) { return !std::isfinite(x); }),
               values.end());
  std::vector<double> out(pcts.size(), 0.0);
  if (values.empty()) return out;
  const std::size_t n = values.size();
  std::size_t done = 0;  // [0, done) holds the smallest `done` values, in place
  for (std::size_t i = 0; i < pcts.size(); ++i) {
    const double pos = std::clamp(pcts[i], 0.0, 100.0) / 100.0 * static_cast<double>(n - 1);
    const std::size_t k = std::min(static_cast<std::size_t>(pos), n - 1);
    const double frac = pos - static_cast<double>(k);
    // Ascending requests reuse the previous partition; otherwise start over.
    const auto first = values.begin() + static_cast<std::ptrdiff_t>(k >= done ? done : 0);
    std::nth_element(first, values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
    double v = values[k];
    if (frac > 0.0 && k + 1 < n) {
      const float next = *std::min_element(values.begin() + static_cast<std::ptrdiff_t>(k + 1),
                                           values.end());
      v += frac * (static_cast<double>(next) - v);
    }
    out[i] = v;
    done = k + 1;  // everything after k is >= values[k]
  }
  return out;
}

}  // namespace

IntensityMap Volume::intensity_map() const {
  IntensityMap m;
  if (scalar_type_is_integer(source_type)) {
    m.lo = scalar_type_min(source_type);
    m.hi = scalar_type_max(source_type);
    m.clamp = false;
    m.rule = "type range";
  } else {
    // Robust bounds so a few outliers do not squash the useful range.
    const std::vector<double> p = percentiles_of(data, {0.5, 99.5});
    m.lo = p[0];
    m.hi = p[1];
    m.clamp = true;
    m.rule = "robust min/max (0.5%, 99.5%)";
  }
  return m;
}

Volume::Volume(Dims3 d, Vec3d s, ScalarType t)
    : dims(d), spacing(s), source_type(t), data(d[0] * d[1] * d[2], 0.0f) {}

Volume Volume::with_data(std::vector<float> samples, ScalarType t) const {
  Volume out;
  out.dims = dims;
  out.spacing = spacing;
  out.origin = origin;
  out.frame = frame;
  out.source_type = t;
  out.data = std::move(samples);
  return out;
}

// ---- the world frame ------------------------------------------------------------

bool WorldFrame::anatomical() const {
  return space.empty() || space == "left-posterior-superior" || space == "right-anterior-superior" ||
         space == "left-anterior-superior";
}

WorldFrame WorldFrame::to_lps(Vec3d& origin) const {
  WorldFrame out = *this;
  // Components to negate: RAS -> LPS flips x and y; LAS -> LPS flips y.
  int flips = 0;
  if (space == "right-anterior-superior") flips = 2;
  else if (space == "left-anterior-superior") flips = 1;
  else return out;
  auto flip = [&](Vec3d& v) {  // + 0.0: no "-0" in written headers
    if (flips == 2) v[0] = -v[0] + 0.0;
    v[1] = -v[1] + 0.0;
  };
  for (Vec3d& a : out.axes) flip(a);
  flip(origin);
  out.space = "left-posterior-superior";
  out.measurement_frame.reset();  // its meaning is tied to the old space
  out.anatomical_orientation.clear();
  return out;
}

std::string lps_orientation_code(const Mat3& axes_lps) {
  // The side each axis points to, then the opposite letter (ITK names the
  // side the axis comes from).
  static const char kFrom[3][2] = {{'R', 'L'}, {'A', 'P'}, {'I', 'S'}};  // [component][direction > 0]
  std::string code;
  for (const Vec3d& a : axes_lps) {
    int best = 0;
    for (int c = 1; c < 3; ++c)
      if (std::fabs(a[c]) > std::fabs(a[best])) best = c;
    code += kFrom[best][a[best] > 0 ? 0 : 1];
  }
  return code;
}

double determinant(const Mat3& m) {
  return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

Mat3 inverse(const Mat3& m) {
  const double det = determinant(m);
  if (!(std::fabs(det) >= 1e-12)) throw std::invalid_argument("inverse: singular 3x3 matrix");
  Mat3 r{};
  r[0][0] = (m[1][1] * m[2][2] - m[1][2] * m[2][1]) / det;
  r[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det;
  r[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det;
  r[1][0] = (m[1][2] * m[2][0] - m[1][0] * m[2][2]) / det;
  r[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det;
  r[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det;
  r[2][0] = (m[1][0] * m[2][1] - m[1][1] * m[2][0]) / det;
  r[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det;
  r[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det;
  return r;
}

Vec3d Volume::index_to_world(const Vec3d& ijk) const {
  Vec3d w = origin;
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) w[c] += ijk[a] * spacing[a] * frame.axes[a][c];
  return w;
}

Vec3d Volume::world_to_index(const Vec3d& xyz) const {
  // world - origin = sum_a ijk[a] * (spacing[a] axes[a]) = M^T ijk, M's rows the scaled axes.
  Mat3 m{};
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) m[a][c] = spacing[a] * frame.axes[a][c];
  const Mat3 inv = inverse(m);  // ijk = (M^T)^-1 d = (M^-1)^T d
  Vec3d d{}, ijk{};
  for (int c = 0; c < 3; ++c) d[c] = xyz[c] - origin[c];
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) ijk[a] += inv[c][a] * d[c];
  return ijk;
}

Vec3d Volume::grid_to_world(const Vec3d& g) const {
  Vec3d w = origin;
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) w[c] += (g[a] - origin[a]) * frame.axes[a][c];
  return w;
}

// ---- statistics ----------------------------------------------------------------

VolumeStats compute_stats(const Volume& v, std::size_t bins) {
  VolumeStats st;
  st.histogram.assign(bins, 0);
  const std::size_t n = v.data.size();
  if (n == 0) return st;

  std::size_t finite = 0, zeros = 0;
  double lo = std::numeric_limits<double>::infinity();
  double hi = -lo;
  double sum = 0.0;
  for (float x : v.data) {
    if (x == 0.0f) ++zeros;
    if (!std::isfinite(x)) continue;
    ++finite;
    lo = std::min(lo, static_cast<double>(x));
    hi = std::max(hi, static_cast<double>(x));
    sum += x;
  }
  st.zero_fraction = static_cast<double>(zeros) / static_cast<double>(n);
  if (finite == 0) return st;
  st.min = lo;
  st.max = hi;
  st.mean = sum / static_cast<double>(finite);
  // Second pass about the mean: no cancellation as with sum of squares.
  double ss = 0.0;
  for (float x : v.data) {
    if (!std::isfinite(x)) continue;
    const double d = x - st.mean;
    ss += d * d;
  }
  st.stddev = std::sqrt(ss / static_cast<double>(finite));

  if (bins > 0) {
    const double width = (hi - lo) / static_cast<double>(bins);
    for (float x : v.data) {
      if (!std::isfinite(x)) continue;
      std::size_t b = 0;
      if (width > 0.0) {
        b = static_cast<std::size_t>((x - lo) / width);
        b = std::min(b, bins - 1);  // x == max lands in the last bin
      }
      ++st.histogram[b];
    }
  }

  const std::vector<double> p = percentiles_of(v.data, {1, 5, 25, 50, 75, 95, 99});
  std::copy(p.begin(), p.end(), st.percentiles.begin());
  return st;
}

// ---- report --------------------------------------------------------------------

namespace {

std::string group_thousands(std::size_t n) {
  std::string digits = std::to_string(n);
  std::string out;
  const std::size_t len = digits.size();
  for (std::size_t i = 0; i < len; ++i) {
    out += digits[i];
    const std::size_t left = len - 1 - i;
    if (left > 0 && left % 3 == 0) out += ',';
  }
  return out;
}

std::string join3(const Vec3d& a, const char* sep) {
  return format_number(a[0]) + sep + format_number(a[1]) + sep + format_number(a[2]);
}

}  // namespace

std::string describe_volume(const Volume& v, const std::string& path) {
  const VolumeStats st = compute_stats(v, 16);
  std::ostringstream os;
  os << "file:               " << path << "\n";
  os << "dims:               " << v.dims[0] << " x " << v.dims[1] << " x " << v.dims[2] << "  ("
     << group_thousands(v.voxels()) << " voxels)\n";
  os << "spacing:            " << join3(v.spacing, " x ") << " mm\n";
  os << "origin:             (" << join3(v.origin, ", ") << ") mm  (centre of voxel 0,0,0)\n";
  os << "world:              " << (v.frame.space.empty() ? "not named (taken as left-posterior-superior)" : v.frame.space);
  if (!v.frame.anatomical_orientation.empty()) os << ", AnatomicalOrientation " << v.frame.anatomical_orientation;
  os << "\n";
  os << "axes:               ";
  if (v.frame.axes_are_identity()) {
    os << "identity (grid axes along the world's x, y, z)\n";
  } else {
    os << "(" << join3(v.frame.axes[0], ", ") << ") (" << join3(v.frame.axes[1], ", ") << ") ("
       << join3(v.frame.axes[2], ", ") << ")  (unit directions of i, j, k in the world)\n";
  }
  const Vec3d extent{v.dims[0] * v.spacing[0], v.dims[1] * v.spacing[1],
                     v.dims[2] * v.spacing[2]};
  os << "extent:             " << join3(extent, " x ") << " mm  (dims x spacing)\n";
  os << "type:               " << scalar_type_name(v.source_type) << " ("
     << scalar_type_size(v.source_type) << " byte" << (scalar_type_size(v.source_type) > 1 ? "s" : "")
     << " per voxel)\n";
  std::size_t non_finite = 0, first = 0;
  for (std::size_t i = 0; i < v.data.size(); ++i)
    if (!std::isfinite(v.data[i]) && non_finite++ == 0) first = i;
  if (non_finite > 0) {
    // Commands that compute refuse these (or replace them on request).
    os << "non-finite samples: " << group_thousands(non_finite) << " (NaN or infinite; the first is sample " << first
       << ", x " << first % v.dims[0] << " y " << (first / v.dims[0]) % v.dims[1] << " z "
       << first / (v.dims[0] * v.dims[1]) << "), left out of the statistics below\n";
  }
  os << "value range:        " << format_number(st.min) << " .. " << format_number(st.max) << "\n";
  os << "mean / std:         " << format_number(st.mean) << " / " << format_number(st.stddev) << "\n";

  char pct[64];
  std::snprintf(pct, sizeof pct, "%.1f %%", st.zero_fraction * 100.0);
  os << "voxels equal to 0:  " << pct;
  if (st.zero_fraction > 0.2) {
    // In freehand ultrasound, large exact-zero regions are usually voxels the
    // probe never swept ("no data"), not dark tissue.
    os << "  (unscanned? exact zeros usually mark voxels the probe never swept)";
  }
  os << "\n";
  os << "normalised:         " << v.intensity_map().describe() << "\n";

  static const int kPct[7] = {1, 5, 25, 50, 75, 95, 99};
  os << "percentiles:       ";
  for (int i = 0; i < 7; ++i) {
    os << " p" << kPct[i] << "=" << format_number(st.percentiles[i]);
  }
  os << "\n";

  os << "histogram (16 equal-width bins over the value range):\n";
  const std::size_t biggest =
      st.histogram.empty() ? 0 : *std::max_element(st.histogram.begin(), st.histogram.end());
  const double width = (st.max - st.min) / 16.0;
  constexpr int kBarWidth = 40;
  for (std::size_t b = 0; b < st.histogram.size(); ++b) {
    const double from = st.min + width * static_cast<double>(b);
    const double to = b + 1 == st.histogram.size() ? st.max : from + width;
    const char close = b + 1 == st.histogram.size() ? ']' : ')';
    int bar = 0;
    if (biggest > 0) {
      bar = static_cast<int>(std::lround(kBarWidth * static_cast<double>(st.histogram[b]) /
                                         static_cast<double>(biggest)));
      if (bar == 0 && st.histogram[b] > 0) bar = 1;  // show that the bin is not empty
    }
    char line[160];
    std::snprintf(line, sizeof line, "  [%11.5g, %11.5g%c %12s ", from, to, close,
                  group_thousands(st.histogram[b]).c_str());
    os << line << std::string(static_cast<std::size_t>(bar), '#') << "\n";
  }
  return os.str();
}

std::string grid_mismatch(const Volume& a, const Volume& b) {
  auto three = [](const Vec3d& v) {
    std::ostringstream s;
    s << v[0] << ',' << v[1] << ',' << v[2];
    return s.str();
  };
  std::string out;
  auto add = [&](const std::string& what) { out += (out.empty() ? "" : "; ") + what; };
  double h = 0;
  for (int i = 0; i < 3; ++i) h = std::max(h, a.spacing[i]);
  bool spacing = false, origin = false, axes = false;
  for (int i = 0; i < 3; ++i) {
    spacing = spacing || std::fabs(a.spacing[i] - b.spacing[i]) > 1e-4 * a.spacing[i];
    origin = origin || std::fabs(a.origin[i] - b.origin[i]) > 1e-3 * h;
    for (int c = 0; c < 3; ++c) axes = axes || std::fabs(a.frame.axes[i][c] - b.frame.axes[i][c]) > 1e-4;
  }
  if (spacing) add("spacing " + three(a.spacing) + " mm against " + three(b.spacing) + " mm");
  if (origin) add("origin (" + three(a.origin) + ") against (" + three(b.origin) + ") mm");
  if (axes) add("axes differ");
  return out;
}

}  // namespace softshell
