// PNG I/O through libpng and the orthogonal-slice montage.
#include "image.hpp"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdio>
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
  } catch (...) {
    png_error(png, "write failed");
  }
}
void png_flush_noop(png_structp) {}

}  // namespace

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

Image slice_montage(const std::vector<const Volume*>& volumes, int height) {
  struct Slice {
    int axis_u, axis_v;  // image x and y run along these volume axes
    int fixed_axis;
  };
  // Axial: x right, y down. Coronal: x right, z down. Sagittal: y right, z down.
  const Slice slices[3] = {{0, 1, 2}, {0, 2, 1}, {1, 2, 0}};
  const int gap = 4;
  std::vector<Image> rows;
  for (const Volume* v : volumes) {
    const double h = std::min({v->spacing[0], v->spacing[1], v->spacing[2]});
    const IntensityMap map = v->intensity_map();
    std::vector<Image> panels;
    for (const Slice& s : slices) {
      const double extent_u = v->dims[s.axis_u] * v->spacing[s.axis_u];
      const double extent_v = v->dims[s.axis_v] * v->spacing[s.axis_v];
      int w = std::max(1, int(std::lround(extent_u / h))), ht = std::max(1, int(std::lround(extent_v / h)));
      if (height > 0) {
        const double scale = double(height) / std::max(extent_v / h, 1.0);
        w = std::max(1, int(std::lround(w * scale)));
        ht = height;
      }
      Image p(w, ht);
      std::size_t c[3];
      c[s.fixed_axis] = v->dims[s.fixed_axis] / 2;
      for (int py = 0; py < ht; ++py)
        for (int px = 0; px < w; ++px) {
          c[s.axis_u] = std::min(v->dims[s.axis_u] - 1, std::size_t((px + 0.5) * v->dims[s.axis_u] / w));
          c[s.axis_v] = std::min(v->dims[s.axis_v] - 1, std::size_t((py + 0.5) * v->dims[s.axis_v] / ht));
          const double u = std::clamp(map.to_unit(v->at(c[0], c[1], c[2])), 0.0, 1.0);
          const auto g = static_cast<std::uint8_t>(std::lround(255.0 * u));
          std::uint8_t* q = p.pixel(px, py);
          q[0] = q[1] = q[2] = g;
        }
      panels.push_back(std::move(p));
    }
    int w = 0, ht = 0;
    for (const auto& p : panels) w += p.width + gap, ht = std::max(ht, p.height);
    Image row(w - gap, ht, 32);
    int x0 = 0;
    for (const auto& p : panels) {
      for (int y = 0; y < p.height; ++y) std::copy_n(p.pixel(0, y), p.width * 3, row.pixel(x0, y));
      x0 += p.width + gap;
    }
    rows.push_back(std::move(row));
  }
  int w = 0, ht = 0;
  for (const auto& r : rows) w = std::max(w, r.width), ht += r.height + gap;
  Image out(std::max(w, 1), std::max(ht - gap, 1), 32);
  int y0 = 0;
  for (const auto& r : rows) {
    for (int y = 0; y < r.height; ++y) std::copy_n(r.pixel(0, y), r.width * 3, out.pixel(0, y0 + y));
    y0 += r.height + gap;
  }
  return out;
}

}  // namespace softshell
