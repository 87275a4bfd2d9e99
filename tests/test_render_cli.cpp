// `softshell render` and `softshell view` end to end (the real binary, under
// xvfb-run like the other GL tests): outputs, turntable frames, the viewer's
// scripted path, and the error contract for bad input (not a volume,
// all-zero opacity, no display, bad options): exit 2 and one line.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <random>

#include "cli_fixture.hpp"
#include "image.hpp"
#include "io.hpp"
#include "opacity_input.hpp"
#include "test_support.hpp"

namespace softshell::test {
namespace {

// Share of pixels that differ from the corner (background) pixel.
double covered(const Image& img) {
  std::size_t n = 0;
  const std::uint8_t* bg = img.pixel(0, 0);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::uint8_t* p = img.pixel(x, y);
      n += p[0] != bg[0] || p[1] != bg[1] || p[2] != bg[2];
    }
  return double(n) / (double(img.width) * img.height);
}

class RenderCli : public CliTest {};

TEST_F(RenderCli, RendersAnOpacityVolumeToPng) {
  const std::string in = file("u.nrrd");
  write_volume(in, shell_volume(32));
  for (const std::string method : {"splat", "isosplat"}) {
    const std::string out = file(method + ".png");
    const RunResult r = run({"render", in, "--method", method, "-o", out, "--size", "160x120", "--view", "30,20"});
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("splats"), std::string::npos) << r.out;
    const Image img = read_png(out);
    EXPECT_EQ(img.width, 160);
    EXPECT_EQ(img.height, 120);
    // The shell's bounding sphere fills the view; the sphere (0.6 of the
    // volume's width) covers a good part of it.
    EXPECT_GT(covered(img), 0.15) << method;
    EXPECT_LT(covered(img), 0.6) << method;
  }
}

TEST_F(RenderCli, OrientationByTheDataTurnsTheSplatsWithTheBmode) {
  // --orientation data: the splats lie perpendicular to the B-mode volume's
  // own orientation, not u's. A B-mode of parallel planes across x turns
  // every splat of a spherical shell edge-on to a camera looking down z
  // (hardly a pixel drawn) and face-on to one looking down x; a B-mode with
  // the sphere's own boundary draws what the tensor of u draws.
  const int n = 32;
  const std::string in = file("u.nrrd");
  const Volume u = shell_volume(n);
  write_volume(in, u);
  Volume planes = u, sphere = u;
  for (std::size_t z = 0; z < u.dims[2]; ++z)
    for (std::size_t y = 0; y < u.dims[1]; ++y)
      for (std::size_t x = 0; x < u.dims[0]; ++x) {
        planes.at(x, y, z) = float(6 * x);
        const double r = std::sqrt(std::pow(x - 0.5 * (n - 1), 2) + std::pow(y - 0.5 * (n - 1), 2) +
                                   std::pow(z - 0.5 * (n - 1), 2));
        sphere.at(x, y, z) = float(200.0 / (1.0 + std::exp((r - 0.3 * n) / 1.5)));
      }
  write_volume(file("planes.nrrd"), planes);
  write_volume(file("sphere.nrrd"), sphere);
  // The picture's coverage and its light (the mean grey level over all pixels).
  struct Drawn {
    double cover, light;
  };
  const auto draw = [&](const std::string& name, const std::string& view, const std::vector<std::string>& extra) {
    std::vector<std::string> args{"render", in, "-o", file(name), "--size", "96x96", "--view", view, "-q"};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult r = run(args);
    EXPECT_EQ(r.status, 0) << r.err;
    const Image img = read_png(file(name));
    double light = 0;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        const std::uint8_t* p = img.pixel(x, y);
        light += (double(p[0]) + p[1] + p[2]) / 3.0;
      }
    return Drawn{covered(img), light / (double(img.width) * img.height)};
  };
  const Drawn by_u = draw("u.png", "0,0", {});
  const Drawn edge_on = draw("edge.png", "0,0", {"--orientation", "data", "--volume", file("planes.nrrd")});
  const Drawn face_on = draw("face.png", "90,0", {"--orientation", "data", "--volume", file("planes.nrrd")});
  const Drawn round = draw("round.png", "0,0", {"--orientation", "data", "--volume", file("sphere.nrrd")});
  EXPECT_GT(by_u.cover, 0.15);
  // Edge-on: slits through which little light comes (measured: a quarter of u's picture's).
  EXPECT_LT(edge_on.light, 0.4 * by_u.light) << by_u.light;
  // Face-on: a flat disc as wide as the sphere, all of it lit alike.
  EXPECT_GT(face_on.cover, 0.8 * by_u.cover) << by_u.cover;
  EXPECT_GT(face_on.light, 0.9 * by_u.light) << by_u.light;
  EXPECT_NEAR(round.cover, by_u.cover, 0.1 * by_u.cover);
  EXPECT_NEAR(round.light, by_u.light, 0.1 * by_u.light);
  // The face preset orients by the data when there is a B-mode volume, by
  // u's tensor (with a line saying so) when there is none; an explicit
  // --orientation wins.
  const RunResult pf = run({"render", in, "-o", file("pf.png"), "--size", "64x64", "--preset", "face", "--volume",
                            file("planes.nrrd")});
  ASSERT_EQ(pf.status, 0) << pf.err;
  EXPECT_NE(pf.out.find("normals data"), std::string::npos) << pf.out;
  const RunResult pn = run({"render", in, "-o", file("pn.png"), "--size", "64x64", "--preset", "face"});
  ASSERT_EQ(pn.status, 0) << pn.err;
  EXPECT_NE(pn.out.find("normals tensor"), std::string::npos) << pn.out;
  EXPECT_NE(pn.out.find("no B-mode volume"), std::string::npos) << pn.out;
  const RunResult pt = run({"render", in, "-o", file("pt.png"), "--size", "64x64", "--preset", "face", "--volume",
                            file("planes.nrrd"), "--orientation", "tensor"});
  ASSERT_EQ(pt.status, 0) << pt.err;
  EXPECT_NE(pt.out.find("normals tensor"), std::string::npos) << pt.out;
  // The viewer takes the same: edge-on from its default camera.
  const RunResult v = run({"view", in, "--volume", file("planes.nrrd"), "--orientation", "data", "--frames", "2",
                           "--screenshot", file("view.png"), "--size", "160x120", "-q"});
  ASSERT_EQ(v.status, 0) << v.err;
  EXPECT_TRUE(fs::exists(file("view.png")));
  // Without the B-mode volume, or with one of other dims: one line, exit 2, no picture.
  expect_one_line_error(run({"render", in, "-o", file("x.png"), "--orientation", "data"}), {"--volume", "u.nrrd"});
  write_volume(file("small.nrrd"), shell_volume(16));
  expect_one_line_error(run({"render", in, "-o", file("x.png"), "--orientation", "data", "--volume", file("small.nrrd")}),
                        {"small.nrrd", "dims"});
  expect_one_line_error(run({"view", in, "--orientation", "data"}), {"--volume", "u.nrrd"});
  EXPECT_FALSE(fs::exists(file("x.png")));
}

TEST_F(RenderCli, TurntableWritesFrames) {
  const std::string in = file("u.nrrd");
  write_volume(in, shell_volume(24));
  const RunResult r = run({"render", in, "-o", file("turn.png"), "--size", "64x64", "--turntable", "3", "--order", "sort",
                           "--normals", "one", "-q"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_TRUE(r.out.empty()) << r.out;
  for (const char* f : {"turn-000.png", "turn-001.png", "turn-002.png"}) EXPECT_TRUE(fs::exists(file(f))) << f;
  EXPECT_FALSE(fs::exists(file("turn.png")));
}

TEST_F(RenderCli, ViewerDrawsScriptedFramesAndSavesAScreenshot) {
  const std::string in = file("u.nrrd");
  write_volume(in, shell_volume(24));
  const std::string shot = file("shot.png");
  const RunResult r = run({"view", in, "--frames", "3", "--screenshot", shot, "--size", "320x240", "-q"});
  ASSERT_EQ(r.status, 0) << r.err;
  const Image img = read_png(shot);
  EXPECT_EQ(img.width, 320);
  EXPECT_EQ(img.height, 240);
  EXPECT_GT(covered(img), 0.05);
}

// Bounding box {x0, y0, x1, y1} of the pixels that differ from the corner pixel.
std::array<int, 4> covered_box(const Image& img) {
  std::array<int, 4> b{img.width, img.height, -1, -1};
  const std::uint8_t* bg = img.pixel(0, 0);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::uint8_t* p = img.pixel(x, y);
      if (p[0] == bg[0] && p[1] == bg[1] && p[2] == bg[2]) continue;
      b = {std::min(b[0], x), std::min(b[1], y), std::max(b[2], x), std::max(b[3], y)};
    }
  return b;
}

TEST_F(RenderCli, ViewerAndRenderPlayAnOpacitySequence) {
  // Three frames of a shell moving 4 voxels along x per frame, as classify
  // writes a sequence (a 4-D NRRD). The camera is fitted on the start frame;
  // playing (one sequence frame per drawn frame) to frame 2 moves the drawn
  // shell right on the screen by about 8 voxels' worth.
  const Volume shell = shell_volume(32);
  std::vector<Volume> frames;
  for (int k = 0; k < 3; ++k) {
    Volume f = shell;
    for (std::size_t z = 0; z < f.dims[2]; ++z)
      for (std::size_t y = 0; y < f.dims[1]; ++y)
        for (std::size_t x = 0; x < f.dims[0]; ++x)
          f.at(x, y, z) = x >= std::size_t(4 * k) ? shell.at(x - std::size_t(4 * k), y, z) : 0.0f;
    frames.push_back(std::move(f));
  }
  const std::string seq = file("useq.nrrd");
  write_frames(seq, frames);
  const auto shot = [&](const std::vector<std::string>& extra, const std::string& name) {
    std::vector<std::string> args{"view", seq, "--size", "320x240", "-q", "--screenshot", file(name)};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult r = run(args);
    EXPECT_EQ(r.status, 0) << r.err;
    return read_png(file(name));
  };
  const Image f0 = shot({"--frames", "1"}, "f0.png");
  const Image f2 = shot({"--frames", "2", "--play", "30"}, "f2.png");
  const auto b0 = covered_box(f0), b2 = covered_box(f2);
  ASSERT_GE(b0[2], 0);
  ASSERT_GE(b2[2], 0);
  EXPECT_GT(b2[0] - b0[0], 10) << "left edge " << b0[0] << " -> " << b2[0];
  EXPECT_GT(b2[2] - b0[2], 10) << "right edge " << b0[2] << " -> " << b2[2];
  // Starting on frame 2 (camera fitted there) draws what frame 2 is.
  EXPECT_GT(covered(shot({"--frames", "1", "--frame", "2"}, "s2.png")), 0.02);
  expect_one_line_error(run({"view", seq, "--frame", "3", "--frames", "1", "--screenshot", file("x.png")}),
                        {"--frame 3: the file holds 3 frames (0 to 2)"});
  // render draws every frame (OUT-000.png ...), the camera fitted on frame 0:
  // the shell moves right; --frame K draws one; the other renderers refuse.
  RunResult rr = run({"render", seq, "-o", file("r.png"), "--size", "320x240", "-q"});
  ASSERT_EQ(rr.status, 0) << rr.err;
  const auto r0 = covered_box(read_png(file("r-000.png"))), r2 = covered_box(read_png(file("r-002.png")));
  EXPECT_GT(r2[0] - r0[0], 10) << "left edge " << r0[0] << " -> " << r2[0];
  EXPECT_TRUE(fs::exists(file("r-001.png")));
  EXPECT_FALSE(fs::exists(file("r-003.png")));
  rr = run({"render", seq, "--frame", "1", "-o", file("one.png"), "--size", "160x120", "-q"});
  EXPECT_EQ(rr.status, 0) << rr.err;
  EXPECT_TRUE(fs::exists(file("one.png")));
  expect_one_line_error(run({"render", seq, "--method", "mc", "-o", file("mc.png")}),
                        {"--method mc draws a 3-D volume", "is a sequence of 3 frames"});
  expect_one_line_error(run({"render", seq, "--turntable", "4", "-o", file("t.png")}),
                        {"--turntable on a sequence of 3 frames: choose one with --frame K"});
  EXPECT_FALSE(fs::exists(file("mc.png")));
  EXPECT_FALSE(fs::exists(file("t-000.png")));
  // A sequence of raw frames: one frame, or classify first.
  ASSERT_EQ(run({"phantom", "--size", "24", "--frames", "2", "-o", file("p"), "-q"}).status, 0);
  expect_one_line_error(run({"view", file("p/volume.nrrd"), "--frames", "1", "--screenshot", file("x.png")}),
                        {"a sequence of 2 raw 3-D frames: classify it first"});
  const RunResult one = run({"view", file("p/volume.nrrd"), "--frame", "1", "--frames", "1", "--size", "160x120",
                             "--screenshot", file("r1.png"), "-q"});
  EXPECT_EQ(one.status, 0) << one.err;
}

TEST_F(RenderCli, ViewerStartsInEachRendererAndTheyLineUp) {
  const std::string in = file("u.nrrd");
  write_volume(in, shell_volume(24));
  auto shot = [&](const std::string& renderer) {
    const std::string out = file("view-" + renderer + ".png");
    const RunResult r = run({"view", in, "--frames", "3", "--screenshot", out, "--size", "320x240", "--view", "30,20",
                             "--renderer", renderer, "-q"});
    EXPECT_EQ(r.status, 0) << renderer << ": " << r.err;
    return read_png(out);
  };
  const Image splat = shot("splat");
  const std::array<int, 4> ref = covered_box(splat);
  ASSERT_GT(covered(splat), 0.05);
  for (const std::string renderer : {"isosplat", "mc", "raycast"}) {
    const Image img = shot(renderer);
    ASSERT_EQ(img.width, 320) << renderer;
    ASSERT_EQ(img.height, 240) << renderer;
    EXPECT_GT(covered(img), 0.05) << renderer;
    // The same camera frames the same object: the boxes agree within 10 % of the image.
    const std::array<int, 4> box = covered_box(img);
    for (int i = 0; i < 4; ++i)
      EXPECT_LE(std::abs(box[i] - ref[i]), (i % 2 ? img.height : img.width) / 10)
          << renderer << " box side " << i << ": " << box[i] << " vs splats " << ref[i];
  }
}

// The output path is a pattern expanded by softshell, never a printf
// format (`-o 'f%s%s%s%s.png'` used to crash), and no frame may replace the
// input (a NRRD named r-000.png used to be overwritten by frame 0).
TEST_F(RenderCli, TurntablePatternsAreSafe) {
  const std::string in = file("u.nrrd");
  write_volume(in, shell_volume(16));
  for (const char* bad : {"f%s%s%s%s.png", "f%n.png", "f%d%d.png", "f%x.png", "f%.png", "f%-3d.png", "f%999d.png"}) {
    SCOPED_TRACE(bad);
    expect_one_line_error(run({"render", in, "--turntable", "2", "--size", "32x32", "-o", file(bad)}),
                          {"a turntable pattern takes exactly one %d"});
  }
  const RunResult r = run({"render", in, "--turntable", "2", "--size", "32x32", "-q", "-o", file("f%%-%03d.png")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_TRUE(fs::exists(file("f%-000.png")));
  EXPECT_TRUE(fs::exists(file("f%-001.png")));
  // A volume named like frame 0 (NRRD by content).
  write_volume(file("r.nrrd"), shell_volume(16));
  fs::rename(file("r.nrrd"), file("r-000.png"));
  const std::string before = slurp(file("r-000.png"));
  expect_one_line_error(run({"render", file("r-000.png"), "--turntable", "2", "--size", "32x32", "-o", file("r.png")}),
                        {file("r-000.png") + ": output would overwrite the input file"});
  EXPECT_EQ(slurp(file("r-000.png")), before);
  EXPECT_FALSE(fs::exists(file("r-001.png")));
}

TEST_F(RenderCli, BadInputIsOneLineExit2) {
  const std::string junk = write("junk.nrrd", "this is not a volume\n");
  expect_one_line_error(run({"render", junk, "-o", file("a.png")}), {"junk.nrrd"});

  const std::string zero = file("zero.nrrd");
  write_volume(zero, Volume({12, 10, 8}));
  expect_one_line_error(run({"render", zero, "-o", file("a.png")}), {"zero.nrrd", "no voxel has opacity above"});

  const std::string in = file("u.nrrd");
  write_volume(in, shell_volume(16));
  expect_one_line_error(run({"render", in, "-o", file("a.png")}, {"DISPLAY=", "WAYLAND_DISPLAY="}),
                        {"no display", "xvfb-run"});
  expect_one_line_error(run({"view", in}, {"DISPLAY=", "WAYLAND_DISPLAY="}), {"no display"});
  expect_one_line_error(run({"render", in, "-o", file("a.png"), "--size", "0x10"}), {"--size"});
  expect_one_line_error(run({"render", in, "-o", file("a.png"), "--view", "10"}), {"--view"});
  expect_one_line_error(run({"render", in, "-o", file("a.png"), "--method", "bogus"}), {"--method"});
  expect_one_line_error(run({"render", in, "-o", file("a.png"), "--orientation", "bogus"}), {"--orientation"});
  expect_one_line_error(run({"render", in, "-o", file("a.png"), "--tensor-sigma", "0"}), {"--tensor-sigma"});
  expect_one_line_error(run({"render", in, "-o", file("a.png"), "--threshold", "1.5"}), {"--threshold"});
  expect_one_line_error(run({"render", in, "-o", file("a.png"), "--crop", "0,1,0.5,0.2,0,1"}), {"--crop"});
  expect_one_line_error(run({"render", in, "-o", file("a.jpg")}), {"png"});
  expect_one_line_error(run({"view", in, "--screenshot", file("s.png")}), {"--frames"});
  expect_one_line_error(run({"view", in, "--frames", "1", "--screenshot", file("s.png"), "--renderer", "bogus"}),
                        {"--renderer", "bogus"});
  // Nothing was written by any failing run.
  for (const auto& name : listing()) EXPECT_EQ(name.find(".png"), std::string::npos) << name;
}

TEST_F(RenderCli, RawVolumeIsClassifiedFirst) {
  // The speckled sphere of `softshell synthetic`, uint8: not an opacity volume.
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", in, "-q"}).status, 0);
  const RunResult r = run({"render", in, "-o", file("raw.png"), "--size", "96x96"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("classified"), std::string::npos) << r.out;
  EXPECT_GT(covered(read_png(file("raw.png"))), 0.05);
  // A raw volume brings its own B-mode for --orientation data.
  const RunResult d = run({"render", in, "-o", file("raw-data.png"), "--size", "96x96", "--orientation", "data"});
  ASSERT_EQ(d.status, 0) << d.err;
  EXPECT_NE(d.out.find("normals data"), std::string::npos) << d.out;
  EXPECT_GT(covered(read_png(file("raw-data.png"))), 0.05);
}

TEST_F(RenderCli, IsoOutsideTheDataWarnsInRenderAndView) {
  // As classify warns (CliArgs.IsoOutsideTheDataWarnsOnce): an explicit
  // --iso outside the samples' range draws nothing useful, so say so, for
  // every renderer that classifies a raw volume, and for the viewer.
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "24", "-o", in, "-q"}).status, 0);  // uint8
  for (const char* method : {"splat", "raycast"}) {
    SCOPED_TRACE(method);
    const RunResult r = run({"render", in, "--method", method, "--iso", "300", "-q", "-o", file("w.png"), "--size", "64x64"});
    // The warning comes first; with nothing above the level the renderer
    // then refuses an empty picture (exit 2), which the warning explains.
    EXPECT_TRUE(r.status == 0 || r.status == 2) << r.err;
    EXPECT_EQ(r.err.rfind("softshell: warning: --iso 300 is outside the data's value range [0, 255] (uint8 samples); "
                          "no boundary lies at that value\n", 0), 0u) << r.err;
    const RunResult ok = run({"render", in, "--method", method, "--iso", "100", "-q", "-o", file("w.png"), "--size", "64x64"});
    EXPECT_EQ(ok.status, 0) << ok.err;
    EXPECT_EQ(ok.err, "");
  }
  const RunResult v = run({"view", in, "--iso", "-5", "--frames", "1", "--screenshot", file("v.png"), "--size", "64x64"});
  EXPECT_EQ(v.status, 0) << v.err;
  EXPECT_NE(v.err.find("softshell: warning: --iso -5 is outside the data's value range [0, 255]"), std::string::npos) << v.err;
}

TEST_F(RenderCli, TheViewersClassificationTakesTheGivenBeamAxis) {
  // render's and view's --beam-axis reach the classification of a raw
  // volume (viewer::load_opacity): the near field, mask and walls follow it.
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", in, "-q"}).status, 0);
  for (int axis : {0, 1, 2}) {
    const viewer::OpacityInput input =
        viewer::load_opacity(runtime(), in, viewer::InputKind::Auto, "auto", nullptr, std::nullopt, BoneCueMode::Off, axis);
    ASSERT_TRUE(input.classified);
    EXPECT_EQ(input.beam_axis, axis);
  }
  const test::RunResult r = run({"render", in, "--beam-axis", "y", "-o", file("y.png"), "-q"});
  EXPECT_EQ(r.status, 0) << r.err;
  const test::RunResult bad = run({"render", in, "--beam-axis", "up", "-o", file("u.png"), "-q"});
  EXPECT_EQ(bad.status, 2);
  EXPECT_NE(bad.err.find("--beam-axis"), std::string::npos) << bad.err;
  EXPECT_FALSE(fs::exists(file("u.png")));
}

TEST_F(RenderCli, TheViewersIsovalueIsRaisedAboveTheBulkAsClassifysIs) {
  // viewer::load_opacity takes classify's automatic isovalue, raised above
  // the bulk where classify raises it (host/auto_iso.hpp), with the shadow
  // walls at the edges' isovalue: the same opacity.
  ASSERT_EQ(run({"phantom", "--shape", "spine", "--physics", "random", "--seed", "119", "--size", "64", "-o",
                 file("spine"), "-q"})
                .status,
            0);
  const test::RunResult c = run({"classify", file("spine/volume.nrrd"), "--iso", "auto", "-o", file("u.nrrd")});
  ASSERT_EQ(c.status, 0) << c.err;
  ASSERT_NE(c.out.find("above the bulk"), std::string::npos) << c.out;
  const viewer::OpacityInput v =
      viewer::load_opacity(runtime(), file("spine/volume.nrrd"), viewer::InputKind::Auto, "auto");
  ASSERT_TRUE(v.classified);
  const std::size_t at = c.out.find(" iso ");
  ASSERT_NE(at, std::string::npos);
  EXPECT_NEAR(v.iso, std::stod(c.out.substr(at + 5)), 1e-3) << c.out;
  const Volume u = read_volume(file("u.nrrd"));
  ASSERT_EQ(u.data.size(), v.u.data.size());
  double worst = 0;
  for (std::size_t i = 0; i < u.data.size(); ++i) worst = std::max(worst, double(std::fabs(u.data[i] - v.u.data[i])));
  EXPECT_LT(worst, 2e-3) << "classify writes u as stored; the viewer keeps floats";
}

TEST_F(RenderCli, TheViewersClassificationTakesClassifysGradientLowpass) {
  // viewer::load_opacity (render and view of a raw volume) takes --grad-sigma's
  // default as classify does (host/speckle.hpp) and says so: uncorrelated
  // speckle over a boundary 20 mm across, bright above dark (an echo over
  // darker data: the lower bound, 1.25 mm) or dark above bright (a step:
  // 1.5 mm); the paper's functional takes none.
  const auto write = [&](const std::string& name, bool bright_above) {
    Volume v({40, 40, 40}, {0.5, 0.5, 0.5}, ScalarType::UInt8);
    std::mt19937_64 rng(seed());
    std::normal_distribution<double> noise(0.0, 12.0);
    for (std::size_t z = 0; z < 40; ++z)
      for (std::size_t y = 0; y < 40; ++y)
        for (std::size_t x = 0; x < 40; ++x)
          v.at(x, y, z) = float(std::clamp(std::round(((z < 20) == bright_above ? 170.0 : 60.0) + noise(rng)), 1.0, 255.0));
    write_volume(file(name), v);
    return file(name);
  };
  const std::string echo = write("echo.nrrd", true), step = write("step.nrrd", false);
  const viewer::OpacityInput e = viewer::load_opacity(runtime(), echo, viewer::InputKind::Auto, "auto");
  ASSERT_TRUE(e.classified);
  EXPECT_DOUBLE_EQ(e.params.grad_sigma_mm, 1.25);
  EXPECT_NE(e.note.find(", gradient lowpass 1.25 mm (from the speckle)"), std::string::npos) << e.note;
  const test::RunResult c = run({"classify", echo, "--iso", "auto", "-o", file("u.nrrd")});
  ASSERT_EQ(c.status, 0) << c.err;
  EXPECT_NE(c.out.find("grad-sigma 1.250 mm (auto:"), std::string::npos) << c.out;
  const viewer::OpacityInput st = viewer::load_opacity(runtime(), step, viewer::InputKind::Auto, "auto");
  EXPECT_DOUBLE_EQ(st.params.grad_sigma_mm, 1.5);
  EXPECT_NE(st.note.find(", gradient lowpass 1.50 mm (the strong edges are no echoes)"), std::string::npos) << st.note;
  const VariationalParams literal = VariationalParams::literal_defaults();
  const viewer::OpacityInput l = viewer::load_opacity(runtime(), echo, viewer::InputKind::Auto, "auto", &literal);
  EXPECT_EQ(l.params.grad_sigma_mm, 0.0);
  EXPECT_EQ(l.note.find("gradient lowpass"), std::string::npos) << l.note;
}

TEST_F(RenderCli, ViewerReSolveUpdatesTheClassifierInPlaceForAnIsoChange) {
  // The viewer's "re-solve" (viewer::reclassify): a new v_iso re-uses the
  // classifier (same object, no new setup) and starts from its last linear
  // solution: no more iterations than a cold classification and as close
  // to the converged reference (sharpening from converged solves); a new
  // beta builds a new classifier.
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", in, "-q"}).status, 0);
  viewer::OpacityInput input = viewer::load_opacity(runtime(), in, viewer::InputKind::Auto, "auto");
  ASSERT_TRUE(input.classified);
  ASSERT_TRUE(input.classifier);
  // Held weakly: a rebuild frees the first classifier (the weak pointer
  // expires), even where the new one lands at the freed one's address.
  const std::weak_ptr<VariationalClassifier> first = input.classifier;
  VariationalParams p = input.params;
  p.v_iso *= 1.05;
  SolveReport warm, cold, ref;
  const Volume uw = viewer::reclassify(runtime(), input, p, nullptr, &warm);
  ASSERT_FALSE(first.expired()) << "the iso re-solve built a new classifier";
  EXPECT_EQ(input.classifier, first.lock());
  const std::vector<std::uint8_t>* mask = input.mask.empty() ? nullptr : &input.mask;
  const Volume uc = classify_variational(runtime(), input.data, p, SolverParams{}, &cold, nullptr, mask);
  SolverParams converged;
  converged.sharpen_tol = 0;
  const Volume ur = classify_variational(runtime(), input.data, p, converged, &ref, nullptr, mask);
  ASSERT_TRUE(warm.converged && cold.converged && ref.converged);
  EXPECT_LE(warm.cycles, cold.cycles);
  EXPECT_LE(test::mean_deviation(uw.data, ur.data, 5e-3).mean, 2 * test::mean_deviation(uc.data, ur.data, 5e-3).mean + 1e-6);
  p.beta *= 2;
  viewer::reclassify(runtime(), input, p, nullptr, &warm);
  EXPECT_TRUE(warm.converged);
  EXPECT_NE(input.classifier.get(), nullptr);
  EXPECT_TRUE(input.classifier->params().beta == p.beta);
  EXPECT_TRUE(first.expired()) << "a new beta needs a new classifier";
}


TEST_F(RenderCli, ViewerHoldsTheBandsUndersideSheetAndItsReSolvesKeepIt) {
  // As classify does (host/mask.hpp, hold_band_sheet): a bright band (230,
  // 3 mm) over a dimmer plateau (125, 3 mm) over dark tissue (40), the
  // isovalue 80: the plateau's lower edge would be a sheet under the removed
  // band. The viewer's input holds the 3 mm under the band at u = 0, says
  // so, and a re-solve at another isovalue keeps it held.
  const Volume v = test::speckled(
      {32, 32, 48}, 0.5, [](double, double, double z) { return z < 3.0 ? 230.0 : z < 6.0 ? 125.0 : 40.0; },
      test::seed() + 3);
  write_volume(file("tail.nrrd"), v);
  viewer::OpacityInput input = viewer::load_opacity(runtime(), file("tail.nrrd"), viewer::InputKind::Auto, "80");
  ASSERT_TRUE(input.classified);
  EXPECT_NE(input.note.find("the band's underside held"), std::string::npos) << input.note;
  ASSERT_FALSE(input.mask.empty());
  EXPECT_EQ(input.mask[16 + 32 * (16 + 32 * 10)], 0) << "the window under the band is held";
  const auto sheet_lines = [](const Volume& u) {
    std::size_t n = 0;
    for (std::size_t y = 4; y < 28; ++y)
      for (std::size_t x = 4; x < 28; ++x) {
        float m = 0;
        for (std::size_t z = 6; z < 18; ++z) m = std::max(m, u.at(x, y, z));
        n += m > 0.2f;
      }
    return n;
  };
  EXPECT_EQ(sheet_lines(input.u), 0u);
  VariationalParams p = input.params;
  p.v_iso *= 0.95;
  SolveReport r;
  const Volume u2 = viewer::reclassify(runtime(), input, p, nullptr, &r);
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(sheet_lines(u2), 0u);
  // Without the hold the same data draws the sheet (the test can fail).
  const Volume k = classify_variational(runtime(), input.data, input.params, SolverParams{}, nullptr, nullptr, nullptr);
  EXPECT_GT(sheet_lines(k), 24u * 24u / 2);
}

}  // namespace
}  // namespace softshell::test
