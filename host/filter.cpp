// Separable Gaussian lowpass: weight tables on the host, three 1-D passes on
// the device.
#include "filter.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "error.hpp"

namespace softshell {

std::vector<float> gaussian_weights(double sigma_voxels, double truncate) {
  if (!(sigma_voxels > 1e-6)) return {1.0f};
  // The radius in double first: ceil(3 sigma) of a huge sigma does not fit
  // an int (and its vector would not fit in memory).
  const double radius = std::ceil(truncate * sigma_voxels);
  if (!(radius <= kMaxWeightsRadius))
    throw std::invalid_argument("gaussian_weights: a radius of " + std::to_string(radius) + " taps is too large");
  const int r = std::max(1, static_cast<int>(radius));
  std::vector<double> w(2 * std::size_t(r) + 1);
  double sum = 0;
  for (int k = -r; k <= r; ++k) sum += w[k + r] = std::exp(-0.5 * (double(k) * k) / (sigma_voxels * sigma_voxels));
  std::vector<float> out(w.size());
  for (std::size_t i = 0; i < w.size(); ++i) out[i] = static_cast<float>(w[i] / sum);
  return out;
}

void check_lowpass_sigma(double sigma_mm, const Vec3d& spacing, const std::string& what, double truncate) {
  if (!(sigma_mm >= 0) || !std::isfinite(sigma_mm)) {
    std::ostringstream m;
    m << what << " must be a finite number >= 0, got " << sigma_mm;
    throw InputError(m.str());
  }
  if (!(truncate > 0) || !std::isfinite(truncate)) throw std::invalid_argument("lowpass truncate must be > 0");
  for (int a = 0; a < 3; ++a) {
    const double vox = sigma_mm / spacing[a];
    if (vox > 1e-6 && std::ceil(truncate * vox) > kMaxLowpassRadius) {
      std::ostringstream m;
      m << what << " " << sigma_mm << " mm is " << vox << " voxels along " << "xyz"[a] << " (spacing " << spacing[a]
        << " mm), more than the " << std::floor(10 * kMaxLowpassRadius / truncate) / 10
        << " voxels a lowpass allows; use a smaller sigma, or check the spacing's unit (mm)";
      throw InputError(m.str());
    }
  }
}

Lowpass::Lowpass(Runtime& rt, const GridDesc& grid, const Params& params)
    : rt_(rt), grid_(grid), params_(params) {
  const double h[3] = {grid.hx, grid.hy, grid.hz};
  // The radius is compiled into the kernel and its tap loops unroll: keep it
  // bounded. A user's sigma is refused with the numbers (InputError, exit 2).
  check_lowpass_sigma(params.sigma_mm, {h[0], h[1], h[2]}, "lowpass sigma", params.truncate);
  const char* names[3] = {"filter_gauss_x", "filter_gauss_y", "filter_gauss_z"};
  for (int a = 0; a < 3; ++a) {
    sigma_vox_[a] = params.sigma_mm / h[a];
    std::vector<float> w = gaussian_weights(sigma_vox_[a], params.truncate);
    radius_[a] = static_cast<int>(w.size() / 2);
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
