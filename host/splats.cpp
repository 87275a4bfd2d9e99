// Host wrapper of kernels/splat.cl and the back-to-front orders.
#include "splats.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>

#include "error.hpp"
#include "orientation.hpp"
#include "text.hpp"

namespace softshell {
namespace {
const char* const kNoBmode = "splat orientation 'data' needs the B-mode volume behind the opacity";
}  // namespace

const char* splat_normals_name(SplatNormals n) {
  switch (n) {
    case SplatNormals::Gradient: return "gradient";
    case SplatNormals::Tensor: return "tensor";
    case SplatNormals::Data: return "data";
  }
  return "?";
}

bool parse_splat_normals(const std::string& name, SplatNormals& out) {
  if (name == "gradient") out = SplatNormals::Gradient;
  else if (name == "tensor") out = SplatNormals::Tensor;
  else if (name == "data") out = SplatNormals::Data;
  else return false;
  return true;
}

const char* splat_centres_name(SplatCentres c) { return c == SplatCentres::Voxel ? "voxel" : "shell"; }

bool parse_splat_centres(const std::string& name, SplatCentres& out) {
  if (name == "shell") out = SplatCentres::Shell;
  else if (name == "voxel") out = SplatCentres::Voxel;
  else return false;
  return true;
}

const char* splat_gaussian_name(SplatGaussian g) { return g == SplatGaussian::Rim ? "rim" : "paper"; }

double splat_lambda(double epsilon, SplatGaussian g) {
  if (!(epsilon > 0 && epsilon < 1)) throw std::invalid_argument("splat threshold must be in (0, 1)");
  return g == SplatGaussian::Rim ? -0.25 / std::log(epsilon) : -0.25 * std::log(epsilon);
}

double splat_size(double epsilon, SplatGaussian g) { return std::sqrt(1.0 / splat_lambda(epsilon, g)); }

Vec3d SplatSet::box_lo() const { return origin; }

Vec3d SplatSet::box_hi() const {
  Vec3d hi{};
  for (int a = 0; a < 3; ++a) hi[a] = origin[a] + spacing[a] * double(dims[a] > 0 ? dims[a] - 1 : 0);
  return hi;
}

std::array<Vec3d, 2> SplatSet::splat_box() const {
  if (splats.empty()) return {box_lo(), box_hi()};
  Vec3d lo{HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi{-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  for (const Splat& s : splats)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], double(s.centre[a])), hi[a] = std::max(hi[a], double(s.centre[a]));
  return {lo, hi};
}

double SplatSet::isotropic_size() const { return a * std::cbrt(spacing[0] * spacing[1] * spacing[2]); }

SplatGenerator::SplatGenerator(Runtime& rt, const GridDesc& grid, const SplatParams& params)
    : rt_(rt), grid_(grid), params_(params) {
  splat_lambda(params.threshold, params.gaussian);  // validates the threshold
  const bool tensor = params.normals == SplatNormals::Tensor || params.normals == SplatNormals::Data;
  if (tensor && !(params.tensor_sigma > 0 && params.tensor_sigma <= 8))
    throw InputError("tensor sigma must be in (0, 8] voxels");
  std::string options = "-D SPLAT_NORMALS=" + std::to_string(static_cast<int>(params.normals)) +
                        " -D SPLAT_CENTRES=" + std::to_string(static_cast<int>(params.centres)) +
                        " -D SPLAT_OCCLUSION=" + std::string(params.occlusion ? "1" : "0");
  if (tensor) {
    char sigma[64];
    std::snprintf(sigma, sizeof sigma, " -D TENSOR_SIGMA=%.9gf", params.tensor_sigma);
    options += sigma;
  }
  count_ = rt.kernel("splat.cl", "splat_count", options);
  emit_ = rt.kernel("splat.cl", "splat_emit", options);
}

SplatSet SplatGenerator::generate(const cl::Buffer& u, const Vec3d& origin, SplatTiming* timing,
                                  const cl::Buffer* field) const {
  if (params_.normals == SplatNormals::Data && !field)
    throw InputError(kNoBmode);
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t rows = std::size_t(grid_.ny) * std::size_t(grid_.nz);
  cl::Buffer counts = rt_.buffer(rows * sizeof(cl_uint));
  Runtime::set_args(count_, u, counts, grid_, params_.threshold);
  cl::Event ec = rt_.enqueue_1d(count_, rows);

  // Exclusive prefix sum on the host: one uint per row, small next to the
  // volume, and the total is needed here anyway to size the output.
  std::vector<cl_uint> offsets(rows);
  rt_.queue().enqueueReadBuffer(counts, CL_TRUE, 0, rows * sizeof(cl_uint), offsets.data());
  std::uint64_t total = 0;
  for (cl_uint& c : offsets) {
    const cl_uint n = c;
    c = static_cast<cl_uint>(total);
    total += n;
  }
  if (total > 0xffffffffull / 7) throw DeviceError("too many splats: " + std::to_string(total));

  SplatSet set;
  set.params = params_;
  set.lambda = splat_lambda(params_.threshold, params_.gaussian);
  set.a = splat_size(params_.threshold, params_.gaussian);
  set.dims = {std::size_t(grid_.nx), std::size_t(grid_.ny), std::size_t(grid_.nz)};
  set.spacing = {grid_.hx, grid_.hy, grid_.hz};
  set.origin = origin;
  set.splats.resize(total);
  if (timing) timing->count = event_seconds(ec);
  if (total == 0) {
    if (timing) timing->total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return set;
  }

  const std::size_t bytes = total * sizeof(Splat);
  cl::Buffer out = rt_.buffer(bytes);
  rt_.queue().enqueueWriteBuffer(counts, CL_FALSE, 0, rows * sizeof(cl_uint), offsets.data());
  const cl_float4 org{{float(origin[0]), float(origin[1]), float(origin[2]), 0.0f}};
  const cl::Buffer& f = params_.normals == SplatNormals::Data ? *field : u;
  Runtime::set_args(emit_, u, f, counts, out, grid_, org, params_.threshold, static_cast<float>(set.a));
  cl::Event ee = rt_.enqueue_1d(emit_, rows);
  rt_.queue().enqueueReadBuffer(out, CL_TRUE, 0, bytes, set.splats.data());
  if (timing) {
    timing->emit = event_seconds(ee);
    timing->total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  return set;
}

cl::Buffer upload_orientation_field(Runtime& rt, const Volume& bmode, const Dims3& u_dims) {
  if (bmode.voxels() == 0)
    throw InputError(kNoBmode);
  if (bmode.dims != u_dims)
    throw InputError("splat orientation 'data': the B-mode volume has dims " + dims_text(bmode.dims) + ", the opacity " +
                     dims_text(u_dims));
  const Volume f = data_orientation_field(bmode);
  const std::size_t bytes = f.voxels() * sizeof(float);
  cl::Buffer fb = rt.buffer(bytes, CL_MEM_READ_ONLY);
  rt.queue().enqueueWriteBuffer(fb, CL_TRUE, 0, bytes, f.data.data());
  return fb;
}

SplatSet generate_splats(Runtime& rt, const Volume& u, const SplatParams& params, SplatTiming* timing,
                         const Volume* bmode) {
  const GridDesc g = make_grid(u.dims, u.spacing);
  const SplatGenerator gen(rt, g, params);  // validates the parameters before any upload
  const std::size_t bytes = u.voxels() * sizeof(float);
  cl::Buffer ub = rt.buffer(bytes, CL_MEM_READ_ONLY);
  rt.queue().enqueueWriteBuffer(ub, CL_TRUE, 0, bytes, u.data.data());
  if (params.normals != SplatNormals::Data) return gen.generate(ub, u.origin, timing);
  if (!bmode) throw InputError(kNoBmode);
  const cl::Buffer fb = upload_orientation_field(rt, *bmode, u.dims);
  return gen.generate(ub, u.origin, timing, &fb);
}

std::vector<std::uint32_t> axis_order(const SplatSet& set, int axis, bool descending) {
  if (axis < 0 || axis > 2) throw std::invalid_argument("axis_order: axis must be 0, 1 or 2");
  std::vector<std::uint32_t> order(set.splats.size());
  std::iota(order.begin(), order.end(), 0u);
  const auto& s = set.splats;
  // By voxel slab (the centre's nearest grid plane along the axis), as the
  // paper's lists of voxel slices: shell centres (SplatCentres::Shell) move
  // up to a voxel off their voxel, and sorting by the exact coordinate
  // scattered each slab's splats through memory (draws 1.2-2x slower under
  // llvmpipe, which fetches the records in list order). Stable, so splats of
  // one slab keep voxel order: the lists are reproducible.
  const double o = set.origin[axis], h = set.spacing[axis] > 0 ? set.spacing[axis] : 1.0;
  std::vector<std::int32_t> slab(s.size());
  for (std::size_t i = 0; i < s.size(); ++i) slab[i] = std::int32_t(std::lround((double(s[i].centre[axis]) - o) / h));
  if (descending)
    std::stable_sort(order.begin(), order.end(), [&](std::uint32_t i, std::uint32_t j) { return slab[i] > slab[j]; });
  else
    std::stable_sort(order.begin(), order.end(), [&](std::uint32_t i, std::uint32_t j) { return slab[i] < slab[j]; });
  return order;
}

int axis_list_for_view(const std::array<double, 3>& d) {
  int axis = 0;
  for (int a = 1; a < 3; ++a)
    if (std::abs(d[a]) > std::abs(d[axis])) axis = a;
  return 2 * axis + (d[axis] > 0 ? 1 : 0);
}

void depth_order(const SplatSet& set, const std::array<double, 3>& eye, std::vector<std::uint32_t>& order) {
  const std::size_t n = set.splats.size();
  // Sort (key, index) pairs: one contiguous array sorts faster than indices
  // that chase keys. Keys are squared distances, far first; ties by index.
  std::vector<std::pair<float, std::uint32_t>> keyed(n);
  const float ex = float(eye[0]), ey = float(eye[1]), ez = float(eye[2]);
  for (std::size_t i = 0; i < n; ++i) {
    const float* c = set.splats[i].centre;
    const float dx = c[0] - ex, dy = c[1] - ey, dz = c[2] - ez;
    keyed[i] = {-(dx * dx + dy * dy + dz * dz), static_cast<std::uint32_t>(i)};
  }
  std::sort(keyed.begin(), keyed.end());
  order.resize(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = keyed[i].second;
}

}  // namespace softshell
