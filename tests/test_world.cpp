// Orientation end to end (docs/formats.md, "Orientation"): the index-to-world transform of
// NRRD (space, space directions, space origin, measurement frame) and MetaImage
// (TransformMatrix, Offset, AnatomicalOrientation) is read, carried through the commands and
// written back; meshes come out in world coordinates. Also the refusal of PLUS tracked-frame
// sequences. Every input here is written by the test, its transform known.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "error.hpp"
#include "io.hpp"
#include "mesh.hpp"
#include "test_support.hpp"
#include "volume.hpp"

namespace softshell {
namespace {

using test::CliTest;
using test::RunResult;
namespace fs = std::filesystem;

// A proper rotation: 35 degrees about (1, 2, 3) / |.|, by Rodrigues' formula. Rows are the
// rotated x, y, z axes (the frame's axes).
Mat3 oblique_axes(double degrees = 35.0) {
  const double n = std::sqrt(14.0), k[3] = {1 / n, 2 / n, 3 / n};
  const double t = degrees * M_PI / 180.0, c = std::cos(t), s = std::sin(t);
  Mat3 r{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const double cross = (i == j) ? 0.0 : ((j == (i + 1) % 3) ? -k[3 - i - j] : k[3 - i - j]);
      r[i][j] = c * (i == j) + (1 - c) * k[i] * k[j] + s * cross;
    }
  return r;
}

std::string num(double x) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

// Header text of an attached raw uint8 NRRD with the given geometry, written by hand so the
// reader is checked against a known transform, not against softshell's writer.
std::string nrrd_header(const Dims3& d, const Vec3d& sp, const Mat3& axes, const Vec3d& origin, const std::string& space,
                        const std::string& extra = "") {
  std::string h = "NRRD0005\ntype: uint8\ndimension: 3\nspace: " + space + "\nsizes: " + std::to_string(d[0]) + " " +
                  std::to_string(d[1]) + " " + std::to_string(d[2]) + "\nspace directions:";
  for (int a = 0; a < 3; ++a)
    h += " (" + num(sp[a] * axes[a][0]) + "," + num(sp[a] * axes[a][1]) + "," + num(sp[a] * axes[a][2]) + ")";
  h += "\nkinds: domain domain domain\nendian: little\nencoding: raw\nspace origin: (" + num(origin[0]) + "," +
       num(origin[1]) + "," + num(origin[2]) + ")\n" + extra + "\n";
  return h;
}

// A bright ball of radius `r_mm` (in mm, about the grid's centre) on a dark background, with a
// one-voxel linear edge: uint8 samples.
std::string ball_samples(const Dims3& d, const Vec3d& sp, double r_mm) {
  std::string s;
  for (std::size_t z = 0; z < d[2]; ++z)
    for (std::size_t y = 0; y < d[1]; ++y)
      for (std::size_t x = 0; x < d[0]; ++x) {
        const double dx = (double(x) - 0.5 * double(d[0] - 1)) * sp[0], dy = (double(y) - 0.5 * double(d[1] - 1)) * sp[1],
                     dz = (double(z) - 0.5 * double(d[2] - 1)) * sp[2];
        const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
        const double f = std::clamp((r_mm - r) / 0.7 + 0.5, 0.0, 1.0);
        s += char(static_cast<unsigned char>(std::lround(20 + 180 * f)));
      }
  return s;
}

void expect_same_frame(const Volume& a, const Volume& b, double tol = 0.0) {
  EXPECT_EQ(a.dims, b.dims);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(a.spacing[i], b.spacing[i], tol * std::fabs(b.spacing[i])) << "spacing " << i;
    EXPECT_NEAR(a.origin[i], b.origin[i], tol * (1 + std::fabs(b.origin[i]))) << "origin " << i;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(a.frame.axes[i][c], b.frame.axes[i][c], tol) << "axis " << i << "," << c;
  }
  EXPECT_EQ(a.frame.space, b.frame.space);
  EXPECT_EQ(a.frame.anatomical_orientation, b.frame.anatomical_orientation);
  ASSERT_EQ(a.frame.measurement_frame.has_value(), b.frame.measurement_frame.has_value());
  if (a.frame.measurement_frame)
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) EXPECT_EQ((*a.frame.measurement_frame)[i][j], (*b.frame.measurement_frame)[i][j]);
}

// Trilinear interpolation of v at a continuous index (clamped to the grid).
double trilinear(const Volume& v, const Vec3d& p) {
  std::size_t i0[3];
  double t[3];
  for (int a = 0; a < 3; ++a) {
    const double c = std::clamp(p[a], 0.0, double(v.dims[a] - 1));
    i0[a] = std::min<std::size_t>(std::size_t(c), v.dims[a] - 2);
    t[a] = c - double(i0[a]);
  }
  double s = 0;
  for (int k = 0; k < 8; ++k) {
    const std::size_t x = i0[0] + (k & 1), y = i0[1] + ((k >> 1) & 1), z = i0[2] + ((k >> 2) & 1);
    const double w = ((k & 1) ? t[0] : 1 - t[0]) * (((k >> 1) & 1) ? t[1] : 1 - t[1]) * (((k >> 2) & 1) ? t[2] : 1 - t[2]);
    s += w * v.at(x, y, z);
  }
  return s;
}

// ---- the transform itself ------------------------------------------------------------------

TEST(WorldFrame, IndexToWorldAndBack) {
  Volume v({5, 6, 7}, {0.5, 0.75, 1.25});
  v.origin = {-3, 4.5, 100};
  v.frame.axes = oblique_axes();
  EXPECT_NEAR(determinant(v.frame.axes), 1.0, 1e-12);
  for (const Vec3d p : {Vec3d{0, 0, 0}, Vec3d{4, 5, 6}, Vec3d{1.5, -2, 3.25}}) {
    const Vec3d w = v.index_to_world(p);
    // By definition: origin + sum_a p[a] spacing[a] axes[a].
    for (int c = 0; c < 3; ++c) {
      double e = v.origin[c];
      for (int a = 0; a < 3; ++a) e += p[a] * v.spacing[a] * v.frame.axes[a][c];
      EXPECT_NEAR(w[c], e, 1e-12);
    }
    const Vec3d back = v.world_to_index(w);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(back[a], p[a], 1e-12);
    // Grid millimetres map like the index they stand for.
    Vec3d g;
    for (int a = 0; a < 3; ++a) g[a] = v.origin[a] + v.spacing[a] * p[a];
    const Vec3d wg = v.grid_to_world(g);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(wg[c], w[c], 1e-12);
  }
  EXPECT_EQ(lps_orientation_code(kIdentityAxes), "RAI");  // what ITK writes for the identity
  EXPECT_EQ(lps_orientation_code({{{-1, 0, 0}, {0, 0, 1}, {0, -1, 0}}}), "LIP");  // from L, from I, from P
  // RAS -> LPS: x and y change sign, the physical point stays.
  WorldFrame ras;
  ras.space = "right-anterior-superior";
  ras.axes = oblique_axes();
  Vec3d o{1, 2, 3};
  const WorldFrame lps = ras.to_lps(o);
  EXPECT_EQ(lps.space, "left-posterior-superior");
  EXPECT_EQ(o, (Vec3d{-1, -2, 3}));
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(lps.axes[a][0], -ras.axes[a][0]);
    EXPECT_EQ(lps.axes[a][1], -ras.axes[a][1]);
    EXPECT_EQ(lps.axes[a][2], ras.axes[a][2]);
  }
}

// ---- NRRD ------------------------------------------------------------------------------------

class WorldIo : public CliTest {};

TEST_F(WorldIo, ObliqueLpsNrrdIsReadAndWrittenBackExactly) {
  const Dims3 d{4, 3, 2};
  const Vec3d sp{0.5, 0.7, 0.9}, org{-12.5, 30.25, 7};
  const Mat3 axes = oblique_axes();
  std::string samples(24, '\0');
  for (int i = 0; i < 24; ++i) samples[i] = char(i * 10);
  const std::string mf = "measurement frame: (1,0,0) (0,0,-1) (0,1,0)\n";
  write("in.nrrd", nrrd_header(d, sp, axes, org, "left-posterior-superior", mf) + samples);
  const Volume v = read_volume(file("in.nrrd"));
  EXPECT_EQ(v.frame.space, "left-posterior-superior");
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(v.spacing[a], sp[a], 1e-14);
    EXPECT_EQ(v.origin[a], org[a]);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(v.frame.axes[a][c], axes[a][c], 1e-14);
  }
  ASSERT_TRUE(v.frame.measurement_frame.has_value());
  // The header's file order: the first vector is (1,0,0), the second (0,0,-1).
  EXPECT_EQ((*v.frame.measurement_frame)[1][2], -1.0);
  // Written and read again: the same transform, space and measurement frame.
  write_volume(file("out.nrrd"), v);
  const Volume w = read_volume(file("out.nrrd"));
  expect_same_frame(w, v, 0.0);
  const std::string text = test::slurp(file("out.nrrd"));
  EXPECT_NE(text.find("space: left-posterior-superior\n"), std::string::npos) << text.substr(0, 600);
  EXPECT_NE(text.find("measurement frame: (1,0,0) (0,0,-1) (0,1,0)"), std::string::npos) << text.substr(0, 600);
  EXPECT_EQ(w.data, v.data);
  // A second generation is byte-identical to the first.
  write_volume(file("out2.nrrd"), w);
  EXPECT_EQ(test::slurp(file("out2.nrrd")), text);
}

TEST_F(WorldIo, NrrdSpaceUnitsAreScaledToMillimetres) {
  // The same grid in metres, centimetres and microns reads as in millimetres; the written
  // NRRD states "mm" and reads back the same.
  const Mat3 axes = oblique_axes(20);
  const Vec3d sp_mm{0.5, 0.7, 0.9}, org_mm{-12.5, 30.25, 7};
  for (const auto& [unit, per_mm] : std::vector<std::pair<std::string, double>>{
           {"m", 1e-3}, {"cm", 0.1}, {"um", 1e3}, {"mm", 1.0}, {"meters", 1e-3}}) {
    SCOPED_TRACE(unit);
    Vec3d sp, org;
    for (int a = 0; a < 3; ++a) sp[a] = sp_mm[a] * per_mm, org[a] = org_mm[a] * per_mm;
    const std::string units = "space units: \"" + unit + "\" \"" + unit + "\" \"" + unit + "\"\n";
    write("u.nrrd", nrrd_header({2, 2, 2}, sp, axes, org, "left-posterior-superior", units) + std::string(8, '\x05'));
    const Volume v = read_volume(file("u.nrrd"));
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(v.spacing[a], sp_mm[a], 1e-12 * sp_mm[a]);
      EXPECT_NEAR(v.origin[a], org_mm[a], 1e-12 * 100);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(v.frame.axes[a][c], axes[a][c], 1e-12);
    }
    write_volume(file("back.nrrd"), v);
    EXPECT_NE(test::slurp(file("back.nrrd")).find("space units: \"mm\" \"mm\" \"mm\"\n"), std::string::npos);
    const Volume w = read_volume(file("back.nrrd"));
    expect_same_frame(w, v, 1e-12);
  }
  expect_one_line_error(
      run({"info", write("f.nrrd", nrrd_header({2, 2, 2}, sp_mm, axes, org_mm, "left-posterior-superior",
                                                "space units: \"furlong\" \"mm\" \"mm\"\n") +
                                       std::string(8, '\x05'))}),
      {"space units: 'furlong' not understood (expected mm, cm, m or um)"});
  expect_one_line_error(
      run({"info", write("mix.nrrd", nrrd_header({2, 2, 2}, sp_mm, axes, org_mm, "left-posterior-superior",
                                                  "space units: \"m\" \"mm\" \"mm\"\n") +
                                         std::string(8, '\x05'))}),
      {"space units differ between the world's axes"});
}

TEST_F(WorldIo, RasAndOtherSpacesKeepTheirName) {
  const Dims3 d{2, 2, 2};
  for (const char* space : {"right-anterior-superior", "left-anterior-superior", "scanner-xyz", "3D-right-handed"}) {
    SCOPED_TRACE(space);
    write("in.nrrd", nrrd_header(d, {1, 2, 3}, oblique_axes(-20), {5, -6, 7}, space) + std::string(8, '\x05'));
    const Volume v = read_volume(file("in.nrrd"));
    EXPECT_EQ(v.frame.space, space);
    write_volume(file("out.nrrd"), v);
    expect_same_frame(read_volume(file("out.nrrd")), v, 1e-15);
    EXPECT_NE(test::slurp(file("out.nrrd")).find(std::string("space: ") + space + "\n"), std::string::npos);
  }
}

TEST_F(WorldIo, VolumesWithoutASpaceAreWrittenAsLps) {
  // A phantom or raw volume names no space: written as ITK's physical space.
  Volume v({3, 4, 5}, {0.5, 0.25, 2}, ScalarType::UInt8);
  v.origin = {-1.5, 2, 30};
  write_volume(file("v.nrrd"), v);
  const std::string text = test::slurp(file("v.nrrd"));
  EXPECT_NE(text.find("space: left-posterior-superior\n"), std::string::npos) << text.substr(0, 400);
  EXPECT_NE(text.find("space directions: (0.5,0,0) (0,0.25,0) (0,0,2)"), std::string::npos) << text.substr(0, 400);
  // A NRRD without a space (per-axis spacings only) reads as axis-aligned and unnamed.
  write("plain.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nspacings: 1 2 3\nencoding: raw\n\n" +
                          std::string(8, '\x01'));
  const Volume p = read_volume(file("plain.nrrd"));
  EXPECT_TRUE(p.frame.axes_are_identity());
  EXPECT_EQ(p.frame.space, "");
  // Degenerate directions say nothing: the grid is taken as axis-aligned.
  write("flat.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\nspace: left-posterior-superior\nsizes: 2 2 2\n"
                     "space directions: (1,0,0) (2,0,0) (0,0,1)\nencoding: raw\n\n" + std::string(8, '\x01'));
  EXPECT_TRUE(read_volume(file("flat.nrrd")).frame.axes_are_identity());
}

// ---- MetaImage -------------------------------------------------------------------------------

std::string mha_header(const Mat3& axes, const Vec3d& org, const std::string& extra) {
  std::string h = "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\nTransformMatrix =";
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) h += " " + num(axes[a][c]);
  h += "\nOffset = " + num(org[0]) + " " + num(org[1]) + " " + num(org[2]) + "\n" + extra +
       "ElementSpacing = 0.5 0.75 1.5\nDimSize = 3 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n";
  return h;
}

TEST_F(WorldIo, RotatedMetaImageRoundTrip) {
  const Mat3 axes = oblique_axes(50);
  write("in.mha", mha_header(axes, {11.5, -7.25, 3}, "AnatomicalOrientation = RAI\n") + std::string(12, '\x07'));
  const Volume v = read_volume(file("in.mha"));
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(v.frame.axes[a][c], axes[a][c], 1e-15);
  EXPECT_EQ(v.origin, (Vec3d{11.5, -7.25, 3}));
  EXPECT_EQ(v.frame.anatomical_orientation, "RAI");
  EXPECT_EQ(v.frame.space, "");
  for (const char* ext : {".mha", ".mhd"}) {
    SCOPED_TRACE(ext);
    const std::string out = file(std::string("out") + ext);
    write_volume(out, v);
    const Volume w = read_volume(out);
    expect_same_frame(w, v, 1e-15);
    const std::string text = test::slurp(out);
    EXPECT_NE(text.find("AnatomicalOrientation = RAI\n"), std::string::npos) << text;
    EXPECT_EQ(text.find("TransformMatrix = 1 0 0"), std::string::npos) << text;
  }
  // MetaImage -> NRRD -> MetaImage: the NRRD states LPS (MetaImage's world) and the transform
  // survives both steps.
  write_volume(file("mid.nrrd"), v);
  const Volume n = read_volume(file("mid.nrrd"));
  EXPECT_EQ(n.frame.space, "left-posterior-superior");
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(n.frame.axes[a][c], axes[a][c], 1e-15);
  // Without AnatomicalOrientation in the input, the written one is derived from the axes.
  write("plain.mha", mha_header({{{0, 1, 0}, {-1, 0, 0}, {0, 0, 1}}}, {0, 0, 0}, "") + std::string(12, '\x07'));
  write_volume(file("plain_out.mha"), read_volume(file("plain.mha")));
  EXPECT_NE(test::slurp(file("plain_out.mha")).find("AnatomicalOrientation = ALI\n"), std::string::npos);
}

// NIfTI-1 (.nii, .nii.gz) and VTK ImageData (.vti) outputs: the samples exactly, and every
// voxel where it was in the world (NIfTI holds its transform in float32: within 1e-5 mm per mm
// of the origin's size; VTI in 17 digits). NIfTI's world is RAS, checked on the header's own
// bytes below, independent of softshell's reader.
TEST_F(WorldIo, NiftiAndVtiOutputsKeepTheVolumesPlaceInTheWorld) {
  struct Case {
    ScalarType type;
    std::string space;
  };
  const std::vector<Case> cases = {{ScalarType::UInt8, "left-posterior-superior"},
                                   {ScalarType::UInt16, "right-anterior-superior"},
                                   {ScalarType::Float32, ""}};
  std::vector<std::string> outputs = {"o.vti", "oz.vti"};
  if (nifti_supported()) outputs.insert(outputs.end(), {"o.nii", "o.nii.gz"});
  for (const Case& c : cases) {
    Volume v({5, 4, 3}, {0.5, 0.75, 1.25}, c.type);
    v.origin = {-12.5, 30.25, 7.125};
    v.frame.axes = oblique_axes(40);
    v.frame.space = c.space;
    for (std::size_t i = 0; i < v.voxels(); ++i) v.data[i] = c.type == ScalarType::Float32 ? 0.25f * float(i) - 3.0f : float(i * 3);
    for (const std::string& name : outputs) {
      SCOPED_TRACE(name + " " + scalar_type_name(c.type) + " " + c.space);
      WriteOptions opt;
      opt.compress = name == "oz.vti";
      write_volume(file(name), v, opt);
      const Volume w = read_volume(file(name));
      ASSERT_EQ(w.dims, v.dims);
      EXPECT_EQ(w.source_type, c.type);
      EXPECT_EQ(w.data, v.data);
      const double tol = name.find(".nii") != std::string::npos ? 1e-5 * 40 : 1e-12;
      for (const Vec3d p : {Vec3d{0, 0, 0}, Vec3d{4, 3, 2}, Vec3d{4, 0, 2}, Vec3d{1.5, 2.5, 0.5}}) {
        // Both in LPS: the read frame may be RAS (NIfTI) or unnamed (VTI, taken as LPS).
        Vec3d ov = v.origin, ow = w.origin;
        Volume vl = v, wl = w;
        vl.frame = v.frame.to_lps(ov), vl.origin = ov;
        wl.frame = w.frame.to_lps(ow), wl.origin = ow;
        const Vec3d a = vl.index_to_world(p), b = wl.index_to_world(p);
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(a[k], b[k], tol) << "component " << k;
      }
    }
  }
  if (!nifti_supported()) return;
  // The header's bytes (nifti1.h's layout, little-endian host): sizeof_hdr 348, magic "n+1",
  // vox_offset 352, sform code 1 (scanner) and its rows in RAS: an LPS origin (x, y, z)
  // reads (-x, -y, z), and each row holds spacing times the axes' RAS components.
  Volume v({5, 4, 3}, {0.5, 0.75, 1.25}, ScalarType::UInt8);
  v.origin = {-12.5, 30.25, 7.125};
  v.frame.axes = oblique_axes(40);
  v.frame.space = "left-posterior-superior";
  write_volume(file("h.nii"), v);
  const std::string b = test::slurp(file("h.nii"));
  ASSERT_EQ(b.size(), 352u + v.voxels());
  auto i32 = [&](std::size_t at) { std::int32_t x; std::memcpy(&x, b.data() + at, 4); return x; };
  auto i16 = [&](std::size_t at) { std::int16_t x; std::memcpy(&x, b.data() + at, 2); return x; };
  auto f32 = [&](std::size_t at) { float x; std::memcpy(&x, b.data() + at, 4); return double(x); };
  EXPECT_EQ(i32(0), 348);
  EXPECT_EQ(b.substr(344, 4), std::string("n+1\0", 4));
  EXPECT_EQ(f32(108), 352.0);       // vox_offset
  EXPECT_EQ(i16(70), 2);            // datatype DT_UINT8
  EXPECT_EQ(i16(254), 1);           // sform_code NIFTI_XFORM_SCANNER_ANAT
  EXPECT_EQ(i16(252), 1);           // qform_code
  const double sign[3] = {-1, -1, 1};  // LPS -> RAS
  for (int r = 0; r < 3; ++r) {
    const std::size_t row = 280 + 16 * std::size_t(r);  // srow_x, srow_y, srow_z
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(f32(row + 4 * a), sign[r] * v.frame.axes[a][r] * v.spacing[a], 1e-6);
    EXPECT_NEAR(f32(row + 12), sign[r] * v.origin[r], 1e-5);
  }
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(f32(76 + 4 * (a + 1)), v.spacing[a], 1e-7);  // pixdim[1..3] (pixdim[0] at 76 is qfac)
}

TEST_F(WorldIo, RasNrrdWrittenAsMetaImageKeepsItsPlaceInLps) {
  write("ras.nrrd", nrrd_header({3, 2, 2}, {1, 2, 3}, oblique_axes(), {10, 20, 30}, "right-anterior-superior") +
                        std::string(12, '\x03'));
  const Volume ras = read_volume(file("ras.nrrd"));
  write_volume(file("lps.mha"), ras);
  const Volume lps = read_volume(file("lps.mha"));
  // Every voxel centre is the same physical point: (x, y, z) in RAS is (-x, -y, z) in LPS.
  for (const Vec3d p : {Vec3d{0, 0, 0}, Vec3d{2, 1, 1}, Vec3d{1, 0, 1}}) {
    const Vec3d a = ras.index_to_world(p), b = lps.index_to_world(p);
    EXPECT_NEAR(b[0], -a[0], 1e-12);
    EXPECT_NEAR(b[1], -a[1], 1e-12);
    EXPECT_NEAR(b[2], a[2], 1e-12);
  }
}

// ---- PLUS tracked-frame sequences ------------------------------------------------------------

TEST_F(WorldIo, PlusTrackedFrameSequenceIsRefused) {
  const std::string seq =
      "ObjectType = Image\nNDims = 3\nAnatomicalOrientation = RAI\nBinaryData = True\n"
      "BinaryDataByteOrderMSB = False\nCompressedData = False\nDimSize = 4 3 2\nElementSpacing = 1 1 1\n"
      "ElementType = MET_UCHAR\nKinds = domain domain list\nUltrasoundImageOrientation = MF\n"
      "Seq_Frame0000_FrameNumber = 0\nSeq_Frame0000_ImageToReferenceTransform = 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n"
      "Seq_Frame0000_ImageToReferenceTransformStatus = OK\nSeq_Frame0000_Timestamp = 1.0\n"
      "Seq_Frame0001_FrameNumber = 1\nSeq_Frame0001_ImageToReferenceTransform = 1 0 0 2 0 1 0 0 0 0 1 0 0 0 0 1\n"
      "Seq_Frame0001_Timestamp = 1.1\nElementDataFile = LOCAL\n" +
      std::string(24, '\x40');
  write("sweep.igs.mha", seq);
  try {
    read_volume(file("sweep.igs.mha"));
    FAIL() << "a tracked-frame sequence was read as a volume";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("PLUS tracked-frame sequence"), std::string::npos) << m;
    EXPECT_NE(m.find("VolumeReconstructor"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
  // The same from the command line: exit 2, one line, nothing written.
  const RunResult r = run({"info", file("sweep.igs.mha")});
  expect_one_line_error(r, {"sweep.igs.mha", "tracked-frame sequence", "reconstruct a volume"});
  const RunResult c = run({"classify", file("sweep.igs.mha"), "--iso", "100", "-o", file("u.nrrd")});
  expect_one_line_error(c, {"tracked-frame sequence"});
  EXPECT_FALSE(fs::exists(file("u.nrrd")));
  // PLUS's own sequence NRRD (.igs.nrrd) keeps the frames' keys as key/value pairs.
  write("sweep.igs.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 3 2\nkinds: domain domain list\n"
                          "encoding: raw\nSeq_Frame0000_ImageToReferenceTransform:=1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n\n" +
                              std::string(24, '\x40'));
  expect_one_line_error(run({"info", file("sweep.igs.nrrd")}), {"tracked-frame sequence"});
  // A 3D+t sequence as 3D Slicer's Sequences module writes it: a 4-D NRRD with a list axis.
  write("beat.seq.nrrd", "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 2 2 2 3\nkinds: domain domain domain list\n"
                         "encoding: raw\n\n" + std::string(24, '\x01'));
  // It is read a frame at a time (tests/test_io.cpp: Sequence.*); `info` counts the frames.
  const RunResult i = run({"info", file("beat.seq.nrrd")});
  EXPECT_EQ(i.status, 0) << i.err;
  EXPECT_NE(i.out.find("frames:             3 (a 3D+t sequence"), std::string::npos) << i.out;
  // A reconstructed volume that keeps PLUS's lone "Seq_Frame0000_ImageStatus" is a volume.
  EXPECT_FALSE(io_detail::is_tracked_frame_key("Seq_Frame0000_ImageStatus"));
  EXPECT_TRUE(io_detail::is_tracked_frame_key("Seq_Frame0000_ProbeToTrackerTransform"));
  EXPECT_TRUE(io_detail::is_tracked_frame_key("Seq_Frame0012_Timestamp"));
  EXPECT_FALSE(io_detail::is_tracked_frame_key("Seq_FrameXYZ_Transform"));
}

// ---- end to end: classify and mesh an oblique volume -----------------------------------------

// ---- 3D+t sequences -----------------------------------------------------------------------------

TEST_F(WorldIo, SequenceFramesAreReadOneAtATime) {
  // Three frames of 16^3 (a growing ball), a 4-D NRRD as 3D Slicer's Sequences module writes it.
  const Dims3 d{16, 16, 16};
  const Vec3d sp{0.5, 0.6, 0.7}, org{-20.5, 14.25, -3};
  const Mat3 axes = oblique_axes();
  std::vector<std::string> frames;
  for (int k = 0; k < 3; ++k) {
    std::string f = ball_samples(d, sp, 2.0 + 0.5 * k);
    frames.push_back(f);
  }
  std::string head = nrrd_header(d, sp, axes, org, "left-posterior-superior");
  // nrrd_header writes a 3-D header: make it 4-D with a list of frames.
  auto replace = [&](const std::string& a, const std::string& b) { head.replace(head.find(a), a.size(), b); };
  replace("dimension: 3", "dimension: 4");
  replace("sizes: 16 16 16", "sizes: 16 16 16 3");
  replace("kinds: domain domain domain", "kinds: domain domain domain list");
  const std::size_t dirs = head.find("space directions:");
  head.insert(head.find('\n', dirs), " none");
  write("seq.nrrd", head + frames[0] + frames[1] + frames[2]);
  for (int k = 0; k < 3; ++k) {
    SCOPED_TRACE(k);
    const Volume v = read_volume(file("seq.nrrd"), std::nullopt, std::size_t(k));
    ASSERT_EQ(v.dims, d);
    for (std::size_t i = 0; i < v.voxels(); ++i)
      ASSERT_EQ(v.data[i], float(static_cast<unsigned char>(frames[k][i]))) << "voxel " << i;
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(v.spacing[a], sp[a], 1e-12);
    EXPECT_EQ(v.origin, org);
    const VolumeHeader h = read_volume_header(file("seq.nrrd"), std::nullopt, std::size_t(k));
    EXPECT_EQ(h.frames, 3u);
    EXPECT_EQ(h.dims, d);
  }
  test::expect_input_error([&] { read_volume(file("seq.nrrd")); },
                     {"a sequence of 3 3-D frames of 16x16x16: choose one with --frame K (0 to 2)"});
  test::expect_input_error([&] { read_volume_header(file("seq.nrrd")); }, {"choose one with --frame K"});
  test::expect_input_error([&] { read_volume(file("seq.nrrd"), std::nullopt, std::size_t(3)); },
                     {"--frame 3: the file holds 3 frames (0 to 2)"});
  EXPECT_EQ(read_any_header(file("seq.nrrd")).frames, 3u);
  // A 3-D file is frame 0 of one, whatever its format.
  write("one.nrrd", nrrd_header(d, sp, axes, org, "left-posterior-superior") + frames[1]);
  EXPECT_EQ(read_volume(file("one.nrrd"), std::nullopt, std::size_t(0)).voxels(), d[0] * d[1] * d[2]);
  test::expect_input_error([&] { read_volume(file("one.nrrd"), std::nullopt, std::size_t(1)); },
                     {"--frame 1: the file holds 1 frame (0)"});
  write_volume(file("one.mha"), read_volume(file("one.nrrd")));
  test::expect_input_error([&] { read_volume(file("one.mha"), std::nullopt, std::size_t(2)); },
                     {"--frame 2: a 3-D volume has one frame (0)"});

  // The command line: info counts the frames; classify --frame K gives exactly what the frame
  // written as a 3-D file gives; without --frame a one-line error before any work.
  RunResult r = run({"info", file("seq.nrrd"), "--frame", "2"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("frames:             3 (a 3D+t sequence; below: frame 2"), std::string::npos) << r.out;
  r = run({"classify", file("seq.nrrd"), "--iso", "110", "--mask", "none", "--frame", "1", "-o", file("u1.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  r = run({"classify", file("one.nrrd"), "--iso", "110", "--mask", "none", "-o", file("u_one.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(read_volume(file("u1.nrrd")).data, read_volume(file("u_one.nrrd")).data);
  // Without --frame classify takes every frame and writes a 4-D NRRD; each
  // frame (cold: --warm-start off) is exactly what --frame K gives.
  r = run({"classify", file("seq.nrrd"), "--iso", "110", "--mask", "none", "--warm-start", "off", "-o", file("u.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("sequence 3 frames of 16x16x16, warm start off"), std::string::npos) << r.out;
  const std::vector<Volume> us = read_frames(file("u.nrrd"));
  ASSERT_EQ(us.size(), 3u);
  EXPECT_EQ(us[1].data, read_volume(file("u1.nrrd")).data);
  for (int a = 0; a < 3; ++a)  // the input's geometry on every frame
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(us[0].frame.axes[a][c], axes[a][c], 1e-12);
  EXPECT_EQ(us[2].origin, org);
  // A 4-D output needs NRRD: refused before any work, nothing written.
  r = run({"classify", file("seq.nrrd"), "--iso", "110", "-o", file("u.mha")});
  expect_one_line_error(r, {"is a sequence of 3 frames, written as a 4-D NRRD only: use a .nrrd output"});
  EXPECT_FALSE(fs::exists(file("u.mha")));
  expect_one_line_error(run({"classify", file("seq.nrrd"), "--iso", "110", "--init", file("u1.nrrd"), "-o", file("v.nrrd")}),
                        {"--init: not with a sequence"});
}

TEST_F(WorldIo, SequenceGivenAsFilesIsClassifiedLikeTheFourDimensionalFile) {
  // The same three frames as a 4-D NRRD and as 3-D files named so that plain
  // sorting would misorder them (f9, f10, f11): a quoted pattern takes them in
  // natural order, a list in the order given; every frame equals the 4-D
  // file's (cold starts), and --per-frame-files writes each frame once more.
  const Dims3 d{16, 16, 16};
  const Vec3d sp{0.5, 0.6, 0.7}, org{-20.5, 14.25, -3};
  const Mat3 axes = oblique_axes();
  std::string head3 = nrrd_header(d, sp, axes, org, "left-posterior-superior"), head4 = head3;
  auto replace = [&](const std::string& a, const std::string& b) { head4.replace(head4.find(a), a.size(), b); };
  replace("dimension: 3", "dimension: 4");
  replace("sizes: 16 16 16", "sizes: 16 16 16 3");
  replace("kinds: domain domain domain", "kinds: domain domain domain list");
  head4.insert(head4.find('\n', head4.find("space directions:")), " none");
  std::vector<std::string> frames;
  for (int k = 0; k < 3; ++k) frames.push_back(ball_samples(d, sp, 2.0 + 0.7 * k));
  write("seq.nrrd", head4 + frames[0] + frames[1] + frames[2]);
  fs::create_directories(file("fr"));
  for (int k = 0; k < 3; ++k) write("fr/f" + std::to_string(9 + k) + ".nrrd", head3 + frames[k]);
  const std::vector<std::string> common{"--iso", "110", "--mask", "none", "--warm-start", "off"};
  auto classify = [&](std::vector<std::string> args) {
    std::vector<std::string> a{"classify"};
    a.insert(a.end(), args.begin(), args.end());
    a.insert(a.end(), common.begin(), common.end());
    return run(a);
  };
  RunResult r = classify({file("seq.nrrd"), "-o", file("u4.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  r = classify({file("fr/f*.nrrd"), "-o", file("ug.nrrd"), "--per-frame-files", file("out/u-##.nrrd")});
  // The per-frame files' folder must exist: checked before any work.
  expect_one_line_error(r, {"--per-frame-files", "u-00.nrrd", "cannot create"});
  EXPECT_FALSE(fs::exists(file("ug.nrrd")));
  fs::create_directories(file("out"));
  r = classify({file("fr/f*.nrrd"), "-o", file("ug.nrrd"), "--per-frame-files", file("out/u-##.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("sequence 3 frames of 16x16x16"), std::string::npos) << r.out;
  r = classify({file("fr/f9.nrrd"), file("fr/f10.nrrd"), file("fr/f11.nrrd"), "-o", file("ul.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  const std::vector<Volume> u4 = read_frames(file("u4.nrrd")), ug = read_frames(file("ug.nrrd")),
                            ul = read_frames(file("ul.nrrd"));
  ASSERT_EQ(ug.size(), 3u);
  ASSERT_EQ(ul.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    SCOPED_TRACE(k);
    EXPECT_EQ(ug[k].data, u4[k].data);
    EXPECT_EQ(ul[k].data, u4[k].data);
    const Volume one = read_volume(file("out/u-0" + std::to_string(k) + ".nrrd"));
    EXPECT_EQ(one.data, u4[k].data);
    EXPECT_EQ(one.origin, org);
  }
  EXPECT_NE(u4[0].data, u4[2].data);  // the frames differ: order matters
  // A list in another order is taken in that order.
  r = classify({file("fr/f11.nrrd"), file("fr/f9.nrrd"), file("fr/f10.nrrd"), "-o", file("ur.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(read_frames(file("ur.nrrd"))[0].data, u4[2].data);
  // --frame K picks one file of the list.
  r = classify({file("fr/f*.nrrd"), "--frame", "1", "-o", file("u1.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(read_volume(file("u1.nrrd")).data, u4[1].data);
  // Refusals, before any work and writing nothing.
  expect_one_line_error(classify({file("fr/g*.nrrd"), "-o", file("x.nrrd")}), {"g*.nrrd: no file matches this pattern"});
  expect_one_line_error(classify({file("fr/f*.nrrd"), "--frame", "3", "-o", file("x.nrrd")}),
                        {"--frame 3: the sequence has 3 frames (0 to 2)"});
  expect_one_line_error(classify({file("fr/f9.nrrd"), file("seq.nrrd"), "-o", file("x.nrrd")}),
                        {"seq.nrrd: a sequence of 3 frames itself"});
  write("fr/odd.nrrd", nrrd_header(d, {0.5, 0.6, 0.9}, axes, org, "left-posterior-superior") + frames[0]);
  expect_one_line_error(classify({file("fr/f9.nrrd"), file("fr/odd.nrrd"), "-o", file("x.nrrd")}),
                        {"odd.nrrd: spacing", "the frames of a sequence share one grid"});
  expect_one_line_error(classify({file("fr/f*.nrrd"), "-o", file("x.nrrd"), "--per-frame-files", file("u-#-#.nrrd")}),
                        {"--per-frame-files", "expected one run of '#'"});
  expect_one_line_error(classify({file("fr/f*.nrrd"), "-o", file("x.nrrd"), "--per-frame-files", file("u-#.png")}),
                        {"--per-frame-files", "unknown extension"});
  expect_one_line_error(classify({file("fr/f9.nrrd"), "-o", file("x.nrrd"), "--per-frame-files", file("u-#.nrrd")}),
                        {"--per-frame-files", "is one 3-D volume, not a sequence"});
  expect_one_line_error(classify({file("fr/f*.nrrd"), "-o", file("fr/f10.nrrd")}), {"f10.nrrd"});
  EXPECT_FALSE(fs::exists(file("x.nrrd")));
  EXPECT_EQ(read_volume(file("fr/f10.nrrd")).data.size(), d[0] * d[1] * d[2]);
}

TEST_F(WorldIo, MovingPhantomSequenceIsClassifiedWithAndWithoutWarmStart) {
  // softshell phantom --frames: the scene drifts 12 mm along x over 4 frames
  // (no turn): the sphere's centroid moves by that, frame to frame.
  RunResult r = run({"phantom", "--shape", "sphere", "--size", "24", "--frames", "4", "--turn", "0", "--drift", "12",
                     "-o", file("p"), "-q"});
  ASSERT_EQ(r.status, 0) << r.err;
  const std::vector<Volume> labels = read_frames(file("p/labels.nrrd"));
  const std::vector<Volume> bmode = read_frames(file("p/volume.nrrd"));
  ASSERT_EQ(labels.size(), 4u);
  ASSERT_EQ(read_frames(file("p/truth_sdf.nrrd")).size(), 4u);
  const auto centroid_x = [](const Volume& l) {
    double sx = 0, n = 0;
    for (std::size_t z = 0; z < l.dims[2]; ++z)
      for (std::size_t y = 0; y < l.dims[1]; ++y)
        for (std::size_t x = 0; x < l.dims[0]; ++x)
          if (l.at(x, y, z) == 1.0f) sx += double(x), n += 1;
    return n > 0 ? sx / n * l.spacing[0] : 0.0;
  };
  const double step = 12.0 / 3.0;  // mm per frame
  for (int k = 1; k < 4; ++k) {
    SCOPED_TRACE(k);
    EXPECT_NEAR(centroid_x(labels[k]) - centroid_x(labels[k - 1]), step, 0.2 * step);
    EXPECT_NE(bmode[k].data, bmode[k - 1].data);
  }
  // Every frame classified, cold and warm; warm frames land within the
  // solver's tolerance of the cold ones (sharpening's loose linear solve lets
  // a little through: the largest difference is checked, and most voxels agree).
  r = run({"classify", file("p/volume.nrrd"), "--iso", "auto", "--warm-start", "off", "-o", file("cold.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  r = run({"classify", file("p/volume.nrrd"), "--iso", "auto", "--warm-start", "on", "-o", file("warm.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("iterations (warm)"), std::string::npos) << r.out;
  const std::vector<Volume> cold = read_frames(file("cold.nrrd")), warm = read_frames(file("warm.nrrd"));
  ASSERT_EQ(cold.size(), 4u);
  ASSERT_EQ(warm.size(), 4u);
  EXPECT_EQ(warm[0].data, cold[0].data);  // frame 0 starts cold either way
  for (int k = 1; k < 4; ++k) {
    SCOPED_TRACE(k);
    std::size_t differ = 0;
    float worst = 0;
    for (std::size_t i = 0; i < cold[k].voxels(); ++i) {
      const float d = std::fabs(warm[k].data[i] - cold[k].data[i]);
      worst = std::max(worst, d);
      differ += d > 0.05f;
    }
    EXPECT_LT(double(differ), 0.01 * double(cold[k].voxels())) << "worst " << worst;
  }
  // On a still scene (same speckle in every frame) the warm start saves
  // iterations: the frames' solver counts as the report prints them.
  r = run({"phantom", "--size", "48", "--frames", "3", "--turn", "0", "--drift", "0", "--frame-speckle", "same", "-o",
           file("still"), "-q"});
  ASSERT_EQ(r.status, 0) << r.err;
  const auto iterations = [](const std::string& out, int k) {
    const std::size_t at = out.find("frame " + std::to_string(k) + ": iso ");
    const std::size_t comma = out.find(", ", at);
    return at == std::string::npos ? -1 : std::atoi(out.c_str() + comma + 2);
  };
  const RunResult c = run({"classify", file("still/volume.nrrd"), "--iso", "auto", "--warm-start", "off", "-o", file("sc.nrrd")});
  const RunResult w = run({"classify", file("still/volume.nrrd"), "--iso", "auto", "--warm-start", "on", "-o", file("sw.nrrd")});
  ASSERT_EQ(c.status, 0) << c.err;
  ASSERT_EQ(w.status, 0) << w.err;
  for (int k = 1; k < 3; ++k) {
    SCOPED_TRACE(c.out + w.out);
    ASSERT_GT(iterations(c.out, k), 0);
    EXPECT_LT(iterations(w.out, k), iterations(c.out, k));
  }
}

TEST_F(WorldIo, MaskInitAndTruthPlacedElsewhereAreNamedInAWarning) {
  // Masks, initial opacities and truths are used index by index; one whose header puts its
  // voxels elsewhere in the world was likely made for another volume: a warning says what
  // differs, and the run goes on (exit 0). Placed the same: no warning.
  const Dims3 d{16, 16, 16};
  const Vec3d sp{0.5, 0.6, 0.7}, org{-20.5, 14.25, -3};
  const Mat3 axes = oblique_axes();
  write("in.nrrd", nrrd_header(d, sp, axes, org, "left-posterior-superior") + ball_samples(d, sp, 2.5));
  const std::string ones(d[0] * d[1] * d[2], '\x01');
  write("same.nrrd", nrrd_header(d, sp, axes, org, "left-posterior-superior") + ones);
  write("moved.nrrd", nrrd_header(d, sp, axes, {org[0] + 5, org[1], org[2]}, "left-posterior-superior") + ones);
  write("scaled.nrrd", nrrd_header(d, {1, 1, 1}, axes, org, "left-posterior-superior") + ones);
  RunResult r = run({"classify", file("in.nrrd"), "--iso", "110", "--mask", file("same.nrrd"), "-o", file("u.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(r.err.find("warning"), std::string::npos) << r.err;
  r = run({"classify", file("in.nrrd"), "--iso", "110", "--mask", file("moved.nrrd"), "-o", file("u2.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("warning: --mask " + file("moved.nrrd") + " lies elsewhere in the world than the volume (origin ("),
            std::string::npos)
      << r.err;
  r = run({"classify", file("in.nrrd"), "--iso", "110", "--mask", "none", "--init", file("scaled.nrrd"), "-o",
           file("u3.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("warning: --init " + file("scaled.nrrd") +
                       " lies elsewhere in the world than the volume (spacing 0.5,0.6,0.7 mm against 1,1,1 mm)"),
            std::string::npos)
      << r.err;
  // evaluate: u against a truth moved by 5 mm.
  Volume sdf(d, sp);
  sdf.frame.axes = axes;
  sdf.frame.space = "left-posterior-superior";
  sdf.origin = org;
  for (std::size_t z = 0; z < d[2]; ++z)
    for (std::size_t y = 0; y < d[1]; ++y)
      for (std::size_t x = 0; x < d[0]; ++x)
        sdf.at(x, y, z) = float(std::sqrt(double((x - 8) * (x - 8) + (y - 8) * (y - 8) + (z - 8) * (z - 8))) - 4.0);
  write_volume(file("sdf_same.nrrd"), sdf);
  sdf.origin[0] += 5;
  write_volume(file("sdf_moved.nrrd"), sdf);
  r = run({"evaluate", file("u.nrrd"), file("sdf_moved.nrrd")});
  EXPECT_NE(r.err.find("warning: the truth " + file("sdf_moved.nrrd") + " lies elsewhere in the world than the opacity"),
            std::string::npos)
      << r.status << r.err;
  r = run({"evaluate", file("u.nrrd"), file("sdf_same.nrrd")});
  EXPECT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(r.err.find("warning"), std::string::npos) << r.err;
}

TEST_F(WorldIo, ObliqueVolumeClassifiedAndMeshedOverlaysItsInput) {
  const Dims3 d{24, 24, 24};
  const Vec3d sp{0.5, 0.6, 0.7}, org{-20.5, 14.25, -3};
  const Mat3 axes = oblique_axes();
  const double radius = 4.0;
  write("in.nrrd", nrrd_header(d, sp, axes, org, "left-posterior-superior", "measurement frame: (1,0,0) (0,1,0) (0,0,1)\n") +
                       ball_samples(d, sp, radius));
  const Volume in = read_volume(file("in.nrrd"));

  // classify and lowpass carry the input's transform to their outputs.
  RunResult r = run({"classify", file("in.nrrd"), "--iso", "110", "--mask", "none", "-o", file("u.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  const Volume u = read_volume(file("u.nrrd"));
  expect_same_frame(u, in, 0.0);  // exact: the input's own space directions are written back
  r = run({"lowpass", file("in.nrrd"), "--sigma", "1", "-o", file("lp.mha")});
  ASSERT_EQ(r.status, 0) << r.err;
  const Volume lp = read_volume(file("lp.mha"));
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(lp.origin[a], in.origin[a], 1e-12);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(lp.frame.axes[a][c], in.frame.axes[a][c], 1e-15);
  }

  // The world mesh of the input: its vertices lie on the ball in world space (centre mapped
  // through the transform), and map back through the inverse transform onto the input's
  // iso-surface.
  r = run({"mesh", file("in.nrrd"), "--level", "110", "-o", file("in.ply")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(test::slurp(file("in.ply")).find("comment SPACE=LPS\n"), std::string::npos);
  const Mesh mi = read_ply_binary(file("in.ply"));
  ASSERT_GT(mi.vertex_count(), 100u);
  const Vec3d centre = in.index_to_world({11.5, 11.5, 11.5});
  double worst_r = 0, worst_level = 0;
  for (std::size_t i = 0; i < mi.vertex_count(); ++i) {
    const Vec3d p{mi.positions[3 * i], mi.positions[3 * i + 1], mi.positions[3 * i + 2]};
    const double dr = std::hypot(p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]) - radius;
    worst_r = std::max(worst_r, std::fabs(dr));
    worst_level = std::max(worst_level, std::fabs(trilinear(in, in.world_to_index(p)) - 110.0));
  }
  EXPECT_LT(worst_r, 0.5) << "input mesh off the ball in world space";
  EXPECT_LT(worst_level, 0.05) << "input mesh does not map back onto the iso-surface";
  // Normals still point out of the region above the level (outwards from the ball here).
  EXPECT_GT(mesh_signed_volume(mi), 0.0);
  EXPECT_NEAR(mesh_signed_volume(mi), 4.0 / 3.0 * M_PI * radius * radius * radius, 0.1 * 4.0 / 3.0 * M_PI * 64);

  // The opacity's 0.5 mesh: on the classified shell (u = 0.5 through the inverse transform)
  // and around the input's surface in world space.
  r = run({"mesh", file("u.nrrd"), "--level", "0.5", "-o", file("u.ply")});
  ASSERT_EQ(r.status, 0) << r.err;
  const Mesh mu = read_ply_binary(file("u.ply"));
  ASSERT_GT(mu.vertex_count(), 100u);
  double worst_u = 0, worst_ur = 0;
  for (std::size_t i = 0; i < mu.vertex_count(); ++i) {
    const Vec3d p{mu.positions[3 * i], mu.positions[3 * i + 1], mu.positions[3 * i + 2]};
    worst_u = std::max(worst_u, std::fabs(trilinear(u, u.world_to_index(p)) - 0.5));
    worst_ur = std::max(worst_ur, std::fabs(std::hypot(p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]) - radius));
  }
  EXPECT_LT(worst_u, 1e-3);
  EXPECT_LT(worst_ur, 2.5) << "the opacity's surface is not around the input's";

  // --coordinates grid: the same mesh before the transform (origin + spacing * index).
  r = run({"mesh", file("in.nrrd"), "--level", "110", "--coordinates", "grid", "-o", file("grid.ply")});
  ASSERT_EQ(r.status, 0) << r.err;
  const Mesh mg = read_ply_binary(file("grid.ply"));
  ASSERT_EQ(mg.vertex_count(), mi.vertex_count());
  double worst_g = 0;
  for (std::size_t i = 0; i < mg.vertex_count(); ++i) {
    const Vec3d w = in.grid_to_world({mg.positions[3 * i], mg.positions[3 * i + 1], mg.positions[3 * i + 2]});
    for (int c = 0; c < 3; ++c) worst_g = std::max(worst_g, std::fabs(w[c] - mi.positions[3 * i + c]));
  }
  EXPECT_LT(worst_g, 1e-4);
  expect_one_line_error(run({"mesh", file("in.nrrd"), "--level", "110", "--coordinates", "index", "-o", file("x.ply")}),
                        {"--coordinates"});
}

TEST(WorldMesh, MirroredAxesKeepNormalsOutAndWindingConsistent) {
  Volume v = test::shell_volume(16);
  Mesh grid = marching_cubes_reference(v, 0.5);
  ASSERT_FALSE(grid.empty());
  v.origin = {3, -2, 5};
  v.frame.axes = oblique_axes();
  for (double& c : v.frame.axes[1]) c = -c;  // a mirror: det -1
  ASSERT_LT(determinant(v.frame.axes), 0);
  // marching_cubes_reference ignores the frame (grid millimetres); move it into the world.
  Mesh shifted = grid;
  for (std::size_t i = 0; i < shifted.positions.size(); ++i) shifted.positions[i] += float(v.origin[i % 3]);
  Mesh world = shifted;
  mesh_to_world(world, v);
  EXPECT_NEAR(mesh_signed_volume(world), mesh_signed_volume(grid), 1e-3 * std::fabs(mesh_signed_volume(grid)));
  EXPECT_NEAR(mesh_area(world), mesh_area(grid), 1e-3 * mesh_area(grid));
  EXPECT_TRUE(mesh_topology(world).closed() == mesh_topology(grid).closed());
  EXPECT_EQ(mesh_topology(world).misoriented_edges, 0u);
  // Each normal still points to where the field is lower: along the normal, the triangle's
  // own winding agrees with it (normal . face normal > 0 on average).
  double agree = 0;
  for (std::size_t t = 0; t < world.triangle_count(); ++t) {
    const float* a = &world.positions[3 * world.triangles[3 * t]];
    const float* b = &world.positions[3 * world.triangles[3 * t + 1]];
    const float* c = &world.positions[3 * world.triangles[3 * t + 2]];
    const double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double fn[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    const float* n = &world.normals[3 * world.triangles[3 * t]];
    agree += fn[0] * n[0] + fn[1] * n[1] + fn[2] * n[2] > 0 ? 1 : -1;
  }
  EXPECT_GT(agree, 0.9 * double(world.triangle_count()));
}

}  // namespace
}  // namespace softshell
