// Host side of the ultrasound phantom (kernels/phantom.cl): parameter checks,
// PSF weights, RNG stream keys, the kernel sequence, medians, phantom.json and
// the slice picture. The model and its parameters: docs/phantom.md.
#include "phantom.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

#include "error.hpp"
#include "phantom_internal.hpp"

namespace softshell {

namespace phantom_detail {

std::uint32_t stream_key(std::uint64_t seed, std::uint64_t stream) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (stream + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return static_cast<std::uint32_t>(z ^ (z >> 32));
}

double median_of_histogram(const std::array<std::size_t, 256>& hist) {
  std::size_t n = 0;
  for (std::size_t c : hist) n += c;
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  auto kth = [&](std::size_t k) {  // k-th smallest, 0-based
    std::size_t acc = 0;
    for (int v = 0; v < 256; ++v)
      if ((acc += hist[v]) > k) return v;
    return 255;
  };
  return 0.5 * (kth((n - 1) / 2) + kth(n / 2));
}

int default_lanes(const Runtime& rt) { return rt.info().is_gpu() ? 1 : 8; }

}  // namespace phantom_detail

namespace {

using phantom_detail::default_lanes;
using phantom_detail::k_median_band;
using phantom_detail::median_of_histogram;
using phantom_detail::stream_key;

constexpr int k_min_size = 16, k_max_size = 512;
constexpr double k_min_sigma = 0.2, k_max_sigma = 8.0;

// 1-D Gaussian with sum of squares 1 (radius ceil(3 sigma)): the separable
// 3-D PSF then has unit energy, so fully developed speckle from scatterers of
// mean power e has mean power e whatever the PSF size.
std::vector<float> psf_weights(double sigma) {
  const int r = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
  std::vector<double> w(2 * r + 1);
  double sum2 = 0;
  for (int k = -r; k <= r; ++k) {
    w[k + r] = std::exp(-0.5 * k * k / (sigma * sigma));
    sum2 += w[k + r] * w[k + r];
  }
  std::vector<float> out(w.size());
  for (std::size_t i = 0; i < w.size(); ++i) out[i] = static_cast<float>(w[i] / std::sqrt(sum2));
  return out;
}

std::string build_options(const PhantomParams& p, int lanes, int radius_lateral, int radius_axial) {
  return "-DSHAPE=" + std::to_string(static_cast<int>(p.shape)) + " -DLANES=" + std::to_string(lanes) +
         " -DRADIUS_LATERAL=" + std::to_string(radius_lateral) + " -DRADIUS_AXIAL=" + std::to_string(radius_axial);
}

std::string json_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '"' || c == '\\')
      out += '\\', out += c;
    else if (static_cast<unsigned char>(c) < 0x20)
      out += ' ';
    else
      out += c;
  }
  return out;
}

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  std::ostringstream s;
  s << std::setprecision(10) << v;
  return s.str();
}

}  // namespace

const char* phantom_shape_name(PhantomShape s) {
  switch (s) {
    case PhantomShape::Face:
      return "face";
    case PhantomShape::Spine:
      return "spine";
    case PhantomShape::Sphere:
      return "sphere";
  }
  return "?";
}

bool parse_phantom_shape(const std::string& name, PhantomShape& out) {
  for (PhantomShape s : {PhantomShape::Face, PhantomShape::Spine, PhantomShape::Sphere})
    if (name == phantom_shape_name(s)) {
      out = s;
      return true;
    }
  return false;
}

double phantom_default_fov(PhantomShape s) {
  switch (s) {
    case PhantomShape::Face:
      return 100.0;
    case PhantomShape::Spine:
      return 60.0;
    case PhantomShape::Sphere:
      return 80.0;
  }
  return 100.0;
}

void validate_phantom_params(const PhantomParams& p) {
  auto num = [](double v) {
    std::ostringstream s;
    s << v;
    return s.str();
  };
  const bool any_dims = p.dims[0] != 0 || p.dims[1] != 0 || p.dims[2] != 0;
  if (any_dims) {
    for (int d : p.dims)
      if (d < k_min_size || d > k_max_size)
        throw InputError("--dims " + std::to_string(p.dims[0]) + "x" + std::to_string(p.dims[1]) + "x" +
                         std::to_string(p.dims[2]) + ": every dimension must be in [16, 512]");
  } else if (p.size < k_min_size || p.size > k_max_size) {
    throw InputError("--size " + std::to_string(p.size) + " is out of range [16, 512]");
  }
  for (double s : {p.psf_axial, p.psf_lateral})
    if (!(s >= k_min_sigma && s <= k_max_sigma))
      throw InputError("--speckle: PSF sigma " + num(s) + " voxels is out of range [0.2, 8]");
  if (!(p.dynamic_range_db >= 10 && p.dynamic_range_db <= 100))
    throw InputError("--dynamic-range " + num(p.dynamic_range_db) + " dB is out of range [10, 100]");
  if (!(p.noise >= 0 && p.noise <= 100)) throw InputError("--noise " + num(p.noise) + " must be in [0, 100]");
  if (!(p.attenuation >= 0 && p.attenuation <= 100))
    throw InputError("--attenuation " + num(p.attenuation) + " must be in [0, 100]");
  if (!(p.specular >= 0 && p.specular <= 100))
    throw InputError("--specular " + num(p.specular) + " must be in [0, 100]");
  if (!(p.fov_mm >= 0 && p.fov_mm <= 10000))
    throw InputError("--fov " + num(p.fov_mm) + " mm is out of range (0, 10000]");
  if (!std::isfinite(p.top_db) || std::fabs(p.top_db) > 100) throw InputError("top level must be in [-100, 100] dB");
  if (p.lanes != 0 && p.lanes != 1 && p.lanes != 8) throw InputError("lanes must be 0 (by device), 1 or 8");
}

std::array<std::size_t, 3> phantom_dims(const PhantomParams& params) {
  if (params.dims[0] != 0 || params.dims[1] != 0 || params.dims[2] != 0)
    return {static_cast<std::size_t>(params.dims[0]), static_cast<std::size_t>(params.dims[1]),
            static_cast<std::size_t>(params.dims[2])};
  const std::size_t n = static_cast<std::size_t>(params.size);
  return {n, n, n};
}

Phantom make_phantom(Runtime& rt, const PhantomParams& params) {
  if (params.physics) return make_scan_phantom(rt, params);
  const auto t0 = std::chrono::steady_clock::now();
  validate_phantom_params(params);
  const std::array<std::size_t, 3> dims = phantom_dims(params);
  // The longest axis spans the field of view (the design cube [-50, 50]);
  // the others are centred crops of it (kernels/phantom.cl, design_coord).
  const double n_max = static_cast<double>(std::max({dims[0], dims[1], dims[2]}));
  const double fov = params.fov_mm > 0 ? params.fov_mm : phantom_default_fov(params.shape);
  const double h = fov / n_max;      // mm per voxel
  const double vox = 100.0 / n_max;  // design units per voxel (kernels/phantom.cl)
  const GridDesc g = make_grid({dims[0], dims[1], dims[2]}, {h, h, h});
  const std::size_t voxels = grid_voxels(g), bytes = voxels * sizeof(float);

  const std::vector<float> w_lat = psf_weights(params.psf_lateral), w_ax = psf_weights(params.psf_axial);
  const int lanes = params.lanes > 0 ? params.lanes : default_lanes(rt);
  const std::string opts =
      build_options(params, lanes, static_cast<int>(w_lat.size() / 2), static_cast<int>(w_ax.size() / 2));
  auto kernel = [&](const char* name) { return rt.kernel("phantom.cl", name, opts); };
  cl::Kernel geometry = kernel("phantom_geometry"), echo = kernel("phantom_echo");
  cl::Kernel redistance[3] = {kernel("phantom_redistance_x"), kernel("phantom_redistance_y"),
                              kernel("phantom_redistance_z")};
  cl::Kernel attenuate = kernel("phantom_attenuate"), bmode = kernel("phantom_bmode");
  cl::Kernel psf[3] = {kernel("phantom_psf_x"), kernel("phantom_psf_y"), kernel("phantom_psf_z")};

  // Five float planes and the uint8 result. The sdf plane holds the truth;
  // a..d change roles along the way (seeds are uint in the same planes):
  //   geometry          -> sdf (local estimate), a = aux (normal, part), b = seeds
  //   redistance x/y/z  b -> c -> b -> c
  //   echo              sdf final; a -> half transmission, c -> im, b = re
  //   attenuate         (b, c) *= transmission in a
  //   PSF x/y/z         (b, c) -> (a, d) -> (b, c) -> (a, d)
  //   bmode             (a, d) -> out
  cl::Buffer d_sdf = rt.buffer(bytes), d_a = rt.buffer(bytes), d_b = rt.buffer(bytes), d_c = rt.buffer(bytes),
             d_d = rt.buffer(bytes);
  cl::Buffer d_out = rt.buffer(voxels, CL_MEM_WRITE_ONLY);
  cl::Buffer d_w_lat(rt.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, w_lat.size() * sizeof(float),
                     const_cast<float*>(w_lat.data()));
  cl::Buffer d_w_ax(rt.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, w_ax.size() * sizeof(float),
                    const_cast<float*>(w_ax.data()));

  Phantom p;
  std::vector<cl::Event> events;
  // Work-items of the lane kernels cover `lanes` neighbouring x voxels each;
  // those of the column kernel 8 neighbouring beams.
  GridDesc lane_grid = g, columns = g;
  lane_grid.nx = (g.nx + lanes - 1) / lanes;
  columns.nx = (g.nx + 7) / 8;
  columns.nz = 1;
  auto run = [&](const char* name, cl::Kernel& k, const GridDesc& items) {
    cl::Event e;
    rt.queue().enqueueNDRangeKernel(k, cl::NullRange, rt.global_3d(items), rt.local_3d(), nullptr, &e);
    events.push_back(e);
    p.kernel_seconds.emplace_back(name, 0.0);
  };
  const cl_float f_vox = static_cast<cl_float>(vox), f_h = static_cast<cl_float>(h);

  Runtime::set_args(geometry, d_sdf, d_a, d_b, g, f_vox);
  run("geometry", geometry, lane_grid);
  Runtime::set_args(redistance[0], d_b, d_c, d_sdf, g);
  run("redistance_x", redistance[0], lane_grid);
  Runtime::set_args(redistance[1], d_c, d_b, d_sdf, g);
  run("redistance_y", redistance[1], lane_grid);
  Runtime::set_args(redistance[2], d_b, d_c, d_sdf, g);
  run("redistance_z", redistance[2], lane_grid);
  Runtime::set_args(echo, d_sdf, d_a, d_c, d_b, g, f_vox, f_h, static_cast<cl_uint>(stream_key(params.seed, 0)),
                    static_cast<cl_uint>(stream_key(params.seed, 1)), static_cast<cl_float>(params.specular),
                    static_cast<cl_float>(params.attenuation));
  run("echo", echo, lane_grid);
  Runtime::set_args(attenuate, d_b, d_c, d_a, g);
  run("attenuate", attenuate, columns);
  Runtime::set_args(psf[0], d_b, d_c, d_a, d_d, d_w_lat, g);
  run("psf_x", psf[0], lane_grid);
  Runtime::set_args(psf[1], d_a, d_d, d_b, d_c, d_w_lat, g);
  run("psf_y", psf[1], g);
  Runtime::set_args(psf[2], d_b, d_c, d_a, d_d, d_w_ax, g);
  run("psf_z", psf[2], g);
  Runtime::set_args(bmode, d_a, d_d, d_out, g, static_cast<cl_uint>(stream_key(params.seed, 2)),
                    static_cast<cl_float>(params.noise), static_cast<cl_float>(params.top_db),
                    static_cast<cl_float>(params.dynamic_range_db));
  run("bmode", bmode, lane_grid);

  p.fov_mm = fov;
  p.device = rt.info().label();
  p.truth_sdf = Volume({dims[0], dims[1], dims[2]}, {h, h, h}, ScalarType::Float32);
  rt.queue().enqueueReadBuffer(d_sdf, CL_FALSE, 0, bytes, p.truth_sdf.data.data());
  std::vector<std::uint8_t> bmode_bytes(voxels);
  rt.queue().enqueueReadBuffer(d_out, CL_TRUE, 0, voxels, bmode_bytes.data());
  p.device_seconds = event_span_seconds(events.front(), events.back());
  for (std::size_t i = 0; i < events.size(); ++i) p.kernel_seconds[i].second = event_seconds(events[i]);

  p.volume = Volume({dims[0], dims[1], dims[2]}, {h, h, h}, ScalarType::UInt8);
  std::array<std::size_t, 256> fluid{}, tissue{};
  const std::vector<float>& sdf = p.truth_sdf.data;
  for (std::size_t i = 0; i < voxels; ++i) {
    const std::uint8_t v = bmode_bytes[i];
    p.volume.data[i] = v;
    if (sdf[i] > k_median_band)
      ++fluid[v];
    else if (sdf[i] < -k_median_band)
      ++tissue[v];
  }
  p.fluid_median = median_of_histogram(fluid);
  p.tissue_median = median_of_histogram(tissue);
  if (!params.physics_name.empty()) {  // `--physics default`: every voxel scanned, no near field
    p.labels = p.truth_sdf.with_data(std::vector<float>(voxels), ScalarType::UInt8);
    for (std::size_t i = 0; i < voxels; ++i) p.labels.data[i] = sdf[i] < 0 ? 1.0f : 0.0f;
    p.near_field_median = std::numeric_limits<double>::quiet_NaN();
  }
  p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return p;
}

namespace {

// phantom.json's description of the beams (`--physics`): the geometry, and
// how to get the beam direction at a voxel.
std::string beam_geometry_json(const PhantomPhysics* phys, const Phantom& p) {
  const double h = p.volume.spacing[0];
  const auto& d = p.volume.dims;
  std::ostringstream j;
  j << "{\"kind\": \"" << (phys ? beam_geometry_name(phys->geometry) : "linear") << '"';
  if (!phys || phys->geometry == BeamGeometry::Linear) {
    j << ", \"direction\": [0, 0, 1], \"rule\": \"every beam runs along +z from the z = 0 face\"}";
    return j.str();
  }
  const double R = phys->probe_radius_mm;
  const bool point = phys->geometry == BeamGeometry::Fan3d;
  j << ", \"apex\": \"" << (point ? "point" : "line parallel to y") << "\", \"apex_mm\": [0, 0, " << json_number(-R)
    << "], \"apex_voxels\": [" << json_number(0.5 * (d[0] - 1.0)) << ", " << json_number(0.5 * (d[1] - 1.0)) << ", "
    << json_number(-R / h - 0.5) << "], \"probe_radius_mm\": " << json_number(R)
    << ", \"sector_half_angle_deg\": [" << json_number(phys->sector_deg) << ", "
    << (point ? json_number(phys->sector_y_deg) : std::string("null"))
    << "], \"scan_depth_mm\": " << json_number(phys->scan_depth_mm) << ", \"rule\": \""
    << (point ? "beam at voxel (i, j, k) = unit((i, j, k) - apex_voxels)"
              : "beam at voxel (i, j, k) = unit(i - apex_voxels[0], 0, k - apex_voxels[2])")
    << "; scanned where |angle| <= the half-angles and 0 <= |p - apex| - R <= scan_depth_mm (label != 3)\"}";
  return j.str();
}

}  // namespace

std::string phantom_json(const PhantomParams& params, const Phantom& p) {
  const double h = p.volume.spacing[0];
  const PhantomPhysics* phys = params.physics ? &*params.physics : nullptr;
  std::ostringstream j;
  j << "{\n"
    << "  \"shape\": \"" << phantom_shape_name(params.shape) << "\",\n"
    << "  \"size\": " << (params.dims[0] != 0 ? std::string("null") : std::to_string(params.size)) << ",\n"
    << "  \"dims\": [" << p.volume.dims[0] << ", " << p.volume.dims[1] << ", " << p.volume.dims[2] << "],\n"
    << "  \"seed\": " << params.seed << ",\n"
    << "  \"fov_mm\": " << json_number(p.fov_mm) << ",\n"
    << "  \"spacing_mm\": [" << json_number(h) << ", " << json_number(h) << ", " << json_number(h) << "],\n"
    << "  \"beam\": [" << json_number(p.beam[0]) << ", " << json_number(p.beam[1]) << ", " << json_number(p.beam[2])
    << "],\n";
  if (!phys) {
    j << "  \"transducer\": \"z = 0 face, parallel beams along +z\",\n"
      << "  \"psf_sigma_voxels\": {\"axial\": " << json_number(params.psf_axial)
      << ", \"lateral\": " << json_number(params.psf_lateral) << "},\n"
      << "  \"dynamic_range_db\": " << json_number(params.dynamic_range_db) << ",\n"
      << "  \"top_db\": " << json_number(params.top_db) << ",\n"
      << "  \"noise\": " << json_number(params.noise) << ",\n"
      << "  \"attenuation\": " << json_number(params.attenuation) << ",\n"
      << "  \"specular\": " << json_number(params.specular) << ",\n";
  } else {
    j << "  \"transducer\": \"probe surface at the top (z = 0) face; beams as beam_geometry says\",\n";
  }
  if (!params.physics_name.empty()) {
    j << "  \"physics\": \"" << json_escape(params.physics_name) << "\",\n";
    if (phys)
      j << "  \"physics_parameters\": {\n" << phantom_physics_json(*phys, 4) << "\n  },\n";
    j << "  \"world_frame\": \"mm: x = (i + 0.5 - nx/2) h, y = (j + 0.5 - ny/2) h, z = (k + 0.5) h (depth below the top "
         "face)\",\n"
      << "  \"beam_geometry\": " << beam_geometry_json(phys, p) << ",\n";
    if (phys)
      j << "  \"scan\": {\"beam_cells\": [" << p.beam_cells[0] << ", " << p.beam_cells[1] << ", " << p.beam_cells[2]
        << "], \"psf_sigma_cells\": {\"lateral\": [" << json_number(p.psf_lateral_cells[0]) << ", "
        << json_number(p.psf_lateral_cells[1]) << "], \"elevation\": [" << json_number(p.psf_elevation_cells[0])
        << ", " << json_number(p.psf_elevation_cells[1]) << "], \"axial\": " << json_number(p.psf_axial_cells)
        << "}, \"psf_radius_cells\": [" << p.psf_radius[0] << ", " << p.psf_radius[1] << ", " << p.psf_radius[2]
        << "]},\n";
    if (phys)
      j << "  \"shadow_db\": \"shadow_db.nrrd\",\n"
        << "  \"shadow_db_meaning\": \"two-way loss (dB) beyond what the TGC restores: > 0 in acoustic shadows, < 0 "
           "below fluid, 1000 outside the scanned region (nothing there can be seen)\",\n";
    j << "  \"labels\": \"labels.nrrd\",\n"
      << "  \"label_values\": {\"0\": \"fluid / background\", \"1\": \"object (sdf < 0)\", \"2\": \"near-field "
         "layers\", \"3\": \"outside the scanned region (grey 0)\"},\n"
      << "  \"near_field_median\": " << json_number(p.near_field_median) << ",\n";
  }
  j << "  \"volume\": \"volume.nrrd\",\n"
    << "  \"truth_sdf\": \"truth_sdf.nrrd\",\n"
    << "  \"sdf_units\": \"voxels\",\n"
    << "  \"sdf_sign\": \"negative inside tissue\",\n"
    << "  \"median_band_voxels\": " << json_number(k_median_band) << ",\n"
    << "  \"fluid_median\": " << json_number(p.fluid_median) << ",\n"
    << "  \"tissue_median\": " << json_number(p.tissue_median) << ",\n"
    << "  \"generation_seconds\": " << json_number(p.seconds) << ",\n"
    << "  \"device_seconds\": " << json_number(p.device_seconds) << ",\n"
    << "  \"kernel_ms\": {";
  for (std::size_t i = 0; i < p.kernel_seconds.size(); ++i)
    j << (i ? ", " : "") << '"' << p.kernel_seconds[i].first
      << "\": " << json_number(std::round(1e6 * p.kernel_seconds[i].second) / 1e3);
  j << "},\n"
    << "  \"device\": \"" << json_escape(p.device) << "\"\n"
    << "}\n";
  return j.str();
}

Image phantom_slices(const Phantom& p, int panel_height) {
  const int height = panel_height > 0 ? panel_height : std::max<int>(static_cast<int>(p.volume.dims[2]), 256);
  const Image grey = slice_montage({&p.volume}, height);
  const int gap = 4;
  Image out(grey.width, 2 * grey.height + gap, 32);
  for (int y = 0; y < grey.height; ++y) {
    std::copy_n(grey.pixel(0, y), grey.width * 3, out.pixel(0, y));
    std::copy_n(grey.pixel(0, y), grey.width * 3, out.pixel(0, grey.height + gap + y));
  }
  // Outlines in the second row: a mask (uint8 0 / 255, so its intensity map
  // is the type range) goes through the same montage, so its pixels line up
  // with the volume's; its boundary is a pixel in the mask with a 4-neighbour
  // outside (the gaps between panels are grey 32 in both montages, so they
  // never count as outside).
  auto outline = [&](auto in_mask, std::array<std::uint8_t, 3> colour) {
    Volume mask = p.truth_sdf.with_data(std::vector<float>(p.truth_sdf.voxels()), ScalarType::UInt8);
    for (std::size_t i = 0; i < mask.voxels(); ++i) mask.data[i] = in_mask(i) ? 255.0f : 0.0f;
    const Image inside = slice_montage({&mask}, height);
    for (int y = 0; y < inside.height; ++y)
      for (int x = 0; x < inside.width; ++x) {
        if (inside.pixel(x, y)[0] <= 128) continue;
        bool edge = false;
        const int dx[4] = {1, -1, 0, 0}, dy[4] = {0, 0, 1, -1};
        for (int k = 0; k < 4 && !edge; ++k) {
          const int u = x + dx[k], v = y + dy[k];
          if (u < 0 || v < 0 || u >= inside.width || v >= inside.height) continue;
          edge = inside.pixel(u, v)[0] == 0;
        }
        if (edge) std::copy_n(colour.data(), 3, out.pixel(x, grey.height + gap + y));
      }
  };
  // The near-field band (label 2) in cyan, under the true boundary in orange.
  if (!p.labels.data.empty()) outline([&](std::size_t i) { return p.labels.data[i] == 2.0f; }, {0, 200, 255});
  outline([&](std::size_t i) { return p.truth_sdf.data[i] < 0; }, {255, 150, 0});
  return out;
}

std::vector<float> phantom_implicit(Runtime& rt, const PhantomParams& params,
                                    const std::vector<std::array<float, 3>>& points) {
  validate_phantom_params(params);
  if (points.empty()) return {};
  const std::size_t n = static_cast<std::size_t>(params.size);
  const GridDesc g = make_grid({n, n, n}, {1.0, 1.0, 1.0});
  const std::size_t count = points.size(), padded = (count + 7) / 8 * 8;
  std::vector<float> planes[3];
  for (int a = 0; a < 3; ++a) {
    planes[a].assign(padded, 0.0f);
    for (std::size_t i = 0; i < count; ++i) planes[a][i] = points[i][a];
  }
  cl::Buffer d_p[3];
  for (int a = 0; a < 3; ++a)
    d_p[a] =
        cl::Buffer(rt.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, padded * sizeof(float), planes[a].data());
  cl::Buffer d_f = rt.buffer(padded * sizeof(float));
  // The PSF radii do not matter here; taking make_phantom's reuses its program.
  const int lanes = params.lanes > 0 ? params.lanes : default_lanes(rt);
  const int r_lat = static_cast<int>(psf_weights(params.psf_lateral).size() / 2);
  const int r_ax = static_cast<int>(psf_weights(params.psf_axial).size() / 2);
  if (params.physics) {  // posed: the program of make_scan_phantom
    const std::string opts =
        "-DSHAPE=" + std::to_string(static_cast<int>(params.shape)) + " -DLANES=" + std::to_string(lanes) + " -DPOSE=1";
    cl::Kernel k = rt.kernel("phantom_scan.cl", "phantom_implicit", opts);
    Runtime::set_args(k, d_p[0], d_p[1], d_p[2], d_f, g, static_cast<cl_float>(100.0 / params.size),
                      static_cast<cl_uint>(count), phantom_detail::pose_argument(*params.physics));
    rt.enqueue_1d(k, (count + lanes - 1) / lanes);
    std::vector<float> f(count);
    rt.queue().enqueueReadBuffer(d_f, CL_TRUE, 0, count * sizeof(float), f.data());
    return f;
  }
  cl::Kernel k = rt.kernel("phantom.cl", "phantom_implicit", build_options(params, lanes, r_lat, r_ax));
  Runtime::set_args(k, d_p[0], d_p[1], d_p[2], d_f, g, static_cast<cl_float>(100.0 / params.size),
                    static_cast<cl_uint>(count));
  rt.enqueue_1d(k, (count + lanes - 1) / lanes);
  std::vector<float> f(count);
  rt.queue().enqueueReadBuffer(d_f, CL_TRUE, 0, count * sizeof(float), f.data());
  return f;
}

}  // namespace softshell
