// Host side of the phantom with physics in physical units
// (kernels/phantom_scan.cl): the beam grid, the parameter block, per-depth
// PSF weights and time-gain compensation, the kernel sequence, labels and
// medians. Parameters and model: docs/phantom.md.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "error.hpp"
#include "phantom.hpp"
#include "phantom_internal.hpp"
#include "phantom_scan.h"

namespace softshell {

namespace phantom_detail {

std::array<double, 9> pose_rotation(const PhantomPhysics& p) {
  const double d2r = M_PI / 180.0;
  const double cy = std::cos(p.yaw_deg * d2r), sy = std::sin(p.yaw_deg * d2r);
  const double cr = std::cos(p.roll_deg * d2r), sr = std::sin(p.roll_deg * d2r);
  const double cp = std::cos(p.pitch_deg * d2r), sp = std::sin(p.pitch_deg * d2r);
  const double rz[9] = {cy, -sy, 0, sy, cy, 0, 0, 0, 1};
  const double ry[9] = {cr, 0, sr, 0, 1, 0, -sr, 0, cr};
  const double rx[9] = {1, 0, 0, 0, cp, -sp, 0, sp, cp};
  auto mul = [](const double* a, const double* b) {
    std::array<double, 9> c{};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) c[3 * i + j] += a[3 * i + k] * b[3 * k + j];
    return c;
  };
  const std::array<double, 9> zy = mul(rz, ry);
  return mul(zy.data(), rx);
}

cl_float16 pose_argument(const PhantomPhysics& p) {
  const std::array<double, 9> r = pose_rotation(p);
  const double design = 100.0 / p.fov_mm;
  cl_float16 f{};
  for (int i = 0; i < 9; ++i) f.s[i] = static_cast<cl_float>(r[i]);
  for (int i = 0; i < 3; ++i) f.s[9 + i] = static_cast<cl_float>(p.shift_mm[i] * design);
  return f;
}

}  // namespace phantom_detail

namespace {

using namespace phantom_detail;

constexpr int k_max_psf_radius = 40;   // cells; wider PSFs are narrowed to radius / 3
constexpr double k_min_psf_cells = 0.3;  // the narrowest PSF the grid represents (sigma, cells)

double deg(double d) { return d * M_PI / 180.0; }

// The beam grid: cells along u (lateral), v (elevation), w (depth).
struct BeamGrid {
  int nu = 0, nv = 0, nw = 0;
  double dth_x = 0, dth_y = 0, dr = 0, depth = 0;
};

BeamGrid beam_grid(const PhantomPhysics& p, int n, double h) {
  BeamGrid b;
  if (p.geometry == BeamGeometry::Linear) {
    b.nu = b.nv = b.nw = n;
    b.dr = h;
    b.depth = n * h;
    return b;
  }
  // Lateral sampling: one voxel spacing at 40 % of the scan depth (finer above,
  // coarser below, as a scanner's lines spread with depth); depth: one voxel.
  b.depth = p.scan_depth_mm;
  const double r_ref = p.probe_radius_mm + 0.4 * b.depth;
  b.nu = std::max(8, static_cast<int>(std::ceil(2 * deg(p.sector_deg) * r_ref / h)));
  b.dth_x = 2 * deg(p.sector_deg) / b.nu;
  if (p.geometry == BeamGeometry::Fan3d) {
    b.nv = std::max(8, static_cast<int>(std::ceil(2 * deg(p.sector_y_deg) * r_ref / h)));
    b.dth_y = 2 * deg(p.sector_y_deg) / b.nv;
  } else {
    b.nv = n;
  }
  b.nw = std::max(2, static_cast<int>(std::ceil(b.depth / h)));
  b.dr = b.depth / b.nw;
  return b;
}

// Gaussian taps with sum of squares 1 (so fully developed speckle keeps its
// mean power), radius `radius`.
void gaussian_row(double sigma, int radius, float* out) {
  double sum2 = 0;
  std::vector<double> w(2 * radius + 1);
  for (int k = -radius; k <= radius; ++k) {
    w[k + radius] = std::exp(-0.5 * k * k / (sigma * sigma));
    sum2 += w[k + radius] * w[k + radius];
  }
  for (int k = 0; k <= 2 * radius; ++k) out[k] = static_cast<float>(w[k] / std::sqrt(sum2));
}

// Per-depth PSF table: sigma (cells) per row, the radius, the weights.
struct PsfTable {
  int radius = 1;
  double lo = 0, hi = 0;  // sigma range, cells
  std::vector<float> weights;
};

PsfTable psf_table(const std::vector<double>& sigma_cells) {
  PsfTable t;
  double top = 0;
  for (double s : sigma_cells) top = std::max(top, std::max(s, k_min_psf_cells));
  t.radius = std::clamp(static_cast<int>(std::ceil(3 * top)), 1, k_max_psf_radius);
  const double cap = t.radius / 3.0;
  t.lo = 1e30, t.hi = 0;
  t.weights.resize(sigma_cells.size() * (2 * t.radius + 1));
  for (std::size_t w = 0; w < sigma_cells.size(); ++w) {
    const double s = std::clamp(sigma_cells[w], k_min_psf_cells, std::max(cap, k_min_psf_cells));
    t.lo = std::min(t.lo, s), t.hi = std::max(t.hi, s);
    gaussian_row(s, t.radius, t.weights.data() + w * (2 * t.radius + 1));
  }
  return t;
}

cl::Buffer upload(Runtime& rt, const std::vector<float>& v) {
  return cl::Buffer(rt.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, v.size() * sizeof(float),
                    const_cast<float*>(v.data()));
}

// The kernels' parameter block (kernels/phantom_scan.h).
std::vector<float> parameter_block(const PhantomPhysics& p, PhantomShape shape, const BeamGrid& b, double h) {
  std::vector<double> P(PS_COUNT, 0.0);
  P[PS_KIND] = static_cast<int>(p.geometry);
  P[PS_H] = h;
  P[PS_R] = p.geometry == BeamGeometry::Linear ? 0.0 : p.probe_radius_mm;
  P[PS_DTH_X] = b.dth_x;
  P[PS_DTH_Y] = b.dth_y;
  P[PS_DR] = b.dr;
  P[PS_TAN_X] = std::tan(deg(p.sector_deg));
  P[PS_TAN_Y] = std::tan(deg(p.sector_y_deg));
  P[PS_DEPTH] = b.depth;
  P[PS_DESIGN] = 100.0 / p.fov_mm;
  const cl_float16 pose = pose_argument(p);
  for (int i = 0; i < 12; ++i) P[PS_POSE + i] = pose.s[i];

  // Soft tissue's two-way attenuation, dB/mm (dB/cm/MHz one-way x MHz x 2 / 10).
  const double att = p.attenuation_db_cm_mhz * p.frequency_mhz / 5.0;
  const double contrast = std::pow(10.0, p.contrast_db / 10.0);
  if (shape == PhantomShape::Spine) {  // muscle around bone
    P[PS_E_BG] = 1.0;
    P[PS_E_PART + 0] = P[PS_E_PART + 1] = 1.0;
    P[PS_E_PART + 2] = contrast;
    P[PS_ATT_BG] = att;
  } else {  // tissue in fluid (its attenuation 2 % of tissue's: water-like)
    P[PS_E_BG] = 1.0 / contrast;
    P[PS_E_PART + 0] = 1.0, P[PS_E_PART + 1] = 1.3, P[PS_E_PART + 2] = 1.0;
    P[PS_ATT_BG] = 0.02 * att;
  }
  P[PS_E_SKULL] = shape == PhantomShape::Face ? std::pow(10.0, p.skull_db / 10.0) : 0.0;
  // Boundary echo amplitudes and reflection losses by part (tissue, wall,
  // bone): the fixed physics' values, x specular.
  const double spec[3] = {2.5, 1.5, 6.0}, refl[3] = {1.0, 1.0, 4.0};
  for (int i = 0; i < 3; ++i) {
    P[PS_SPEC_PART + i] = spec[i] * p.specular;
    P[PS_REFL_PART + i] = refl[i] * p.specular;
  }
  P[PS_ATT_PART + 0] = P[PS_ATT_PART + 1] = att;
  P[PS_ATT_PART + 2] = p.bone_atten_db_mm;
  P[PS_ATT_SKULL] = shape == PhantomShape::Face ? p.bone_atten_db_mm : 0.0;
  P[PS_TEXTURE] = p.texture;
  // Point density: scatterers per resolution cell over its volume at the focus.
  const double cell = std::pow(2 * M_PI, 1.5) * p.psf_lateral_mm * p.psf_elevation_mm * p.psf_axial_mm;
  P[PS_RHO] = p.scatterers_per_cell / cell;
  P[PS_SPEC_W] = 0.5 * std::max(h, b.dr);

  P[PS_NF] = p.near_field_mm > 0 ? 1.0 : 0.0;
  P[PS_NF_B + 0] = p.skin_mm;
  P[PS_NF_B + 1] = p.skin_mm + p.fat_mm;
  P[PS_NF_B + 2] = p.near_field_mm;
  P[PS_NF_WAVE] = p.near_field_wave;
  const double k = 2 * M_PI / p.near_field_wavelength_mm;
  P[PS_NF_K + 0] = k * std::cos(deg(p.near_field_dir_deg[0]));
  P[PS_NF_K + 1] = k * std::sin(deg(p.near_field_dir_deg[0]));
  P[PS_NF_K + 2] = 1.7 * k * std::cos(deg(p.near_field_dir_deg[1]));
  P[PS_NF_K + 3] = 1.7 * k * std::sin(deg(p.near_field_dir_deg[1]));
  for (int i = 0; i < 8; ++i) P[PS_NF_PHASE + i] = deg(p.near_field_phase_deg[i]);
  P[PS_NF_E + 0] = std::pow(10.0, (p.near_field_db + 3) / 10.0);
  P[PS_NF_E + 1] = std::pow(10.0, (p.near_field_db + p.fat_db) / 10.0);
  P[PS_NF_E + 2] = std::pow(10.0, p.near_field_db / 10.0);
  P[PS_NF_SPEC] = 2.5 * p.near_field_specular;
  P[PS_NF_REFL] = 0.5 * p.near_field_specular;
  P[PS_NF_ATT + 0] = att, P[PS_NF_ATT + 1] = 0.8 * att, P[PS_NF_ATT + 2] = 1.2 * att;
  P[PS_NF_REVERB] = std::pow(10.0, p.reverb_db / 20.0);

  P[PS_JITTER] = p.jitter_mm;
  P[PS_NOISE] = std::pow(10.0, p.noise_db / 20.0);
  P[PS_DR_DB] = p.dynamic_range_db;
  P[PS_TOP_DB] = p.dynamic_range_db * (1.0 - p.tissue_grey / 255.0);
  P[PS_ATT_REF] = att;
  return std::vector<float>(P.begin(), P.end());
}

}  // namespace

BeamAt phantom_beam_at(const PhantomPhysics& p, double x, double y, double z) {
  BeamAt b;
  if (p.geometry == BeamGeometry::Linear) {
    b.depth_mm = z;
    return b;
  }
  const double R = p.probe_radius_mm, zz = z + R;
  const double ty = p.geometry == BeamGeometry::Fan3d ? y : 0.0;
  const double r = std::sqrt(x * x + ty * ty + zz * zz);
  b.dir = {x / r, ty / r, zz / r};
  b.depth_mm = r - R;
  b.scanned = zz > 0 && std::fabs(x) <= zz * std::tan(deg(p.sector_deg)) && b.depth_mm >= 0 &&
              b.depth_mm <= p.scan_depth_mm;
  if (p.geometry == BeamGeometry::Fan3d) b.scanned = b.scanned && std::fabs(y) <= zz * std::tan(deg(p.sector_y_deg));
  return b;
}

Phantom make_scan_phantom(Runtime& rt, const PhantomParams& params) {
  const auto t0 = std::chrono::steady_clock::now();
  validate_phantom_params(params);
  if (!params.physics) throw std::logic_error("make_scan_phantom needs params.physics");
  const PhantomPhysics& phys = *params.physics;
  validate_phantom_physics(phys);
  if (params.dims[0] != 0 || params.dims[1] != 0 || params.dims[2] != 0)
    throw InputError("--dims cannot be combined with --physics (cubic volumes only)");

  const int n = params.size;
  const std::size_t nn = static_cast<std::size_t>(n);
  const double h = phys.fov_mm / n;  // mm per voxel
  const double vox = 100.0 / n;       // design units per voxel
  const GridDesc g = make_grid({nn, nn, nn}, {h, h, h});
  const std::size_t voxels = grid_voxels(g), bytes = voxels * sizeof(float);
  const BeamGrid bgrid = beam_grid(phys, n, h);
  const GridDesc bg = make_grid({static_cast<std::size_t>(bgrid.nu), static_cast<std::size_t>(bgrid.nv),
                                 static_cast<std::size_t>(bgrid.nw)},
                                {1.0, 1.0, 1.0});
  const std::size_t cells = grid_voxels(bg), cell_bytes = cells * sizeof(float);

  // Per-depth tables: the PSF's widths in cells, and the TGC's amplitude gain.
  const bool fan = phys.geometry != BeamGeometry::Linear;
  const double R = fan ? phys.probe_radius_mm : 0.0;
  std::vector<double> s_lat(bgrid.nw), s_elev(bgrid.nw);
  std::vector<float> gain(bgrid.nw);
  const double att = phys.attenuation_db_cm_mhz * phys.frequency_mhz / 5.0;
  for (int w = 0; w < bgrid.nw; ++w) {
    const double d = (w + 0.5) * bgrid.dr, r = R + d;
    // Away from the focus the beam widens; in elevation (a fixed lens focus,
    // a wider aperture's worth of slice already) half as fast.
    const double off = std::fabs(d - phys.focus_depth_mm) / bgrid.depth;
    const double du = fan ? r * bgrid.dth_x : h;
    const double dv = phys.geometry == BeamGeometry::Fan3d ? r * bgrid.dth_y : h;
    s_lat[w] = phys.psf_lateral_mm * (1.0 + phys.beam_spread * off) / du;
    s_elev[w] = phys.psf_elevation_mm * (1.0 + 0.5 * phys.beam_spread * off) / dv;
    const double t = d / bgrid.depth;
    const double tgc_db = att * d + phys.tgc_slope_db * t + phys.tgc_bow_db * 4 * t * (1 - t);
    gain[w] = static_cast<float>(std::pow(10.0, tgc_db / 20.0));
  }
  const PsfTable psf_u = psf_table(s_lat), psf_v = psf_table(s_elev);
  const PsfTable psf_w = psf_table({phys.psf_axial_mm / bgrid.dr});
  const std::vector<float> P = parameter_block(phys, params.shape, bgrid, h);

  const int lanes = params.lanes > 0 ? params.lanes : default_lanes(rt);
  const std::string opts = "-DSHAPE=" + std::to_string(static_cast<int>(params.shape)) +
                           " -DLANES=" + std::to_string(lanes) + " -DPOSE=1";
  auto kernel = [&](const char* name) { return rt.kernel("phantom_scan.cl", name, opts); };
  cl::Kernel geometry = kernel("phantom_geometry"), finish = kernel("phantom_scan_finish");
  cl::Kernel redistance[3] = {kernel("phantom_redistance_x"), kernel("phantom_redistance_y"),
                              kernel("phantom_redistance_z")};
  cl::Kernel echo = kernel("phantom_scan_echo"), attenuate = kernel("phantom_scan_attenuate");
  cl::Kernel psf[3] = {kernel("phantom_scan_psf_x"), kernel("phantom_scan_psf_y"), kernel("phantom_scan_psf_z")};
  cl::Kernel bmode = kernel("phantom_scan_bmode"), convert = kernel("phantom_scan_convert");

  // Voxel planes: sdf (truth), aux (normal_z + 4 part), seeds in b and c,
  // later the shadow (b). Beam planes: (re, im) and (re2, im2) ping-pong
  // (re later the grey levels), t = the loss per cell, then accumulated.
  cl::Buffer d_sdf = rt.buffer(bytes), d_aux = rt.buffer(bytes), d_b = rt.buffer(bytes), d_c = rt.buffer(bytes);
  cl::Buffer d_re = rt.buffer(cell_bytes), d_im = rt.buffer(cell_bytes), d_re2 = rt.buffer(cell_bytes),
             d_im2 = rt.buffer(cell_bytes), d_t = rt.buffer(cell_bytes);
  cl::Buffer d_out = rt.buffer(voxels, CL_MEM_WRITE_ONLY), d_labels = rt.buffer(voxels, CL_MEM_WRITE_ONLY);
  cl::Buffer d_P = upload(rt, P), d_gain = upload(rt, gain);
  cl::Buffer d_wu = upload(rt, psf_u.weights), d_wv = upload(rt, psf_v.weights), d_ww = upload(rt, psf_w.weights);

  Phantom p;
  std::vector<cl::Event> events;
  auto lane_items = [&](GridDesc items) {
    items.nx = (items.nx + lanes - 1) / lanes;
    return items;
  };
  GridDesc columns = bg;
  columns.nx = (bg.nx + 7) / 8;
  columns.nz = 1;
  auto run = [&](const char* name, cl::Kernel& k, const GridDesc& items) {
    cl::Event e;
    rt.queue().enqueueNDRangeKernel(k, cl::NullRange, rt.global_3d(items), rt.local_3d(), nullptr, &e);
    events.push_back(e);
    p.kernel_seconds.emplace_back(name, 0.0);
  };
  const cl_float16 pose = pose_argument(phys);
  const std::uint64_t seed = params.seed;

  Runtime::set_args(geometry, d_sdf, d_aux, d_b, g, static_cast<cl_float>(vox), pose);
  run("geometry", geometry, lane_items(g));
  Runtime::set_args(redistance[0], d_b, d_c, d_sdf, g);
  run("redistance_x", redistance[0], lane_items(g));
  Runtime::set_args(redistance[1], d_c, d_b, d_sdf, g);
  run("redistance_y", redistance[1], lane_items(g));
  Runtime::set_args(redistance[2], d_b, d_c, d_sdf, g);
  run("redistance_z", redistance[2], lane_items(g));
  Runtime::set_args(finish, d_sdf, d_c, g);
  run("finish", finish, lane_items(g));
  Runtime::set_args(echo, d_sdf, d_aux, g, d_re, d_im, d_t, bg, d_P, static_cast<cl_uint>(stream_key(seed, 0)),
                    static_cast<cl_uint>(stream_key(seed, 1)), static_cast<cl_uint>(stream_key(seed, 3)));
  run("echo", echo, lane_items(bg));
  Runtime::set_args(attenuate, d_re, d_im, d_t, bg);
  run("attenuate", attenuate, columns);
  Runtime::set_args(psf[0], d_re, d_im, d_re2, d_im2, d_wu, static_cast<cl_int>(psf_u.radius), bg);
  run("psf_u", psf[0], lane_items(bg));
  Runtime::set_args(psf[1], d_re2, d_im2, d_re, d_im, d_wv, static_cast<cl_int>(psf_v.radius), bg);
  run("psf_v", psf[1], bg);
  Runtime::set_args(psf[2], d_re, d_im, d_re2, d_im2, d_ww, static_cast<cl_int>(psf_w.radius), bg);
  run("psf_w", psf[2], bg);
  Runtime::set_args(bmode, d_re2, d_im2, d_re, bg, d_gain, d_P, static_cast<cl_uint>(stream_key(seed, 2)));
  run("bmode", bmode, lane_items(bg));
  Runtime::set_args(convert, d_re, d_t, bg, d_sdf, d_out, d_labels, d_b, g, d_P,
                    static_cast<cl_uint>(stream_key(seed, 4)));
  run("convert", convert, lane_items(g));

  p.fov_mm = phys.fov_mm;
  p.device = rt.info().label();
  p.truth_sdf = Volume({nn, nn, nn}, {h, h, h}, ScalarType::Float32);
  rt.queue().enqueueReadBuffer(d_sdf, CL_FALSE, 0, bytes, p.truth_sdf.data.data());
  p.shadow_db = Volume({nn, nn, nn}, {h, h, h}, ScalarType::Float32);
  rt.queue().enqueueReadBuffer(d_b, CL_FALSE, 0, bytes, p.shadow_db.data.data());
  std::vector<std::uint8_t> grey(voxels), labels(voxels);
  rt.queue().enqueueReadBuffer(d_labels, CL_FALSE, 0, voxels, labels.data());
  rt.queue().enqueueReadBuffer(d_out, CL_TRUE, 0, voxels, grey.data());
  p.device_seconds = event_span_seconds(events.front(), events.back());
  for (std::size_t i = 0; i < events.size(); ++i) p.kernel_seconds[i].second = event_seconds(events[i]);

  p.volume = Volume({nn, nn, nn}, {h, h, h}, ScalarType::UInt8);
  p.labels = Volume({nn, nn, nn}, {h, h, h}, ScalarType::UInt8);
  std::array<std::size_t, 256> fluid{}, tissue{}, band{};
  const std::vector<float>& sdf = p.truth_sdf.data;
  for (std::size_t i = 0; i < voxels; ++i) {
    const std::uint8_t v = grey[i], l = labels[i];
    p.volume.data[i] = v;
    p.labels.data[i] = l;
    if (l == 2)
      ++band[v];
    else if (l == 0 && sdf[i] > k_median_band)
      ++fluid[v];
    else if (l == 1 && sdf[i] < -k_median_band)
      ++tissue[v];
  }
  p.fluid_median = median_of_histogram(fluid);
  p.tissue_median = median_of_histogram(tissue);
  p.near_field_median = median_of_histogram(band);
  p.beam_cells = {bgrid.nu, bgrid.nv, bgrid.nw};
  p.psf_lateral_cells = {psf_u.lo, psf_u.hi};
  p.psf_elevation_cells = {psf_v.lo, psf_v.hi};
  p.psf_axial_cells = psf_w.lo;
  p.psf_radius = {psf_u.radius, psf_v.radius, psf_w.radius};
  p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return p;
}

}  // namespace softshell
