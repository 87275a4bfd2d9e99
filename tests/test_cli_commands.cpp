// End-to-end checks of the working commands: devices (and what happens with
// no OpenCL at all or an unknown device), lowpass on NRRD, MetaImage and raw
// input against the CPU reference, info on every input kind, slices pixels,
// the synthetic volume's determinism, and usage errors.
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "image.hpp"
#include "io.hpp"
#include "reference.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

using test::CliTest;
using test::RunResult;
using test::slurp;
namespace fs = std::filesystem;

Volume small_volume() {
  Volume v({13, 9, 7}, {0.5, 0.8, 1.2}, ScalarType::UInt16);
  v.origin = {-3.5, 10.0, 2.25};
  std::uint32_t s = 12345;
  for (float& f : v.data) f = float((s = s * 1664525u + 1013904223u) >> 20);  // 0..4095
  return v;
}

TEST_F(CliTest, DevicesListsTheDefaultDevice) {
  const RunResult r = run({"devices"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("* 0"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("CPU"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("max alloc"), std::string::npos) << r.out;
  const RunResult j = run({"devices", "--json"});
  ASSERT_EQ(j.status, 0) << j.err;
  EXPECT_EQ(j.out.rfind("{\"default\": ", 0), 0u) << j.out;
  EXPECT_NE(j.out.find("\"compute_units\": "), std::string::npos) << j.out;
}

TEST_F(CliTest, NoOpenclPlatformIsAOneLineError) {
  // An empty vendors directory: the ICD loader finds no driver at all.
  const std::string empty = file("vendors");
  fs::create_directory(empty);
  expect_one_line_error(run({"devices"}, {"OCL_ICD_VENDORS=" + empty}),
                        {"no OpenCL platform found", "apt-get install pocl-opencl-icd"});
  // Commands that need no device still work.
  ASSERT_EQ(run({"synthetic", "--size", "8", "-q", "-o", file("s.nrrd")}, {"OCL_ICD_VENDORS=" + empty}).status, 0);
  const RunResult r = run({"lowpass", file("s.nrrd"), "-o", file("t.nrrd")}, {"OCL_ICD_VENDORS=" + empty});
  expect_one_line_error(r, {"no OpenCL platform found"});
  EXPECT_FALSE(fs::exists(file("t.nrrd")));
}

TEST_F(CliTest, UnknownDeviceIsAOneLineError) {
  ASSERT_EQ(run({"synthetic", "--size", "8", "-q", "-o", file("s.nrrd")}).status, 0);
  RunResult r = run({"lowpass", file("s.nrrd"), "-o", file("t.nrrd"), "--device", "no-such-gpu"});
  expect_one_line_error(r, {"--device 'no-such-gpu'", "found 0: "});
  r = run({"lowpass", file("s.nrrd"), "-o", file("t.nrrd")}, {"SOFTSHELL_DEVICE=no-such-gpu"});
  expect_one_line_error(r, {"SOFTSHELL_DEVICE 'no-such-gpu'", "found 0: "});
  r = run({"lowpass", file("s.nrrd"), "-o", file("t.nrrd"), "--device", "42"});
  expect_one_line_error(r, {"--device 42: no device with that index"});
  EXPECT_FALSE(fs::exists(file("t.nrrd")));
}

TEST_F(CliTest, LowpassOnNrrdMetaImageAndRawMatchesReference) {
  const Volume v = small_volume();
  write_volume(file("in.nrrd"), v);
  write_volume(file("in.mha"), v, {std::nullopt, true});
  {
    // Headerless raw: the same samples as little-endian uint16.
    std::vector<std::uint16_t> raw(v.data.begin(), v.data.end());
    std::ofstream out(file("in.raw"), std::ios::binary);
    out.write(reinterpret_cast<const char*>(raw.data()), std::streamsize(raw.size() * 2));
  }
  const double sigma = 0.9;
  const auto want = test::reference_lowpass(v, sigma, 3.0);
  struct Input {
    std::string path;
    std::vector<std::string> extra;
  };
  const std::vector<Input> inputs{{file("in.nrrd"), {}},
                                  {file("in.mha"), {}},
                                  {file("in.raw"), {"--raw", "13,9,7", "--type", "uint16", "--spacing", "0.5,0.8,1.2"}}};
  for (const Input& in : inputs) {
    SCOPED_TRACE(in.path);
    for (const char* ext : {".nrrd", ".mha", ".mhd"}) {
      const std::string out = file("out" + std::string(ext));
      std::vector<std::string> args{"lowpass", in.path, "--sigma", std::to_string(sigma), "--float", "-o", out};
      args.insert(args.end(), in.extra.begin(), in.extra.end());
      const RunResult r = run(args);
      ASSERT_EQ(r.status, 0) << r.err;
      EXPECT_NE(r.out.find("filter"), std::string::npos) << "reports timings: " << r.out;
      const Volume got = read_volume(out);
      EXPECT_EQ(got.dims, v.dims);
      EXPECT_EQ(got.source_type, ScalarType::Float32);
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(got.spacing[a], v.spacing[a], 1e-9);
      if (in.extra.empty())  // raw input carries no origin
        for (int a = 0; a < 3; ++a) EXPECT_NEAR(got.origin[a], v.origin[a], 1e-9);
      EXPECT_TRUE(test::all_near(got.data, want, v.dims, 0.05, 1e-5));
    }
  }
  // Default output type is the input's: uint16, rounded.
  ASSERT_EQ(run({"lowpass", file("in.nrrd"), "--sigma", "0.9", "-q", "-o", file("int.nrrd")}).status, 0);
  const Volume rounded = read_volume(file("int.nrrd"));
  EXPECT_EQ(rounded.source_type, ScalarType::UInt16);
  for (std::size_t i = 0; i < want.size(); ++i) ASSERT_NEAR(rounded.data[i], std::round(want[i]), 1.0) << i;
}

TEST_F(CliTest, LowpassRejectsBadSigma) {
  ASSERT_EQ(run({"synthetic", "--size", "8", "-q", "-o", file("s.nrrd")}).status, 0);
  expect_one_line_error(run({"lowpass", file("s.nrrd"), "--sigma", "-1", "-o", file("t.nrrd")}), {"--sigma"});
  expect_one_line_error(run({"lowpass", file("s.nrrd"), "--sigma", "abc", "-o", file("t.nrrd")}), {"--sigma"});
  expect_one_line_error(run({"lowpass", file("s.nrrd"), "--sigma", "1e6", "-o", file("t.nrrd")}),
                        {"--sigma 1e+06 mm is 1e+06 voxels along x (spacing 1 mm), more than the 33.3 voxels"});
  EXPECT_FALSE(fs::exists(file("t.nrrd")));
}

TEST_F(CliTest, InfoOnNrrdMetaImageAndRaw) {
  const Volume v = small_volume();
  write_volume(file("a.nrrd"), v);
  write_volume(file("a.mhd"), v);
  std::vector<std::uint16_t> raw(v.data.begin(), v.data.end());
  std::ofstream(file("a.raw"), std::ios::binary)
      .write(reinterpret_cast<const char*>(raw.data()), std::streamsize(raw.size() * 2));
  for (const auto& args : {std::vector<std::string>{"info", file("a.nrrd")}, std::vector<std::string>{"info", file("a.mhd")},
                           std::vector<std::string>{"info", file("a.raw"), "--raw", "13,9,7", "--type", "uint16"}}) {
    const RunResult r = run(args);
    SCOPED_TRACE(args[1]);
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("13 x 9 x 7"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("uint16"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("histogram"), std::string::npos) << r.out;
  }
  expect_one_line_error(run({"info", file("a.nrrd"), "--type", "uint8"}), {"need --raw"});
  expect_one_line_error(run({"info", file("a.raw"), "--raw", "13,9,7"}), {"--raw needs --type"});
  expect_one_line_error(run({"info", file("a.raw"), "--raw", "13,9,7", "--type", "complex"}), {"--type", "complex"});
}

TEST_F(CliTest, SlicesAreLabelledWithTheirViewsAndAScaleBar) {
  // Without --plain: each row under its label, each panel under its title, a scale bar of a
  // round length in the axial panel. The panels' own pixels are the plain montage's, except
  // where the bar and its text are drawn.
  Volume v({64, 48, 40}, {0.5, 0.5, 0.5}, ScalarType::UInt8);
  for (std::size_t i = 0; i < v.voxels(); ++i) v.data[i] = float(60 + (i % 64) * 2);
  write_volume(file("a.nrrd"), v);
  RunResult r = run({"slices", file("a.nrrd"), file("a.nrrd"), "--labels", "input,again", "-o", file("l.png")});
  ASSERT_EQ(r.status, 0) << r.err;
  ASSERT_EQ(run({"slices", file("a.nrrd"), "--plain", "-o", file("p.png")}).status, 0);
  const Image l = read_png(file("l.png")), p = read_png(file("p.png"));
  EXPECT_GT(l.width, p.width);
  EXPECT_GT(l.height, 2 * p.height);
  // Find the axial panel: the first 64x48 block equal to the plain montage's first panel
  // (ignoring the bar's corner).
  int px0 = -1, py0 = -1;
  for (int y = 0; y + 48 <= l.height && px0 < 0; ++y)
    for (int x = 0; x + 64 <= l.width && px0 < 0; ++x) {
      bool same = true;
      for (int yy = 0; yy < 20 && same; ++yy)
        for (int xx = 0; xx < 64 && same; ++xx) same = l.pixel(x + xx, y + yy)[0] == p.pixel(xx, yy)[0];
      if (same) px0 = x, py0 = y;
    }
  ASSERT_GE(px0, 0) << "the axial panel's pixels are in the labelled montage";
  // Above it: the title's and the label's text pixels (not the dark ground), left of it the ground.
  int text_pixels = 0, bar_pixels = 0;
  for (int y = 0; y < py0; ++y)
    for (int x = 0; x < l.width; ++x) text_pixels += l.pixel(x, y)[0] > 120;
  EXPECT_GT(text_pixels, 60) << "labels and titles above the first row";
  for (int y = py0 + 30; y < py0 + 48; ++y)
    for (int x = px0; x < px0 + 64; ++x) {
      const std::uint8_t* q = l.pixel(x, y);
      bar_pixels += q[0] == 255 && q[1] == 214 && q[2] == 90;
    }
  // 32 mm wide panel: a bar of 5 mm = 10 pixels, 2 rows, plus its "5 mm" text.
  EXPECT_GE(bar_pixels, 20) << "the scale bar";
  expect_one_line_error(run({"slices", file("a.nrrd"), "--labels", "a,b", "-o", file("x.png")}),
                        {"--labels: 2 labels for 1 inputs"});
  EXPECT_FALSE(fs::exists(file("x.png")));
}

TEST_F(CliTest, SlicesShowTheVolume) {
  // Left half (x < 8) dark, right half bright: every panel must show it.
  Volume v({16, 12, 10}, {1, 1, 1}, ScalarType::UInt8);
  for (std::size_t z = 0; z < 10; ++z)
    for (std::size_t y = 0; y < 12; ++y)
      for (std::size_t x = 0; x < 16; ++x) v.at(x, y, z) = x < 8 ? 0.0f : 255.0f;
  write_volume(file("half.nrrd"), v);
  const RunResult r = run({"slices", file("half.nrrd"), "--plain", "-o", file("half.png")});
  ASSERT_EQ(r.status, 0) << r.err;
  const Image img = read_png(file("half.png"));
  // Axial panel 16x12 at x 0, coronal 16x10 at x 20, sagittal 12x10 at x 40 (4-pixel gaps).
  ASSERT_EQ(img.width, 16 + 4 + 16 + 4 + 12);
  ASSERT_EQ(img.height, 12);
  EXPECT_EQ(img.pixel(2, 5)[0], 0);     // axial, left half
  EXPECT_EQ(img.pixel(13, 5)[0], 255);  // axial, right half
  EXPECT_EQ(img.pixel(22, 5)[1], 0);    // coronal, left
  EXPECT_EQ(img.pixel(33, 5)[1], 255);  // coronal, right
  EXPECT_EQ(img.pixel(45, 5)[2], 255);  // sagittal cuts at x = 8: bright
  EXPECT_EQ(img.pixel(18, 5)[0], 32);   // the gap
  const RunResult bad = run({"slices", file("missing.nrrd"), "-o", file("x.png")});
  expect_one_line_error(bad, {"missing.nrrd"});
  EXPECT_FALSE(fs::exists(file("x.png")));
}

TEST_F(CliTest, SyntheticIsDeterministicPerSeed) {
  ASSERT_EQ(run({"synthetic", "--size", "24", "--seed", "3", "-q", "-o", file("a.nrrd")}).status, 0);
  ASSERT_EQ(run({"synthetic", "--size", "24", "--seed", "3", "-q", "-o", file("b.nrrd")}).status, 0);
  ASSERT_EQ(run({"synthetic", "--size", "24", "--seed", "4", "-q", "-o", file("c.nrrd")}).status, 0);
  EXPECT_EQ(slurp(file("a.nrrd")), slurp(file("b.nrrd")));
  EXPECT_NE(slurp(file("a.nrrd")), slurp(file("c.nrrd")));
  const Volume v = read_volume(file("a.nrrd"));
  EXPECT_EQ(v.dims, (Dims3{24, 24, 24}));
  // Brighter inside the sphere than in the fluid around it.
  EXPECT_GT(v.at(12, 12, 12) + v.at(11, 12, 12) + v.at(12, 11, 12), v.at(1, 1, 1) + v.at(2, 1, 1) + v.at(1, 2, 1));
}

TEST_F(CliTest, UsageErrorsAndHelp) {
  expect_one_line_error(run({}), {"subcommand is required"});
  expect_one_line_error(run({"frobnicate"}), {"frobnicate"});
  expect_one_line_error(run({"info"}), {"FILE is required"});
  expect_one_line_error(run({"synthetic", "--size", "3", "-o", file("x.nrrd")}), {"--size"});
  for (const char* cmd : {"devices", "info", "lowpass", "slices", "synthetic"}) {
    const RunResult h = run({cmd, "--help"});
    EXPECT_EQ(h.status, 0) << cmd;
    EXPECT_NE(h.out.find("Usage: softshell " + std::string(cmd)), std::string::npos) << h.out;
  }
  EXPECT_EQ(run({"--help"}).status, 0);
  EXPECT_EQ(listing(), std::vector<std::string>{});
}

}  // namespace
}  // namespace softshell
