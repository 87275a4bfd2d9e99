// The ray caster next to the GL splat renderer, and the figure commands end to
// end (under xvfb-run like the other GL tests):
//  - RayCamera::orbit is viewer::OrbitCamera (same eye and axes), and a ray
//    cast and a splat render of the same shell line up (silhouette centre and
//    radius);
//  - `render --method raycast` (opacity and --unclassified), `figure5`,
//    `figure6`: PNG sizes and contents;
//  - bad input: exit 2, one line, nothing written.
#include <cmath>

#include "cli_fixture.hpp"
#include "headless.hpp"
#include "image.hpp"
#include "io.hpp"
#include "raycast.hpp"
#include "splats.hpp"
#include "test_support.hpp"

namespace softshell::test {
namespace {

// The renderer tests' shell, moved off the origin (the figures honour it).
Volume shell(int n) {
  Volume u = shell_volume(n);
  u.origin = {5.0, -3.0, 1.0};
  return u;
}

struct Silhouette {
  double cx = 0, cy = 0, radius = 0;
};

template <class Alpha>
Silhouette silhouette(int w, int h, Alpha alpha) {
  double n = 0, mx = 0, my = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (alpha(x, y) > 0.5) n += 1, mx += x + 0.5, my += y + 0.5;
  return {mx / n, my / n, std::sqrt(n / M_PI)};
}

TEST(RaycastVsSplats, CameraIsTheOrbitCamera) {
  const Vec3d lo{-3, 2, 10}, hi{40, 30, 70};
  for (const auto& v : {std::array<float, 2>{0, 0}, std::array<float, 2>{-30, 10}, std::array<float, 2>{135, -60}}) {
    viewer::OrbitCamera oc;
    oc.fit(lo, hi);
    oc.azimuth = v[0];
    oc.elevation = v[1];
    const RayCamera rc = RayCamera::orbit(v[0], v[1], lo, hi);
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(rc.eye[a], oc.eye()[a], 1e-3);
      EXPECT_NEAR(rc.forward[a], oc.forward()[a], 1e-5);
      EXPECT_NEAR(rc.right[a], oc.right()[a], 1e-5);
      EXPECT_NEAR(rc.up[a], oc.up()[a], 1e-5);
    }
    EXPECT_EQ(rc.fov_y, oc.fov_y);
  }
}

TEST(RaycastVsSplats, PanelsLineUp) {
  const Volume u = shell(32);
  Runtime& rt = runtime();
  SplatParams sp;
  // Voxel centres: the ray caster frames the voxels, and shell centres move
  // the outermost splats up to a voxel inwards (0.74 here), which would
  // shift the framing compared here by as much.
  sp.centres = SplatCentres::Voxel;
  const SplatSet set = generate_splats(rt, u, sp);
  RaycastParams p;
  const auto box = visible_box(u, p);
  const auto sbox = set.splat_box();
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(box[0][a], sbox[0][a], 1e-4);  // the same framing as `render`
    EXPECT_NEAR(box[1][a], sbox[1][a], 1e-4);
  }
  const int size = 160;
  viewer::HeadlessRenderer r(size, size);
  r.upload(set);
  RayCaster rc(rt, u, p);
  for (const auto& v : {std::array<float, 2>{0, 0}, std::array<float, 2>{40, -25}}) {
    viewer::OrbitCamera cam;
    cam.fit(box[0], box[1]);
    cam.azimuth = v[0];
    cam.elevation = v[1];
    r.render(cam, viewer::RenderSettings{});
    const viewer::RgbaImage gl = r.read();
    const RaycastImage ray = rc.render(RayCamera::orbit(v[0], v[1], box[0], box[1]), size, size);
    const Silhouette a = silhouette(size, size, [&](int x, int y) { return gl.pixel(x, y)[3] / 255.0; });
    const Silhouette b = silhouette(size, size, [&](int x, int y) { return double(ray.pixel(x, y)[3]); });
    std::cout << "[ line-up  ] view " << v[0] << "," << v[1] << ": splats r " << a.radius << " at (" << a.cx << ", "
              << a.cy << "), ray cast r " << b.radius << " at (" << b.cx << ", " << b.cy << ")\n";
    EXPECT_NEAR(a.cx, b.cx, 0.75);
    EXPECT_NEAR(a.cy, b.cy, 0.75);
    // Same size within 1.5 voxels (3.3 px each here): a grazing ray gathers
    // the soft shell along a chord, so the ray-cast silhouette sits about a
    // voxel further out than the splats' (edge-on splats add little).
    EXPECT_NEAR(a.radius, b.radius, 5.0);
  }
}

class FiguresCli : public CliTest {};

// Share of pixels brighter than dark grey in a rectangle.
double lit(const Image& img, int x0, int y0, int w, int h) {
  std::size_t n = 0;
  for (int y = y0; y < y0 + h; ++y)
    for (int x = x0; x < x0 + w; ++x) n += img.pixel(x, y)[0] > 40;
  return double(n) / (double(w) * h);
}

TEST_F(FiguresCli, RenderRaycastOpacityAndRaw) {
  const std::string u = file("u.nrrd");
  write_volume(u, shell(32));
  RunResult r = run({"render", u, "--method", "raycast", "-o", file("u.png"), "--size", "120x90", "--view", "30,20"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("ray casting"), std::string::npos) << r.out;
  Image img = read_png(file("u.png"));
  EXPECT_EQ(img.width, 120);
  EXPECT_EQ(img.height, 90);
  EXPECT_GT(lit(img, 0, 0, 120, 90), 0.15);

  const std::string raw = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", raw, "-q"}).status, 0);
  r = run({"render", raw, "--method", "raycast", "--unclassified", "-o", file("raw.png"), "--size", "64x64"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("not classified"), std::string::npos) << r.out;
  EXPECT_GT(lit(read_png(file("raw.png")), 0, 0, 64, 64), 0.05);
}

TEST_F(FiguresCli, Figure5And6WriteLabelledPanels) {
  const std::string raw = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", raw, "-q"}).status, 0);
  RunResult r = run({"figure5", raw, "-o", file("f5.png"), "--size", "96x80", "--repeat", "1"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("before classification"), std::string::npos) << r.out;
  Image img = read_png(file("f5.png"));
  // A row label above the panels, a label band below each, the caption at
  // the bottom (the band and label sizes follow the font).
  const int head = text_height("Ag", 2) + 12, band = 6 + text_height("Ag", 2) + 2 + text_height("Ag") + 4;
  EXPECT_EQ(img.width, 2 * 96 + 3 * 4);  // panels, gaps
  EXPECT_GT(img.height, head + 80 + band + 4);
  EXPECT_GT(lit(img, 0, 0, 96, head), 0.01) << "row label";
  EXPECT_GT(lit(img, 4, head, 96, 80), 0.05) << "before";
  EXPECT_GT(lit(img, 104, head, 96, 80), 0.05) << "after";
  EXPECT_GT(lit(img, 4, head + 80, 96, band), 0.01) << "panel labels";
  EXPECT_GT(lit(img, 0, head + 80 + band + 4, img.width, img.height - (head + 80 + band + 4)), 0.01) << "caption";

  r = run({"figure6", raw, "-o", file("f6.png"), "--size", "96x80", "--repeat", "1", "--view", "20,10"});
  ASSERT_EQ(r.status, 0) << r.err;
  for (const char* s : {"ray casting", "Marching Cubes", "shear-warp", "oriented splats"})
    EXPECT_NE(r.out.find(s), std::string::npos) << s << " in " << r.out;
  img = read_png(file("f6.png"));
  EXPECT_EQ(img.width, 4 * 96 + 5 * 4);
  EXPECT_GT(lit(img, 4, head, 96, 80), 0.05) << "ray casting";
  EXPECT_GT(lit(img, 4 + 3 * 100, head, 96, 80), 0.05) << "splats";

  // Two rows (a simulated and a second volume), each with its own view and
  // label: the second row's panels sit one row lower and are drawn.
  const std::string raw2 = file("raw2.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "24", "-o", raw2, "-q"}).status, 0);
  r = run({"figure6", raw, raw2, "-o", file("f6b.png"), "--size", "96x80", "--repeat", "1", "--view", "20,10", "--view",
           "0,30", "--labels", "first,second"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("row 2"), std::string::npos) << r.out;
  const Image two = read_png(file("f6b.png"));
  const int row_h = head + 80 + band + 4;
  EXPECT_EQ(two.width, img.width);
  EXPECT_GT(two.height, 2 * row_h);
  EXPECT_GT(lit(two, 4, row_h + head, 96, 80), 0.05) << "second row, ray casting";
  EXPECT_GT(lit(two, 4 + 3 * 100, row_h + head, 96, 80), 0.05) << "second row, splats";
  expect_one_line_error(run({"figure6", raw, raw2, "-o", file("x.png"), "--labels", "only one"}), {"--labels"});
  expect_one_line_error(run({"figure6", raw, raw2, "-o", file("x.png"), "--view", "0,0", "--view", "1,1", "--view", "2,2"}),
                        {"--view"});
}

TEST_F(FiguresCli, BadInputIsOneLineExit2) {
  const std::string junk = write("junk.nrrd", "this is not a volume\n");
  const std::string u = file("u.nrrd");
  write_volume(u, shell(16));
  expect_one_line_error(run({"figure5", junk, "-o", file("a.png")}), {"junk.nrrd"});
  expect_one_line_error(run({"figure6", junk, "-o", file("a.png")}), {"junk.nrrd"});
  expect_one_line_error(run({"figure5", u, "-o", file("a.png")}), {"u.nrrd", "raw volume"});
  expect_one_line_error(run({"figure6", u, "-o", file("a.jpg")}), {"png"});
  expect_one_line_error(run({"figure6", u, "-o", file("a.png"), "--size", "0x3"}), {"--size"});
  expect_one_line_error(run({"figure6", u, "-o", file("a.png"), "--repeat", "0"}), {"--repeat"});
  expect_one_line_error(run({"render", u, "--method", "raycast", "-o", file("a.png"), "--tf-lo", "0.8", "--tf-hi", "0.2"}),
                        {"--tf-lo"});
  expect_one_line_error(run({"render", u, "--method", "raycast", "-o", file("a.png"), "--step", "0"}), {"--step"});
  expect_one_line_error(run({"render", u, "--method", "raycast", "-o", file("a.png"), "--turntable", "3"}),
                        {"--turntable"});
  const std::string zero = file("zero.nrrd");
  write_volume(zero, Volume({12, 10, 8}));
  expect_one_line_error(run({"render", zero, "--method", "raycast", "--opacity", "-o", file("a.png")}),
                        {"zero.nrrd", "transparent"});
  for (const auto& name : listing()) EXPECT_EQ(name.find(".png"), std::string::npos) << name;
}

}  // namespace
}  // namespace softshell::test
