// Levoy's classifier: upload, optional lowpass, gradient, per-voxel opacity.
#include "levoy.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "error.hpp"
#include "filter.hpp"
#include "gradient.hpp"

namespace softshell {

double levoy_thickness_mm(double thickness_voxels, const Vec3d& spacing) {
  return thickness_voxels * std::cbrt(spacing[0] * spacing[1] * spacing[2]);
}

Volume classify_levoy(Runtime& rt, const Volume& v, const LevoyParams& p, LevoyReport* report) {
  if (!std::isfinite(p.iso)) throw InputError("--iso must be a finite number");
  if (!(p.thickness > 0) || p.thickness > 100) throw InputError("--thickness must be in (0, 100] voxels");
  if (!(p.sigma_mm >= 0) || !std::isfinite(p.sigma_mm)) throw InputError("--sigma must be >= 0 (millimetres)");
  if (!(p.alpha > 0) || p.alpha > 1) throw InputError("--alpha must be in (0, 1]");

  const GridDesc g = make_grid(v.dims, v.spacing);
  const std::size_t n = v.voxels(), bytes = n * sizeof(float);
  cl::Buffer f = rt.buffer(bytes, CL_MEM_READ_ONLY);
  cl::Buffer gx = rt.buffer(bytes), gy = rt.buffer(bytes), gz = rt.buffer(bytes);
  cl::Event up, down;
  rt.queue().enqueueWriteBuffer(f, CL_FALSE, 0, bytes, v.data.data(), nullptr, &up);

  std::vector<cl::Event> smooth_events;
  cl::Buffer source = f;
  if (p.sigma_mm > 0) {
    cl::Buffer smooth = rt.buffer(bytes);
    try {
      smooth_events = Lowpass(rt, g, {p.sigma_mm, 3.0}).apply(f, smooth);
    } catch (const std::invalid_argument& e) {
      throw InputError(std::string("--sigma: ") + e.what());
    }
    source = smooth;
  }
  const cl::Event grad = Gradient(rt, g).apply(source, gx, gy, gz);

  cl::Buffer alpha = rt.buffer(bytes);
  cl::Kernel k = rt.kernel("classify_levoy.cl", "classify_levoy");
  Runtime::set_args(k, source, gx, gy, gz, alpha, static_cast<cl_float>(p.iso),
                    static_cast<cl_float>(levoy_thickness_mm(p.thickness, v.spacing)),
                    static_cast<cl_float>(p.alpha), static_cast<cl_ulong>(n));
  const cl::Event cls = rt.enqueue_1d(k, n);
  std::vector<float> out(n);
  rt.queue().enqueueReadBuffer(alpha, CL_TRUE, 0, bytes, out.data(), nullptr, &down);
  if (report) {
    report->upload = event_seconds(up);
    report->lowpass = smooth_events.empty() ? 0.0 : event_span_seconds(smooth_events.front(), smooth_events.back());
    report->gradient = event_seconds(grad);
    report->classify = event_seconds(cls);
    report->download = event_seconds(down);
  }
  // Samples near float's limits overflow the lowpass or the gradient to
  // infinity, and the opacity to NaN (found by fuzzing): refused rather
  // than written.
  for (float a : out)
    if (!std::isfinite(a)) {
      float big = 0;
      for (float x : v.data) big = std::max(big, std::fabs(x));
      throw InputError("the data's values (up to " + std::to_string(big) +
                       " in magnitude) overflow float arithmetic in the lowpass or the gradients; rescale the data");
    }
  return v.with_data(std::move(out), ScalarType::Float32);
}

}  // namespace softshell
