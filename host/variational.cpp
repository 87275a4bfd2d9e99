// One level of the variational classifier's linear system on the device:
// densities (from a volume, from the host, or restricted from a finer level),
// assembly, operator, smoothers, norm. The solver is in multigrid.cpp.
#include "variational.hpp"

#include <algorithm>
#include <cstring>
#include <cmath>
#include <stdexcept>

#include "filter.hpp"
#include "parallel.hpp"

namespace softshell {
namespace {

constexpr const char* kSystem = "system.cl";

// The build options of the kernels that form the densities (system.cl,
// shell_power): the default build takes powers that are half-integers in
// [0, 8] and vectorises; any other edge or profile power needs the general
// build (exp2 and log2, scalar).
bool half_integer_power(float q) { return q >= 0.0f && q <= 8.0f && 2.0f * q == std::floor(2.0f * q); }
std::string density_options(const ClassifyCoeffs& k) {
  return half_integer_power(k.edge_power) && half_integer_power(k.profile_power) ? "" : "-DSHELL_GENERAL_POWERS";
}
constexpr const char* kMultigrid = "multigrid.cl";
constexpr std::size_t kReduceGroups = 64, kReduceLocal = 256;  // GPU: strided work-groups
constexpr std::size_t kReduceChunks = 256;                     // CPU: contiguous chunks

template <class T>
cl::Buffer upload(Runtime& rt, const std::vector<T>& host) {
  cl::Buffer b = rt.buffer(std::max<std::size_t>(host.size(), 1) * sizeof(T));
  // Blocking: callers pass temporaries (e.g. an all-ones mask), which must
  // outlive the transfer.
  if (!host.empty()) rt.queue().enqueueWriteBuffer(b, CL_TRUE, 0, host.size() * sizeof(T), host.data());
  return b;
}

template <class T>
std::vector<T> download(Runtime& rt, const cl::Buffer& b, std::size_t n) {
  std::vector<T> out(n);
  rt.queue().enqueueReadBuffer(b, CL_TRUE, 0, n * sizeof(T), out.data());
  return out;
}

}  // namespace

ClassifyCoeffs VariationalParams::coeffs() const {
  ClassifyCoeffs k;
  k.alpha = float(alpha), k.beta = float(beta), k.gamma = float(gamma), k.omega = float(omega);
  k.delta = float(delta), k.epsilon = float(epsilon), k.u_ind = float(u_ind), k.v_iso = float(v_iso);
  k.kappa = float(kappa);
  const double h = 0.5 * thickness_mm;
  k.shell_h2 = float(h * h), k.profile_power = float(profile_power);
  k.g_ref = edge_share > 0 ? float(g_ref) : 0.0f, k.edge_power = float(edge_power);
  k.weight_cap = float(weight_cap);
  k.shell_shift = float(shell_shift_mm);
  k.sharpen_lambda = 0.0f, k.sharpen_ratio = 1.0f;
  return k;
}

VariationalParams VariationalParams::literal_defaults() {
  VariationalParams p;
  p.alpha = 0.2, p.beta = 3.0, p.gamma = 3.5, p.omega = 0.6, p.delta = 0.02, p.epsilon = 0.01;
  p.grad_sigma_mm = 0, p.kappa = 0, p.thickness_mm = 0, p.edge_share = 0;
  p.sharpen_iterations = 0, p.max_gain = 0;
  return p;
}

double small_volume_scale(const Dims3& dims, const Vec3d& spacing, double reference_mm) {
  if (!(reference_mm > 0)) return 1.0;
  double extent = INFINITY;
  for (int a = 0; a < 3; ++a)
    if (dims[a] >= 2 && spacing[a] > 0) extent = std::min(extent, double(dims[a]) * spacing[a]);
  // Under 1 mm across is no small scan but a spacing in the wrong unit
  // (metres, micrometres): not scaled, so the lowpass checks refuse it.
  if (!std::isfinite(extent) || extent < kSmallVolumeMinMm) return 1.0;
  return std::min(1.0, extent / reference_mm);
}

void scale_length_scales(VariationalParams& p, double f) {
  p.sigma_mm *= f, p.grad_sigma_mm *= f, p.thickness_mm *= f, p.shell_shift_mm *= f;
  p.beta *= f * f, p.kappa *= f * f;
}

double VariationalParams::effective_thickness_mm(const Vec3d& spacing) const {
  if (thickness_mm <= 0) return 0;
  return std::max(thickness_mm, 2.0 * std::max({spacing[0], spacing[1], spacing[2]}));
}

double crest_of(const Volume& u) {
  const Dims3& d = u.dims;
  if (d[0] < 3 || d[1] < 3 || d[2] < 3) return 0;
  // Over z-slabs on every core (the viewer's re-solve waits for it); the
  // ridge values are gathered in slab order, so the median is the same for
  // any thread count.
  const int parts = host_threads(0);
  std::vector<float> slab_max(std::size_t(range_count(d[2], parts)), 0.0f);
  parallel_ranges_indexed(d[2], parts, [&](int k, std::size_t z0, std::size_t z1) {
    float m = 0;
    for (std::size_t i = z0 * d[0] * d[1]; i < z1 * d[0] * d[1]; ++i) m = std::max(m, u.data[i]);
    slab_max[std::size_t(k)] = m;
  });
  const float umax = *std::max_element(slab_max.begin(), slab_max.end());
  if (!(umax > 0)) return 0;
  const float floor = 0.05f * umax;
  const std::size_t stride[3] = {1, d[0], d[0] * d[1]};
  std::vector<std::vector<float>> slab_ridge(std::size_t(range_count(d[2] - 2, parts)));
  parallel_ranges_indexed(d[2] - 2, parts, [&](int k, std::size_t b, std::size_t e) {
    std::vector<float>& ridge = slab_ridge[std::size_t(k)];
    for (std::size_t z = b + 1; z < e + 1; ++z)
      for (std::size_t y = 1; y + 1 < d[1]; ++y)
        for (std::size_t x = 1; x + 1 < d[0]; ++x) {
          const std::size_t i = u.index(x, y, z);
          const float c = u.data[i];
          if (c <= floor) continue;
          int axis = -1;
          float most = 0;
          for (int a = 0; a < 3; ++a) {
            const float d2 = u.data[i - stride[a]] + u.data[i + stride[a]] - 2 * c;
            if (d2 < most) most = d2, axis = a;
          }
          if (axis >= 0 && c >= u.data[i - stride[axis]] && c >= u.data[i + stride[axis]]) ridge.push_back(c);
        }
  });
  std::vector<float> ridge;
  for (std::vector<float>& r : slab_ridge) ridge.insert(ridge.end(), r.begin(), r.end());
  if (ridge.empty()) return 0;
  std::nth_element(ridge.begin(), ridge.begin() + long(ridge.size() / 2), ridge.end());
  return ridge[ridge.size() / 2];
}

double reference_edge_gradient(const std::vector<float>& grad2, double share) {
  return reference_edge_gradient(grad2, share, 0.0, 0.0).g_ref;
}

double edge_split_weight(double ratio, double split, double split_from) {
  if (!(split > 0) || !(ratio > 0)) return 0.0;
  if (ratio >= split) return 1.0;
  if (!(split_from > 0) || !(split_from < split) || !(ratio > split_from)) return 0.0;
  return (ratio - split_from) / (split - split_from);
}

ReferenceEdge reference_edge_gradient(const std::vector<float>& grad2, double share, double fine_share, double split,
                                      double split_from) {
  ReferenceEdge r;
  r.share = share;
  std::vector<float> g;
  g.reserve(grad2.size());
  for (float x : grad2)
    if (x >= 0) g.push_back(x);
  if (g.empty()) return r;
  // The top `share` of the entries, at least one; their median (the entry
  // at index k once sorted).
  const auto median_index = [&](double s) {
    const std::size_t top = std::max<std::size_t>(1, std::size_t(double(g.size()) * std::clamp(s, 0.0, 1.0)));
    return g.size() - top / 2 - 1;
  };
  const std::size_t k = median_index(share);
  std::nth_element(g.begin(), g.begin() + long(k), g.end());
  r.g_ref = std::sqrt(double(g[k]));
  if (!(split > 0) || !(fine_share > 0) || !(fine_share < share) || !(r.g_ref > 0)) return r;
  // The finer share's median lies above k, among the entries nth_element
  // left there.
  const std::size_t kf = median_index(fine_share);
  if (kf <= k) return r;
  std::nth_element(g.begin() + long(k) + 1, g.begin() + long(kf), g.end());
  const double fine = std::sqrt(double(g[kf]));
  r.ratio = fine / r.g_ref;
  r.weight = edge_split_weight(r.ratio, split, split_from);
  if (r.weight >= 1) r.g_ref = fine, r.share = fine_share;
  else if (r.weight > 0) r.g_ref *= std::pow(r.ratio, r.weight);  // blended (edge_split_from)
  return r;
}

DeviceSystem::DeviceSystem(Runtime& rt, const GridDesc& g) : rt_(rt), grid_(g) {
  const std::size_t n = voxels();
  rt.check_allocation(STENCIL_SLICE(n) * STENCIL_COEFS * sizeof(float), "the classifier's 19-point system");
  mu_ = rt.buffer(n * sizeof(float));
  rho_ = rt.buffer(n * sizeof(float));
  for (auto& t : T_) t = rt.buffer(n * sizeof(float));
  fixed_ = rt.buffer(n);
  coef_ = rt.buffer(STENCIL_SLICE(n) * STENCIL_COEFS * sizeof(float));
  b_ = rt.buffer(n * sizeof(float));
  dT_ = rt.buffer(n * sizeof(float));
  partial_ = rt.buffer(std::max(kReduceGroups, kReduceChunks) * sizeof(float));
  apply_ = rt.kernel(kSystem, "system_apply");
  residual_ = rt.kernel(kSystem, "system_residual");
  gs_ = rt.kernel(kSystem, "relax_gs_colour");
  gs_slabs_ = rt.kernel(kSystem, "relax_gs_slabs");
  gs_order_ = rt.info().is_gpu() ? GsOrder::Points : GsOrder::Slabs;
  jacobi_ = rt.kernel(kSystem, "relax_jacobi");
  zero_fixed_ = rt.kernel(kSystem, "system_zero_fixed");
  set_strided_dot(rt.info().is_gpu());
  axpby_ = rt.kernel(kSystem, "vec_axpby");
}

DeviceSystem::DeviceSystem(Runtime& rt, const Densities& d) : DeviceSystem(rt, make_grid(d.dims, d.spacing)) {
  const std::size_t n = voxels();
  auto check = [n](std::size_t size, const char* what) {
    if (size != n) throw std::invalid_argument(std::string("Densities: ") + what + " has the wrong size");
  };
  check(d.mu.size(), "mu");
  check(d.rho.size(), "rho");
  check(d.fixed.size(), "fixed");
  for (const auto& t : d.T) check(t.size(), "T");
  // The kernels skip the stencil on the volume boundary: it must be fixed.
  for (std::size_t z = 0; z < d.dims[2]; ++z)
    for (std::size_t y = 0; y < d.dims[1]; ++y)
      for (std::size_t x = 0; x < d.dims[0]; ++x) {
        const bool boundary = x == 0 || y == 0 || z == 0 || x + 1 == d.dims[0] || y + 1 == d.dims[1] || z + 1 == d.dims[2];
        if (boundary && !d.fixed[x + d.dims[0] * (y + d.dims[1] * z)])
          throw std::invalid_argument("Densities: boundary voxels must be fixed (u = 0 on the boundary)");
      }
  rt.queue().enqueueWriteBuffer(mu_, CL_FALSE, 0, n * 4, d.mu.data());
  rt.queue().enqueueWriteBuffer(rho_, CL_FALSE, 0, n * 4, d.rho.data());
  for (int i = 0; i < 6; ++i) rt.queue().enqueueWriteBuffer(T_[i], CL_FALSE, 0, n * 4, d.T[i].data());
  rt.queue().enqueueWriteBuffer(fixed_, CL_TRUE, 0, n, d.fixed.data());
  assemble();
}

// The bone cue's reference edge: the median of the upper half of the cued
// voxels' weighted |grad v| (docs/numerics.md, "The bone cue").
constexpr double kCueEdgeShare = 0.5;

DeviceSystem::DeviceSystem(Runtime& rt, const Volume& v, const VariationalParams& p,
                           const std::vector<std::uint8_t>* mask)
    : DeviceSystem(rt, make_grid(v.dims, v.spacing)) {
  const std::size_t n = voxels(), bytes = n * sizeof(float);
  if (mask && mask->size() != n) throw std::invalid_argument("mask size differs from the volume");
  cl::Buffer dv = upload(rt, v.data);
  cl::Buffer dvs = rt.buffer(bytes);
  Lowpass(rt, grid_, {p.sigma_mm, 3.0}).apply(dv, dvs);
  cl::Buffer grad2 = rt.buffer(bytes);
  cl::Buffer dvg = dv;  // |grad v| from v, or from its --grad-sigma lowpass
  if (p.grad_sigma_mm > 0) {
    dvg = rt.buffer(bytes);
    Lowpass(rt, grid_, {p.grad_sigma_mm, 3.0}).apply(dv, dvg);
  }
  cl::Buffer dmask = mask ? upload(rt, *mask) : upload(rt, std::vector<std::uint8_t>(n, 1));
  resolved_ = p;
  spacing_ = v.spacing;
  resolved_.thickness_mm = p.effective_thickness_mm(v.spacing);
  if (p.edge_share > 0 && !(p.g_ref > 0)) {
    // g_ref from the data: |grad v|^2 of the scanned voxels, to the host.
    cl::Kernel kg = rt.kernel(kSystem, "system_grad2");
    Runtime::set_args(kg, dvg, dmask, grad2, grid_);
    rt.enqueue_3d(kg, grid_);
    std::vector<float> g2 = download<float>(rt, grad2, n);
    if (p.edge_weight && p.edge_reference == VariationalParams::EdgeReference::Cue) {
      // With the bone cue the reference is the cued edges' own: the median
      // weighted |grad v| of the voxels whose weight is at least 1/2 (the
      // bone echoes are weaker edges than the shadows' walls).
      if (p.edge_weight->size() != n) throw std::invalid_argument("edge weight size differs from the volume");
      const std::vector<float>& w = *p.edge_weight;
      std::size_t cued = 0;
      for (std::size_t i = 0; i < n; ++i) {
        if (g2[i] >= 0 && w[i] >= 0.5f) g2[i] *= w[i] * w[i], ++cued;
        else g2[i] = -1.0f;
      }
      if (cued == 0) g2 = download<float>(rt, grad2, n);  // nothing cued: the data's own reference
      resolved_.g_ref = reference_edge_gradient(g2, cued ? kCueEdgeShare : p.edge_share);
    } else {
      if (p.edge_weight && p.edge_reference == VariationalParams::EdgeReference::Weighted) {
        // The strongest edges that remain once weighted (the shadow walls).
        if (p.edge_weight->size() != n) throw std::invalid_argument("edge weight size differs from the volume");
        const std::vector<float>& w = *p.edge_weight;
        for (std::size_t i = 0; i < n; ++i)
          if (g2[i] >= 0) g2[i] *= w[i] * w[i];
      }
      const ReferenceEdge r = reference_edge_gradient(g2, p.edge_share, p.edge_share_fine, p.edge_split, p.edge_split_from);
      resolved_.g_ref = r.g_ref, resolved_.g_ref_ratio = r.ratio;
    }
    // A volume without edges: any positive unit keeps the system defined
    // (F_ind is then delta everywhere).
    if (!(resolved_.g_ref > 0)) resolved_.g_ref = 1.0;
  }
  cl::Kernel k = rt.kernel(kSystem, "system_densities", density_options(resolved_.coeffs()));
  Runtime::set_args(k, dv, dvs, dvg, dmask, mu_, rho_, T_[0], T_[1], T_[2],
                    T_[3], T_[4], T_[5], fixed_, grad2, resolved_.coeffs(), grid_);
  rt.enqueue_3d(k, grid_);
  assemble();
  // mu, rho, the diagonal and b re-derived once, by the update kernel, when
  // the edge weights or the crest rule below changed |grad v| or v~ (T and
  // the couplings do not depend on them).
  bool changed = false;
  if (p.edge_weight) {
    // The bone cue and the shadow walls: |grad v| weighted per voxel (grad2
    // by w^2). g_ref stays the data's own.
    if (p.edge_weight->size() != n) throw std::invalid_argument("edge weight size differs from the volume");
    std::vector<float> g2 = download<float>(rt, grad2, n);
    const std::vector<float>& w = *p.edge_weight;
    for (std::size_t i = 0; i < n; ++i) g2[i] *= w[i] * w[i];
    rt.queue().enqueueWriteBuffer(grad2, CL_TRUE, 0, bytes, g2.data());
    changed = true;
  }
  sources_ = {dv, dvs, grad2};
  if (p.crest.ridge > 0 && resolved_.thickness_mm > 0) {
    // Shells on a bright echo's crest (host/crest.hpp): v~ and |grad v| over
    // each ridge replaced.
    crest_params_ = p.crest, dims_ = v.dims;
    changed = apply_crest(resolved_.v_iso, resolved_.shell_shift_mm) || changed;
  }
  if (changed) {
    cl::Kernel ku = rt.kernel(kSystem, "system_update_point", density_options(resolved_.coeffs()));
    Runtime::set_args(ku, dv, dvs, grad2, fixed_, dT_, mu_, rho_, coef_, b_, resolved_.coeffs(), grid_);
    rt.enqueue_3d(ku, grid_);
  }
}

bool DeviceSystem::apply_crest(double v_iso, double shift_mm) {
  // The data as they were before the rule: the voxels it changed last time
  // restored from their kept values, so the result is a fresh build's.
  const std::size_t n = voxels(), bytes = n * sizeof(float);
  std::vector<float> vs = download<float>(rt_, sources_[1], n), g2 = download<float>(rt_, sources_[2], n);
  CrestChanges& c = crest_changes_;
  const bool had = !c.index.empty();
  for (std::size_t k = 0; k < c.index.size(); ++k) vs[c.index[k]] = c.vs[k], g2[c.index[k]] = c.grad2[k];
  const std::vector<std::uint8_t> fx = download<std::uint8_t>(rt_, fixed_, n);
  crest_ = crest_shells(vs, g2, fx, dims_, spacing_, v_iso, shift_mm, resolved_.g_ref, crest_params_, 0, &c);
  crest_iso_ = v_iso, crest_shift_ = shift_mm;
  if (!had && c.index.empty()) return false;
  rt_.queue().enqueueWriteBuffer(sources_[1], CL_TRUE, 0, bytes, vs.data());
  rt_.queue().enqueueWriteBuffer(sources_[2], CL_TRUE, 0, bytes, g2.data());
  return true;
}

void DeviceSystem::update_point(const VariationalParams& p) {
  if (!updatable())
    throw std::logic_error("DeviceSystem::update_point: the system was not built from a volume");
  // The data's resolved quantities stay (g_ref, the thickness floor).
  VariationalParams r = p;
  r.g_ref = resolved_.g_ref, r.g_ref_ratio = resolved_.g_ref_ratio;
  r.thickness_mm = p.effective_thickness_mm(spacing_);
  // The echo-crest rule for the new isovalue and shell shift, on the data as
  // they were before it (apply_crest).
  if (crest_params_.ridge > 0 && (r.v_iso != crest_iso_ || r.shell_shift_mm != crest_shift_))
    apply_crest(r.v_iso, r.shell_shift_mm);
  cl::Kernel k = rt_.kernel(kSystem, "system_update_point", density_options(r.coeffs()));
  Runtime::set_args(k, sources_[0], sources_[1], sources_[2], fixed_, dT_, mu_, rho_, coef_, b_, r.coeffs(), grid_);
  resolved_ = r;
  rt_.enqueue_3d(k, grid_);
}

void DeviceSystem::update_sharpen(const VariationalParams& p, const std::vector<float>& u0, double lambda,
                                  double ratio) {
  if (u0.size() != voxels()) throw std::invalid_argument("DeviceSystem::update_sharpen: u0 has the wrong size");
  cl::Buffer b = rt_.buffer(voxels() * sizeof(float));
  rt_.queue().enqueueWriteBuffer(b, CL_TRUE, 0, voxels() * sizeof(float), u0.data());
  update_sharpen(p, b, lambda, ratio);
}

void DeviceSystem::update_sharpen(const VariationalParams& p, const cl::Buffer& u0, double lambda, double ratio) {
  if (!updatable())
    throw std::logic_error("DeviceSystem::update_sharpen: the system was not built from a volume");
  VariationalParams r = p;
  r.g_ref = resolved_.g_ref, r.g_ref_ratio = resolved_.g_ref_ratio;
  r.thickness_mm = p.effective_thickness_mm(spacing_);
  ClassifyCoeffs k = r.coeffs();
  k.sharpen_lambda = float(lambda), k.sharpen_ratio = float(ratio);
  cl::Kernel kern = rt_.kernel(kSystem, "system_update_sharpen", density_options(k));
  Runtime::set_args(kern, sources_[0], sources_[1], sources_[2], fixed_, dT_, u0, mu_, rho_, coef_, b_, k, grid_);
  rt_.enqueue_3d(kern, grid_);
  resolved_ = r;
}

namespace {
// A coarsening kernel over the coarse grid g: a work-item per x-row (`rows`,
// the CPU ordering's *_rows kernels) or per voxel.
void enqueue_coarse(Runtime& rt, const cl::Kernel& k, const GridDesc& g, bool rows) {
  if (rows)
    rt.enqueue_rows(k, g);
  else
    rt.enqueue_3d(k, g);
}
}  // namespace

void DeviceSystem::restrict_point(const DeviceSystem& fine) {
  // With the CPU ordering (GsOrder::Slabs) a work-item per coarse x-row (fine
  // rows read in memory order), as the V-cycle's transfers and coarsen(); with
  // the GPU's a work-item per voxel (set_gs_order picks either on any device).
  const bool rows = gs_order_ == GsOrder::Slabs;
  cl::Kernel k = rt_.kernel(kMultigrid, rows ? "mg_restrict_point_rows" : "mg_restrict_point");
  Runtime::set_args(k, fine.mu_, fine.rho_, fixed_, dT_, mu_, rho_, coef_, b_, fine.grid_, grid_);
  enqueue_coarse(rt_, k, grid_, rows);
}

std::unique_ptr<DeviceSystem> DeviceSystem::coarsen(const DeviceSystem& fine) {
  if (!fine.has_tensor()) throw std::logic_error("DeviceSystem::coarsen: the tensor T was released");
  const GridDesc& gf = fine.grid_;
  GridDesc gc = gf;
  gc.nx = gf.nx / 2 + 1, gc.ny = gf.ny / 2 + 1, gc.nz = gf.nz / 2 + 1;
  gc.hx = 2 * gf.hx, gc.hy = 2 * gf.hy, gc.hz = 2 * gf.hz;
  std::unique_ptr<DeviceSystem> c(new DeviceSystem(fine.rt_, gc));
  c->gs_order_ = fine.gs_order_;
  c->gs_slab_ = fine.gs_slab_;
  // The same kernel form as restrict_point's (rows with the CPU ordering): the
  // re-restricted mu and rho then have the bits of a fresh coarsening.
  const bool rows = fine.gs_order_ == GsOrder::Slabs;
  cl::Kernel k = fine.rt_.kernel(kMultigrid, rows ? "mg_restrict_densities_rows" : "mg_restrict_densities");
  Runtime::set_args(k, fine.mu_, fine.rho_, fine.T_[0], fine.T_[1], fine.T_[2], fine.T_[3], fine.T_[4], fine.T_[5],
                    fine.fixed_, c->mu_, c->rho_, c->T_[0], c->T_[1], c->T_[2], c->T_[3], c->T_[4], c->T_[5],
                    c->fixed_, gf, gc);
  enqueue_coarse(fine.rt_, k, gc, rows);
  c->assemble();
  return c;
}

void DeviceSystem::assemble() {
  cl::Kernel k = rt_.kernel(kSystem, "system_assemble");
  Runtime::set_args(k, mu_, rho_, T_[0], T_[1], T_[2], T_[3], T_[4], T_[5], fixed_, coef_, b_, dT_, grid_);
  rt_.enqueue_3d(k, grid_);
}

cl::Event DeviceSystem::apply(const cl::Buffer& x, const cl::Buffer& y) const {
  Runtime::set_args(apply_, coef_, x, y, grid_);
  return rt_.enqueue_3d(apply_, grid_);
}

cl::Event DeviceSystem::residual(const cl::Buffer& rhs, const cl::Buffer& x, const cl::Buffer& r) const {
  Runtime::set_args(residual_, coef_, rhs, x, r, grid_);
  return rt_.enqueue_3d(residual_, grid_);
}

int DeviceSystem::gs_slab() const {
  // 1 plane: measured as fast as 2 or 4 on the 2-core CPU (128^3: 14.4 ms
  // against 15.7 and 14.4-19.7 ms per sweep), with the most work-items.
  return gs_slab_ > 0 ? gs_slab_ : 1;
}

std::pair<cl::Event, cl::Event> DeviceSystem::slab_sweeps(cl::Kernel& k, cl_uint first, const cl::Buffer& rhs,
                                                          const cl::Buffer& x, int sweeps, bool reverse) const {
  // One work-item (and work-group) per slab of a colour.
  const int slab = gs_slab();
  const cl::NDRange global((grid_.nz + 2 * slab - 1) / (2 * slab));
  k.setArg(first, rhs);
  k.setArg(first + 1, x);
  k.setArg(first + 3, static_cast<cl_int>(reverse));
  k.setArg(first + 4, static_cast<cl_int>(slab));
  k.setArg(first + 5, grid_);
  std::pair<cl::Event, cl::Event> span;
  for (int s = 0; s < sweeps; ++s)
    for (int c = 0; c < 2; ++c) {
      k.setArg(first + 2, static_cast<cl_int>(reverse ? 1 - c : c));
      cl::Event e;
      rt_.queue().enqueueNDRangeKernel(k, cl::NullRange, global, cl::NDRange(1), nullptr, &e);
      if (!span.first()) span.first = e;
      span.second = e;
    }
  return span;
}

std::pair<cl::Event, cl::Event> DeviceSystem::relax_gs(const cl::Buffer& rhs, const cl::Buffer& x, int sweeps,
                                                       bool reverse) const {
  std::pair<cl::Event, cl::Event> span;
  auto launched = [&span](const cl::Event& e) {
    if (!span.first()) span.first = e;
    span.second = e;
  };
  if (gs_order_ == GsOrder::Slabs) {
    gs_slabs_.setArg(0, coef_);
    return slab_sweeps(gs_slabs_, 1, rhs, x, sweeps, reverse);
  }
  GridDesc half = grid_;  // one work-item per voxel of a colour
  half.nx = (grid_.nx + 1) / 2, half.ny = (grid_.ny + 1) / 2, half.nz = (grid_.nz + 1) / 2;
  for (int s = 0; s < sweeps; ++s)
    for (int c = 0; c < 8; ++c) {
      Runtime::set_args(gs_, coef_, rhs, x, static_cast<cl_int>(reverse ? 7 - c : c), grid_);
      launched(rt_.enqueue_3d(gs_, half));
    }
  return span;
}

void DeviceSystem::build_compact() {
  if (has_compact()) return;
  const std::size_t slices = STENCIL_SLICE(voxels()) * (STENCIL_COEFS - 1);
  rt_.check_allocation(slices * sizeof(std::uint16_t), "the smoother's compact stencil");
  compact_h_ = rt_.buffer(slices * sizeof(std::uint16_t));
  compact_delta_ = rt_.buffer(voxels() * sizeof(float));
  cl::Kernel k = rt_.kernel(kSystem, "system_compact");
  Runtime::set_args(k, coef_, compact_h_, compact_delta_, grid_);
  rt_.enqueue_3d(k, grid_);
  gs_slabs_compact_ = rt_.kernel(kSystem, "relax_gs_slabs_compact");
  residual_compact_ = rt_.kernel(kSystem, "system_residual_compact");
}

std::pair<cl::Event, cl::Event> DeviceSystem::relax_gs_compact(const cl::Buffer& rhs, const cl::Buffer& x, int sweeps,
                                                               bool reverse) const {
  if (!has_compact()) throw std::logic_error("DeviceSystem::relax_gs_compact: build_compact() first");
  gs_slabs_compact_.setArg(0, coef_);
  gs_slabs_compact_.setArg(1, compact_delta_);
  gs_slabs_compact_.setArg(2, compact_h_);
  return slab_sweeps(gs_slabs_compact_, 3, rhs, x, sweeps, reverse);
}

cl::Event DeviceSystem::residual_compact(const cl::Buffer& rhs, const cl::Buffer& x, const cl::Buffer& r) const {
  if (!has_compact()) throw std::logic_error("DeviceSystem::residual_compact: build_compact() first");
  Runtime::set_args(residual_compact_, coef_, compact_delta_, compact_h_, rhs, x, r, grid_);
  return rt_.enqueue_3d(residual_compact_, grid_);
}

void DeviceSystem::relax_jacobi(const cl::Buffer& rhs, const cl::Buffer& x, const cl::Buffer& tmp, double w,
                                int sweeps) const {
  for (int s = 0; s < sweeps; ++s) {
    Runtime::set_args(jacobi_, coef_, rhs, x, tmp, static_cast<cl_float>(w), grid_);
    rt_.enqueue_3d(jacobi_, grid_);
    rt_.queue().enqueueCopyBuffer(tmp, x, 0, 0, voxels() * sizeof(float));
  }
}

void DeviceSystem::zero_fixed(const cl::Buffer& x) const {
  Runtime::set_args(zero_fixed_, fixed_, x, static_cast<cl_ulong>(voxels()));
  rt_.enqueue_1d(zero_fixed_, voxels());
}

double DeviceSystem::norm(const cl::Buffer& x) const { return std::sqrt(dot(x, x)); }

void DeviceSystem::set_strided_dot(bool strided) {
  strided_dot_ = strided;
  dot_ = rt_.kernel(kSystem, strided ? "reduce_dot" : "reduce_dot_chunks");
}

// x . y: per-group (GPU) or per-chunk (CPU) partial sums on the device, added
// on the host in a fixed order, so the result is deterministic.
double DeviceSystem::dot(const cl::Buffer& x, const cl::Buffer& y) const {
  const cl_ulong n = voxels();
  std::size_t parts = 0;
  if (strided_dot_) {
    const std::size_t local = std::min<std::size_t>(kReduceLocal, rt_.info().max_work_group);
    Runtime::set_args(dot_, x, y, n, partial_, cl::Local(local * sizeof(float)));
    parts = kReduceGroups;
    rt_.queue().enqueueNDRangeKernel(dot_, cl::NullRange, cl::NDRange(parts * local), cl::NDRange(local));
  } else {
    const cl_ulong chunk = (n + kReduceChunks * 8 - 1) / (kReduceChunks * 8) * 8;
    Runtime::set_args(dot_, x, y, n, chunk, partial_);
    parts = kReduceChunks;
    rt_.queue().enqueueNDRangeKernel(dot_, cl::NullRange, cl::NDRange(parts), cl::NDRange(1));
  }
  std::vector<float> partial(parts);
  rt_.queue().enqueueReadBuffer(partial_, CL_TRUE, 0, parts * sizeof(float), partial.data());
  double sum = 0;
  for (float f : partial) sum += f;  // fixed order: deterministic
  return sum;
}

void DeviceSystem::axpby(float a, const cl::Buffer& x, float b, const cl::Buffer& y) const {
  Runtime::set_args(axpby_, a, x, b, y, static_cast<cl_ulong>(voxels()));
  rt_.enqueue_1d(axpby_, voxels());
}

void DeviceSystem::release_tensor() {
  for (auto& t : T_) t = cl::Buffer();  // enqueued kernels keep their own reference
}

Densities DeviceSystem::download_densities() const {
  if (!has_tensor()) throw std::logic_error("DeviceSystem::download_densities: the tensor T was released");
  Densities d;
  d.dims = {std::size_t(grid_.nx), std::size_t(grid_.ny), std::size_t(grid_.nz)};
  d.spacing = {grid_.hx, grid_.hy, grid_.hz};
  const std::size_t n = voxels();
  d.mu = download<float>(rt_, mu_, n);
  d.rho = download<float>(rt_, rho_, n);
  for (int i = 0; i < 6; ++i) d.T[i] = download<float>(rt_, T_[i], n);
  d.fixed = download<std::uint8_t>(rt_, fixed_, n);
  return d;
}

std::vector<float> DeviceSystem::download_coefficients() const {
  // The device's slices are STENCIL_SLICE(n) apart; the host's are packed.
  const std::size_t n = voxels();
  std::vector<float> coef(n * STENCIL_COEFS);
  for (std::size_t k = 0; k < STENCIL_COEFS; ++k)
    rt_.queue().enqueueReadBuffer(coef_, CL_FALSE, k * STENCIL_SLICE(n) * sizeof(float), n * sizeof(float),
                                  coef.data() + k * n);
  rt_.queue().finish();
  return coef;
}

std::vector<float> DeviceSystem::download_b() const { return download<float>(rt_, b_, voxels()); }

std::vector<std::uint16_t> DeviceSystem::download_compact() const {
  if (!has_compact()) throw std::logic_error("DeviceSystem::download_compact: build_compact() first");
  const std::size_t n = voxels();
  std::vector<std::uint16_t> h(n * (STENCIL_COEFS - 1));
  for (std::size_t k = 0; k + 1 < STENCIL_COEFS; ++k)
    rt_.queue().enqueueReadBuffer(compact_h_, CL_FALSE, k * STENCIL_SLICE(n) * sizeof(std::uint16_t),
                                  n * sizeof(std::uint16_t), h.data() + k * n);
  rt_.queue().finish();
  return h;
}

std::vector<float> DeviceSystem::download_compact_delta() const {
  if (!has_compact()) throw std::logic_error("DeviceSystem::download_compact_delta: build_compact() first");
  return download<float>(rt_, compact_delta_, voxels());
}

std::size_t DeviceSystem::memory_bytes() const {
  // mu, rho, b, dT, T (6, until released), the stencil, fixed; v, v~, |grad v|^2 when updatable;
  // the compact stencil (9 bfloat16 and a float) once built
  return voxels() * ((4 + (has_tensor() ? 6 : 0) + STENCIL_COEFS + (updatable() ? 3 : 0)) * sizeof(float) + 1 +
                     (has_compact() ? STENCIL_COMPACT_BYTES : 0));
}

}  // namespace softshell
