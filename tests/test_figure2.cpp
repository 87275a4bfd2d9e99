// The figures' text (host/image.hpp: draw_text, TrueType, and the bitmap font) and `softshell figure2` end to
// end: six grey panels of the expected size, captions, panel (a) equal to the
// input slice, the default slice, and one-line errors for bad arguments.
#include <algorithm>
#include <array>
#include <random>
#include <map>
#include <cstdio>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "image.hpp"
#include "io.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

namespace fs = std::filesystem;

bool is_grey(const Image& im, int x, int y) {
  const std::uint8_t* p = im.pixel(x, y);
  return p[0] == p[1] && p[1] == p[2];
}

// ---- font --------------------------------------------------------------------------------------------------------

TEST(Figure2Text, GlyphsAreDrawnScaledAndClipped) {
  const Rgb c{250, 200, 100};
  Image im(40, 20, 0);
  draw_bitmap_text(im, 1, 2, "I", c, 2);
  // 'I' in the 5x7 font: the middle column full height, the top and bottom
  // rows three columns wide; each font pixel a 2x2 block.
  auto set = [&](int x, int y) { return im.pixel(x, y)[0] == c.r && im.pixel(x, y)[1] == c.g && im.pixel(x, y)[2] == c.b; };
  for (int row = 0; row < 7; ++row)
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx) EXPECT_TRUE(set(1 + 2 * 2 + dx, 2 + 2 * row + dy)) << "row " << row;
  EXPECT_TRUE(set(1 + 2 * 1, 2)) << "top bar";
  EXPECT_TRUE(set(1 + 2 * 3, 2 + 2 * 6)) << "bottom bar";
  EXPECT_FALSE(set(1 + 2 * 0, 2 + 2 * 3)) << "left column is empty in the middle";
  std::size_t lit = 0;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x) lit += set(x, y);
  EXPECT_EQ(lit, (7u + 4u) * 4u);  // 11 font pixels of 'I'

  EXPECT_EQ(bitmap_text_width("ab", 1), 11);
  EXPECT_EQ(bitmap_text_width("ab\nabc", 2), 34);
  EXPECT_EQ(bitmap_text_height("ab\nabc", 1), 20);  // 11 rows to the next line, 9 rows of glyph

  // g, j, p, q and y have descenders below the baseline (rows 7-8), so "g"
  // does not read as "9" nor "p" as "P"; no other letter reaches there.
  auto rows_lit = [](const std::string& ch) {
    Image t(6, 9);
    draw_bitmap_text(t, 0, 0, ch, {255, 255, 255}, 1);
    std::vector<bool> lit(9, false);
    for (int y = 0; y < 9; ++y)
      for (int x = 0; x < 6; ++x) lit[std::size_t(y)] = lit[std::size_t(y)] || t.pixel(x, y)[0] == 255;
    return lit;
  };
  auto pixels = [](const std::string& ch) {
    Image t(6, 9);
    draw_bitmap_text(t, 0, 0, ch, {255, 255, 255}, 1);
    std::string bits;
    for (int y = 0; y < 9; ++y)
      for (int x = 0; x < 6; ++x) bits += t.pixel(x, y)[0] == 255 ? '#' : '.';
    return bits;
  };
  for (const char* d : {"g", "j", "p", "q", "y"}) {
    SCOPED_TRACE(d);
    EXPECT_TRUE(rows_lit(d)[8]) << "descender";
  }
  for (const char* n : {"a", "b", "9", "P", "Q", "x"}) {
    SCOPED_TRACE(n);
    EXPECT_FALSE(rows_lit(n)[7] || rows_lit(n)[8]);
  }
  EXPECT_NE(pixels("g"), pixels("9"));
  EXPECT_NE(pixels("p"), pixels("P"));
  EXPECT_EQ(bitmap_text_width("", 3), 0);

  // Every printable character lights something except the space; bytes
  // outside printable ASCII draw as '?'.
  for (int ch = 0x21; ch < 0x7F; ++ch) {
    Image g(8, 8, 0);
    draw_bitmap_text(g, 0, 0, std::string(1, char(ch)), c, 1);
    EXPECT_TRUE(std::any_of(g.rgb.begin(), g.rgb.end(), [](std::uint8_t b) { return b != 0; })) << char(ch);
  }
  Image q1(8, 8, 0), q2(8, 8, 0);
  draw_bitmap_text(q1, 0, 0, "\x01", c, 1);
  draw_bitmap_text(q2, 0, 0, "?", c, 1);
  EXPECT_EQ(q1.rgb, q2.rgb);

  // Clipped at every edge, no writes outside.
  Image small(5, 4, 7);
  draw_bitmap_text(small, -3, -3, "W@W", c, 3);
  draw_bitmap_text(small, 3, 2, "M", c, 1);
  EXPECT_EQ(small.rgb.size(), 5u * 4u * 3u);
}

TEST(Figure2Text, TrueTypeTextIsAntiAliasedProportionalAndMeasuredAsDrawn) {
  // scripts/common.sh installs fonts-dejavu-core: the figures' text is
  // DejaVu Sans, not the bitmap font.
  ASSERT_TRUE(truetype_text()) << "no TrueType font (fonts-dejavu-core)";
  EXPECT_NE(text_font_path().find("DejaVuSans"), std::string::npos) << text_font_path();
  const Rgb white{255, 255, 255};
  // The drawn extent of a text lies inside the box text_width x text_height.
  auto extent = [&](const std::string& t, int scale, int* lit_out = nullptr, int* grey_out = nullptr) {
    Image im(400, 120, 0);
    draw_text(im, 10, 10, t, white, scale);
    int x0 = im.width, x1 = -1, y0 = im.height, y1 = -1, lit = 0, grey = 0;
    for (int y = 0; y < im.height; ++y)
      for (int x = 0; x < im.width; ++x) {
        const int v = im.pixel(x, y)[0];
        if (v == 0) continue;
        ++lit, grey += v < 255;
        x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
      }
    if (lit_out) *lit_out = lit;
    if (grey_out) *grey_out = grey;
    return std::array<int, 4>{x0 - 10, y0 - 10, x1 - 10, y1 - 10};
  };
  for (int scale : {1, 2, 3}) {
    SCOPED_TRACE(scale);
    const std::string t = "Agpy (bone) 12.5 mm\nsecond line";
    int lit = 0, grey = 0;
    const auto e = extent(t, scale, &lit, &grey);
    EXPECT_GE(e[0], -1);
    EXPECT_GE(e[1], -1);
    EXPECT_LE(e[2], text_width(t, scale) + 1);
    EXPECT_LE(e[3], text_height(t, scale) + 1);
    EXPECT_GE(e[2], text_width(t, scale) - 3 * scale) << "the width is what is drawn";
    EXPECT_GT(grey, lit / 5) << "anti-aliased edges";
    // Capitals 8 pixels high per scale: 'H' alone.
    const auto h = extent("H", scale);
    EXPECT_NEAR(h[3] - h[1] + 1, 8 * scale, scale);
  }
  // Proportional: 'i' is narrower than 'W'; lines add up.
  EXPECT_LT(text_width("iiii"), text_width("WWWW") / 2);
  EXPECT_GT(text_height("a\nb\nc"), 2 * text_height("a"));
  EXPECT_EQ(text_width(""), 0);
  EXPECT_EQ(text_height(""), 0);
  // "g" has a descender, "9" does not; "p" differs from "P".
  const auto g = extent("g", 2), nine = extent("9", 2), base = extent("x", 2);
  EXPECT_GT(g[3], base[3] + 3);
  EXPECT_LE(nine[3], base[3] + 1);
  EXPECT_GT(extent("p", 2)[3], extent("P", 2)[3] + 3);
  // Outside printable ASCII: '?'; blended over the image; clipped.
  Image q1(30, 30, 0), q2(30, 30, 0);
  draw_text(q1, 2, 2, "\x01", white, 1);
  draw_text(q2, 2, 2, "?", white, 1);
  EXPECT_EQ(q1.rgb, q2.rgb);
  Image blue(40, 30, 0);
  fill_rect(blue, 0, 0, 40, 30, {0, 0, 200});
  draw_text(blue, 2, 2, "O", {255, 0, 0}, 2);
  bool mixed = false;
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) {
      const std::uint8_t* p = blue.pixel(x, y);
      mixed = mixed || (p[0] > 0 && p[0] < 255 && p[2] > 0 && p[2] < 200);
    }
  EXPECT_TRUE(mixed) << "edge pixels blend the text colour with the ground";
  // Wrapping: every line fits, the words come back in order.
  const std::string para = "blobs / contour roughness:  (b) 14 / 1.82  (c) 42 / 3.46  (d) 44 / 3.66  (e) 4 / 1.21";
  const auto wrapped = wrap_text(para, 150);
  EXPECT_GT(wrapped.size(), 2u);
  std::string joined;
  for (const std::string& l : wrapped) {
    EXPECT_LE(text_width(l), 150) << l;
    joined += (joined.empty() ? "" : " ") + l;
  }
  auto squeeze = [](std::string t) {
    t.erase(std::remove(t.begin(), t.end(), ' '), t.end());
    return t;
  };
  EXPECT_EQ(squeeze(joined), squeeze(para));
  EXPECT_EQ(wrap_text("a\nb", 500).size(), 2u);
  Image small(5, 4, 7);
  draw_text(small, -6, -6, "W@W", white, 3);
  draw_text(small, 3, 2, "M", white, 1);
  EXPECT_EQ(small.rgb.size(), 5u * 4u * 3u);
}

// ---- figure2 ------------------------------------------------------------------------------------------------------

class CliFigure2 : public test::CliTest {
 protected:
  // 24 x 20 x 16 uint8: a speckled sphere of tissue in fluid with a bright rim.
  std::string write_volume_file() {
    Volume v({24, 20, 16}, {1, 1, 1}, ScalarType::UInt8);
    std::mt19937_64 rng(test::seed());
    std::uniform_real_distribution<double> u(0.6, 1.4);
    for (std::size_t z = 0; z < 16; ++z)
      for (std::size_t y = 0; y < 20; ++y)
        for (std::size_t x = 0; x < 24; ++x) {
          const double d = std::sqrt((x - 11.5) * (x - 11.5) + (y - 9.5) * (y - 9.5) + (z - 7.5) * (z - 7.5)) - 6.0;
          const double base = d < 0 ? 150 : 20;
          v.at(x, y, z) = float(std::clamp(std::round(base * u(rng)), 1.0, 255.0));
        }
    write_volume(file("in.nrrd"), v);
    volume_ = v;
    return file("in.nrrd");
  }

  struct Box {
    int x0, y0, x1, y1;  // inclusive
    std::size_t pixels;
  };
  // Bounding boxes of the 4-connected regions of grey pixels, row-major order
  // of their top-left corners; regions under 16 pixels are left out (an
  // anti-aliased edge of the label colour over the ground passes through a
  // grey level).
  static std::vector<Box> grey_regions(const Image& im) {
    std::vector<int> seen(std::size_t(im.width) * im.height, 0);
    std::vector<Box> boxes;
    std::vector<std::pair<int, int>> stack;
    for (int y = 0; y < im.height; ++y)
      for (int x = 0; x < im.width; ++x) {
        if (seen[std::size_t(y) * im.width + x] || !is_grey(im, x, y)) continue;
        Box b{x, y, x, y, 0};
        stack.assign(1, {x, y});
        seen[std::size_t(y) * im.width + x] = 1;
        while (!stack.empty()) {
          const auto [px, py] = stack.back();
          stack.pop_back();
          ++b.pixels;
          b.x0 = std::min(b.x0, px), b.x1 = std::max(b.x1, px), b.y0 = std::min(b.y0, py), b.y1 = std::max(b.y1, py);
          const int nx[4] = {px - 1, px + 1, px, px}, ny[4] = {py, py, py - 1, py + 1};
          for (int k = 0; k < 4; ++k) {
            if (nx[k] < 0 || ny[k] < 0 || nx[k] >= im.width || ny[k] >= im.height) continue;
            int& s = seen[std::size_t(ny[k]) * im.width + nx[k]];
            if (!s && is_grey(im, nx[k], ny[k])) s = 1, stack.push_back({nx[k], ny[k]});
          }
        }
        if (b.pixels >= 16) boxes.push_back(b);
      }
    return boxes;
  }

  Volume volume_;
};

TEST_F(CliFigure2, SixLabelledPanelsAndTheInputSlice) {
  const std::string in = write_volume_file();
  const int zoom = 4;
  const test::RunResult r =
      run({"figure2", in, "-o", file("fig.png"), "--slice", "y:7", "--iso", "85", "--zoom", std::to_string(zoom)});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("y = 7 of 20"), std::string::npos) << r.out;
  const Image im = read_png(file("fig.png"));

  // Panels: the only grey pixels; six full rectangles of 24 x 16 voxels x zoom,
  // three across and two down.
  const auto boxes = grey_regions(im);
  ASSERT_EQ(boxes.size(), 6u) << "grey regions in a " << im.width << "x" << im.height << " figure";
  for (std::size_t k = 0; k < 6; ++k) {
    const Box& b = boxes[k];
    EXPECT_EQ(b.x1 - b.x0 + 1, 24 * zoom) << "panel " << k;
    EXPECT_EQ(b.y1 - b.y0 + 1, 16 * zoom) << "panel " << k;
    EXPECT_EQ(b.pixels, std::size_t(24 * zoom) * (16 * zoom)) << "panel " << k << " is not a full rectangle";
  }
  EXPECT_EQ(boxes[0].y0, boxes[2].y0);
  EXPECT_LT(boxes[0].x0, boxes[1].x0);
  EXPECT_LT(boxes[1].x0, boxes[2].x0);
  EXPECT_EQ(boxes[3].x0, boxes[0].x0);
  EXPECT_GT(boxes[3].y0, boxes[0].y1);

  // Captions: each panel has non-grey, non-background (label) pixels in the
  // strip just above it, and the strip is otherwise the blank background.
  const std::uint8_t* bg = im.pixel(0, 0);
  for (std::size_t k = 0; k < 6; ++k) {
    std::size_t label = 0;
    for (int y = std::max(0, boxes[k].y0 - 20); y < boxes[k].y0; ++y)
      for (int x = boxes[k].x0; x <= boxes[k].x1; ++x) {
        const std::uint8_t* p = im.pixel(x, y);
        label += !(p[0] == bg[0] && p[1] == bg[1] && p[2] == bg[2]);
      }
    EXPECT_GT(label, 20u) << "no caption above panel " << k;
  }

  // (a): the input slice y = 7, grey = value (uint8, type range), each voxel
  // a zoom x zoom block; x to the right, z down.
  const Box& a = boxes[0];
  for (int py = 0; py < 16 * zoom; ++py)
    for (int px = 0; px < 24 * zoom; ++px) {
      const float want = volume_.at(std::size_t(px / zoom), 7, std::size_t(py / zoom));
      ASSERT_EQ(im.pixel(a.x0 + px, a.y0 + py)[0], std::uint8_t(want)) << "panel (a) pixel " << px << ", " << py;
    }
  // Opacity panels are not all black: the sphere's boundary is drawn.
  for (std::size_t k = 1; k < 6; ++k) {
    int brightest = 0;
    for (int y = boxes[k].y0; y <= boxes[k].y1; ++y)
      for (int x = boxes[k].x0; x <= boxes[k].x1; ++x) brightest = std::max<int>(brightest, im.pixel(x, y)[0]);
    EXPECT_GT(brightest, 50) << "panel " << k;
  }
}

TEST_F(CliFigure2, DefaultsMiddleYSliceAutoIsoAndZoom) {
  const std::string in = write_volume_file();
  const test::RunResult r = run({"figure2", in, "-o", file("fig.png")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("y = 10 of 20"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("(auto)"), std::string::npos) << r.out;
  const Image im = read_png(file("fig.png"));
  const auto boxes = grey_regions(im);
  ASSERT_EQ(boxes.size(), 6u);
  // Automatic zoom: the long side (24 voxels) to at least 256 pixels.
  EXPECT_GE(boxes[0].x1 - boxes[0].x0 + 1, 256);
  EXPECT_EQ((boxes[0].x1 - boxes[0].x0 + 1) % 24, 0);
  // Other axes: a z slice is 24 x 20, an x slice 20 x 16.
  ASSERT_EQ(run({"figure2", in, "-o", file("z.png"), "--slice", "z", "--zoom", "2", "--iso", "85", "-q"}).status, 0);
  const auto bz = grey_regions(read_png(file("z.png")));
  ASSERT_EQ(bz.size(), 6u);
  EXPECT_EQ(bz[0].x1 - bz[0].x0 + 1, 48);
  EXPECT_EQ(bz[0].y1 - bz[0].y0 + 1, 40);
  ASSERT_EQ(run({"figure2", in, "-o", file("x.png"), "--slice", "x:0", "--zoom", "2", "--iso", "85", "-q"}).status, 0);
  const auto bx = grey_regions(read_png(file("x.png")));
  ASSERT_EQ(bx.size(), 6u);
  EXPECT_EQ(bx[0].x1 - bx[0].x0 + 1, 40);
  EXPECT_EQ(bx[0].y1 - bx[0].y0 + 1, 32);
}

TEST_F(CliFigure2, TheTangentialTermSmoothsTheContourAndRemovesBlobs) {
  // The paper's point (Section 3.5): beta > 0 gives a smoother contour with
  // fewer blobs than beta = 0. On a face phantom slice, (e) and (f) have a
  // lower contour roughness and fewer small pieces than (c) and (d); the
  // numbers are on the figure's footer and on stdout.
  ASSERT_EQ(run({"phantom", "--shape", "face", "--size", "64", "--seed", "3", "-o", file("ph"), "-q"}).status, 0);
  const test::RunResult r = run({"figure2", file("ph") + "/volume.nrrd", "-o", file("fig.png")});
  ASSERT_EQ(r.status, 0) << r.err;
  const std::size_t at = r.out.find("contour roughness");
  ASSERT_NE(at, std::string::npos) << r.out;
  std::map<char, std::pair<int, double>> stats;
  for (char panel : {'b', 'c', 'd', 'e', 'f'}) {
    const std::size_t q = r.out.find(std::string("(") + panel + ") ", at);
    ASSERT_NE(q, std::string::npos) << panel << ": " << r.out;
    int blobs = -1;
    double rough = -1;
    ASSERT_EQ(std::sscanf(r.out.c_str() + q + 4, "%d / %lf", &blobs, &rough), 2) << r.out.substr(q, 40);
    stats[panel] = {blobs, rough};
  }
  for (char smooth : {'e', 'f'})
    for (char rough : {'c', 'd'}) {
      EXPECT_LT(stats[smooth].second, stats[rough].second) << smooth << " vs " << rough;
      EXPECT_LE(stats[smooth].first, stats[rough].first) << smooth << " vs " << rough;
    }
  EXPECT_GE(stats['e'].second, 0.5) << "a contour exists";
}

TEST_F(CliFigure2, FloatDataWhoseFillIsNotZeroKeepTheirMask) {
  // A face phantom slice as float data with an unswept wedge at 0, and the
  // same plus 500, fill and all: figure2 finds the fill as classify does
  // (host/mask.hpp, unscanned_fill_value), so the mask, the panels' blob
  // counts and roughness are the same, and the isovalue shown is 500 higher
  // (the file's units). Before, the shifted fill was data: no mask.
  ASSERT_EQ(run({"phantom", "--shape", "face", "--size", "48", "--seed", "3", "-o", file("ph"), "-q"}).status, 0);
  const Volume v = read_volume(file("ph") + "/volume.nrrd");
  Volume f = v.with_data(v.data, ScalarType::Float32);
  for (std::size_t z = 0; z < f.dims[2]; ++z)
    for (std::size_t y = 0; y < f.dims[1]; ++y)
      for (std::size_t x = 0; x + z / 4 < 10; ++x) f.at(x, y, z) = 0.0f;
  std::vector<std::string> outs;
  std::vector<double> isos;
  for (const float c : {0.0f, 500.0f}) {
    Volume g = f;
    for (float& x : g.data) x += c;
    const std::string in = file("f" + std::to_string(int(c)) + ".nrrd");
    write_volume(in, g);
    const test::RunResult r = run({"figure2", in, "-o", file("fig" + std::to_string(int(c)) + ".png")});
    ASSERT_EQ(r.status, 0) << r.err;
    const std::size_t m = r.out.find("  mask     "), iso = r.out.find("  iso      ");
    ASSERT_NE(m, std::string::npos) << r.out;
    ASSERT_NE(iso, std::string::npos) << r.out;
    isos.push_back(std::atof(r.out.c_str() + iso + 11));
    const std::size_t dev = r.out.find("  device ");
    ASSERT_NE(dev, std::string::npos) << r.out;
    outs.push_back(r.out.substr(m, dev - m));  // the mask, panels and slice lines
  }
  EXPECT_EQ(outs[1], outs[0]);
  EXPECT_EQ(outs[0].find(", 0 voxels unscanned"), std::string::npos) << "the wedge is unscanned: " << outs[0];
  EXPECT_NEAR(isos[1] - isos[0], 500.0, 1e-3);
}

TEST_F(CliFigure2, BadArgumentsAreOneLineErrors) {
  const std::string in = write_volume_file();
  const std::string out = file("fig.png");
  expect_one_line_error(run({"figure2", in, "-o", out, "--slice", "q"}), {"--slice", "'q'"});
  expect_one_line_error(run({"figure2", in, "-o", out, "--slice", "y:"}), {"--slice"});
  expect_one_line_error(run({"figure2", in, "-o", out, "--slice", "y:-1"}), {"--slice"});
  expect_one_line_error(run({"figure2", in, "-o", out, "--slice", "y:20"}), {"--slice", "out of range", "20"});
  expect_one_line_error(run({"figure2", in, "-o", out, "--slice", "z:3x"}), {"--slice"});
  expect_one_line_error(run({"figure2", in, "-o", out, "--iso", "abc"}), {"--iso", "abc"});
  expect_one_line_error(run({"figure2", in, "-o", out, "--zoom", "-2"}), {"--zoom"});
  expect_one_line_error(run({"figure2", in, "-o", out, "--beta", "-1"}), {"--beta"});
  expect_one_line_error(run({"figure2", file("missing.nrrd"), "-o", out}), {"missing.nrrd"});
  write_volume(file("small.nrrd"), Volume({4, 4, 4}, {1, 1, 1}, ScalarType::UInt8));
  expect_one_line_error(run({"figure2", in, "-o", out, "--mask", file("small.nrrd")}), {"--mask", "4x4x4"});
  expect_one_line_error(run({"figure2", in, "-o", in}), {"in.nrrd"});
  expect_one_line_error(run({"figure2", in}), {"--output"});
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace softshell
