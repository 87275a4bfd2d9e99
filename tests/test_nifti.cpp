// NIfTI-1/2 input through niftilib (host/io_nifti.cpp, docs/formats.md "NIfTI"): dims,
// datatypes, byte order, gzip, .hdr/.img pairs, the qform/sform index-to-world transform
// (NIfTI's world is RAS), units, scl_slope/scl_inter, and the bad-input answers. Every file is
// written by the test (fuzz::nifti_header builds the header field by field).
#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <cstring>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "error.hpp"
#include "fuzz_inputs.hpp"
#include "io.hpp"
#include "volume.hpp"

namespace softshell {
namespace {

using fuzz::NiftiSpec;
using test::CliTest;
namespace fs = std::filesystem;

class Nifti : public CliTest {
 protected:
  void SetUp() override {
    CliTest::SetUp();
    if (!nifti_supported()) GTEST_SKIP() << "built without niftilib (libnifti2-dev)";
  }
  std::string gzip_file(const std::string& name, const std::string& bytes) const {
    gzFile g = gzopen(file(name).c_str(), "wb");
    EXPECT_NE(g, nullptr);
    EXPECT_EQ(gzwrite(g, bytes.data(), unsigned(bytes.size())), int(bytes.size()));
    gzclose(g);
    return file(name);
  }
};

std::string u8_samples(int n) {
  std::string s;
  for (int i = 0; i < n; ++i) s += char(i * 7 + 1);
  return s;
}

NiftiSpec small(int version = 1) {
  NiftiSpec n;
  n.version = version;
  n.dim[1] = 4, n.dim[2] = 3, n.dim[3] = 2;
  n.pixdim[1] = 0.5, n.pixdim[2] = 0.75, n.pixdim[3] = 2;
  return n;
}

TEST_F(Nifti, PixdimOnlyIsAxisAlignedAndUnnamed) {
  for (int version : {1, 2}) {
    SCOPED_TRACE(version);
    write("a.nii", fuzz::nifti_header(small(version)) + u8_samples(24));
    const Volume v = read_volume(file("a.nii"));
    EXPECT_EQ(v.dims, (Dims3{4, 3, 2}));
    EXPECT_EQ(v.source_type, ScalarType::UInt8);
    EXPECT_EQ(v.spacing, (Vec3d{0.5, 0.75, 2}));
    EXPECT_EQ(v.origin, (Vec3d{0, 0, 0}));
    EXPECT_TRUE(v.frame.axes_are_identity());
    EXPECT_EQ(v.frame.space, "");
    const std::string s = u8_samples(24);
    for (int i = 0; i < 24; ++i) ASSERT_EQ(v.data[i], float(static_cast<unsigned char>(s[i])));
    const VolumeHeader h = read_volume_header(file("a.nii"));
    EXPECT_EQ(h.dims, v.dims);
    EXPECT_EQ(h.files, std::vector<std::string>{file("a.nii")});
  }
}

// NIfTI's qform: rotation from the quaternion (b, c, d), a = sqrt(1 - b^2 - c^2 - d^2),
// columns scaled by pixdim, the third also by qfac = pixdim[0]; written here from the
// standard's formula, independently of niftilib.
TEST_F(Nifti, QformGivesTheRasTransform) {
  NiftiSpec n = small();
  n.qform_code = 1;
  n.quatern[0] = 0.1, n.quatern[1] = -0.3, n.quatern[2] = 0.2;
  n.qoffset[0] = 12.5, n.qoffset[1] = -4, n.qoffset[2] = 30;
  n.pixdim[0] = -1;  // qfac: a left-handed grid
  write("q.nii", fuzz::nifti_header(n) + u8_samples(24));
  const Volume v = read_volume(file("q.nii"));
  const double b = float(0.1), c = float(-0.3), d = float(0.2), a = std::sqrt(1 - b * b - c * c - d * d);
  const double r[3][3] = {{a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)},
                          {2 * (b * c + a * d), a * a + c * c - b * b - d * d, 2 * (c * d - a * b)},
                          {2 * (b * d - a * c), 2 * (c * d + a * b), a * a + d * d - c * c - b * b}};
  EXPECT_EQ(v.frame.space, "right-anterior-superior");
  for (int ax = 0; ax < 3; ++ax) {
    EXPECT_NEAR(v.spacing[ax], n.pixdim[ax + 1], 1e-6);
    const double sign = ax == 2 ? -1.0 : 1.0;
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(v.frame.axes[ax][k], sign * r[k][ax], 1e-6) << ax << "," << k;
  }
  EXPECT_NEAR(v.origin[0], 12.5, 1e-6);
  EXPECT_NEAR(v.origin[1], -4, 1e-6);
  EXPECT_NEAR(v.origin[2], 30, 1e-6);
  EXPECT_LT(determinant(v.frame.axes), 0);
  // Written as NRRD, the transform stays in RAS, named; as MetaImage it is converted to LPS.
  write_volume(file("q.nrrd"), v);
  const Volume w = read_volume(file("q.nrrd"));
  EXPECT_EQ(w.frame.space, "right-anterior-superior");
  for (int ax = 0; ax < 3; ++ax)
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(w.frame.axes[ax][k], v.frame.axes[ax][k], 1e-15);
  EXPECT_NE(test::slurp(file("q.nrrd")).find("space: right-anterior-superior\n"), std::string::npos);
  write_volume(file("q.mha"), v);
  const Volume m = read_volume(file("q.mha"));
  const Vec3d pr = v.index_to_world({3, 2, 1}), pl = m.index_to_world({3, 2, 1});
  EXPECT_NEAR(pl[0], -pr[0], 1e-9);
  EXPECT_NEAR(pl[1], -pr[1], 1e-9);
  EXPECT_NEAR(pl[2], pr[2], 1e-9);
  // `info` names the world.
  const test::RunResult info = run({"info", file("q.nii")});
  ASSERT_EQ(info.status, 0) << info.err;
  EXPECT_NE(info.out.find("world:              right-anterior-superior"), std::string::npos) << info.out;
}

TEST_F(Nifti, SformWinsAndScalingAndUnitsApply) {
  for (int version : {1, 2}) {
    SCOPED_TRACE(version);
    NiftiSpec n = small(version);
    n.qform_code = 1;  // ignored: the sform is set
    n.sform_code = 2;
    n.srow[0][1] = -0.75, n.srow[1][0] = 0.5, n.srow[2][2] = 2, n.srow[0][3] = 0.01, n.srow[1][3] = -0.02;
    n.xyzt_units = 1;  // metres
    n.datatype = 16, n.bitpix = 32;
    n.scl_slope = 2, n.scl_inter = -1;
    std::string f;
    for (int i = 0; i < 24; ++i) {
      const float x = float(i) * 0.25f;
      f.append(reinterpret_cast<const char*>(&x), 4);
    }
    write("s.nii", fuzz::nifti_header(n) + f);
    const Volume v = read_volume(file("s.nii"));
    EXPECT_EQ(v.frame.space, "right-anterior-superior");
    EXPECT_NEAR(v.spacing[0], 500, 1e-9);  // 0.5 m
    EXPECT_NEAR(v.spacing[1], 750, 1e-9);
    EXPECT_NEAR(v.spacing[2], 2000, 1e-9);
    EXPECT_EQ(v.frame.axes[0], (Vec3d{0, 1, 0}));
    EXPECT_EQ(v.frame.axes[1], (Vec3d{-1, 0, 0}));
    EXPECT_NEAR(v.origin[0], 10, 1e-4);
    EXPECT_NEAR(v.origin[1], -20, 1e-4);
    EXPECT_EQ(v.source_type, ScalarType::Float32);
    for (int i = 0; i < 24; ++i) ASSERT_FLOAT_EQ(v.data[i], 2 * (float(i) * 0.25f) - 1);
    // Scaled integers read as float, and the header says so too.
    NiftiSpec k = small(version);
    k.scl_slope = 0.5, k.scl_inter = 10;
    write("k.nii", fuzz::nifti_header(k) + u8_samples(24));
    const Volume kv = read_volume(file("k.nii"));
    EXPECT_EQ(kv.source_type, ScalarType::Float32);
    EXPECT_EQ(read_volume_header(file("k.nii")).type, ScalarType::Float32);
    EXPECT_FLOAT_EQ(kv.data[3], 0.5f * float(3 * 7 + 1) + 10);
  }
}

TEST_F(Nifti, BigEndianGzipAndPairs) {
  NiftiSpec n = small();
  n.datatype = 512, n.bitpix = 16;  // uint16
  n.big_endian = true;
  std::string be;
  for (int i = 0; i < 24; ++i) be += char((i * 1000) >> 8), be += char((i * 1000) & 0xff);
  write("be.nii", fuzz::nifti_header(n) + be);
  const Volume v = read_volume(file("be.nii"));
  EXPECT_EQ(v.source_type, ScalarType::UInt16);
  for (int i = 0; i < 24; ++i) ASSERT_EQ(v.data[i], float(i * 1000));
  // gzip: the same samples.
  gzip_file("be.nii.gz", fuzz::nifti_header(n) + be);
  EXPECT_EQ(read_volume(file("be.nii.gz")).data, v.data);
  // .hdr + .img (plain and gzipped data).
  NiftiSpec p = small();
  p.pair = true;
  write("pair.hdr", fuzz::nifti_header(p));
  write("pair.img", u8_samples(24));
  const Volume pv = read_volume(file("pair.hdr"));
  EXPECT_EQ(pv.dims, (Dims3{4, 3, 2}));
  EXPECT_EQ(read_volume_header(file("pair.hdr")).files, (std::vector<std::string>{file("pair.hdr"), file("pair.img")}));
  fs::remove(file("pair.img"));
  gzip_file("pair.img.gz", u8_samples(24));
  EXPECT_EQ(read_volume(file("pair.hdr")).data, pv.data);
}

TEST_F(Nifti, BadInputGetsOneLineAndExit2) {
  NiftiSpec n = small();
  // Fewer samples than the dims need.
  write("short.nii", fuzz::nifti_header(n) + u8_samples(20));
  info_fails(file("short.nii"), {"short.nii", "data truncated", "expected 24 bytes"});
  // A time series.
  NiftiSpec t = small();
  t.dim[0] = 4, t.dim[4] = 3;
  write("t.nii", fuzz::nifti_header(t) + u8_samples(72));
  info_fails(file("t.nii"), {"expected a 3-D scalar volume", "4-D", "time series"});
  // RGB samples.
  NiftiSpec c = small();
  c.datatype = 128, c.bitpix = 24;
  write("rgb.nii", fuzz::nifti_header(c) + std::string(72, 'x'));
  info_fails(file("rgb.nii"), {"unsupported NIfTI datatype", "RGB"});
  // Not a NIfTI file at all, and an Analyze header without the magic.
  write("junk.nii", std::string(400, 'j'));
  info_fails(file("junk.nii"), {"not a NIfTI file"});
  std::string analyze = fuzz::nifti_header(small());
  analyze.replace(344, 4, std::string(4, '\0'));
  write("an.nii", analyze + u8_samples(24));
  info_fails(file("an.nii"), {"Analyze"});
  // A header that lies: dim[0] = 9.
  std::string bad = fuzz::nifti_header(small());
  bad[40] = 9;
  write("dim9.nii", bad + u8_samples(24));
  info_fails(file("dim9.nii"), {"dim9.nii"});
  // A gzip stream cut in the middle.
  const std::string whole = gzip_file("whole.nii.gz", fuzz::nifti_header(small()) + std::string(4000, 'a'));
  NiftiSpec big = small();
  big.dim[1] = 40, big.dim[2] = 10, big.dim[3] = 10;
  const std::string cut_src = test::slurp(gzip_file("big.nii.gz", fuzz::nifti_header(big) + u8_samples(4000)));
  write("cut.nii.gz", cut_src.substr(0, cut_src.size() / 2));
  info_fails(file("cut.nii.gz"), {"cut.nii.gz"});
  // The pair's data file missing.
  NiftiSpec p = small();
  p.pair = true;
  write("lonely.hdr", fuzz::nifti_header(p));
  info_fails(file("lonely.hdr"), {"lonely.hdr", "lonely.img"});
  // classify on a bad file writes nothing.
  const test::RunResult r = run({"classify", file("short.nii"), "--iso", "10", "-o", file("u.nrrd")});
  expect_one_line_error(r, {"data truncated"});
  EXPECT_FALSE(fs::exists(file("u.nrrd")));
}

}  // namespace
}  // namespace softshell
