// GE Kretz `.vol` (Voluson 3D ultrasound): the tagged-item container, the
// probe's toroidal sampling grid, and its scan conversion to a Cartesian
// grid (docs/formats.md, "GE Kretz .vol").
//
// Format facts (as 3D Slicer's SlicerHeart KretzFileReader reads them; our
// own code): a 16-byte signature "KRETZFILE 1.0   ", then items, each a
// little-endian uint16 group, uint16 element, uint32 length and that many
// bytes. The items used:
//   (C000,0001) (C000,0002) (C000,0003)  uint16 dims: radial samples i, theta lines j, phi planes k
//   (C100,0001)  float64 radial resolution, metres
//   (C200,0001)  float64 offset1: the first radial sample, in resolutions
//   (C200,0002)  float64 offset2: minus the B-mode plane's rotation radius, in resolutions
//   (C300,0002)  float64[j] theta angles (radians, pi/2 at the centre line)
//   (C300,0001)  float64[k] phi angles (radians, pi/2 at the centre plane)
//   (0010,0022)  float64 voxel spacing of a Cartesian volume (no angle tables)
//   (D000,0001)  uint8[i j k] the samples, i fastest (uncompressed)
// Sample (i, j, k) lies at, with r = (offset1 + i) res, th = theta_j - pi/2,
// ph = phi_k - pi/2 and R = -offset2 res:
//   x = r sin th,  y = -(r cos th - R) sin ph,  z = R (1 - cos ph) + r cos th cos ph,
// z the depth below the probe. Everything is checked against the file's size
// before it is read or allocated.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "error.hpp"
#include "io.hpp"

namespace softshell::io_detail {
namespace {

constexpr char kSignature[] = "KRETZFILE 1.0   ";  // 16 bytes
constexpr std::size_t kSignatureSize = 16;
// The Cartesian grid: the radial resolution, coarsened so that no axis has
// more than kMaxCartesianVoxels voxels and the grid no more than
// kMaxUpsampling voxels per sample of the file.
constexpr double kMaxCartesianVoxels = 256, kMaxUpsampling = 8;

std::string tag_text(unsigned group, unsigned element) {
  char t[16];
  std::snprintf(t, sizeof t, "(%04X,%04X)", group, element);
  return t;
}

double le_double(const unsigned char* b) {
  std::uint64_t u = 0;
  for (int i = 7; i >= 0; --i) u = (u << 8) | b[i];
  double d;
  std::memcpy(&d, &u, sizeof d);
  return d;
}

struct KretzFile {
  std::array<std::uint32_t, 3> dims{0, 0, 0};
  double resolution_mm = std::numeric_limits<double>::quiet_NaN();
  double offset1 = 0, offset2 = 0;
  std::vector<double> theta, phi;
  double cartesian_spacing = std::numeric_limits<double>::quiet_NaN();
  std::uint64_t data_offset = 0, data_size = 0;
  bool have_data = false;
  bool spherical() const { return !theta.empty() || !phi.empty(); }
};

// Reads the items (not the samples); validates everything the conversion uses.
KretzFile scan(const std::string& path, std::FILE* f) {
  const std::uint64_t size = file_size(f);
  char sig[kSignatureSize];
  if (read_up_to(f, sig, kSignatureSize, path) != kSignatureSize || std::memcmp(sig, kSignature, kSignatureSize) != 0)
    throw input_error(path, "not a Kretz file (expected the signature 'KRETZFILE 1.0' at its start)");
  KretzFile k;
  bool have_dim[3] = {false, false, false};
  std::uint64_t pos = kSignatureSize;
  while (pos + 8 <= size) {
    unsigned char h[8];
    if (read_up_to(f, h, 8, path) != 8) break;
    pos += 8;
    const unsigned group = unsigned(h[0]) | unsigned(h[1]) << 8, element = unsigned(h[2]) | unsigned(h[3]) << 8;
    const std::uint64_t length = std::uint64_t(h[4]) | std::uint64_t(h[5]) << 8 | std::uint64_t(h[6]) << 16 |
                                 std::uint64_t(h[7]) << 24;
    const std::string tag = tag_text(group, element);
    if (length > size - pos)
      throw input_error(path, "item " + tag + " of " + std::to_string(length) + " bytes runs past the end of the file (" +
                                  std::to_string(size - pos) + " bytes left)");
    // Small items are read whole; the samples are only located.
    const bool voxels = group == 0xD000 && element == 0x0001;
    const bool wanted = group == 0xC000 || group == 0xC100 || group == 0xC200 || group == 0xC300 ||
                        (group == 0x0010 && element == 0x0022);
    std::vector<unsigned char> b;
    if (wanted && !voxels) {
      if (length > (std::uint64_t(1) << 20)) throw input_error(path, "item " + tag + " is implausibly large (" + std::to_string(length) + " bytes)");
      b.resize(std::size_t(length));
      if (read_up_to(f, b.data(), b.size(), path) != b.size()) throw input_error(path, "data truncated in item " + tag);
    } else if (std::fseek(f, long(pos + length), SEEK_SET) != 0) {
      throw input_error(path, "cannot seek past item " + tag);
    }
    const auto need = [&](std::size_t n) {
      if (b.size() < n)
        throw input_error(path, "item " + tag + " holds " + std::to_string(b.size()) + " bytes, expected " + std::to_string(n));
    };
    if (group == 0xC000 && element >= 1 && element <= 3) {
      need(2);
      k.dims[element - 1] = std::uint32_t(b[0]) | std::uint32_t(b[1]) << 8;
      have_dim[element - 1] = true;
    } else if (group == 0xC100 && element == 0x0001) {
      need(8);
      k.resolution_mm = le_double(b.data()) * 1000.0;
    } else if (group == 0xC200 && (element == 1 || element == 2)) {
      need(8);
      (element == 1 ? k.offset1 : k.offset2) = le_double(b.data());
    } else if (group == 0xC300 && (element == 1 || element == 2)) {
      if (b.size() % 8 != 0) throw input_error(path, "item " + tag + " (angles) holds " + std::to_string(b.size()) + " bytes, not a multiple of 8");
      std::vector<double>& a = element == 1 ? k.phi : k.theta;
      a.resize(b.size() / 8);
      for (std::size_t i = 0; i < a.size(); ++i) a[i] = le_double(b.data() + 8 * i);
    } else if (group == 0x0010 && element == 0x0022) {
      need(8);
      k.cartesian_spacing = le_double(b.data());
    } else if (voxels && !k.have_data) {
      k.have_data = true;
      k.data_offset = pos;
      k.data_size = length;
    }
    pos += length;
  }
  for (int a = 0; a < 3; ++a)
    if (!have_dim[a] || k.dims[a] == 0)
      throw input_error(path, "no dimension " + std::string(1, "IJK"[a]) + " (item " + tag_text(0xC000, unsigned(a + 1)) + ")");
  if (!k.have_data)
    throw input_error(path, "no uncompressed voxel data (item (D000,0001)); compressed Kretz volumes are not read");
  const std::uint64_t n = std::uint64_t(k.dims[0]) * k.dims[1] * k.dims[2];
  if (k.data_size != n)
    throw input_error(path, "the voxel data holds " + std::to_string(k.data_size) + " bytes, the dimensions " +
                                std::to_string(k.dims[0]) + " x " + std::to_string(k.dims[1]) + " x " +
                                std::to_string(k.dims[2]) + " need " + std::to_string(n));
  if (k.spherical()) {
    if (k.theta.size() != k.dims[1] || k.phi.size() != k.dims[2])
      throw input_error(path, "the angle tables hold " + std::to_string(k.theta.size()) + " theta and " +
                                  std::to_string(k.phi.size()) + " phi angles, the dimensions need " +
                                  std::to_string(k.dims[1]) + " and " + std::to_string(k.dims[2]));
    for (const std::vector<double>* table : {&k.theta, &k.phi}) {
      const bool up = table->size() < 2 || (*table)[1] > (*table)[0];
      for (std::size_t i = 0; i < table->size(); ++i) {
        const double a = (*table)[i];
        if (!std::isfinite(a) || a < 0 || a > M_PI)
          throw input_error(path, std::string(table == &k.theta ? "theta" : "phi") + " angle " + std::to_string(i) +
                                      " is outside [0, pi] radians");
        if (i > 0 && (up ? !(a > (*table)[i - 1]) : !(a < (*table)[i - 1])))
          throw input_error(path, std::string(table == &k.theta ? "theta" : "phi") + " angles are not monotonic");
      }
    }
    if (!(k.resolution_mm >= 1e-4 && k.resolution_mm <= 100))
      throw input_error(path, "radial resolution (item (C100,0001)) missing or outside 0.1 um - 10 cm");
    if (!std::isfinite(k.offset1) || !std::isfinite(k.offset2) || std::fabs(k.offset1) > 1e6 || std::fabs(k.offset2) > 1e6)
      throw input_error(path, "offsets (items (C200,0001), (C200,0002)) not finite or beyond 1e6 resolutions");
    if (k.offset1 < 0) throw input_error(path, "the first radial sample (offset1) lies behind the probe");
  } else if (std::isnan(k.cartesian_spacing)) {
    k.cartesian_spacing = 1.0;
  }
  return k;
}

// The probe geometry and its inverse.
struct Geometry {
  double r0, res, R;
  const std::vector<double>* theta;
  const std::vector<double>* phi;

  Vec3d point(double i, double th, double ph) const {
    const double r = r0 + i * res, t = th - M_PI / 2, p = ph - M_PI / 2;
    return {r * std::sin(t), -(r * std::cos(t) - R) * std::sin(p), R * (1 - std::cos(p)) + r * std::cos(t) * std::cos(p)};
  }
  // Fractional index of `a` in a monotonic table; < 0 or > n-1 outside.
  static double index_in(const std::vector<double>& table, double a) {
    const std::size_t n = table.size();
    if (n == 1) return a == table[0] ? 0.0 : -1.0;
    const bool up = table[1] > table[0];
    const auto lo = up ? std::lower_bound(table.begin(), table.end(), a)
                       : std::lower_bound(table.begin(), table.end(), a, std::greater<double>());
    std::size_t j = std::size_t(lo - table.begin());
    if (j == 0) return a == table[0] ? 0.0 : -1.0;
    if (j >= n) return double(n);
    const double f = (a - table[j - 1]) / (table[j] - table[j - 1]);
    return double(j - 1) + f;
  }
  // (i, j, k) of a Cartesian point, fractional; outside: some coordinate out of range.
  std::array<double, 3> index(const Vec3d& q) const {
    // z - R = s cos p, y = -s sin p with s = r cos t - R; cos p > 0 (|p| < pi/2).
    const double dz = q[2] - R;
    double s = std::hypot(q[1], dz);
    if (dz < 0) s = -s;
    const double p = s == 0 ? 0.0 : std::atan2(-q[1] / s, dz / s);
    const double rc = s + R;  // r cos t
    const double r = std::hypot(q[0], rc);
    const double t = std::atan2(q[0], rc);
    return {(r - r0) / res, index_in(*theta, t + M_PI / 2), index_in(*phi, p + M_PI / 2)};
  }
};

struct Cartesian {
  Dims3 dims{0, 0, 0};
  double spacing = 1;
  Vec3d origin{0, 0, 0};
};

Cartesian cartesian_grid(const std::string& path, const KretzFile& k, const Geometry& g) {
  Vec3d lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  const std::uint32_t ni = k.dims[0], nj = k.dims[1], nk = k.dims[2];
  const auto add = [&](std::uint32_t i, std::uint32_t j, std::uint32_t kk) {
    const Vec3d p = g.point(i, k.theta[j], k.phi[kk]);
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
  };
  // A smooth one-to-one map takes the box's boundary to the region's: its
  // extremes lie on the six faces.
  for (std::uint32_t j = 0; j < nj; ++j)
    for (std::uint32_t kk = 0; kk < nk; ++kk) add(0, j, kk), add(ni - 1, j, kk);
  for (std::uint32_t i = 0; i < ni; ++i)
    for (std::uint32_t kk = 0; kk < nk; ++kk) add(i, 0, kk), add(i, nj - 1, kk);
  for (std::uint32_t i = 0; i < ni; ++i)
    for (std::uint32_t j = 0; j < nj; ++j) add(i, j, 0), add(i, j, nk - 1);
  Cartesian c;
  double extent = 0;
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(lo[a]) || !std::isfinite(hi[a])) throw input_error(path, "the probe geometry is not finite");
    extent = std::max(extent, hi[a] - lo[a]);
  }
  // No axis beyond kMaxCartesianVoxels, and no more than kMaxUpsampling
  // voxels per sample (finer adds no information, only time).
  double box = 1;
  for (int a = 0; a < 3; ++a) box *= std::max(hi[a] - lo[a], k.resolution_mm);
  const double samples = double(ni) * double(nj) * double(nk);
  c.spacing = std::max({k.resolution_mm, extent / kMaxCartesianVoxels, std::cbrt(box / (kMaxUpsampling * samples))});
  for (int a = 0; a < 3; ++a) {
    c.dims[a] = std::size_t(std::floor((hi[a] - lo[a]) / c.spacing)) + 1;
    c.origin[a] = lo[a];
  }
  check_geometry(path, {c.spacing, c.spacing, c.spacing}, c.origin);
  return c;
}

std::vector<unsigned char> read_samples(const std::string& path, std::FILE* f, const KretzFile& k) {
  std::vector<unsigned char> s(std::size_t(k.data_size));
  if (std::fseek(f, long(k.data_offset), SEEK_SET) != 0 || read_up_to(f, s.data(), s.size(), path) != s.size())
    throw input_error(path, "data truncated: the voxel data ends early");
  return s;
}

VolumeHeader header_of(const std::string& path, const KretzFile& k, Cartesian* grid) {
  VolumeHeader h;
  h.type = ScalarType::UInt8;
  h.files = {path};
  if (k.spherical()) {
    const Geometry g{k.offset1 * k.resolution_mm, k.resolution_mm, -k.offset2 * k.resolution_mm, &k.theta, &k.phi};
    const Cartesian c = cartesian_grid(path, k, g);
    h.dims = c.dims;
    h.spacing = {c.spacing, c.spacing, c.spacing};
    h.origin = c.origin;
    if (grid) *grid = c;
  } else {
    if (!(k.cartesian_spacing >= kMinSpacingMm && k.cartesian_spacing <= kMaxSpacingMm))
      throw input_error(path, "voxel spacing (item (0010,0022)) outside 1 nm - 1 km");
    h.dims = {k.dims[0], k.dims[1], k.dims[2]};
    h.spacing = {k.cartesian_spacing, k.cartesian_spacing, k.cartesian_spacing};
  }
  checked_voxels(path, h.dims, h.type);
  return h;
}

}  // namespace

VolumeHeader read_kretz_header(const std::string& path) {
  FilePtr f = open_for_reading(path);
  const KretzFile k = scan(path, f.get());
  return header_of(path, k, nullptr);
}

Volume read_kretz(const std::string& path) {
  FilePtr f = open_for_reading(path);
  const KretzFile k = scan(path, f.get());
  Cartesian c;
  const VolumeHeader h = header_of(path, k, &c);
  checked_voxels(path, {k.dims[0], k.dims[1], k.dims[2]}, ScalarType::UInt8);
  const std::vector<unsigned char> s = read_samples(path, f.get(), k);
  Volume v(h.dims, h.spacing, ScalarType::UInt8);
  v.origin = h.origin;
  if (!k.spherical()) {
    for (std::size_t i = 0; i < s.size(); ++i) v.data[i] = float(s[i]);
    return v;
  }
  // Scan conversion: each Cartesian voxel centre mapped back onto the probe
  // grid, the samples interpolated trilinearly; outside the scanned sector
  // 0 (the zero fill softshell's mask takes as unscanned).
  const Geometry g{k.offset1 * k.resolution_mm, k.resolution_mm, -k.offset2 * k.resolution_mm, &k.theta, &k.phi};
  const std::size_t ni = k.dims[0], nj = k.dims[1], nk = k.dims[2];
  const auto sample = [&](std::size_t i, std::size_t j, std::size_t kk) { return float(s[(kk * nj + j) * ni + i]); };
  for (std::size_t z = 0; z < v.dims[2]; ++z)
    for (std::size_t y = 0; y < v.dims[1]; ++y)
      for (std::size_t x = 0; x < v.dims[0]; ++x) {
        const Vec3d q{c.origin[0] + double(x) * c.spacing, c.origin[1] + double(y) * c.spacing,
                      c.origin[2] + double(z) * c.spacing};
        const std::array<double, 3> f3 = g.index(q);
        const double lim[3] = {double(ni - 1), double(nj - 1), double(nk - 1)};
        bool inside = true;
        for (int a = 0; a < 3; ++a) inside = inside && f3[a] >= 0 && f3[a] <= lim[a];
        if (!inside) continue;  // 0: outside the sector
        std::size_t i0[3];
        double w[3];
        for (int a = 0; a < 3; ++a) {
          i0[a] = std::min(std::size_t(f3[a]), std::size_t(std::max(lim[a] - 1, 0.0)));
          w[a] = lim[a] > 0 ? f3[a] - double(i0[a]) : 0.0;
        }
        const std::size_t i1[3] = {std::min<std::size_t>(i0[0] + 1, ni - 1), std::min<std::size_t>(i0[1] + 1, nj - 1),
                                   std::min<std::size_t>(i0[2] + 1, nk - 1)};
        double acc = 0;
        for (int c8 = 0; c8 < 8; ++c8) {
          const std::size_t ii = c8 & 1 ? i1[0] : i0[0], jj = c8 & 2 ? i1[1] : i0[1], kk = c8 & 4 ? i1[2] : i0[2];
          const double wt = (c8 & 1 ? w[0] : 1 - w[0]) * (c8 & 2 ? w[1] : 1 - w[1]) * (c8 & 4 ? w[2] : 1 - w[2]);
          acc += wt * sample(ii, jj, kk);
        }
        v.at(x, y, z) = float(std::round(acc));  // 8-bit data stays 8-bit (as written back)
      }
  return v;
}

}  // namespace softshell::io_detail
