// GE Kretz .vol (host/io_kretz.cpp): synthetic files written here, with a
// known probe geometry, read and scan-converted; where each sample lands is
// computed here from the format's geometry, independently of the reader's
// inverse mapping.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "io.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

namespace fs = std::filesystem;

void put16(std::string& s, unsigned v) { s += char(v & 0xFF), s += char((v >> 8) & 0xFF); }
void put32(std::string& s, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) s += char((v >> (8 * i)) & 0xFF);
}
void put_double(std::string& s, double d) {
  std::uint64_t u;
  std::memcpy(&u, &d, sizeof u);
  for (int i = 0; i < 8; ++i) s += char((u >> (8 * i)) & 0xFF);
}
void item(std::string& s, unsigned group, unsigned element, const std::string& data) {
  put16(s, group), put16(s, element), put32(s, std::uint32_t(data.size()));
  s += data;
}
std::string u16(unsigned v) {
  std::string s;
  put16(s, v);
  return s;
}
std::string doubles(const std::vector<double>& v) {
  std::string s;
  for (double d : v) put_double(s, d);
  return s;
}

// A small fan: 40 radial samples of 0.5 mm from 5 mm, 31 lines over +-0.4
// rad, 21 planes over +-0.3 rad swept about an axis 4 mm above the array (below the first sample: the planes do not cross).
struct Probe {
  int ni = 40, nj = 31, nk = 21;
  double res_m = 0.0005, offset1 = 10, offset2 = -8;
  std::vector<double> theta, phi;
  std::vector<unsigned char> samples;
  Probe() {
    for (int j = 0; j < nj; ++j) theta.push_back(M_PI / 2 - 0.4 + 0.8 * j / (nj - 1));
    for (int k = 0; k < nk; ++k) phi.push_back(M_PI / 2 - 0.3 + 0.6 * k / (nk - 1));
    // Tissue 60, a bright shell at radial sample 25 (r = 17.5 mm).
    samples.assign(std::size_t(ni) * nj * nk, 60);
    for (int k = 0; k < nk; ++k)
      for (int j = 0; j < nj; ++j)
        for (int i = 24; i <= 26; ++i) samples[(std::size_t(k) * nj + j) * ni + i] = 220;
  }
  // The format's geometry (sample (i, j, k) -> mm).
  Vec3d point(int i, int j, int k) const {
    const double res = res_m * 1000, r = (offset1 + i) * res, R = -offset2 * res;
    const double t = theta[j] - M_PI / 2, p = phi[k] - M_PI / 2;
    return {r * std::sin(t), -(r * std::cos(t) - R) * std::sin(p), R * (1 - std::cos(p)) + r * std::cos(t) * std::cos(p)};
  }
  std::string file(bool with_data = true, bool with_angles = true) const {
    std::string s = "KRETZFILE 1.0   ";
    item(s, 0x0001, 0x0002, "patient name, skipped");
    item(s, 0xC000, 0x0001, u16(unsigned(ni)));
    item(s, 0xC000, 0x0002, u16(unsigned(nj)));
    item(s, 0xC000, 0x0003, u16(unsigned(nk)));
    item(s, 0xC100, 0x0001, doubles({res_m}));
    item(s, 0xC200, 0x0001, doubles({offset1}));
    item(s, 0xC200, 0x0002, doubles({offset2}));
    if (with_angles) {
      item(s, 0xC300, 0x0001, doubles(phi));
      item(s, 0xC300, 0x0002, doubles(theta));
    }
    if (with_data) item(s, 0xD000, 0x0001, std::string(samples.begin(), samples.end()));
    item(s, 0xD100, 0x0001, "trailing item, skipped");
    return s;
  }
};

class Kretz : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("softshell-kretz-" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& bytes) {
    const std::string p = (dir_ / name).string();
    std::ofstream(p, std::ios::binary) << bytes;
    return p;
  }
  fs::path dir_;
};

TEST_F(Kretz, ScanConversionPutsEverySampleWhereTheProbeGeometrySays) {
  const Probe probe;
  const std::string path = write("fan.vol", probe.file());
  const Volume v = read_volume(path);
  const VolumeHeader h = read_volume_header(path);
  EXPECT_EQ(h.dims, v.dims);
  EXPECT_EQ(v.source_type, ScalarType::UInt8);
  // Isotropic at the radial resolution (the fan is small: no coarsening).
  for (int a = 0; a < 3; ++a) EXPECT_DOUBLE_EQ(v.spacing[a], 0.5);
  // Every sample of the bright shell's middle (i = 25) and of the tissue
  // well away from it (i = 10, 38), mapped here from the format's geometry,
  // lands in a voxel of its brightness (interpolation within 0.5 voxel of a
  // sample of the other kind is not asked).
  const auto value_at = [&](const Vec3d& p) {
    std::size_t idx[3];
    for (int a = 0; a < 3; ++a) {
      const double f = (p[a] - v.origin[a]) / v.spacing[a];
      EXPECT_GE(f, -0.5) << "axis " << a;
      EXPECT_LE(f, double(v.dims[a]) - 0.5) << "axis " << a;
      idx[a] = std::size_t(std::clamp(std::lround(f), 0L, long(v.dims[a]) - 1));
    }
    return v.at(idx[0], idx[1], idx[2]);
  };
  int checked = 0;
  for (int k = 2; k < probe.nk - 2; k += 3)
    for (int j = 2; j < probe.nj - 2; j += 3) {
      EXPECT_GT(value_at(probe.point(25, j, k)), 180.0f) << "bright sample at j " << j << " k " << k;
      EXPECT_NEAR(value_at(probe.point(10, j, k)), 60.0f, 1.0f) << "tissue at j " << j << " k " << k;
      EXPECT_NEAR(value_at(probe.point(36, j, k)), 60.0f, 1.0f) << "tissue at j " << j << " k " << k;
      checked += 3;
    }
  EXPECT_GT(checked, 100);
  // Outside the sector: 0 (the zero fill the mask takes as unscanned): the
  // grid's corners near the probe lie outside the fan.
  EXPECT_EQ(v.at(0, 0, 0), 0.0f);
  EXPECT_EQ(v.at(v.dims[0] - 1, v.dims[1] - 1, 0), 0.0f);
  std::size_t zero = 0;
  for (float x : v.data) zero += x == 0.0f;
  EXPECT_GT(zero, v.voxels() / 10);
  EXPECT_LT(zero, v.voxels() * 9 / 10);
}

TEST_F(Kretz, ACartesianVolumeIsReadAsItIs) {
  Probe probe;
  std::string s = "KRETZFILE 1.0   ";
  item(s, 0xC000, 0x0001, u16(4));
  item(s, 0xC000, 0x0002, u16(3));
  item(s, 0xC000, 0x0003, u16(2));
  item(s, 0x0010, 0x0022, doubles({0.7}));
  std::string data;
  for (int i = 0; i < 24; ++i) data += char(i * 10);
  item(s, 0xD000, 0x0001, data);
  const Volume v = read_volume(write("cart.vol", s));
  EXPECT_EQ(v.dims, (Dims3{4, 3, 2}));
  EXPECT_DOUBLE_EQ(v.spacing[1], 0.7);
  for (int i = 0; i < 24; ++i) EXPECT_EQ(v.data[std::size_t(i)], float(i * 10));
}

TEST_F(Kretz, DamagedFilesGetOneLineErrors) {
  const Probe probe;
  const std::string good = probe.file();
  const auto fails = [&](const std::string& name, const std::string& bytes, const std::string& expected) {
    SCOPED_TRACE(name);
    const std::string p = write(name, bytes);
    test::expect_input_error([&] { read_volume(p); }, {expected});
    test::expect_input_error([&] { read_volume_header(p); }, {expected});
  };
  fails("sig.vol", "KRETZFILE 2.0   " + good.substr(16), "not a Kretz file");
  fails("nodata.vol", probe.file(false), "no uncompressed voxel data (item (D000,0001))");
  // Truncated anywhere: an item runs past the end, or the voxel data is missing.
  for (std::size_t cut : {std::size_t(17), std::size_t(40), good.size() / 2, good.size() - 31})
    fails("cut" + std::to_string(cut) + ".vol", good.substr(0, cut), "");
  // Dimensions that do not match the data.
  Probe wrong = probe;
  wrong.nj = 30;
  wrong.theta.pop_back();
  fails("dims.vol", wrong.file(), "the voxel data holds");
  // Angle tables of the wrong length, out of range, or not monotonic.
  Probe short_table = probe;
  short_table.theta.pop_back();
  fails("angles.vol", short_table.file(), "the angle tables hold 30 theta and 21 phi angles");
  Probe bad_angle = probe;
  bad_angle.phi[3] = 9.0;
  fails("range.vol", bad_angle.file(), "phi angle 3 is outside [0, pi] radians");
  Probe unsorted = probe;
  std::swap(unsorted.theta[4], unsorted.theta[5]);
  fails("order.vol", unsorted.file(), "theta angles are not monotonic");
  Probe nan_res = probe;
  nan_res.res_m = std::nan("");
  fails("res.vol", nan_res.file(), "radial resolution (item (C100,0001)) missing or outside");
  // An item that claims more bytes than the file has.
  std::string huge = good.substr(0, 16);
  item(huge, 0xC000, 0x0001, u16(8));
  put16(huge, 0xD000), put16(huge, 0x0001), put32(huge, 0xFFFFFFF0u);
  huge += "abc";
  fails("huge.vol", huge, "item (D000,0001) of 4294967280 bytes runs past the end of the file (3 bytes left)");
}

}  // namespace
}  // namespace softshell
