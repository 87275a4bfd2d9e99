// 8-bit RGB images: PNG output (libpng, written atomically like every output),
// the orthogonal-slice montage behind `softshell slices`, and text for
// labelling figures.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "volume.hpp"

namespace softshell {

struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;  // width * height * 3, rows top to bottom

  Image() = default;
  Image(int w, int h, std::uint8_t fill = 0) : width(w), height(h), rgb(std::size_t(w) * h * 3, fill) {}
  std::uint8_t* pixel(int x, int y) { return &rgb[(std::size_t(y) * width + x) * 3]; }
  const std::uint8_t* pixel(int x, int y) const { return &rgb[(std::size_t(y) * width + x) * 3]; }
};

struct Rgb {
  std::uint8_t r = 0, g = 0, b = 0;
};

// Fills the rectangle [x, x + w) x [y, y + h), clipped to the image.
void fill_rect(Image& image, int x, int y, int w, int h, Rgb colour);
// Copies `src` into `dst` with its top-left corner at (x0, y0), x0 >= 0;
// rows and columns beyond dst are left out.
void blit(Image& dst, const Image& src, int x0, int y0);

// Draws ASCII text, top-left corner at (x, y), in DejaVu Sans (TrueType,
// anti-aliased, 11 * scale pixels per em: capitals 8 * scale pixels high)
// when its file is there ($SOFTSHELL_FONT, else Debian's fonts-dejavu-core),
// else in the bitmap font below. '\n' starts a new line; characters outside
// printable ASCII draw as '?'. Only glyph pixels are written (blended over
// the image, no background), clipped to the image.
void draw_text(Image& image, int x, int y, const std::string& text, Rgb colour, int scale = 1);
// Width and height in pixels that draw_text covers (0 for empty text).
int text_width(const std::string& text, int scale = 1);
int text_height(const std::string& text, int scale = 1);
// Lines of at most `width` pixels (a word wider than that stands alone on
// its line); '\n' in the text starts a new line.
std::vector<std::string> wrap_text(const std::string& text, int width, int scale = 1);
// Whether draw_text uses the TrueType font, and its file ("" if not).
bool truetype_text();
std::string text_font_path();

// The built-in 5x7 bitmap font (5x9 with the descenders of g, j, p, q, y),
// each font pixel a scale x scale block; glyphs advance 6 * scale pixels,
// '\n' starts a new line 11 * scale pixels lower.
void draw_bitmap_text(Image& image, int x, int y, const std::string& text, Rgb colour, int scale = 1);
int bitmap_text_width(const std::string& text, int scale = 1);
int bitmap_text_height(const std::string& text, int scale = 1);

// The depth colour map of the renderers (viewer/shaders: splat.vert and
// mesh.frag, SlicerHeart-style), t in [0, 1] from near the transducer to
// deep: light skin tone, orange-brown, dark red-brown.
Rgb depth_colour(double t);
// A colour bar of depth_colour over the right edge of a rendered image:
// the bar (12 px wide, half the image high, centred vertically, 10 px from
// the edge), "depth" above it and the near and far depths (mm) beside its
// ends. Returns the bar's rectangle {x, y, w, h}; nothing is drawn (w = 0)
// on an image too small to hold it.
std::array<int, 4> draw_depth_legend(Image& image, double near_mm, double far_mm);

void write_png(const std::string& path, const Image& image);
Image read_png(const std::string& path);  // RGB8 (other layouts converted)

// One row per volume: the axial (XY at mid z), coronal (XZ at mid y) and
// sagittal (YZ at mid x) slices, resampled to square pixels of the volume's
// smallest spacing, grey levels from each volume's intensity map. With
// `height` > 0 every row is scaled to that many pixels high.
Image slice_montage(const std::vector<const Volume*>& volumes, int height = 0);
// The same panels for people: each row headed by its label (e.g. the file
// name), each panel titled with its view and slice ("axial z 48"), a scale
// bar of a round length in the axial panel's lower left corner, on a dark
// blue-grey ground. `softshell slices` writes this unless --plain.
Image labelled_slice_montage(const std::vector<const Volume*>& volumes, const std::vector<std::string>& labels,
                             int height = 0);

}  // namespace softshell
