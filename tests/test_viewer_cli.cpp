// `softshell view` with its panel, slice views and histogram, looked at in
// pixels (the real binary under xvfb-run, Mesa llvmpipe), and the parameters
// file round trip: view saves it, classify --params reproduces the same u.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "cli_fixture.hpp"
#include "image.hpp"
#include "io.hpp"
#include "test_support.hpp"

namespace softshell::test {
namespace {

class ViewerCli : public CliTest {
 protected:
  static void one_line_error(const RunResult& r, const std::vector<std::string>& parts) {
    expect_one_line_error(r, {});
    for (const std::string& p : parts) EXPECT_NE(r.err.find(p), std::string::npos) << "'" << p << "' not in: " << r.err;
  }
};

struct PaneImage {
  int x = 0, y = 0, w = 0, h = 0, nu = 0, nv = 0, at = 0;
};

// "view: slice axial z = 16, image at 351,533 263x263 (32x32 voxels)"
PaneImage pane_from(const std::string& out, const std::string& name) {
  PaneImage p;
  const auto at = out.find("view: slice " + name);
  if (at == std::string::npos) return p;
  const std::string line = out.substr(at, out.find('\n', at) - at);
  char axis = 0;
  const std::string fmt = "view: slice " + name + " %c = %d, image at %d,%d %dx%d (%dx%d voxels)";
  if (std::sscanf(line.c_str(), fmt.c_str(), &axis, &p.at, &p.x, &p.y, &p.w, &p.h, &p.nu, &p.nv) != 8) p.w = 0;
  return p;
}

struct Histogram {
  double x = 0, y = 0, w = 0, h = 0, lo = 0, hi = 0, marker = 0;
  bool ok = false;
};

Histogram histogram_from(const std::string& out) {
  Histogram hg;
  const auto at = out.find("view: histogram");
  if (at == std::string::npos) return hg;
  hg.ok = std::sscanf(out.c_str() + at, "view: histogram at %lf,%lf %lfx%lf, range [%lf, %lf], marker %lf", &hg.x, &hg.y,
                      &hg.w, &hg.h, &hg.lo, &hg.hi, &hg.marker) == 7;
  return hg;
}

// The pixel at the centre of texel (i, j) of a slice image.
const std::uint8_t* texel(const Image& img, const PaneImage& p, int i, int j) {
  const int x = p.x + int((i + 0.5) * p.w / p.nu), y = p.y + int((j + 0.5) * p.h / p.nv);
  return img.pixel(x, y);
}

TEST_F(ViewerCli, SliceViewsShowTheBModeGreyAndTheOverlayWhereUIsHigh) {
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", in, "-q"}).status, 0);
  const std::string shot = file("panel.png"), u_path = file("u.nrrd");
  const RunResult r = run({"view", in, "--iso", "120", "--frames", "2", "--size", "900x600", "--screenshot", shot,
                           "--screenshot-panel", "--cursor", "16,14,18", "--save-u", u_path});
  ASSERT_EQ(r.status, 0) << r.err;
  const Image img = read_png(shot);
  const Volume v = read_volume(in), u = read_volume(u_path);
  ASSERT_EQ(v.source_type, ScalarType::UInt8);  // grey = the sample (type range [0, 255])
  const char* names[3] = {"axial", "coronal", "sagittal"};
  const int axes[3][3] = {{0, 1, 2}, {0, 2, 1}, {1, 2, 0}};
  const int cursor[3] = {16, 14, 18};
  for (int k = 0; k < 3; ++k) {
    SCOPED_TRACE(names[k]);
    const PaneImage p = pane_from(r.out, names[k]);
    ASSERT_GT(p.w, 0) << r.out;
    ASSERT_EQ(p.nu, 32);
    ASSERT_EQ(p.at, cursor[axes[k][2]]);
    ASSERT_LE(p.x + p.w, img.width);
    ASSERT_LE(p.y + p.h, img.height);
    const int au = axes[k][0], av = axes[k][1], an = axes[k][2];
    auto voxel = [&](int i, int j) {
      std::size_t c[3];
      c[au] = std::size_t(i), c[av] = std::size_t(j), c[an] = std::size_t(cursor[an]);
      return v.index(c[0], c[1], c[2]);
    };
    int grey = 0, grey_ok = 0, high = 0, high_orange = 0, all = 0, all_ok = 0;
    for (int j = 1; j + 1 < p.nv; ++j)
      for (int i = 1; i + 1 < p.nu; ++i) {
        if (std::abs(i - cursor[au]) <= 1 || std::abs(j - cursor[av]) <= 1) continue;  // the cursor's lines
        const std::size_t idx = voxel(i, j);
        const std::uint8_t* px = texel(img, p, i, j);
        // Off the contour (u below the splat threshold 0.2 here and around):
        // the grey level, blended with the orange overlay at 0.5 u.
        bool quiet = true;
        for (int dj = -1; dj <= 1; ++dj)
          for (int di = -1; di <= 1; ++di) quiet &= u.data[voxel(i + di, j + dj)] < 0.15f;
        if (quiet) {
          const double g = v.data[idx] / 255.0, a = 0.5 * u.data[idx], col[3] = {1.0, 0.45, 0.05};
          bool ok = true;
          for (int c = 0; c < 3; ++c) ok &= std::abs(px[c] - 255.0 * (g * (1 - a) + col[c] * a)) <= 1.5;
          ++all, all_ok += ok;
        }
        // u ~ 0 (the overlay under half a grey level): the B-mode grey level itself.
        if (quiet && u.data[idx] < 0.003f) {
          ++grey;
          const int want = int(std::lround(v.data[idx]));
          grey_ok += std::abs(px[0] - want) <= 1 && std::abs(px[1] - want) <= 1 && std::abs(px[2] - want) <= 1;
        }
        if (u.data[idx] > 0.5f) {  // the overlay (orange, opacity 0.5 u): red well above blue
          ++high;
          high_orange += int(px[0]) - int(px[2]) > 40;
        }
      }
    EXPECT_GT(all, 100);
    EXPECT_EQ(all_ok, all) << "slice texels off the contour not showing grey blended with the overlay";
    EXPECT_GT(grey, 30);
    EXPECT_EQ(grey_ok, grey) << "slice texels with u = 0 not showing the volume's grey";
    EXPECT_GT(high, 5);
    EXPECT_EQ(high_orange, high) << "texels with u > 0.5 without the overlay colour";
  }
}

TEST_F(ViewerCli, OpacityVolumeSlicesShowUOrTheGivenBModeVolume) {
  const std::string in = file("u.nrrd"), bmode = file("b.nrrd");
  const Volume u = shell_volume(24);
  write_volume(in, u);
  Volume b(u.dims);  // a B-mode stand-in: a grey ramp unlike u
  b.source_type = ScalarType::UInt8;
  for (std::size_t z = 0; z < u.dims[2]; ++z)
    for (std::size_t y = 0; y < u.dims[1]; ++y)
      for (std::size_t x = 0; x < u.dims[0]; ++x) b.at(x, y, z) = float((x * 9 + y * 5 + z * 3) % 256);
  write_volume(bmode, b);
  for (int with_bmode = 0; with_bmode < 2; ++with_bmode) {
    SCOPED_TRACE(with_bmode ? "--volume" : "u alone");
    const std::string shot = file("s.png");
    std::vector<std::string> args{"view", in, "--frames", "2", "--size", "900x600", "--screenshot", shot,
                                  "--screenshot-panel", "--cursor", "5,5,12"};
    if (with_bmode) args.insert(args.end(), {"--volume", bmode});
    const RunResult r = run(args);
    ASSERT_EQ(r.status, 0) << r.err;
    const Image img = read_png(shot);
    const PaneImage p = pane_from(r.out, "axial");
    ASSERT_GT(p.w, 0) << r.out;
    int n = 0, ok = 0;
    for (int j = 7; j + 1 < p.nv; ++j)
      for (int i = 7; i + 1 < p.nu; ++i) {
        bool quiet = true;  // away from the contour at the threshold 0.2
        for (int dj = -1; dj <= 1; ++dj)
          for (int di = -1; di <= 1; ++di) quiet &= u.at(i + di, j + dj, 12) < 0.15f;
        if (!quiet) continue;
        const float uu = u.at(i, j, 12);
        const double g = with_bmode ? b.at(i, j, 12) / 255.0 : uu, a = with_bmode ? 0.5 * uu : 0.0;
        const double col[3] = {1.0, 0.45, 0.05};
        const std::uint8_t* px = texel(img, p, i, j);
        bool good = true;
        for (int c = 0; c < 3; ++c) good &= std::abs(px[c] - 255.0 * (g * (1 - a) + col[c] * a)) <= 1.5;
        ++n, ok += good;
      }
    EXPECT_GT(n, 40);
    EXPECT_EQ(ok, n);
    EXPECT_NE(r.out.find("view: histogram"), std::string::npos);
  }
  expect_one_line_error(run({"view", in, "--frames", "1", "--volume", file("small.nrrd")}), {"small.nrrd"});
  write_volume(file("small.nrrd"), shell_volume(16));
  expect_one_line_error(run({"view", in, "--frames", "1", "--volume", file("small.nrrd")}), {"--volume", "dims"});
}

TEST_F(ViewerCli, CursorMovesTheSlicePlaneIn3DAndTheCropBoxIsDrawnOnTheSlices) {
  const std::string in = file("u.nrrd");
  write_volume(in, shell_volume(32));
  // The sagittal plane (x = cursor x) is drawn in 3-D in exactly (235, 79, 69), no blending.
  // Seen down the beam (--view 0,0: x to the right) its pixels' mean column follows the cursor.
  double column[2] = {0, 0};
  int k = 0;
  for (const char* cursor : {"4,16,16", "27,16,16"}) {
    SCOPED_TRACE(cursor);
    const std::string shot = file("c.png");
    const RunResult r = run({"view", in, "--frames", "2", "--size", "900x600", "--screenshot", shot,
                             "--screenshot-panel", "--cursor", cursor, "--crop", "0,1,0,1,0,0.5"});
    ASSERT_EQ(r.status, 0) << r.err;
    const Image img = read_png(shot);
    int vx = 0, vy = 0, vw = 0, vh = 0;
    const auto at = r.out.find("view: 3-D view at ");
    ASSERT_NE(at, std::string::npos) << r.out;
    ASSERT_EQ(std::sscanf(r.out.c_str() + at, "view: 3-D view at %d,%d %dx%d", &vx, &vy, &vw, &vh), 4);
    double sum = 0;
    int n = 0;
    for (int y = vy; y < vy + vh - 60; ++y)  // above the scale bar and the orientation marker
      for (int x = vx; x < vx + vw; ++x) {
        const std::uint8_t* p = img.pixel(x, y);
        if (p[0] == 235 && p[1] == 79 && p[2] == 69) sum += x, ++n;
      }
    ASSERT_GT(n, 50) << "no sagittal plane outline in the 3-D view";
    column[k++] = sum / n;
    // The crop box (z up to 0.5) on the coronal slice (x right, z down): a near-white row at
    // z = 0.5 (31) = 15.5, i.e. between texel rows 15 and 16.
    const PaneImage p = pane_from(r.out, "coronal");
    ASSERT_GT(p.w, 0);
    const int y = p.y + int(16.0 * p.h / p.nv);
    int white = 0;
    for (int dy = -2; dy <= 2; ++dy)
      for (int x = p.x; x < p.x + p.w; ++x) {
        const std::uint8_t* q = img.pixel(x, y + dy);
        white += q[0] > 225 && q[1] > 225 && q[2] > 225;
      }
    EXPECT_GT(white, p.w / 2) << "no crop box edge across the coronal slice";
    int white_elsewhere = 0;  // and not at z = 0.25 (a row of u and grey only)
    for (int x = p.x; x < p.x + p.w; ++x) {
      const std::uint8_t* q = img.pixel(x, p.y + int(8.5 * p.h / p.nv));
      white_elsewhere += q[0] > 225 && q[1] > 225 && q[2] > 225;
    }
    EXPECT_LT(white_elsewhere, p.w / 4);
  }
  EXPECT_GT(column[1] - column[0], 40.0) << "the sagittal plane did not follow the cursor to the right";
}

// The red isovalue marker's column in the histogram (-1: none).
double marker_column(const Image& img, const Histogram& hg) {
  const int y = int(hg.y + 0.1 * hg.h);  // near the top: above most bars
  double sum = 0;
  int n = 0;
  for (int x = int(hg.x); x < int(hg.x + hg.w); ++x) {
    const std::uint8_t* p = img.pixel(x, y);
    if (p[0] > 220 && p[1] < 80 && p[2] < 80) sum += x, ++n;
  }
  return n ? sum / n : -1;
}

TEST_F(ViewerCli, HistogramMarkerMovesWithTheIsovalue) {
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", in, "-q"}).status, 0);
  std::vector<double> columns;
  for (const char* iso : {"90", "170"}) {
    SCOPED_TRACE(iso);
    const std::string shot = file(std::string("h") + iso + ".png");
    const RunResult r = run({"view", in, "--iso", iso, "--frames", "2", "--size", "900x600", "--screenshot", shot,
                             "--screenshot-panel"});
    ASSERT_EQ(r.status, 0) << r.err;
    const Histogram hg = histogram_from(r.out);
    ASSERT_TRUE(hg.ok) << r.out;
    EXPECT_NEAR(hg.marker, std::stod(iso), 1e-3);
    const double col = marker_column(read_png(shot), hg);
    ASSERT_GE(col, 0) << "no marker drawn";
    EXPECT_NEAR(col, hg.x + hg.w * (hg.marker - hg.lo) / (hg.hi - hg.lo), 2.0);
    columns.push_back(col);
  }
  // 80 grey levels apart: the marker moved right by the histogram's scale.
  EXPECT_GT(columns[1] - columns[0], 20.0);
}

// Mean green / red of the object's pixels (not the black background) in columns [x0, x1).
double green_over_red(const Image& img, int x0, int x1) {
  double sum = 0;
  int n = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = x0; x < x1; ++x) {
      const std::uint8_t* p = img.pixel(x, y);
      if (p[0] > 40) sum += double(p[1]) / p[0], ++n;
    }
  return n ? sum / n : -1;
}

TEST_F(ViewerCli, DepthColourMapShadesAlongTheBeam) {
  // Seen from +x (--view 90,0), depth z runs left to right on the screen:
  // with --colour-map depth the shallow side is light (green/red near 0.9),
  // the deep side red-brown (near 0.3); with one colour both sides alike.
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", in, "-q"}).status, 0);
  double diff[2] = {0, 0};
  for (int depth = 0; depth < 2; ++depth) {
    const std::string shot = file(depth ? "depth.png" : "solid.png");
    const RunResult r = run({"view", in, "--iso", "120", "--frames", "2", "--size", "240x240", "--view", "90,0",
                             "--screenshot", shot, "--colour-map", depth ? "depth" : "solid", "-q"});
    ASSERT_EQ(r.status, 0) << r.err;
    const Image img = read_png(shot);
    const double left = green_over_red(img, 0, 100), right = green_over_red(img, 140, 240);
    ASSERT_GT(left, 0);
    ASSERT_GT(right, 0);
    diff[depth] = left - right;
  }
  EXPECT_LT(std::abs(diff[0]), 0.05) << "one colour: green/red should not depend on depth";
  EXPECT_GT(diff[1], 0.2) << "depth colour: the shallow side should be lighter (more green) than the deep side";
}

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST_F(ViewerCli, SavedParametersReproduceTheClassification) {
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", in, "-q"}).status, 0);
  const std::string given = write("given.txt", "# a session\niso = 120\nalpha = 0.5\nkappa = 0.2\nshell_shift = 0.3\nrenderer = mc\nview = 20,10\n");
  const std::string saved = file("saved.txt"), vu = file("view-u.nrrd"), mesh = file("mesh.ply");
  const RunResult r = run({"view", in, "--params", given, "--frames", "2", "--size", "320x240", "--save-params", saved,
                           "--save-u", vu, "--save-mesh", mesh});
  ASSERT_EQ(r.status, 0) << r.err;
  const std::string text = slurp(saved);
  for (const char* line : {"iso = 120\n", "alpha = 0.5\n", "kappa = 0.2\n", "shell_shift = 0.3\n", "renderer = mc\n", "view = 20,10\n", "beta = 2\n"})
    EXPECT_NE(text.find(line), std::string::npos) << line << " not in:\n" << text;
  EXPECT_TRUE(fs::exists(mesh));

  const std::string a = file("a.nrrd"), b = file("b.nrrd"), c = file("c.nrrd"), d = file("d.nrrd");
  ASSERT_EQ(run({"classify", in, "--params", saved, "-o", a, "-q"}).status, 0);
  ASSERT_EQ(run({"classify", in, "--iso", "120", "--alpha", "0.5", "--kappa", "0.2", "--shell-shift", "0.3", "-o", b, "-q"}).status, 0);
  const Volume ua = read_volume(a), ub = read_volume(b), uv = read_volume(vu);
  EXPECT_EQ(ua.data, ub.data) << "classify --params differs from the same options on the command line";
  EXPECT_EQ(ua.data, uv.data) << "classify --params differs from the viewer's u";
  // The command line wins over the file.
  ASSERT_EQ(run({"classify", in, "--params", saved, "--alpha", "2", "-o", c, "-q"}).status, 0);
  ASSERT_EQ(run({"classify", in, "--iso", "120", "--alpha", "2", "--kappa", "0.2", "--shell-shift", "0.3", "-o", d, "-q"}).status, 0);
  const Volume uc = read_volume(c), ud = read_volume(d);
  EXPECT_EQ(uc.data, ud.data);
  EXPECT_NE(uc.data, ua.data);
}

TEST_F(ViewerCli, FloatDataWhoseFillIsNotZeroViewAsClassify) {
  // Float data shifted by 500, with an unswept wedge filled at 500 (the data's
  // 0 moved with it): the viewer takes the fill as classify does (host/mask.hpp,
  // unscanned_fill_value), its u is classify's, and the parameters it saves
  // hold the isovalue in the file's units (620, as given).
  const std::string raw = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", raw, "-q"}).status, 0);
  Volume v = read_volume(raw);
  Volume f = v.with_data(v.data, ScalarType::Float32);
  for (std::size_t z = 0; z < f.dims[2]; ++z)
    for (std::size_t y = 0; y < f.dims[1]; ++y)
      for (std::size_t x = 0; x + z / 4 < 8; ++x) f.at(x, y, z) = 0.0f;
  for (float& x : f.data) x += 500.0f;
  const std::string in = file("fill500.nrrd"), vu = file("view-u.nrrd"), saved = file("saved.txt");
  write_volume(in, f);
  const RunResult r = run({"view", in, "--iso", "620", "--frames", "1", "--size", "320x240", "--save-params", saved,
                           "--save-u", vu});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(slurp(saved).find("iso = 620\n"), std::string::npos) << slurp(saved);
  const std::string a = file("a.nrrd"), b = file("b.nrrd");
  const RunResult c = run({"classify", in, "--iso", "620", "-o", a});
  ASSERT_EQ(c.status, 0) << c.err;
  EXPECT_NE(c.out.find("(float data: their fill, 500, counted as 0)"), std::string::npos) << c.out;
  EXPECT_NE(c.out.find(", iso 620.000"), std::string::npos) << c.out;
  ASSERT_EQ(run({"classify", in, "--params", saved, "-o", b, "-q"}).status, 0);
  const Volume ua = read_volume(a), ub = read_volume(b), uv = read_volume(vu);
  EXPECT_EQ(ua.data, uv.data) << "the viewer's u differs from classify's";
  EXPECT_EQ(ua.data, ub.data) << "classify --params (saved by the viewer) differs";
  std::size_t drawn = 0;
  for (float x : ua.data) drawn += x > 0.2f;
  EXPECT_GT(drawn, 100u);
  EXPECT_EQ(ua.at(0, 16, 2), 0.0f) << "the wedge is unscanned";
}

TEST_F(ViewerCli, DepthColourMapRendersWithAColourBarOfItsRange) {
  // render --colour-map depth draws a colour bar at the right edge: the
  // shader's depth colours from near (top) to deep (bottom), labelled; the
  // drawn object's near side is as light as the bar's top and its deep side
  // darker; --legend off leaves the edge to the picture.
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", in, "-q"}).status, 0);
  const RunResult r = run({"render", in, "-o", file("d.png"), "--size", "320x240", "--colour-map", "depth", "-q"});
  ASSERT_EQ(r.status, 0) << r.err;
  ASSERT_EQ(run({"render", in, "-o", file("n.png"), "--size", "320x240", "--colour-map", "depth", "--legend", "off", "-q"})
                .status,
            0);
  const Image with = read_png(file("d.png")), without = read_png(file("n.png"));
  // Where draw_depth_legend puts the bar on a 320x240 picture.
  const int bw = 12, bh = 120, bx = 320 - 10 - bw, by = 60;
  auto same = [](const std::uint8_t* p, Rgb c) { return p[0] == c.r && p[1] == c.g && p[2] == c.b; };
  int matching = 0;
  for (int y = 0; y < bh; ++y) matching += same(with.pixel(bx + bw / 2, by + y), depth_colour(double(y) / (bh - 1)));
  EXPECT_EQ(matching, bh) << "the bar is the depth colour map, near at the top";
  const Rgb top = depth_colour(0), bottom = depth_colour(1);
  EXPECT_GT(top.g, bottom.g + 100) << "light near, dark deep";
  // Labels beside the bar: light text left of it, nothing there without the legend.
  auto lit = [](const Image& im, int x0, int y0, int w, int h) {
    int n = 0;
    for (int y = y0; y < y0 + h; ++y)
      for (int x = x0; x < x0 + w; ++x) n += im.pixel(x, y)[0] > 150 && im.pixel(x, y)[2] > 150;
    return n;
  };
  EXPECT_GT(lit(with, bx - 70, by, 64, 14), 10) << "the near depth's label";
  EXPECT_GT(lit(with, bx - 70, by + bh - 14, 64, 14), 10) << "the far depth's label";
  EXPECT_EQ(lit(without, bx, by, bw, bh), 0) << "--legend off drew a bar";
  // Elsewhere the two pictures are the same.
  int differ = 0;
  for (int y = 0; y < 240; ++y)
    for (int x = 0; x < 320 / 2; ++x) differ += !same(with.pixel(x, y), {without.pixel(x, y)[0], without.pixel(x, y)[1], without.pixel(x, y)[2]});
  EXPECT_EQ(differ, 0);
  expect_one_line_error(run({"render", in, "-o", file("x.png"), "--legend", "maybe"}), {"--legend"});
}

TEST_F(ViewerCli, PresetsSetClassificationAndRenderingAndGiveWayToOptions) {
  // host/presets.hpp. A raw volume viewed with --preset bone: the saved
  // parameters name the preset and hold its rendering (threshold 0.3, light
  // 0,50, ivory), and `classify --params` of that file classifies with the
  // bone cue on, as `classify --bone-cue on` does; an option on the command
  // line wins over the preset; render --preset vessels draws red where the
  // default draws skin tones; an unknown preset is a one-line error listing
  // the presets as --help does.
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "32", "-o", in, "-q"}).status, 0);
  const std::string saved = file("bone.txt");
  RunResult r = run({"view", in, "--preset", "bone", "--frames", "2", "--size", "320x240", "--save-params", saved});
  ASSERT_EQ(r.status, 0) << r.err;
  std::string text = slurp(saved);
  for (const char* line : {"preset = bone\n", "threshold = 0.300000012\n", "light = 0,50\n", "colour = 0.949999988,0.920000017,0.819999993\n"})
    EXPECT_NE(text.find(line), std::string::npos) << line << " not in:\n" << text;
  EXPECT_NE(r.out.find("bone cue on"), std::string::npos) << r.out;
  const std::string a = file("a.nrrd"), b = file("b.nrrd"), c = file("c.nrrd");
  ASSERT_EQ(run({"classify", in, "--params", saved, "-o", a, "-q"}).status, 0);
  ASSERT_EQ(run({"classify", in, "--iso", "auto", "--bone-cue", "on", "-o", b, "-q"}).status, 0);
  ASSERT_EQ(run({"classify", in, "--iso", "auto", "-o", c, "-q"}).status, 0);
  EXPECT_EQ(read_volume(a).data, read_volume(b).data) << "the bone preset's classification differs from --bone-cue on";
  EXPECT_NE(read_volume(a).data, read_volume(c).data) << "the bone cue changed nothing";
  // The command line wins: threshold and light given, the rest from the preset.
  r = run({"view", in, "--preset", "bone", "--threshold", "0.25", "--light", "10,20", "--frames", "2", "--size",
           "320x240", "--save-params", saved});
  ASSERT_EQ(r.status, 0) << r.err;
  text = slurp(saved);
  for (const char* line : {"preset = bone\n", "threshold = 0.25\n", "light = 10,20\n"})
    EXPECT_NE(text.find(line), std::string::npos) << line << " not in:\n" << text;
  // A parameters file's preset key is a preset: the face preset's depth colour comes back.
  const std::string face = write("face.txt", "preset = face\n");
  ASSERT_EQ(run({"view", in, "--params", face, "--frames", "2", "--size", "320x240", "--save-params", saved}).status, 0);
  text = slurp(saved);
  EXPECT_NE(text.find("colour_map = depth\n"), std::string::npos) << text;
  // Pixels: the vessels preset is red, the default skin-toned.
  const auto mean_rg = [&](const std::vector<std::string>& extra) {
    std::vector<std::string> args{"render", in, "-o", file("r.png"), "--size", "160x160", "-q"};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult rr = run(args);
    EXPECT_EQ(rr.status, 0) << rr.err;
    const Image img = read_png(file("r.png"));
    double red = 0, green = 0;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x)
        red += img.pixel(x, y)[0], green += img.pixel(x, y)[1];
    return std::make_pair(red, green);
  };
  const auto [r0, g0] = mean_rg({});
  const auto [r1, g1] = mean_rg({"--preset", "vessels"});
  EXPECT_LT(r0, 1.6 * g0) << "the default is not red";
  EXPECT_GT(r1, 3.0 * g1) << "the vessels preset is red";
  // Unknown names: one line, the list as --help gives it.
  expect_one_line_error(run({"render", in, "-o", file("x.png"), "--preset", "heart"}),
                        {"--preset", "default, face, bone or vessels"});
  expect_one_line_error(run({"view", in, "--frames", "1", "--preset", "heart"}), {"--preset"});
  one_line_error(run({"view", in, "--frames", "1", "--params", write("bad.txt", "preset = heart\n")}),
                 {"preset", "heart"});
  const RunResult help = run({"render", "--help"});
  EXPECT_NE(help.out.find("default, face, bone, vessels"), std::string::npos);
  EXPECT_FALSE(fs::exists(file("x.png")));
}

TEST_F(ViewerCli, BadParametersFilesAreOneLineErrors) {
  const std::string in = file("raw.nrrd");
  ASSERT_EQ(run({"synthetic", "--size", "16", "-o", in, "-q"}).status, 0);
  const std::pair<const char*, std::vector<std::string>> cases[] = {
      {"iso = 120\nalpah = 1\n", {"bad.txt:2", "alpah", "unknown key"}},
      {"alpha = one\n", {"bad.txt:1", "alpha", "expected a number"}},
      {"omega = 2\n", {"omega", "out of range"}},
      {"crop = 0,1,0,1\n", {"crop", "6 comma-separated"}},
      {"renderer = voxels\n", {"renderer", "voxels"}},
      {"alpha 1\n", {"bad.txt:1", "key = value"}},
      {"beta = 1\nbeta = 2\n", {"beta", "twice"}},
  };
  for (const auto& [content, words] : cases) {
    SCOPED_TRACE(content);
    const std::string bad = write("bad.txt", content);
    one_line_error(run({"classify", in, "--iso", "120", "--params", bad, "-o", file("u.nrrd")}), words);
    one_line_error(run({"view", in, "--params", bad, "--frames", "1"}), words);
  }
  expect_one_line_error(run({"classify", in, "--params", file("missing.txt"), "-o", file("u.nrrd")}), {"missing.txt"});
  expect_one_line_error(run({"classify", in, "-o", file("u.nrrd")}), {"--iso"});
  expect_one_line_error(run({"view", in, "--save-params", file("p.txt")}), {"--frames"});
  expect_one_line_error(run({"view", in, "--frames", "1", "--cursor", "1,2"}), {"--cursor"});
  expect_one_line_error(run({"view", in, "--frames", "1", "--cursor", "1,2,99"}), {"--cursor", "outside"});
  expect_one_line_error(run({"view", in, "--frames", "1", "--volume", file("missing.nrrd")}), {"missing.nrrd"});
  EXPECT_FALSE(fs::exists(file("u.nrrd")));
  EXPECT_FALSE(fs::exists(file("p.txt")));
}

}  // namespace
}  // namespace softshell::test
