// 8-bit RGB images: PNG output (libpng, written atomically like every output)
// and the orthogonal-slice montage behind `softshell slices`.
#pragma once

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

void write_png(const std::string& path, const Image& image);
Image read_png(const std::string& path);  // RGB8 (other layouts converted)

// One row per volume: the axial (XY at mid z), coronal (XZ at mid y) and
// sagittal (YZ at mid x) slices, resampled to square pixels of the volume's
// smallest spacing, grey levels from each volume's intensity map. With
// `height` > 0 every row is scaled to that many pixels high.
Image slice_montage(const std::vector<const Volume*>& volumes, int height = 0);

}  // namespace softshell
