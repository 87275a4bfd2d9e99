// Splat generation for oriented splatting (paper Section 4.1) on the OpenCL
// device (kernels/splat.cl): one splat triangle per voxel with u > epsilon,
// centred at the voxel, perpendicular to the splat normal, alpha u. GL-free:
// the viewer (viewer/) only uploads the result. docs/rendering.md.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "cl_runtime.hpp"
#include "volume.hpp"

namespace softshell {

// Which field orients the splats and gives their shading normals; compiled
// into kernels/splat.cl's splat_normal() as -D SPLAT_NORMALS=<value>.
enum class SplatNormals : int {
  Gradient = 0,  // central-difference grad u per mm (the paper)
  Tensor = 1,    // structure tensor of u (kernels/orientation.h; the default)
  Data = 2,      // the same tensor of the data (host/orientation.hpp, data_orientation_field)
};
const char* splat_normals_name(SplatNormals n);  // "gradient", "tensor", "data"
// Parses "gradient" / "tensor" / "data"; false when unknown.
bool parse_splat_normals(const std::string& name, SplatNormals& out);

// How lambda follows from epsilon. The paper prints lambda = -0.25 ln eps
// and says this makes G = eps on the inscribed circle (radius 0.5); it does
// not: G(0.5) = exp(1 / ln eps), 0.54 for eps = 0.2. `Rim` takes the stated
// condition instead, lambda = -0.25 / ln eps (G(0.5) = eps, larger
// triangles). Both give the paper's ~0.95 midway opacity, since a^2 lambda
// = 1 either way. docs/rendering.md compares them.
enum class SplatGaussian : int {
  Paper = 0,  // lambda = -0.25 ln eps, as printed (the contract)
  Rim = 1,    // lambda = -0.25 / ln eps: G = eps at the window's edge
};
const char* splat_gaussian_name(SplatGaussian g);  // "paper", "rim"

enum class SplatCentres : int {
  Voxel = 0,  // the voxel's centre (the paper)
  Shell = 1,  // moved along the normal to the centroid of u across the shell (the default; kernels/splat.cl)
};
const char* splat_centres_name(SplatCentres c);  // "voxel", "shell"
bool parse_splat_centres(const std::string& name, SplatCentres& out);

struct SplatParams {
  // epsilon: voxels with u > epsilon get a splat, and the Gaussian texture
  // falls to epsilon at the inscribed circle (paper: 0.2).
  float threshold = 0.2f;
  SplatNormals normals = SplatNormals::Tensor;
  double tensor_sigma = 1.5;  // voxels, for SplatNormals::Tensor and Data (host/orientation.hpp), in (0, 8]
  SplatGaussian gaussian = SplatGaussian::Paper;
  SplatCentres centres = SplatCentres::Shell;
  // Ambient occlusion from u (kernels/splat.cl, splat_occlusion) on both
  // sides of each splat, darkening the creases and hollows the renderer lights.
  bool occlusion = false;
};

// The Gaussian's lambda (see SplatGaussian) and the triangle size
// a = sqrt(1 / lambda) in voxels, for a threshold epsilon in (0, 1).
double splat_lambda(double epsilon, SplatGaussian g = SplatGaussian::Paper);
double splat_size(double epsilon, SplatGaussian g = SplatGaussian::Paper);

// One splat as kernels/splat.cl writes it: 7 float4 (112 bytes).
struct Splat {
  float centre[3];          // mm
  float alpha;              // u at the voxel
  float normal[3];          // unit, mm space
  float strength;           // |normal field| before normalising (|grad u| per mm)
  float s[4];               // half-axis S (mm), w unused
  float t[4];               // half-axis T (mm), w: colour ramp value for the renderer (0 here)
  // Unit normals midway to vertex 0, 1, 2; w of [0] and [1]: the ambient
  // occlusion (0 open .. 1 enclosed) on the side `normal` points to and on
  // the other (0 unless SplatParams::occlusion); [2].w unused.
  float vertex_normal[3][4];
};
static_assert(sizeof(Splat) == 7 * 16, "Splat must match kernels/splat.cl's 7 float4");

struct SplatSet {
  std::vector<Splat> splats;  // voxel-index order (x fastest)
  SplatParams params;
  double lambda = 0, a = 0;   // the Gaussian's lambda and the triangle size (voxels)
  Vec3d spacing{1, 1, 1}, origin{0, 0, 0};
  Dims3 dims{0, 0, 0};
  // Axis-aligned box of the whole volume in mm (voxel centres).
  Vec3d box_lo() const;
  Vec3d box_hi() const;
  // Box of the splat centres (the volume's box when there are none), for
  // framing the camera on what is drawn.
  std::array<Vec3d, 2> splat_box() const;
  // Size of an isotropic splat, a times the geometric mean spacing (mm).
  double isotropic_size() const;
};

struct SplatTiming {
  double count = 0, emit = 0, total = 0;  // seconds (profiling events; total includes transfers)
};

// Generates splats from an opacity volume already on the device.
class SplatGenerator {
 public:
  SplatGenerator(Runtime& rt, const GridDesc& grid, const SplatParams& params = {});
  // `u` holds grid voxels floats; origin in mm. Blocks until the splats are
  // on the host. `field`: the data orientation field on the device (grid
  // voxels floats, data_orientation_field), needed by SplatNormals::Data
  // (InputError without it) and ignored otherwise.
  SplatSet generate(const cl::Buffer& u, const Vec3d& origin, SplatTiming* timing = nullptr,
                    const cl::Buffer* field = nullptr) const;

 private:
  Runtime& rt_;
  GridDesc grid_;
  SplatParams params_;
  mutable cl::Kernel count_, emit_;
};

// Uploads `u` (opacity in [0, 1]) and generates its splats. `bmode`: the
// B-mode volume behind u (same dims), needed by SplatNormals::Data, which
// orients by its data_orientation_field; InputError when that is missing
// or its dims differ.
SplatSet generate_splats(Runtime& rt, const Volume& u, const SplatParams& params = {},
                         SplatTiming* timing = nullptr, const Volume* bmode = nullptr);
// The data orientation field of `bmode` on the device, for
// SplatGenerator::generate (InputError unless its dims are `u_dims`).
cl::Buffer upload_orientation_field(Runtime& rt, const Volume& bmode, const Dims3& u_dims);

// Back-to-front draw orders (indices into SplatSet::splats).
// The paper's presorted lists: splats by centre coordinate along `axis`
// (0, 1, 2), descending when `descending`, ties in voxel order. Viewing along
// +axis draws the descending list (far first), along -axis the ascending one.
std::vector<std::uint32_t> axis_order(const SplatSet& set, int axis, bool descending);
// The list for a view direction (eye towards the scene): the axis of the
// largest |component|; returns the list number 2 * axis + (d[axis] > 0).
int axis_list_for_view(const std::array<double, 3>& view_dir);
// Exact per-view order: by distance from `eye` (mm), farthest first.
void depth_order(const SplatSet& set, const std::array<double, 3>& eye, std::vector<std::uint32_t>& order);

}  // namespace softshell
