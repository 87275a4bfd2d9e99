// Picture sheet of the randomised phantom family (docs/phantom.md):
//   softshell_phantom_family OUT.png SIZE SPEC... [--outline] [--height=PX]
// SPEC is shape:physics:seed[@size] (e.g. face:random:3, spine:harsh:1@256;
// the size defaults to SIZE). Each case
// is one tile: its axial | coronal | sagittal mid-slices (`phantom --slices`'s
// first row, or with --outline its second: the true boundary in orange, the
// near-field layers in cyan), captioned with the case and a few of its
// parameters; two tiles per row.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "cl_runtime.hpp"
#include "error.hpp"
#include "image.hpp"
#include "phantom.hpp"

using namespace softshell;

namespace {

Image crop_row(const Image& two_rows, bool second) {
  const int h = (two_rows.height - 4) / 2;
  Image out(two_rows.width, h);
  const int y0 = second ? h + 4 : 0;
  for (int y = 0; y < h; ++y) std::copy_n(two_rows.pixel(0, y0 + y), two_rows.width * 3, out.pixel(0, y));
  return out;
}

std::string caption(const std::string& spec, const PhantomParams& pp, const Phantom& p) {
  std::ostringstream s;
  s.precision(3);
  s << spec;
  if (pp.physics) {
    const PhantomPhysics& q = *pp.physics;
    s << "  " << p.volume.dims[0] << "^3 " << beam_geometry_name(q.geometry) << ", " << p.volume.spacing[0] << " mm, DR " << q.dynamic_range_db
      << " dB, grey " << q.tissue_grey << ", near " << q.near_field_mm << " mm";
  }
  return s.str();
}

}  // namespace

int main(int argc, char** argv) {
  try {
    std::vector<std::string> args(argv + 1, argv + argc);
    bool outline = false;
    int height = 200;  // panel height, pixels
    args.erase(std::remove_if(args.begin(), args.end(),
                              [&](const std::string& a) {
                                if (a == "--outline") return outline = true;
                                if (a.rfind("--height=", 0) == 0) return (height = std::stoi(a.substr(9))) > 0;
                                return false;
                              }),
               args.end());
    if (args.size() < 3) {
      std::cerr << "usage: softshell_phantom_family OUT.png SIZE shape:physics:seed[@size]... [--outline] [--height=PX]\n";
      return 2;
    }
    const std::string out = args[0];
    const int size = std::stoi(args[1]);
    Runtime rt("");
    std::vector<Image> tiles;
    for (std::size_t i = 2; i < args.size(); ++i) {
      std::string spec = args[i];
      int case_size = size;
      if (const std::size_t at = spec.find('@'); at != std::string::npos) {
        case_size = std::stoi(spec.substr(at + 1));
        spec = spec.substr(0, at);
      }
      const std::size_t a = spec.find(':'), b = spec.rfind(':');
      if (a == std::string::npos || a == b) throw InputError("bad spec '" + spec + "', expected shape:physics:seed");
      PhantomParams pp;
      if (!parse_phantom_shape(spec.substr(0, a), pp.shape)) throw InputError("bad shape in '" + spec + "'");
      pp.size = case_size;
      pp.seed = std::stoull(spec.substr(b + 1));
      pp.physics_name = spec.substr(a + 1, b - a - 1);
      pp.physics = phantom_physics(pp.physics_name, pp.shape, pp.seed);
      const Phantom p = make_phantom(rt, pp);
      const Image row = crop_row(phantom_slices(p, height), outline);
      Image tile(row.width, row.height + 16, 24);
      for (int y = 0; y < row.height; ++y) std::copy_n(row.pixel(0, y), row.width * 3, tile.pixel(0, 16 + y));
      draw_text(tile, 3, 4, caption(spec, pp, p), Rgb{255, 230, 120});
      tiles.push_back(std::move(tile));
      std::printf("%-24s %.2f s  fluid %.0f tissue %.0f near %.0f\n", spec.c_str(), p.seconds, p.fluid_median,
                  p.tissue_median, p.near_field_median);
    }
    const int cols = 2, gap = 6;
    const int tw = tiles[0].width, th = tiles[0].height;
    const int rows = static_cast<int>((tiles.size() + cols - 1) / cols);
    Image sheet(cols * tw + (cols - 1) * gap, rows * th + (rows - 1) * gap, 48);
    for (std::size_t i = 0; i < tiles.size(); ++i) {
      const int x0 = static_cast<int>(i % cols) * (tw + gap), y0 = static_cast<int>(i / cols) * (th + gap);
      for (int y = 0; y < std::min(th, tiles[i].height); ++y)
        std::copy_n(tiles[i].pixel(0, y), std::min(tw, tiles[i].width) * 3, sheet.pixel(x0, y0 + y));
    }
    write_png(out, sheet);
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "softshell_phantom_family: " << e.what() << '\n';
    return 2;
  }
}
