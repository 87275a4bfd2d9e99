// PNG I/O through libpng, the orthogonal-slice montage, and text: DejaVu
// Sans through stb_truetype (Debian's libstb and fonts-dejavu-core), the
// built-in bitmap font where the font file is missing.
#include "image.hpp"

#include <png.h>
#include <stb_truetype.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <memory>

#include "error.hpp"
#include "io.hpp"

namespace softshell {
namespace {

void png_error_fn(png_structp png, png_const_charp msg) {
  *static_cast<std::string*>(png_get_error_ptr(png)) = msg;
  png_longjmp(png, 1);
}
void png_warning_fn(png_structp, png_const_charp) {}

void png_write_to_atomic(png_structp png, png_bytep data, png_size_t n) {
  auto* f = static_cast<io_detail::AtomicFile*>(png_get_io_ptr(png));
  try {
    f->write(data, n);
  } catch (const std::exception& e) {
    png_error(png, e.what());  // "<path>: cannot write: <why>", passed on as it is
  }
}
void png_flush_noop(png_structp) {}

// The classic 5x7 ASCII font, printable characters 0x20..0x7E: five columns
// per glyph, bit 0 the top row; g, j, p, q and y are redrawn below with
// descenders in two more rows (without them "g" read as "9" and "p" as "P").
constexpr std::uint16_t kFont5x7[95][5] = {
    {0x00, 0x00, 0x00, 0x00, 0x00}, {0x00, 0x00, 0x5F, 0x00, 0x00}, {0x00, 0x07, 0x00, 0x07, 0x00},  //  !"
    {0x14, 0x7F, 0x14, 0x7F, 0x14}, {0x24, 0x2A, 0x7F, 0x2A, 0x12}, {0x23, 0x13, 0x08, 0x64, 0x62},  // #$%
    {0x36, 0x49, 0x55, 0x22, 0x50}, {0x00, 0x05, 0x03, 0x00, 0x00}, {0x00, 0x1C, 0x22, 0x41, 0x00},  // &'(
    {0x00, 0x41, 0x22, 0x1C, 0x00}, {0x08, 0x2A, 0x1C, 0x2A, 0x08}, {0x08, 0x08, 0x3E, 0x08, 0x08},  // )*+
    {0x00, 0x50, 0x30, 0x00, 0x00}, {0x08, 0x08, 0x08, 0x08, 0x08}, {0x00, 0x60, 0x60, 0x00, 0x00},  // ,-.
    {0x20, 0x10, 0x08, 0x04, 0x02}, {0x3E, 0x51, 0x49, 0x45, 0x3E}, {0x00, 0x42, 0x7F, 0x40, 0x00},  // /01
    {0x42, 0x61, 0x51, 0x49, 0x46}, {0x21, 0x41, 0x45, 0x4B, 0x31}, {0x18, 0x14, 0x12, 0x7F, 0x10},  // 234
    {0x27, 0x45, 0x45, 0x45, 0x39}, {0x3C, 0x4A, 0x49, 0x49, 0x30}, {0x01, 0x71, 0x09, 0x05, 0x03},  // 567
    {0x36, 0x49, 0x49, 0x49, 0x36}, {0x06, 0x49, 0x49, 0x29, 0x1E}, {0x00, 0x36, 0x36, 0x00, 0x00},  // 89:
    {0x00, 0x56, 0x36, 0x00, 0x00}, {0x08, 0x14, 0x22, 0x41, 0x00}, {0x14, 0x14, 0x14, 0x14, 0x14},  // ;<=
    {0x00, 0x41, 0x22, 0x14, 0x08}, {0x02, 0x01, 0x51, 0x09, 0x06}, {0x32, 0x49, 0x79, 0x41, 0x3E},  // >?@
    {0x7E, 0x11, 0x11, 0x11, 0x7E}, {0x7F, 0x49, 0x49, 0x49, 0x36}, {0x3E, 0x41, 0x41, 0x41, 0x22},  // ABC
    {0x7F, 0x41, 0x41, 0x22, 0x1C}, {0x7F, 0x49, 0x49, 0x49, 0x41}, {0x7F, 0x09, 0x09, 0x01, 0x01},  // DEF
    {0x3E, 0x41, 0x41, 0x51, 0x32}, {0x7F, 0x08, 0x08, 0x08, 0x7F}, {0x00, 0x41, 0x7F, 0x41, 0x00},  // GHI
    {0x20, 0x40, 0x41, 0x3F, 0x01}, {0x7F, 0x08, 0x14, 0x22, 0x41}, {0x7F, 0x40, 0x40, 0x40, 0x40},  // JKL
    {0x7F, 0x02, 0x04, 0x02, 0x7F}, {0x7F, 0x04, 0x08, 0x10, 0x7F}, {0x3E, 0x41, 0x41, 0x41, 0x3E},  // MNO
    {0x7F, 0x09, 0x09, 0x09, 0x06}, {0x3E, 0x41, 0x51, 0x21, 0x5E}, {0x7F, 0x09, 0x19, 0x29, 0x46},  // PQR
    {0x46, 0x49, 0x49, 0x49, 0x31}, {0x01, 0x01, 0x7F, 0x01, 0x01}, {0x3F, 0x40, 0x40, 0x40, 0x3F},  // STU
    {0x1F, 0x20, 0x40, 0x20, 0x1F}, {0x7F, 0x20, 0x18, 0x20, 0x7F}, {0x63, 0x14, 0x08, 0x14, 0x63},  // VWX
    {0x03, 0x04, 0x78, 0x04, 0x03}, {0x61, 0x51, 0x49, 0x45, 0x43}, {0x00, 0x7F, 0x41, 0x41, 0x00},  // YZ[
    {0x02, 0x04, 0x08, 0x10, 0x20}, {0x00, 0x41, 0x41, 0x7F, 0x00}, {0x04, 0x02, 0x01, 0x02, 0x04},  // \]^
    {0x40, 0x40, 0x40, 0x40, 0x40}, {0x00, 0x01, 0x02, 0x04, 0x00}, {0x20, 0x54, 0x54, 0x54, 0x78},  // _`a
    {0x7F, 0x48, 0x44, 0x44, 0x38}, {0x38, 0x44, 0x44, 0x44, 0x20}, {0x38, 0x44, 0x44, 0x48, 0x7F},  // bcd
    {0x38, 0x54, 0x54, 0x54, 0x18}, {0x08, 0x7E, 0x09, 0x01, 0x02}, {0x08, 0x14, 0x54, 0x54, 0x3C},  // efg
    {0x7F, 0x08, 0x04, 0x04, 0x78}, {0x00, 0x44, 0x7D, 0x40, 0x00}, {0x20, 0x40, 0x44, 0x3D, 0x00},  // hij
    {0x00, 0x7F, 0x10, 0x28, 0x44}, {0x00, 0x41, 0x7F, 0x40, 0x00}, {0x7C, 0x04, 0x18, 0x04, 0x78},  // klm
    {0x7C, 0x08, 0x04, 0x04, 0x78}, {0x38, 0x44, 0x44, 0x44, 0x38}, {0x7C, 0x14, 0x14, 0x14, 0x08},  // nop
    {0x08, 0x14, 0x14, 0x18, 0x7C}, {0x7C, 0x08, 0x04, 0x04, 0x08}, {0x48, 0x54, 0x54, 0x54, 0x20},  // qrs
    {0x04, 0x3F, 0x44, 0x40, 0x20}, {0x3C, 0x40, 0x40, 0x20, 0x7C}, {0x1C, 0x20, 0x40, 0x20, 0x1C},  // tuv
    {0x3C, 0x40, 0x30, 0x40, 0x3C}, {0x44, 0x28, 0x10, 0x28, 0x44}, {0x0C, 0x50, 0x50, 0x50, 0x3C},  // wxy
    {0x44, 0x64, 0x54, 0x4C, 0x44}, {0x00, 0x08, 0x36, 0x41, 0x00}, {0x00, 0x00, 0x7F, 0x00, 0x00},  // z{|
    {0x00, 0x41, 0x36, 0x08, 0x00}, {0x08, 0x04, 0x08, 0x10, 0x08},                                  // }~
};

constexpr int kGlyphRows = 9;    // 7 above the baseline, 2 of descenders
constexpr int kLineAdvance = 11;  // rows from one line's top to the next's
constexpr const char* kDefaultFont = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

}  // namespace

void fill_rect(Image& image, int x, int y, int w, int h, Rgb colour) {
  const int x0 = std::max(x, 0), y0 = std::max(y, 0);
  const int x1 = std::min(x + w, image.width), y1 = std::min(y + h, image.height);
  for (int py = y0; py < y1; ++py)
    for (int px = x0; px < x1; ++px) {
      std::uint8_t* q = image.pixel(px, py);
      q[0] = colour.r, q[1] = colour.g, q[2] = colour.b;
    }
}

void blit(Image& dst, const Image& src, int x0, int y0) {
  for (int y = 0; y < src.height; ++y)
    if (y0 + y >= 0 && y0 + y < dst.height)
      std::copy_n(src.pixel(0, y), std::min(src.width, dst.width - x0) * 3, dst.pixel(x0, y0 + y));
}

// Rows 0-8: the lower-case letters with descenders (x-height rows 2-6 as
// the rest of the font, descender rows 7-8).
const std::uint16_t* glyph_of(char ch) {
  static constexpr std::uint16_t kG[5] = {0x038, 0x144, 0x144, 0x144, 0x0FC};
  static constexpr std::uint16_t kJ[5] = {0x100, 0x100, 0x104, 0x0FD, 0x000};
  static constexpr std::uint16_t kP[5] = {0x1FC, 0x044, 0x044, 0x044, 0x038};
  static constexpr std::uint16_t kQ[5] = {0x038, 0x044, 0x044, 0x044, 0x1FC};
  static constexpr std::uint16_t kY[5] = {0x03C, 0x140, 0x140, 0x140, 0x0FC};
  switch (ch) {
    case 'g': return kG;
    case 'j': return kJ;
    case 'p': return kP;
    case 'q': return kQ;
    case 'y': return kY;
    default: break;
  }
  const int code = static_cast<unsigned char>(ch);
  return kFont5x7[(code >= 0x20 && code <= 0x7E ? code : '?') - 0x20];
}

namespace {

// The TrueType font, loaded once: $SOFTSHELL_FONT, else DejaVu Sans.
struct Font {
  std::string path;
  std::vector<unsigned char> ttf;
  stbtt_fontinfo info{};
  int ascent = 0, descent = 0, gap = 0;  // font units
  bool ok = false;
};

const Font& font() {
  static const Font f = [] {
    Font f;
    const char* env = std::getenv("SOFTSHELL_FONT");
    for (const std::string& path : {std::string(env ? env : ""), std::string(kDefaultFont)}) {
      if (path.empty()) continue;
      std::ifstream in(path, std::ios::binary);
      if (!in) continue;
      f.ttf.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
      const int offset = f.ttf.empty() ? -1 : stbtt_GetFontOffsetForIndex(f.ttf.data(), 0);
      if (offset >= 0 && stbtt_InitFont(&f.info, f.ttf.data(), offset) &&
          stbtt_FindGlyphIndex(&f.info, 'g') != 0) {
        stbtt_GetFontVMetrics(&f.info, &f.ascent, &f.descent, &f.gap);
        f.path = path;
        f.ok = true;
        break;
      }
      f.ttf.clear();
    }
    return f;
  }();
  return f;
}

// Pixels per em for a scale: 11 px at scale 1 (cap height 8 px).
float em_scale(const Font& f, int scale) { return stbtt_ScaleForMappingEmToPixels(&f.info, 11.0f * float(scale)); }
int line_advance(const Font& f, float sc) { return int(std::lround(float(f.ascent - f.descent + f.gap) * sc)); }
int printable(char ch) {
  const int code = static_cast<unsigned char>(ch);
  return code >= 0x20 && code <= 0x7E ? code : '?';
}

// Calls f(line, begin, end) for each '\n'-separated line of `text`.
template <class F>
void for_each_line(const std::string& text, F&& f) {
  std::size_t begin = 0;
  for (int line = 0; begin <= text.size(); ++line) {
    std::size_t end = text.find('\n', begin);
    if (end == std::string::npos) end = text.size();
    f(line, begin, end);
    begin = end + 1;
  }
}

// Walks the glyphs of text[begin, end) from pen position `pen`, calling
// glyph(codepoint, pen) for each, advancing by the glyph's advance and the
// kerning to the next; returns the pen after the last glyph.
template <class G>
float walk_glyphs(const Font& f, float sc, const std::string& text, std::size_t begin, std::size_t end, float pen,
                  G&& glyph) {
  for (std::size_t i = begin; i < end; ++i) {
    const int c = printable(text[i]);
    int adv = 0, lsb = 0;
    stbtt_GetCodepointHMetrics(&f.info, c, &adv, &lsb);
    glyph(c, pen);
    pen += float(adv) * sc;
    if (i + 1 < end) pen += float(stbtt_GetCodepointKernAdvance(&f.info, c, printable(text[i + 1]))) * sc;
  }
  return pen;
}

}  // namespace

std::vector<std::string> wrap_text(const std::string& text, int width, int scale) {
  std::vector<std::string> lines;
  for_each_line(text, [&](int, std::size_t begin, std::size_t end) {
    std::string line;
    for (std::size_t i = begin; i < end;) {
      // The next word with the spaces before it (kept, so that aligned
      // columns of a footer stay aligned).
      std::size_t j = i;
      while (j < end && text[j] == ' ') ++j;
      while (j < end && text[j] != ' ') ++j;
      const std::string piece = text.substr(i, j - i);
      if (!line.empty() && text_width(line + piece, scale) > width) {
        lines.push_back(line);
        line = piece.substr(std::min(piece.find_first_not_of(' '), piece.size()));
      } else {
        line += piece;
      }
      i = j;
    }
    lines.push_back(line);
  });
  return lines;
}

Rgb depth_colour(double t) {
  t = std::clamp(t, 0.0, 1.0);
  auto mix = [](const double a[3], const double b[3], double f) {
    return Rgb{std::uint8_t(std::lround(255 * (a[0] + (b[0] - a[0]) * f))),
               std::uint8_t(std::lround(255 * (a[1] + (b[1] - a[1]) * f))),
               std::uint8_t(std::lround(255 * (a[2] + (b[2] - a[2]) * f)))};
  };
  static const double near[3] = {1.0, 0.9, 0.72}, mid[3] = {0.93, 0.55, 0.33}, deep[3] = {0.5, 0.16, 0.12};
  return t < 0.5 ? mix(near, mid, 2 * t) : mix(mid, deep, 2 * t - 1);
}

std::array<int, 4> draw_depth_legend(Image& image, double near_mm, double far_mm) {
  auto mm = [](double v) {
    char b[32];
    std::snprintf(b, sizeof b, std::abs(v) < 100 ? "%.1f mm" : "%.0f mm", v);
    return std::string(b);
  };
  const std::string top = mm(near_mm), bottom = mm(far_mm);
  const int bw = 12, bh = image.height / 2;
  const int label_w = std::max({text_width(top), text_width(bottom), text_width("depth")});
  const int bx = image.width - 10 - bw, by = (image.height - bh) / 2;
  const int line = text_height("Ag");
  if (bh < 3 * line || bx - 6 - label_w < image.width / 2 || by - line - 4 < 0) return {0, 0, 0, 0};
  const Rgb text{220, 220, 220};
  for (int y = 0; y < bh; ++y) fill_rect(image, bx, by + y, bw, 1, depth_colour(bh > 1 ? double(y) / (bh - 1) : 0.0));
  draw_text(image, bx + bw - text_width("depth"), by - line - 4, "depth", text);
  draw_text(image, bx - 6 - text_width(top), by, top, text);
  draw_text(image, bx - 6 - text_width(bottom), by + bh - line, bottom, text);
  return {bx, by, bw, bh};
}

bool truetype_text() { return font().ok; }
std::string text_font_path() { return font().path; }

void draw_text(Image& image, int x, int y, const std::string& text, Rgb colour, int scale) {
  const Font& f = font();
  if (!f.ok) {
    draw_bitmap_text(image, x, y, text, colour, scale);
    return;
  }
  const float sc = em_scale(f, std::max(scale, 1));
  const int baseline0 = y + int(std::lround(float(f.ascent) * sc));
  const int advance = line_advance(f, sc);
  for_each_line(text, [&](int line, std::size_t begin, std::size_t end) {
    const int baseline = baseline0 + line * advance;
    walk_glyphs(f, sc, text, begin, end, float(x), [&](int c, float pen) {
      const float shift = pen - std::floor(pen);
      int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
      stbtt_GetCodepointBitmapBoxSubpixel(&f.info, c, sc, sc, shift, 0, &x0, &y0, &x1, &y1);
      const int w = x1 - x0, h = y1 - y0;
      if (w <= 0 || h <= 0) return;
      std::vector<unsigned char> alpha(std::size_t(w) * std::size_t(h));
      stbtt_MakeCodepointBitmapSubpixel(&f.info, alpha.data(), w, h, w, sc, sc, shift, 0, c);
      const int ox = int(std::floor(pen)) + x0, oy = baseline + y0;
      for (int gy = 0; gy < h; ++gy) {
        const int py = oy + gy;
        if (py < 0 || py >= image.height) continue;
        for (int gx = 0; gx < w; ++gx) {
          const int px = ox + gx;
          const int a = alpha[std::size_t(gy) * std::size_t(w) + std::size_t(gx)];
          if (px < 0 || px >= image.width || a == 0) continue;
          std::uint8_t* q = image.pixel(px, py);
          q[0] = std::uint8_t((q[0] * (255 - a) + colour.r * a + 127) / 255);
          q[1] = std::uint8_t((q[1] * (255 - a) + colour.g * a + 127) / 255);
          q[2] = std::uint8_t((q[2] * (255 - a) + colour.b * a + 127) / 255);
        }
      }
    });
  });
}

int text_width(const std::string& text, int scale) {
  const Font& f = font();
  if (!f.ok) return bitmap_text_width(text, scale);
  const float sc = em_scale(f, std::max(scale, 1));
  float widest = 0;
  for_each_line(text, [&](int, std::size_t begin, std::size_t end) {
    widest = std::max(widest, walk_glyphs(f, sc, text, begin, end, 0.0f, [](int, float) {}));
  });
  return int(std::ceil(widest));
}

int text_height(const std::string& text, int scale) {
  const Font& f = font();
  if (!f.ok) return bitmap_text_height(text, scale);
  if (text.empty()) return 0;
  const float sc = em_scale(f, std::max(scale, 1));
  const int lines = 1 + int(std::count(text.begin(), text.end(), '\n'));
  return line_advance(f, sc) * (lines - 1) + int(std::lround(float(f.ascent - f.descent) * sc));
}

void draw_bitmap_text(Image& image, int x, int y, const std::string& text, Rgb colour, int scale) {
  scale = std::max(scale, 1);
  int cx = x, cy = y;
  for (const char ch : text) {
    if (ch == '\n') {
      cx = x, cy += kLineAdvance * scale;
      continue;
    }
    const std::uint16_t* glyph = glyph_of(ch);
    for (int col = 0; col < 5; ++col)
      for (int row = 0; row < kGlyphRows; ++row)
        if (glyph[col] >> row & 1) fill_rect(image, cx + col * scale, cy + row * scale, scale, scale, colour);
    cx += 6 * scale;
  }
}

int bitmap_text_width(const std::string& text, int scale) {
  scale = std::max(scale, 1);
  int widest = 0, chars = 0;
  for (const char ch : text) {
    if (ch == '\n') chars = 0;
    else widest = std::max(widest, ++chars);
  }
  return widest == 0 ? 0 : (6 * widest - 1) * scale;
}

int bitmap_text_height(const std::string& text, int scale) {
  scale = std::max(scale, 1);
  if (text.empty()) return 0;
  const int lines = 1 + int(std::count(text.begin(), text.end(), '\n'));
  return (kLineAdvance * (lines - 1) + kGlyphRows) * scale;
}

void write_png(const std::string& path, const Image& image) {
  if (image.width <= 0 || image.height <= 0) throw InputError(path + ": cannot write an empty image");
  io_detail::AtomicFile file(path);
  std::string err;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &err, png_error_fn, png_warning_fn);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_write_struct(&png, &info);
    throw std::bad_alloc();
  }
  std::vector<png_bytep> rows(image.height);
  for (int y = 0; y < image.height; ++y) rows[y] = const_cast<png_bytep>(image.pixel(0, y));
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    if (err.rfind(path + ": ", 0) == 0) throw InputError(err);  // a failed write (a full disk ...)
    throw InputError(path + ": cannot write PNG: " + err);
  }
  png_set_write_fn(png, &file, png_write_to_atomic, png_flush_noop);
  png_set_IHDR(png, info, image.width, image.height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_write_image(png, rows.data());
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  file.commit();
}

Image read_png(const std::string& path) {
  png_image img{};
  img.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&img, path.c_str()))
    throw InputError(path + ": cannot read PNG: " + img.message);
  img.format = PNG_FORMAT_RGB;
  Image out(static_cast<int>(img.width), static_cast<int>(img.height));
  if (!png_image_finish_read(&img, nullptr, out.rgb.data(), 0, nullptr)) {
    png_image_free(&img);
    throw InputError(path + ": cannot read PNG: " + img.message);
  }
  return out;
}

namespace {

// One panel of the montage and what it shows.
struct MontagePanel {
  Image image;
  int fixed_axis = 2;          // the axis the slice is taken across
  std::size_t index = 0;       // at this index along it
  double mm_per_pixel = 1.0;   // along the image's x
};

// The three mid-slices of `v`: axial (x right, y down), coronal (x right, z
// down), sagittal (y right, z down).
std::vector<MontagePanel> montage_panels(const Volume* v, int height) {
  struct Slice {
    int axis_u, axis_v;  // image x and y run along these volume axes
    int fixed_axis;
  };
  const Slice slices[3] = {{0, 1, 2}, {0, 2, 1}, {1, 2, 0}};
  const double h = std::min({v->spacing[0], v->spacing[1], v->spacing[2]});
  const IntensityMap map = v->intensity_map();
  std::vector<MontagePanel> panels;
  for (const Slice& s : slices) {
    const double extent_u = v->dims[s.axis_u] * v->spacing[s.axis_u];
    const double extent_v = v->dims[s.axis_v] * v->spacing[s.axis_v];
    int w = std::max(1, int(std::lround(extent_u / h))), ht = std::max(1, int(std::lround(extent_v / h)));
    if (height > 0) {
      const double scale = double(height) / std::max(extent_v / h, 1.0);
      w = std::max(1, int(std::lround(w * scale)));
      ht = height;
    }
    MontagePanel panel;
    panel.image = Image(w, ht);
    panel.fixed_axis = s.fixed_axis;
    panel.index = v->dims[s.fixed_axis] / 2;
    panel.mm_per_pixel = extent_u / w;
    std::size_t c[3];
    c[s.fixed_axis] = panel.index;
    for (int py = 0; py < ht; ++py)
      for (int px = 0; px < w; ++px) {
        c[s.axis_u] = std::min(v->dims[s.axis_u] - 1, std::size_t((px + 0.5) * v->dims[s.axis_u] / w));
        c[s.axis_v] = std::min(v->dims[s.axis_v] - 1, std::size_t((py + 0.5) * v->dims[s.axis_v] / ht));
        const double u = std::clamp(map.to_unit(v->at(c[0], c[1], c[2])), 0.0, 1.0);
        const auto g = static_cast<std::uint8_t>(std::lround(255.0 * u));
        std::uint8_t* q = panel.image.pixel(px, py);
        q[0] = q[1] = q[2] = g;
      }
    panels.push_back(std::move(panel));
  }
  return panels;
}

// A round length (1, 2 or 5 times a power of ten, in mm) of about a quarter
// of `span_mm`.
double scale_bar_mm(double span_mm) {
  const double target = std::max(span_mm / 4.0, 1e-9);
  const double p = std::pow(10.0, std::floor(std::log10(target)));
  for (double m : {5.0, 2.0, 1.0})
    if (m * p <= target) return m * p;
  return p;
}

std::string length_text(double mm) {
  char buf[32];
  if (mm >= 1.0) std::snprintf(buf, sizeof buf, "%g mm", mm);
  else std::snprintf(buf, sizeof buf, "%g um", mm * 1000.0);
  return buf;
}

}  // namespace

Image slice_montage(const std::vector<const Volume*>& volumes, int height) {
  const int gap = 4;
  std::vector<Image> rows;
  for (const Volume* v : volumes) {
    const std::vector<MontagePanel> panels = montage_panels(v, height);
    int w = 0, ht = 0;
    for (const auto& p : panels) w += p.image.width + gap, ht = std::max(ht, p.image.height);
    Image row(w - gap, ht, 32);
    int x0 = 0;
    for (const auto& p : panels) {
      blit(row, p.image, x0, 0);
      x0 += p.image.width + gap;
    }
    rows.push_back(std::move(row));
  }
  int w = 0, ht = 0;
  for (const auto& r : rows) w = std::max(w, r.width), ht += r.height + gap;
  Image out(std::max(w, 1), std::max(ht - gap, 1), 32);
  int y0 = 0;
  for (const auto& r : rows) {
    blit(out, r, 0, y0);
    y0 += r.height + gap;
  }
  return out;
}

Image labelled_slice_montage(const std::vector<const Volume*>& volumes, const std::vector<std::string>& labels,
                             int height) {
  const Rgb kBackground{24, 26, 34}, kLabel{235, 225, 170}, kTitle{160, 190, 230}, kBar{255, 214, 90};
  const int gap = 6, margin = 6, scale = 1;
  const int line = text_height("Ag", scale);
  const char* names[3] = {"axial", "coronal", "sagittal"};
  // Each row: its label, the panels' titles above them, the panels with a
  // scale bar in the axial panel's lower left corner.
  std::vector<Image> rows;
  for (std::size_t r = 0; r < volumes.size(); ++r) {
    const Volume* v = volumes[r];
    std::vector<MontagePanel> panels = montage_panels(v, height);
    int w = margin, ht = 0;
    for (const auto& p : panels) w += p.image.width + gap, ht = std::max(ht, p.image.height);
    w += margin - gap;
    const std::string label = r < labels.size() ? labels[r] : "";
    w = std::max(w, 2 * margin + text_width(label, scale));
    const int top = margin + line + 4 + line + 3;  // label, then the titles
    Image row(w, top + ht + margin);
    fill_rect(row, 0, 0, row.width, row.height, kBackground);
    draw_text(row, margin, margin, label, kLabel, scale);
    int x0 = margin;
    for (std::size_t k = 0; k < panels.size(); ++k) {
      MontagePanel& p = panels[k];
      if (k == 0) {
        // The scale bar: a round length, drawn with a dark outline so that
        // it reads on bright and dark data alike.
        const double bar_mm = scale_bar_mm(p.mm_per_pixel * p.image.width);
        const int bar_px = std::max(1, int(std::lround(bar_mm / p.mm_per_pixel)));
        const int bx = 4, by = p.image.height - 5;
        if (bar_px + 2 * bx < p.image.width && by > 4) {
          fill_rect(p.image, bx - 1, by - 1, bar_px + 2, 4, {0, 0, 0});
          fill_rect(p.image, bx, by, bar_px, 2, kBar);
          const std::string t = length_text(bar_mm);
          if (text_width(t, scale) + bx < p.image.width && by - line - 2 >= 0)
            draw_text(p.image, bx, by - line - 2, t, kBar, scale);
        }
      }
      const std::string title = std::string(names[k]) + " " + "xyz"[p.fixed_axis] + " " + std::to_string(p.index);
      draw_text(row, x0, margin + line + 4, title, kTitle, scale);
      blit(row, p.image, x0, top);
      x0 += p.image.width + gap;
    }
    rows.push_back(std::move(row));
  }
  int w = 0, ht = 0;
  for (const auto& r : rows) w = std::max(w, r.width), ht += r.height;
  Image out(std::max(w, 1), std::max(ht, 1));
  fill_rect(out, 0, 0, out.width, out.height, kBackground);
  int y0 = 0;
  for (const auto& r : rows) {
    blit(out, r, 0, y0);
    y0 += r.height;
  }
  return out;
}

}  // namespace softshell
