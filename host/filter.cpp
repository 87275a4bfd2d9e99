// Separable Gaussian lowpass: weight tables on the host, three 1-D passes on
// the device.
#include "filter.hpp"

#include <cmath>
#include <stdexcept>

namespace softshell {
namespace {
constexpr int k_max_radius = 100;
}  // namespace

std::vector<float> gaussian_weights(double sigma_voxels, double truncate) {
  if (!(sigma_voxels > 1e-6)) return {1.0f};
  const int r = std::max(1, static_cast<int>(std::ceil(truncate * sigma_voxels)));
  std::vector<double> w(2 * r + 1);
  double sum = 0;
  for (int k = -r; k <= r; ++k) sum += w[k + r] = std::exp(-0.5 * (k * k) / (sigma_voxels * sigma_voxels));
  std::vector<float> out(w.size());
  for (std::size_t i = 0; i < w.size(); ++i) out[i] = static_cast<float>(w[i] / sum);
  return out;
}

Lowpass::Lowpass(Runtime& rt, const GridDesc& grid, const Params& params)
    : rt_(rt), grid_(grid), params_(params) {
  if (!(params.sigma_mm >= 0) || !std::isfinite(params.sigma_mm))
    throw std::invalid_argument("lowpass sigma must be a finite number >= 0");
  if (!(params.truncate > 0)) throw std::invalid_argument("lowpass truncate must be > 0");
  const double h[3] = {grid.hx, grid.hy, grid.hz};
  const char* names[3] = {"filter_gauss_x", "filter_gauss_y", "filter_gauss_z"};
  for (int a = 0; a < 3; ++a) {
    sigma_vox_[a] = params.sigma_mm / h[a];
    std::vector<float> w = gaussian_weights(sigma_vox_[a], params.truncate);
    radius_[a] = static_cast<int>(w.size() / 2);
    // The radius is compiled into the kernel and its tap loops unroll: keep it
    // bounded (sigma up to ~33 voxels), which covers any lowpass that still
    // leaves a surface to find.
    if (radius_[a] > k_max_radius)
      throw std::invalid_argument("lowpass sigma too large for this volume (radius " +
                                  std::to_string(radius_[a]) + " voxels along axis " + "xyz"[a] +
                                  ", at most " + std::to_string(k_max_radius) + ")");
    weights_[a] = cl::Buffer(rt.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, w.size() * sizeof(float),
                             w.data());
    kernels_[a] = rt.kernel("filter.cl", names[a], "-DRADIUS=" + std::to_string(radius_[a]));
  }
  scratch_ = rt.buffer(grid_voxels(grid) * sizeof(float));
}

std::size_t Lowpass::memory_bytes() const {
  std::size_t b = grid_voxels(grid_) * sizeof(float);
  for (int a = 0; a < 3; ++a) b += (2 * radius_[a] + 1) * sizeof(float);
  return b;
}

std::vector<cl::Event> Lowpass::apply(const cl::Buffer& in, const cl::Buffer& out,
                                      const std::vector<cl::Event>* wait) const {
  if (in() == out()) throw std::invalid_argument("Lowpass::apply: input and output must be distinct buffers");
  // x: in -> out, y: out -> scratch, z: scratch -> out.
  const cl::Buffer* src[3] = {&in, &out, &scratch_};
  const cl::Buffer* dst[3] = {&out, &scratch_, &out};
  std::vector<cl::Event> events(3);
  for (int a = 0; a < 3; ++a) {
    Runtime::set_args(kernels_[a], *src[a], *dst[a], weights_[a], grid_);
    events[a] = rt_.enqueue_3d(kernels_[a], grid_, a == 0 ? wait : nullptr);
  }
  return events;
}

Volume lowpass_volume(Runtime& rt, const Volume& in, const Lowpass::Params& params, LowpassReport* report) {
  const GridDesc g = make_grid(in.dims, in.spacing);
  const std::size_t bytes = in.voxels() * sizeof(float);
  Lowpass filter(rt, g, params);
  cl::Buffer d_in = rt.buffer(bytes, CL_MEM_READ_ONLY);
  cl::Buffer d_out = rt.buffer(bytes, CL_MEM_READ_WRITE);
  cl::Event up, down;
  rt.queue().enqueueWriteBuffer(d_in, CL_FALSE, 0, bytes, in.data.data(), nullptr, &up);
  const auto passes = filter.apply(d_in, d_out);
  std::vector<float> result(in.voxels());
  rt.queue().enqueueReadBuffer(d_out, CL_TRUE, 0, bytes, result.data(), nullptr, &down);
  if (report) {
    report->sigma_voxels = filter.sigma_voxels();
    report->radius = filter.radius();
    report->upload = event_seconds(up);
    report->filter = event_span_seconds(passes.front(), passes.back());
    report->download = event_seconds(down);
  }
  return in.with_data(std::move(result), in.source_type);
}

}  // namespace softshell
