// DICOM (host/io_dicom.cpp, through GDCM): files written here element by
// element (fuzz::dicom_file, no GDCM on the writing side), read back and
// checked sample by sample and in the world: a multi-frame volume in patient
// space, an Enhanced US Volume in its own frame (frames along and against
// the slice normal), a series folder in shuffled file order with rescaled
// 16-bit slices, Philips' Cartesian 3D+t file, colour and MONOCHROME1
// samples; and the refusals (2-D ultrasound, one slice, uneven spacing, two
// series, damaged files), one line each.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "error.hpp"
#include "fuzz_inputs.hpp"
#include "io.hpp"
#include "cli_fixture.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

namespace fs = std::filesystem;
using fuzz::DicomElement;
using fuzz::dicom_ds;
using fuzz::dicom_f64;
using fuzz::dicom_file;
using fuzz::dicom_items;
using fuzz::dicom_u16;

constexpr const char* kSecondaryCapture8 = "1.2.840.10008.5.1.4.1.1.7.2";
constexpr const char* kSecondaryCapture16 = "1.2.840.10008.5.1.4.1.1.7.3";
constexpr const char* kCt = "1.2.840.10008.5.1.4.1.1.2";
constexpr const char* kEnhancedUsVolume = "1.2.840.10008.5.1.4.1.1.6.2";

// The image pixel module of cols x rows x frames samples.
std::vector<DicomElement> pixels(unsigned cols, unsigned rows, unsigned frames, unsigned bits, const std::string& data,
                                 const std::string& photometric = "MONOCHROME2", unsigned samples_per_pixel = 1,
                                 bool is_signed = false) {
  std::vector<DicomElement> e{{0x0028, 0x0002, "US", dicom_u16(std::uint16_t(samples_per_pixel))},
                              {0x0028, 0x0004, "CS", photometric},
                              {0x0028, 0x0010, "US", dicom_u16(std::uint16_t(rows))},
                              {0x0028, 0x0011, "US", dicom_u16(std::uint16_t(cols))},
                              {0x0028, 0x0100, "US", dicom_u16(std::uint16_t(bits))},
                              {0x0028, 0x0101, "US", dicom_u16(std::uint16_t(bits))},
                              {0x0028, 0x0102, "US", dicom_u16(std::uint16_t(bits - 1))},
                              {0x0028, 0x0103, "US", dicom_u16(is_signed ? 1 : 0)},
                              {0x7fe0, 0x0010, bits == 8 ? "OB" : "OW", data}};
  if (frames > 0) e.push_back({0x0028, 0x0008, "IS", std::to_string(frames)});
  if (samples_per_pixel == 3) e.push_back({0x0028, 0x0006, "US", dicom_u16(0)});
  return e;
}

std::vector<DicomElement> operator+(std::vector<DicomElement> a, const std::vector<DicomElement>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// World position of voxel (i, j, k).
Vec3d world(const Volume& v, double i, double j, double k) {
  Vec3d p = v.origin;
  const double ijk[3] = {i, j, k};
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) p[c] += ijk[a] * v.spacing[a] * v.frame.axes[a][c];
  return p;
}

class Dicom : public test::CliTest {
 protected:
  void SetUp() override {
    if (!dicom_supported()) GTEST_SKIP() << "this build has no DICOM (GDCM) support";
    CliTest::SetUp();
  }
  std::string write(const std::string& name, const std::string& bytes) const {
    fs::create_directories(fs::path(file(name)).parent_path());
    return CliTest::write(name, bytes);
  }
};

TEST_F(Dicom, MultiFrameVolumeKeepsItsSamplesAndItsPlaceInPatientSpace) {
  // 5 x 4 x 3, oblique rows and columns, in LPS: every voxel's value and
  // its world position (origin + i dx row + j dy column + k dz normal).
  std::string data;
  for (int i = 0; i < 60; ++i) data += char(3 * i + 1);
  const std::vector<double> iop{0.8, 0.6, 0, -0.6, 0.8, 0};
  const std::string path =
      write("mf.dcm", dicom_file(kSecondaryCapture8, pixels(5, 4, 3, 8, data) + std::vector<DicomElement>{
                                                         {0x0020, 0x0032, "DS", dicom_ds({-12.5, 30, 7})},
                                                         {0x0020, 0x0037, "DS", dicom_ds(iop)},
                                                         {0x0028, 0x0030, "DS", dicom_ds({0.6, 0.5})},
                                                         {0x0018, 0x0088, "DS", dicom_ds({0.7})}}));
  const Volume v = read_volume(path);
  ASSERT_EQ(v.dims, (Dims3{5, 4, 3}));
  EXPECT_EQ(v.source_type, ScalarType::UInt8);
  for (int i = 0; i < 60; ++i) ASSERT_EQ(v.data[i], float(3 * i + 1)) << i;
  // DICOM's Pixel Spacing is (between rows, between columns): x 0.5, y 0.6.
  EXPECT_NEAR(v.spacing[0], 0.5, 1e-9);
  EXPECT_NEAR(v.spacing[1], 0.6, 1e-9);
  EXPECT_NEAR(v.spacing[2], 0.7, 1e-9);
  EXPECT_EQ(v.frame.space, "left-posterior-superior");
  const Vec3d p = world(v, 4, 3, 2);
  const Vec3d want{-12.5 + 4 * 0.5 * 0.8 - 3 * 0.6 * 0.6, 30 + 4 * 0.5 * 0.6 + 3 * 0.6 * 0.8, 7 + 2 * 0.7};
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(p[c], want[c], 1e-9) << c;
  const VolumeHeader h = read_volume_header(path);
  EXPECT_EQ(h.dims, v.dims);
  EXPECT_EQ(h.frames, 1u);
  // Written as NRRD, the transform survives: the same world positions.
  write_volume(file("mf.nrrd"), v);
  const Volume back = read_volume(file("mf.nrrd"));
  EXPECT_EQ(back.data, v.data);
  const Vec3d q = world(back, 4, 3, 2);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(q[c], want[c], 1e-6) << c;
}

TEST_F(Dicom, EnhancedUsVolumeTakesItsVolumeFrameOfReference) {
  // Image Position / Orientation (Volume) in the functional groups; the
  // second frame's position gives the slice step and its direction.
  std::string data;
  for (int i = 0; i < 2 * 3 * 4; ++i) data += char(10 * i);
  const auto file_with_step = [&](double step) {
    const auto position = [](double z) {
      return std::vector<DicomElement>{
          {0x0020, 0x930e, "SQ", dicom_items({{{0x0020, 0x9301, "FD", dicom_f64({1.0, 2.0, z})}}})}};
    };
    std::vector<DicomElement> shared{
        {0x0028, 0x9110, "SQ",
         dicom_items({{{0x0028, 0x0030, "DS", dicom_ds({0.4, 0.3})}, {0x0018, 0x0088, "DS", dicom_ds({std::fabs(step)})}}})},
        {0x0020, 0x930f, "SQ", dicom_items({{{0x0020, 0x9302, "FD", dicom_f64({0, 1, 0, 1, 0, 0})}}})}};
    std::vector<std::vector<DicomElement>> per_frame;
    for (int k = 0; k < 4; ++k) per_frame.push_back(position(3.0 + k * step));
    return dicom_file(kEnhancedUsVolume, pixels(2, 3, 4, 8, data) + std::vector<DicomElement>{
                                                         {0x5200, 0x9229, "SQ", dicom_items({shared})},
                                                         {0x5200, 0x9230, "SQ", dicom_items(per_frame)}});
  };
  for (const double step : {0.5, -0.5}) {
    SCOPED_TRACE(step);
    const Volume v = read_volume(write("us.dcm", file_with_step(step)));
    ASSERT_EQ(v.dims, (Dims3{2, 3, 4}));
    EXPECT_NEAR(v.spacing[0], 0.3, 1e-9);
    EXPECT_NEAR(v.spacing[1], 0.4, 1e-9);
    EXPECT_NEAR(v.spacing[2], 0.5, 1e-9);
    EXPECT_EQ(v.frame.space, "");  // the volume's own frame, not patient space
    // Frame k lies at (1, 2, 3 + k step), rows along y, columns along x.
    for (int k = 0; k < 4; ++k) {
      const Vec3d p = world(v, 1, 2, k);
      EXPECT_NEAR(p[0], 1.0 + 2 * 0.4, 1e-9);
      EXPECT_NEAR(p[1], 2.0 + 1 * 0.3, 1e-9);
      EXPECT_NEAR(p[2], 3.0 + k * step, 1e-9) << k;
    }
    EXPECT_EQ(v.data[23], float(230));
  }
}

TEST_F(Dicom, SeriesFolderIsStackedAlongTheNormalWithRescaledSamples) {
  // Five int16 CT-style slices, files named in shuffled order, Rescale
  // Slope 2 / Intercept -100, a README beside them: the volume is stacked
  // by position along the normal, the values rescaled.
  const std::vector<double> iop{1, 0, 0, 0, 0, -1};  // a coronal stack: normal (0, 1, 0) x ... = row x column
  const Vec3d n{0 * -1 - 0 * 0, 0 * 0 - 1 * -1, 1 * 0 - 0 * 0};  // row x column = (0, 1, 0)
  const int order[5] = {3, 0, 4, 1, 2};
  for (int f = 0; f < 5; ++f) {
    const int k = order[f];
    std::string data;
    for (int i = 0; i < 6; ++i) data += dicom_u16(std::uint16_t(std::int16_t(100 * k + i - 3)));
    const double y = 50.0 + 1.25 * k;
    write("series/IM" + std::to_string(f),
          dicom_file(kCt, pixels(3, 2, 0, 16, data, "MONOCHROME2", 1, true) + std::vector<DicomElement>{
                                                 {0x0020, 0x000e, "UI", "1.2.3.4"},
                                                 {0x0020, 0x0032, "DS", dicom_ds({-5, y, 20})},
                                                 {0x0020, 0x0037, "DS", dicom_ds(iop)},
                                                 {0x0028, 0x0030, "DS", dicom_ds({0.8, 0.9})},
                                                 {0x0028, 0x1052, "DS", dicom_ds({-100})},
                                                 {0x0028, 0x1053, "DS", dicom_ds({2})}}));
  }
  write("series/README.txt", "not DICOM\n");
  const Volume v = read_volume(file("series"));
  ASSERT_EQ(v.dims, (Dims3{3, 2, 5}));
  for (int k = 0; k < 5; ++k)
    for (int i = 0; i < 6; ++i) ASSERT_EQ(v.data[k * 6 + i], float(2 * (100 * k + i - 3) - 100)) << k << " " << i;
  EXPECT_EQ(v.source_type, ScalarType::Float32);  // rescaled: no longer int16 values
  EXPECT_NEAR(v.spacing[2], 1.25, 1e-9);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(v.frame.axes[2][c], n[c], 1e-12);
  const Vec3d last = world(v, 0, 0, 4);
  EXPECT_NEAR(last[1], 55.0, 1e-9);
  EXPECT_EQ(read_volume_header(file("series")).files.size(), 5u);

  // A missing slice, a second series, a lone slice: one line each.
  fs::remove(file("series/IM4"));  // slice k = 2: a gap in the middle
  test::expect_input_error([&] { read_volume(file("series")); }, {"unevenly spaced", "a missing slice?"});
  fs::remove_all(file("series"));
  for (int k = 0; k < 2; ++k)
    write("two/IM" + std::to_string(k),
          dicom_file(kCt, pixels(3, 2, 0, 16, std::string(12, '\1')) + std::vector<DicomElement>{
                                                 {0x0020, 0x000e, "UI", k ? "1.2.3.5" : "1.2.3.4"},
                                                 {0x0020, 0x0032, "DS", dicom_ds({0, 0, double(k)})},
                                                 {0x0020, 0x0037, "DS", dicom_ds({1, 0, 0, 0, 1, 0})}}));
  test::expect_input_error([&] { read_volume(file("two")); }, {"more than one series in this folder"});
  fs::remove(file("two/IM1"));
  test::expect_input_error([&] { read_volume(file("two")); }, {"one DICOM slice in this folder"});
  test::expect_input_error([&] { read_volume(file("two/IM0")); }, {"one 2-D DICOM slice: give the folder"});
}

TEST_F(Dicom, PhilipsCartesianFileIsASequenceOfVolumes) {
  // 2 frames of 3 slices x 2 rows x 4 columns, spacing in cm; frame k's
  // samples follow frame k-1's at the end of the file.
  std::string data;
  for (int i = 0; i < 48; ++i) data += char(5 * i);
  const std::string path =
      write("philips.dcm", dicom_file("1.2.840.113543.6.6.1.3.10002",
                                      {{0x0018, 0x602c, "FD", dicom_f64({0.05})},
                                       {0x0018, 0x602e, "FD", dicom_f64({0.04})},
                                       {0x0028, 0x0002, "US", dicom_u16(1)},
                                       {0x0028, 0x0004, "CS", "MONOCHROME2"},
                                       {0x0028, 0x0008, "IS", "2"},
                                       {0x0028, 0x0010, "US", dicom_u16(2)},
                                       {0x0028, 0x0011, "US", dicom_u16(4)},
                                       {0x0028, 0x0100, "US", dicom_u16(8)},
                                       {0x3001, 0x1001, "UL", std::string("\3\0\0\0", 4)},
                                       {0x3001, 0x1003, "FD", dicom_f64({0.1})},
                                       {0x7fe0, 0x0010, "OB", data}}));
  EXPECT_EQ(read_any_header(path).frames, 2u);
  test::expect_input_error([&] { read_volume(path); }, {"a sequence of 2 3-D frames of 4x2x3: choose one with --frame K"});
  const std::vector<Volume> frames = read_frames(path);
  ASSERT_EQ(frames.size(), 2u);
  for (int k = 0; k < 2; ++k) {
    ASSERT_EQ(frames[k].dims, (Dims3{4, 2, 3}));
    for (int i = 0; i < 24; ++i) ASSERT_EQ(frames[k].data[i], float(5 * (24 * k + i))) << k << " " << i;
    EXPECT_NEAR(frames[k].spacing[0], 0.5, 1e-9);
    EXPECT_NEAR(frames[k].spacing[1], 0.4, 1e-9);
    EXPECT_NEAR(frames[k].spacing[2], 1.0, 1e-9);
  }
  EXPECT_EQ(read_volume(path, std::nullopt, std::size_t(1)).data, frames[1].data);
  test::expect_input_error([&] { read_volume(path, std::nullopt, std::size_t(2)); }, {"--frame 2: the file holds 2 frames"});
  // Declared frames beyond the file: refused before reading.
  const std::string cut = file("cut.dcm");
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  bytes.replace(bytes.find(std::string("IS\2\0" "2 ", 6)), 6, std::string("IS\2\0" "99", 6));
  write("cut.dcm", bytes);
  test::expect_input_error([&] { read_any_header(cut); }, {"99 frames of 4x2x3 need", "bytes of samples"});
}

TEST_F(Dicom, ColourAndMonochrome1SamplesBecomeGrey) {
  // RGB (interleaved) -> Rec. 601 luma; MONOCHROME1 (white low) inverted.
  std::string rgb;
  for (int i = 0; i < 8; ++i) rgb += std::string{char(10 * i), char(20 + i), char(200 - i)};
  const std::vector<DicomElement> geometry{{0x0020, 0x0032, "DS", dicom_ds({0, 0, 0})},
                                           {0x0020, 0x0037, "DS", dicom_ds({1, 0, 0, 0, 1, 0})},
                                           {0x0028, 0x0030, "DS", dicom_ds({1, 1})}};
  const Volume c = read_volume(write("rgb.dcm", dicom_file(kSecondaryCapture8, pixels(2, 2, 2, 8, rgb, "RGB", 3) + geometry)));
  for (int i = 0; i < 8; ++i)
    EXPECT_NEAR(c.data[i], 0.299 * (10 * i) + 0.587 * (20 + i) + 0.114 * (200 - i), 1e-3) << i;
  std::string grey;
  for (int i = 0; i < 8; ++i) grey += char(30 * i);
  const Volume m = read_volume(write("m1.dcm", dicom_file(kSecondaryCapture8, pixels(2, 2, 2, 8, grey, "MONOCHROME1") + geometry)));
  for (int i = 0; i < 8; ++i) EXPECT_EQ(m.data[i], float(255 - 30 * i)) << i;
}

TEST_F(Dicom, TwoDimensionalUltrasoundAndDamagedFilesAreOneLineErrors) {
  std::string data(2 * 2 * 3, '\7');
  const std::string cine = write("cine.dcm", dicom_file("1.2.840.10008.5.1.4.1.1.3.1", pixels(2, 2, 3, 8, data)));
  test::expect_input_error([&] { read_volume(cine); }, {"2-D ultrasound DICOM (a cine loop of 3 frames over time), not a 3-D volume"});
  const std::string full = dicom_file(kSecondaryCapture16, pixels(4, 4, 4, 16, std::string(128, '\1')));
  for (const std::size_t keep : {std::size_t(100), std::size_t(140), full.size() / 2, full.size() - 1}) {
    SCOPED_TRACE(keep);
    const std::string cut = write("cut.dcm", full.substr(0, keep));
    test::expect_input_error([&] { read_volume(cut); }, {"cut.dcm"});
  }
  // Pixel data shorter than its header's size.
  const std::string shorter = write("short.dcm", dicom_file(kSecondaryCapture16, pixels(4, 4, 4, 16, std::string(64, '\1'))));
  test::expect_input_error([&] { read_volume(shorter); }, {"short.dcm"});
  // The command line: one line, exit 2, nothing written.
  expect_one_line_error(run({"classify", cine, "--iso", "auto", "-o", file("u.nrrd")}), {"2-D ultrasound DICOM"});
  EXPECT_FALSE(fs::exists(file("u.nrrd")));
}

}  // namespace
}  // namespace softshell
