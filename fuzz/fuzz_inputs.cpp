// The fuzz harnesses' bodies and seeds (fuzz/fuzz_inputs.hpp).
#include "fuzz_inputs.hpp"

#include <bzlib.h>
#include <zlib.h>
#include <dirent.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

#include "auto_iso.hpp"
#include "cl_runtime.hpp"
#include "classify_checks.hpp"
#include "error.hpp"
#include "filter.hpp"
#include "io.hpp"
#include "levoy.hpp"
#include "mask.hpp"
#include "shadow_walls.hpp"
#include "speckle.hpp"
#include "variational.hpp"

namespace softshell::fuzz {
namespace {

namespace fs = std::filesystem;

// The input being run, kept so fail() can save it: libFuzzer writes its
// crash artifact from a SIGABRT handler, which LLVM inside PoCL replaces
// with its own once it has compiled a kernel (a classify failure left no
// artifact).
const std::uint8_t* g_input = nullptr;
std::size_t g_input_size = 0;

void current_input(const std::uint8_t* data, std::size_t size) { g_input = data, g_input_size = size; }

[[noreturn]] void fail(const std::string& what) {
  std::cerr << "softshell fuzz: " << what << std::endl;
  // SOFTSHELL_FUZZ_ARTIFACT (scripts/fuzz.sh sets it): a path prefix; the
  // input goes to PREFIX failed-<FNV-1a hash>.
  if (const char* prefix = std::getenv("SOFTSHELL_FUZZ_ARTIFACT"); prefix && g_input) {
    std::uint64_t h = 1469598103934665603ull;
    for (std::size_t i = 0; i < g_input_size; ++i) h = (h ^ g_input[i]) * 1099511628211ull;
    char name[32];
    std::snprintf(name, sizeof name, "failed-%016llx", static_cast<unsigned long long>(h));
    const std::string path = std::string(prefix) + name;
    if (FILE* f = std::fopen(path.c_str(), "wb")) {
      std::fwrite(g_input, 1, g_input_size, f);
      std::fclose(f);
      std::cerr << "softshell fuzz: input saved to " << path << std::endl;
    }
  }
  std::abort();
}

// One scratch directory per process, emptied before every input; on tmpfs
// when there is one (the writers fsync).
const std::string& scratch() {
  // Never destroyed: the exit handler below still needs it.
  static const std::string* dir = [] {
    std::string base = "/dev/shm";
    if (::access(base.c_str(), W_OK) != 0) base = fs::temp_directory_path().string();
    std::string pattern = base + "/softshell-fuzz-XXXXXX";
    if (!::mkdtemp(pattern.data())) fail("cannot create a scratch directory in " + base);
    auto* kept = new std::string(pattern);
    std::atexit([] {
      std::error_code ec;
      fs::remove_all(scratch(), ec);
    });
    return kept;
  }();
  return *dir;
}

std::string reset_scratch() {
  const std::string& dir = scratch();
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) fs::remove_all(e.path(), ec);
  return dir;
}

void put(const std::string& path, const char* data, std::size_t size) {
  std::ofstream out(path, std::ios::binary);
  out.write(data, static_cast<std::streamsize>(size));
  if (!out) fail("cannot write " + path);
}

// Writes the input as a header file (and its data file after the
// separator); returns the header's path.
std::string place(const std::uint8_t* data, std::size_t size, const char* attached, const char* detached,
                  const char* data_name = "v.raw") {
  const std::string dir = reset_scratch();
  const char* bytes = reinterpret_cast<const char*>(data);
  const std::string all(bytes, size);
  const std::size_t sep = all.find(kDataSeparator, 0, 4);
  if (sep == std::string::npos) {
    put(dir + "/" + attached, bytes, size);
    return dir + "/" + attached;
  }
  put(dir + "/" + detached, bytes, sep);
  put(dir + "/" + data_name, bytes + sep + 4, size - sep - 4);
  return dir + "/" + detached;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

bool close(double a, double b) { return std::fabs(a - b) <= 1e-5 * std::max(std::fabs(a), std::fabs(b)); }

// What every volume that reads must satisfy, and its round trip through
// every writer.
void check_volume(const std::string& path, const Volume& v) {
  const VolumeHeader h = read_any_header(path);
  if (v.voxels() == 0 || v.data.size() != v.voxels()) fail("a volume without samples read from " + path);
  if (h.dims != v.dims || h.type != v.source_type || h.spacing != v.spacing || h.origin != v.origin)
    fail("read_volume_header and read_volume disagree on " + path);
  if (h.files.empty() || h.files.front() != path) fail("the header's file list does not start with it");
  for (int a = 0; a < 3; ++a)
    if (!(v.spacing[a] >= kMinSpacingMm && v.spacing[a] <= kMaxSpacingMm) || !std::isfinite(v.origin[a]))
      fail("implausible geometry passed the checks");
  // A run can never write over the files it read.
  for (const std::string& f : h.files) {
    bool refused = false;
    try {
      ensure_distinct_output(path, f);
    } catch (const InputError&) {
      refused = true;
    }
    if (!refused) fail("ensure_distinct_output let " + f + " overwrite its input " + path);
  }
  if (v.voxels() > (1u << 16)) return;
  const std::string dir = scratch();
  // Positions are compared in LPS: a RAS or LAS volume is written to MetaImage converted.
  const auto lps_point = [](const Volume& vol, const Vec3d& p) {
    Vec3d w = vol.index_to_world(p);
    if (vol.frame.space == "right-anterior-superior") w[0] = -w[0], w[1] = -w[1];
    if (vol.frame.space == "left-anterior-superior") w[1] = -w[1];
    return w;
  };
  double extent = 0;
  for (int a = 0; a < 3; ++a) extent += std::fabs(v.origin[a]) + v.spacing[a] * double(v.dims[a]);
  for (const char* name : {"o.nrrd", "o.mha", "o.mhd", "z.nrrd", "z.mha", "z.mhd"}) {
    WriteOptions w;
    w.compress = name[0] == 'z';
    const std::string out = dir + "/" + name;
    write_volume(out, v, w);  // an InputError here is a bug: the volume is valid
    const Volume back = read_volume(out);
    if (back.dims != v.dims || back.source_type != v.source_type || !same_bits(back.data, v.data))
      fail(std::string("samples changed through ") + name);
    for (int a = 0; a < 3; ++a)
      if (!close(back.spacing[a], v.spacing[a])) fail(std::string("spacing changed through ") + name);
    for (const Vec3d p : {Vec3d{0, 0, 0}, Vec3d{double(v.dims[0] - 1), double(v.dims[1] - 1), double(v.dims[2] - 1)},
                          Vec3d{double(v.dims[0] - 1), 0, 0}, Vec3d{0, double(v.dims[1] - 1), 0}}) {
      const Vec3d a = lps_point(back, p), b = lps_point(v, p);
      for (int c = 0; c < 3; ++c)
        if (!(std::fabs(a[c] - b[c]) <= 1e-6 * extent)) fail(std::string("world position changed through ") + name);
    }
    if (std::string(name).find(".nrrd") != std::string::npos &&
        back.frame.space != (v.frame.space.empty() ? "left-posterior-superior" : v.frame.space))
      fail(std::string("space changed through ") + name);
  }
}

// Runs `body`: true when it completes, false for an InputError or
// NotConvergedError (documented answers); anything else is a bug.
template <class F>
bool answered(F&& body) {
  try {
    body();
    return true;
  } catch (const InputError& e) { if (std::getenv("SOFTSHELL_FUZZ_DEBUG")) std::fprintf(stderr, "answer: %s\n", e.what());
  } catch (const NotConvergedError&) {
  } catch (const std::exception& e) {
    fail(std::string("not a documented answer: ") + typeid(e).name() + ": " + e.what());
  }
  return false;
}

bool run_reader(const std::string& path) {
  return answered([&] {
    // A 3D+t sequence (4-D NRRD): its last frame, and the header of every
    // read must agree with the volume.
    const VolumeHeader h = read_any_header(path);
    if (h.frames == 0) fail("a header with no frames");
    const std::optional<std::size_t> frame = h.frames > 1 ? std::optional<std::size_t>(h.frames - 1) : std::nullopt;
    const Volume v = read_volume(path, std::nullopt, frame);
    if (v.dims != h.dims) fail("header dims differ from the volume's");
    check_volume(path, v);
  });
}

// ---- classify ---------------------------------------------------------------

// A byte as a parameter: mostly a value in [lo, hi], sometimes one of the
// values a careless user or a bad script gives.
double param(std::uint8_t b, double lo, double hi) {
  static const double special[] = {0.0, -1.0, 1e-9, 1e9, std::nan(""), HUGE_VAL, -HUGE_VAL, 1e6, 1e-6,
                                   1e30, -1e-30, 0.5, 1.0, 2.0, 1e-3, 1e3};
  if (b < 240) return lo + (hi - lo) * b / 239.0;
  return special[b - 240];
}

Runtime& runtime() {
  static std::unique_ptr<Runtime> rt = std::make_unique<Runtime>();
  return *rt;
}

void check_opacity(const Volume& u, const Volume& v) {
  if (u.dims != v.dims || u.data.size() != v.voxels()) fail("opacity of other dims than the volume");
  for (float x : u.data)
    if (!(x >= 0.0f && x <= 1.0f)) fail("opacity outside [0, 1] or not finite: " + std::to_string(x));
}

}  // namespace

bool run_nrrd(const std::uint8_t* data, std::size_t size) {
  current_input(data, size);
  return run_reader(place(data, size, "v.nrrd", "v.nhdr"));
}

bool run_metaimage(const std::uint8_t* data, std::size_t size) {
  current_input(data, size);
  return run_reader(place(data, size, "v.mha", "v.mhd"));
}

bool run_nifti(const std::uint8_t* data, std::size_t size) {
  current_input(data, size);
  return run_reader(place(data, size, "v.nii", "v.hdr", "v.img"));
}

bool run_vti(const std::uint8_t* data, std::size_t size) {
  current_input(data, size);
  return run_reader(place(data, size, "v.vti", "v.vti"));
}

bool run_dicom(const std::uint8_t* data, std::size_t size) {
  current_input(data, size);
  return run_reader(place(data, size, "v.dcm", "v.dcm"));
}

bool run_kretz(const std::uint8_t* data, std::size_t size) {
  current_input(data, size);
  return run_reader(place(data, size, "v.vol", "v.vol"));
}

bool run_raw(const std::uint8_t* data, std::size_t size) {
  current_input(data, size);
  // The option parsers on the first line.
  const std::string text(reinterpret_cast<const char*>(data), std::min<std::size_t>(size, 64));
  const std::string line = text.substr(0, text.find('\n'));
  const bool dims_ok = answered([&] { parse_dims(line, "--raw"); });
  const bool vec_ok = answered([&] { parse_vec3(line, "--spacing"); });
  if (size < 8) return dims_ok || vec_ok;
  static const ScalarType types[] = {ScalarType::Int8,   ScalarType::UInt8,  ScalarType::Int16,  ScalarType::UInt16,
                                     ScalarType::Int32,  ScalarType::UInt32, ScalarType::Int64,  ScalarType::UInt64,
                                     ScalarType::Float32, ScalarType::Float64};
  RawSpec spec;
  spec.type = types[data[0] % 10];
  spec.big_endian = data[1] & 1;
  spec.dims = {std::size_t(1 + data[2] % 16), std::size_t(1 + data[3] % 16), std::size_t(1 + data[4] % 16)};
  // 2^-24 .. 2^23 mm: the middle is plausible, the ends are refused.
  for (int a = 0; a < 3; ++a) spec.spacing[a] = std::ldexp(1.0, int(data[5 + a] % 48) - 24);
  const std::string path = reset_scratch() + "/v.raw";
  put(path, reinterpret_cast<const char*>(data) + 8, size - 8);
  return answered([&] {
    const Volume v = read_volume(path, spec);
    if (v.dims != spec.dims || v.data.size() != v.voxels()) fail("raw volume of the wrong size");
    const VolumeHeader h = read_volume_header(path, spec);
    if (h.dims != v.dims || h.files != std::vector<std::string>{path}) fail("raw header disagrees");
    // Decoding is exact: re-encode and compare with the file.
    std::vector<unsigned char> bytes = io_detail::encode_samples(v.data, spec.type);
    const std::size_t e = scalar_type_size(spec.type);
    if (spec.big_endian != io_detail::host_is_big_endian())
      for (std::size_t i = 0; i + e <= bytes.size(); i += e) std::reverse(&bytes[i], &bytes[i] + e);
    const bool integer64 = spec.type == ScalarType::Int64 || spec.type == ScalarType::UInt64;
    const bool f64 = spec.type == ScalarType::Float64;
    // float holds 8-, 16- and 32-bit integers and float32 exactly; 64-bit
    // types and doubles are rounded to float on reading.
    if (!integer64 && !f64 && spec.type != ScalarType::Int32 && spec.type != ScalarType::UInt32 &&
        std::memcmp(bytes.data(), data + 8, bytes.size()) != 0) {
      // Float32 NaNs keep their payload, so even those compare equal.
      fail("raw samples did not survive decoding and encoding");
    }
  });
}

bool run_classify(const std::uint8_t* data, std::size_t size) {
  current_input(data, size);
  std::uint8_t b[kClassifyHeader] = {};
  std::memcpy(b, data, std::min<std::size_t>(size, kClassifyHeader));
  const std::uint8_t* samples = data + std::min<std::size_t>(size, kClassifyHeader);
  const std::size_t nsamples = size > kClassifyHeader ? size - kClassifyHeader : 0;

  const Dims3 dims{std::size_t(3 + b[0] % 6), std::size_t(3 + b[1] % 6), std::size_t(3 + b[2] % 6)};
  const int type = b[3] % 3;  // uint8, uint16, float
  const double h = std::ldexp(1.0, b[4] % 9 - 4);  // 1/16 .. 16 mm
  const Vec3d spacing{h, h, h * std::ldexp(1.0, b[5] % 5 - 2)};
  Volume v(dims, spacing, type == 0 ? ScalarType::UInt8 : type == 1 ? ScalarType::UInt16 : ScalarType::Float32);
  const std::size_t bytes_per = type == 0 ? 1 : type == 1 ? 2 : 4;
  for (std::size_t i = 0; i < v.voxels(); ++i) {
    if (nsamples < bytes_per) break;
    const std::uint8_t* p = samples + (i * bytes_per) % (nsamples - nsamples % bytes_per);
    if (type == 0) v.data[i] = p[0];
    if (type == 1) v.data[i] = float(p[0] | (p[1] << 8));
    if (type == 2) std::memcpy(&v.data[i], p, 4);
  }
  const bool levoy = b[6] & 1;
  const int mask_rule = b[7] % 3;  // auto, none, zeros
  const bool auto_iso_value = b[8] < 128;

  // The shell functional's terms (bytes 32-47), or the paper's functional.
  VariationalParams p = (b[45] & 1) ? VariationalParams::literal_defaults() : VariationalParams{};
  if (!(b[45] & 1)) {
    p.thickness_mm = param(b[34], 0, 6);
    p.profile_power = param(b[35], 1, 4);
    p.weight_cap = param(b[36], 1, 1000);
    p.edge_share = param(b[37], 0, 0.5);
    p.edge_power = param(b[38], 0, 8);
    p.sharpen_iterations = b[39] % 4;
    p.sharpen_lambda = param(b[40], 0, 4);
    p.sharpen_barrier = param(b[41], 0.05, 1);
    p.max_gain = param(b[42], 0, 4);
  }
  p.alpha = param(b[11], 0, 2);
  p.beta = param(b[12], 0, 10);
  p.gamma = param(b[13], 0, 10);
  p.omega = param(b[14], 0, 1);
  p.delta = param(b[15], 0, 1);
  p.epsilon = param(b[16], 0, 0.1);
  p.sigma_mm = param(b[17], 0, 4);
  p.grad_sigma_mm = param(b[18], 0, 4);
  p.kappa = param(b[19], 0, 4);
  p.u_ind = param(b[20], 0, 2);
  // Small volumes' length scales (classify --small-volume MM, byte 47 the
  // reference extent up to 255 mm): on for odd byte 46.
  if ((b[46] & 1) && !(b[45] & 1)) scale_length_scales(p, small_volume_scale(dims, spacing, double(b[47])));
  SolverParams sp;
  sp.max_cycles = 1 + b[21] % 20;
  sp.max_levels = 1 + b[22] % 8;
  sp.jacobi = b[23] & 1;
  sp.krylov = !(b[23] & 2);
  sp.full_multigrid = !(b[23] & 4);
  sp.tol = std::pow(10.0, -1.0 - b[24] % 6);
  LevoyParams lp;
  lp.thickness = param(b[25], 0.5, 5);
  lp.sigma_mm = param(b[26], 0, 2);
  const bool replace = b[27] & 1;
  // The automatic isovalue's rule and the local rule's field, the near field.
  static const AutoIsoRule rules[] = {AutoIsoRule::Local, AutoIsoRule::EchoRidge, AutoIsoRule::Edge};
  const AutoIsoRule rule = rules[b[32] % 3];
  const bool want_field = rule == AutoIsoRule::Local && !(b[32] & 4);
  const double local_fraction = param(b[43], 0, 1);
  const double field_sigma = param(b[44], 0.5, 8);
  const double field_depth_sigma = param(b[28], 0.5, 16);
  const int beam_axis = b[29] % 3;
  const bool near_field = b[33] & 1;

  bool solved = false;
  const bool ok = answered([&] {
    if (levoy) {
      if (!(lp.thickness > 0) || lp.thickness > 100) throw InputError("--thickness must be in (0, 100] voxels");
      check_lowpass_sigma(lp.sigma_mm, spacing, "--sigma");
    } else {
      check_variational_params(p);
      check_solver_params(sp);
      check_lowpass_sigma(p.sigma_mm, spacing, "--sigma");
      check_lowpass_sigma(p.grad_sigma_mm, spacing, "--grad-sigma");
    }
    if (replace) replace_non_finite(v, 0.0f);
    require_finite(v, "fuzz", "");
    std::vector<std::uint8_t> mask;
    if (mask_rule == 0) {
      MaskReport r;
      mask = scanned_mask(v, MaskParams{}, &r);
      if (r.unscanned == 0) mask.clear();
    } else if (mask_rule == 2) {
      mask.resize(v.voxels());
      for (std::size_t i = 0; i < mask.size(); ++i) mask[i] = v.data[i] != 0.0f;
    }
    // What `classify` checks of the local rule's options (CLI11 ranges).
    if (!(local_fraction >= 0 && local_fraction <= 1)) throw InputError("--iso-fraction must be in [0, 1]");
    if (!(field_sigma >= 0.5 && field_sigma <= 1000)) throw InputError("--iso-field-sigma must be in [0.5, 1000]");
    if (!(field_depth_sigma >= 0.5 && field_depth_sigma <= 1000))
      throw InputError("--iso-field-depth-sigma must be in [0.5, 1000]");
    // The mask before the near field's removal: the band sheet's skin line (below).
    std::vector<std::uint8_t> before_near;
    NearFieldReport nf;
    if (near_field) {
      before_near = mask;
      nf = remove_near_field(v, mask);
      if (nf.found && !mask.empty() && mask.size() != v.voxels()) fail("near-field mask of the wrong size");
    }
    const std::vector<std::uint8_t>* m = mask.empty() ? nullptr : &mask;
    double iso;
    HostVector<float> field;
    if (auto_iso_value) {
      AutoIsoParams ap;
      ap.rule = rule;
      ap.want_field = want_field;
      ap.local_fraction = local_fraction;
      ap.field_sigma_mm = field_sigma;
      ap.field_depth_sigma_mm = field_depth_sigma;
      ap.beam_axis = beam_axis;
      AutoIsoReport rep;
      iso = auto_iso(v, m, ap, &rep);
      if (!std::isfinite(iso)) fail("automatic isovalue not finite");
      field = std::move(rep.field);
      if (!field.empty() && field.size() != v.voxels()) fail("isovalue field of the wrong size");
      for (float f : field)
        if (!std::isfinite(f)) fail("isovalue field not finite");
      if (rule == AutoIsoRule::Local && want_field) {
        // Levelled as classify levels (the isovalue above the bulk runs only then).
        AutoIsoReport lr;
        const LevelledVolume lv = auto_iso_levelled(v, m, nullptr, ap, &lr);
        if (!std::isfinite(lv.iso)) fail("levelled automatic isovalue not finite");
        if (lr.bulk_raised && !(lv.iso > lr.local_iso && lv.iso < lr.ridge_iso && lv.iso > lr.bulk_mode))
          fail("isovalue raised above the bulk outside (mode, crest)");
        if (!lr.bulk_raised && lv.iso != lr.local_iso) fail("levelled isovalue is not the edges' median");
      }
    } else {
      const IntensityMap map = v.intensity_map();
      iso = map.from_unit(param(b[9], -0.2, 1.2));
      if (b[10] >= 240) iso = param(b[10], 0, 1);  // the specials: NaN, huge, ...
      if (!std::isfinite(iso)) throw InputError("--iso must be a finite number");
    }
    if (m) fill_unscanned_in_place(v, mask);
    if (!field.empty()) {
      v = level_isovalue(v, field, iso);
      for (float x : v.data)
        if (!std::isfinite(x)) fail("levelled volume not finite");
    }
    if (levoy) {
      lp.iso = iso;
      if (!(std::fabs(iso) <= 3.0e38)) throw InputError("--iso does not fit a float");
      Volume u = classify_levoy(runtime(), v, lp);
      if (m)
        for (std::size_t i = 0; i < u.data.size(); ++i)
          if (!mask[i]) u.data[i] = 0.0f;
      check_opacity(u, v);
      solved = true;
    } else {
      const IntensityMap map = v.intensity_map();
      p.v_iso = map.to_unit(iso);
      check_normalised_iso(p.v_iso, std::to_string(iso), map.describe());
      if (near_field && !p.literal()) {
        // classify's default gradient lowpass, from the speckle (host/speckle.hpp);
        // the fuzzed --grad-sigma stays the one solved with.
        const GradSigmaChoice gc = auto_grad_sigma(v, m, 2);
        const SpeckleReport& sr = gc.speckle;
        if (sr.measured && !(sr.sigma_mm > 0 && std::isfinite(sr.sigma_mm))) fail("speckle size not positive and finite");
        if (!(gc.sigma_mm >= kGradSigmaMinMm && gc.sigma_mm <= kGradSigmaMaxMm)) fail("grad sigma outside its bounds");
        // classify's default: the walls of acoustic shadows weighted down
        // (with the near field's removal, the other default occluder step).
        ShadowWallParams wp = shadow_wall_params(p, 2);
        wp.underside = underside_applies(gc.falling, gc.rising);
        auto w = std::make_shared<const std::vector<float>>(shadow_wall_weight(runtime(), v, m, iso, wp));
        for (float x : *w)
          if (!(x >= 0.0f && x <= 1.0f)) fail("shadow wall weight outside [0, 1]");
        set_edge_weights(p, nullptr, std::move(w));
        // classify's default: shells on bright echoes' crests (host/crest.hpp),
        // or a fuzzed ridge (byte 30).
        p.crest.ridge = b[30] < 128 ? kEchoCrestRidge : param(b[30], 0, 1);
        p.crest.axis = 2;
      }
      SolveReport rep;
      const Volume u = classify_variational(runtime(), v, p, sp, &rep, nullptr, m);
      if (rep.converged) check_opacity(u, v);  // not converged: the CLI writes nothing (exit 3)
      solved = rep.converged;
      if (rep.converged && near_field && !p.literal()) {
        // classify's band sheet (host/mask.hpp): the windows under the band
        // and the skin window, and what is held there; only scanned voxels
        // are held, and nothing changes when nothing is.
        const std::vector<std::uint8_t> window = band_underside(v, nf, before_near, mask);
        if (!window.empty() && window.size() != v.voxels()) fail("band sheet window of the wrong size");
        for (std::uint8_t w : window)
          if (w > 3) fail("band sheet window label out of range");
        std::vector<std::uint8_t> held = mask;
        const BandSheetReport bs = hold_band_sheet(u, window, nf.axis, held);
        if (bs.held) {
          if (held.size() != v.voxels()) fail("band sheet mask of the wrong size");
          std::size_t newly = 0;
          for (std::size_t i = 0; i < held.size(); ++i) {
            if (held[i] && !mask.empty() && !mask[i]) fail("band sheet scans a voxel the mask did not");
            newly += !held[i] && (mask.empty() || mask[i]);
          }
          if (newly != bs.voxels) fail("band sheet's held count differs from its mask");
        } else if (held != mask) {
          fail("band sheet held nothing but changed the mask");
        }
      }
    }
  });
  return ok && solved;
}

// ---- seeds ---------------------------------------------------------------------

namespace {

Volume seed_volume(ScalarType t, const Dims3& d, double lo, double hi) {
  Volume v(d, {0.5, 0.75, 1.25}, t);
  v.origin = {-3.5, 2.0, 10.25};
  for (std::size_t z = 0; z < d[2]; ++z)
    for (std::size_t y = 0; y < d[1]; ++y)
      for (std::size_t x = 0; x < d[0]; ++x) {
        const double r = std::hypot(double(x) - d[0] / 2.0, double(y) - d[1] / 2.0, double(z) - d[2] / 2.0);
        v.at(x, y, z) = float(std::round(lo + (hi - lo) * std::exp(-0.2 * r * r)));
      }
  return v;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

std::string written(const Volume& v, const std::string& name, bool compress) {
  const std::string path = reset_scratch() + "/" + name;
  WriteOptions w;
  w.compress = compress;
  write_volume(path, v, w);
  std::string bytes = slurp(path);
  if (name.size() > 4 && name.substr(name.size() - 4) == ".mhd") {
    const std::string data = slurp(fs::path(path).replace_extension(compress ? ".zraw" : ".raw").string());
    // The harness names the data file v.raw.
    const std::string key = "ElementDataFile = ";
    bytes = bytes.substr(0, bytes.find(key)) + key + "v.raw\n" + std::string(kDataSeparator, 4) + data;
  }
  return bytes;
}

std::string bzip2(const std::string& in) {
  std::vector<char> out(in.size() + in.size() / 100 + 700);
  unsigned int n = static_cast<unsigned int>(out.size());
  if (BZ2_bzBuffToBuffCompress(out.data(), &n, const_cast<char*>(in.data()), static_cast<unsigned int>(in.size()), 9,
                               0, 0) != BZ_OK)
    fail("bzip2 failed");
  return std::string(out.data(), n);
}

}  // namespace

std::string nifti_header(const NiftiSpec& n) {
  const bool two = n.version == 2;
  std::string h(two ? 540 : 348, '\0');
  auto put_bytes = [&](std::size_t off, const void* p, std::size_t len) {
    std::string b(static_cast<const char*>(p), len);
    if (n.big_endian) std::reverse(b.begin(), b.end());
    h.replace(off, len, b);
  };
  auto i16 = [&](std::size_t off, double v) { const std::int16_t x = std::int16_t(v); put_bytes(off, &x, 2); };
  auto i32 = [&](std::size_t off, double v) { const std::int32_t x = std::int32_t(v); put_bytes(off, &x, 4); };
  auto i64 = [&](std::size_t off, double v) { const std::int64_t x = std::int64_t(v); put_bytes(off, &x, 8); };
  auto f32 = [&](std::size_t off, double v) { const float x = float(v); put_bytes(off, &x, 4); };
  auto f64 = [&](std::size_t off, double v) { put_bytes(off, &v, 8); };
  if (!two) {
    i32(0, 348);
    for (int i = 0; i < 8; ++i) i16(40 + 2 * i, double(n.dim[i]));
    i16(70, n.datatype);
    i16(72, n.bitpix);
    for (int i = 0; i < 8; ++i) f32(76 + 4 * i, n.pixdim[i]);
    f32(108, n.pair ? 0 : 352);
    f32(112, n.scl_slope);
    f32(116, n.scl_inter);
    h[123] = char(n.xyzt_units);
    i16(252, n.qform_code);
    i16(254, n.sform_code);
    for (int i = 0; i < 3; ++i) f32(256 + 4 * i, n.quatern[i]), f32(268 + 4 * i, n.qoffset[i]);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) f32(280 + 16 * r + 4 * c, n.srow[r][c]);
    h.replace(344, 4, n.pair ? std::string("ni1\0", 4) : std::string("n+1\0", 4));
  } else {
    i32(0, 540);
    h.replace(4, 8, n.pair ? std::string("ni2\0\r\n\032\n", 8) : std::string("n+2\0\r\n\032\n", 8));
    i16(12, n.datatype);
    i16(14, n.bitpix);
    for (int i = 0; i < 8; ++i) i64(16 + 8 * i, double(n.dim[i]));
    for (int i = 0; i < 8; ++i) f64(104 + 8 * i, n.pixdim[i]);
    i64(168, n.pair ? 0 : 544);
    f64(176, n.scl_slope);
    f64(184, n.scl_inter);
    i32(344, n.qform_code);
    i32(348, n.sform_code);
    for (int i = 0; i < 3; ++i) f64(352 + 8 * i, n.quatern[i]), f64(376 + 8 * i, n.qoffset[i]);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) f64(400 + 32 * r + 8 * c, n.srow[r][c]);
    i32(500, n.xyzt_units);
  }
  if (!n.pair) h += std::string(4, '\0');  // no extensions
  return h;
}


// ---- DICOM files, element by element ---------------------------------------------

namespace {

std::string dicom_element_bytes(const DicomElement& e) {
  static const std::set<std::string> long_vr{"OB", "OW", "OF", "OD", "SQ", "UT", "UN", "UC", "UR"};
  std::string value = e.value;
  if (value.size() % 2 == 1) value += (e.vr == "UI" || e.vr == "OB" || e.vr == "UN") ? '\0' : ' ';
  std::string t;
  for (unsigned v : {unsigned(e.group & 0xFF), unsigned(e.group >> 8), unsigned(e.element & 0xFF), unsigned(e.element >> 8)})
    t += char(v);
  t += e.vr.substr(0, 2);
  const std::size_t n = value.size();
  if (long_vr.count(e.vr)) {
    t += std::string(2, '\0');
    for (int i = 0; i < 4; ++i) t += char((n >> (8 * i)) & 0xFF);
  } else {
    t += char(n & 0xFF);
    t += char((n >> 8) & 0xFF);
  }
  return t + value;
}

std::string sorted_elements(std::vector<DicomElement> elements) {
  std::stable_sort(elements.begin(), elements.end(), [](const DicomElement& a, const DicomElement& b) {
    return std::make_pair(a.group, a.element) < std::make_pair(b.group, b.element);
  });
  std::string t;
  for (const DicomElement& e : elements) t += dicom_element_bytes(e);
  return t;
}

}  // namespace

std::string dicom_u16(std::uint16_t v) { return std::string{char(v & 0xFF), char(v >> 8)}; }

std::string dicom_f64(const std::vector<double>& v) {
  std::string t(8 * v.size(), '\0');
  if (!v.empty()) std::memcpy(t.data(), v.data(), t.size());
  return t;
}

std::string dicom_f32(const std::vector<float>& v) {
  std::string t(4 * v.size(), '\0');
  if (!v.empty()) std::memcpy(t.data(), v.data(), t.size());
  return t;
}

std::string dicom_ds(const std::vector<double>& v) {
  std::string t;
  for (std::size_t i = 0; i < v.size(); ++i) {
    char b[32];
    std::snprintf(b, sizeof b, "%.10g", v[i]);
    t += (i ? "\\" : "") + std::string(b);
  }
  return t;
}

std::string dicom_items(const std::vector<std::vector<DicomElement>>& items) {
  std::string t;
  for (const auto& item : items) {
    const std::string body = sorted_elements(item);
    t += std::string("\xfe\xff\x00\xe0", 4);  // (FFFE,E000) item, explicit length
    for (int i = 0; i < 4; ++i) t += char((body.size() >> (8 * i)) & 0xFF);
    t += body;
  }
  return t;
}

std::string dicom_file(const std::string& sop_class, std::vector<DicomElement> elements) {
  const std::string instance = "1.2.826.0.1.3680043.2.1125.1";
  std::vector<DicomElement> meta{{0x0002, 0x0001, "OB", std::string("\x00\x01", 2)},
                                 {0x0002, 0x0002, "UI", sop_class},
                                 {0x0002, 0x0003, "UI", instance},
                                 {0x0002, 0x0010, "UI", "1.2.840.10008.1.2.1"}};
  const std::string body = sorted_elements(meta);
  std::string length;
  for (int i = 0; i < 4; ++i) length += char((body.size() >> (8 * i)) & 0xFF);
  elements.push_back({0x0008, 0x0016, "UI", sop_class});
  elements.push_back({0x0008, 0x0018, "UI", instance});
  return std::string(128, '\0') + "DICM" + dicom_element_bytes({0x0002, 0x0000, "UL", length}) + body +
         sorted_elements(std::move(elements));
}

std::vector<Seed> seeds(const std::string& harness) {
  std::vector<Seed> s;
  const Dims3 d{5, 4, 3};
  if (harness == "nrrd") {
    s.push_back({"uint8.nrrd", written(seed_volume(ScalarType::UInt8, d, 10, 250), "v.nrrd", false)});
    s.push_back({"int16.nrrd", written(seed_volume(ScalarType::Int16, d, -900, 3000), "v.nrrd", false)});
    s.push_back({"float-gzip.nrrd", written(seed_volume(ScalarType::Float32, d, -1, 1), "v.nrrd", true)});
    s.push_back({"double.nrrd", written(seed_volume(ScalarType::Float64, d, 0, 1e6), "v.nrrd", false)});
    const std::string head = "NRRD0004\ntype: unsigned short\ndimension: 3\nsizes: 3 2 2\nspacings: 0.5 0.5 2\n";
    std::string raw;
    for (int i = 0; i < 12; ++i) raw += char(i * 17), raw += char(i);
    s.push_back({"big-endian.nrrd", head + "endian: big\nencoding: raw\n\n" + raw});
    s.push_back({"ascii.nrrd", "NRRD0004\ntype: float\ndimension: 3\nsizes: 2 2 2\nencoding: ascii\n"
                               "space: right-anterior-superior\nspace directions: (0.5,0,0) (0,0.5,0) (0,0,1)\n"
                               "space origin: (1,2,3)\n\n"
                               "0 1.5 -2 3e2\n4 5 6 7\n"});
    s.push_back({"oblique-lps.nrrd", "NRRD0005\ntype: short\ndimension: 3\nspace: left-posterior-superior\nsizes: 2 2 2\n"
                                     "space directions: (0.3,0.4,0) (-0.8,0.6,0) (0,0,2)\nspace origin: (-5,7.5,100)\n"
                                     "measurement frame: (1,0,0) (0,0,-1) (0,1,0)\nendian: little\nencoding: raw\n\n" +
                                         std::string("\x01\x00\x02\x00\x03\x00\x04\x00\x05\x00\x06\x00\x07\x00\x08\x00", 16)});
    s.push_back({"hex.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: hex\n\n0102030405060708\n"});
    s.push_back({"sequence.nrrd", "NRRD0005\ntype: uchar\ndimension: 4\nspace: left-posterior-superior\nsizes: 2 2 2 3\n"
                                  "space directions: (0.5,0,0) (0,0.5,0) (0,0,1) none\nkinds: domain domain domain list\n"
                                  "encoding: raw\nspace origin: (0,0,0)\n\n" + std::string(24, '\x05')});
    s.push_back({"bzip2.nrrd", head + "endian: little\nencoding: bzip2\n\n" + bzip2(raw)});
    s.push_back({"skips.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 1\nencoding: raw\nline skip: 1\n"
                               "byte skip: 2\n\nskip me\nxxABCD"});
    s.push_back({"detached.nhdr", "NRRD0004\ntype: int\ndimension: 3\nsizes: 2 1 2\nencoding: raw\nendian: little\n"
                                  "data file: v.raw\n" + std::string(kDataSeparator, 4) + std::string(16, '\x03')});
    const std::string gz = written(seed_volume(ScalarType::UInt8, {2, 2, 2}, 0, 9), "v.nrrd", true);
    s.push_back({"detached-gzip.nhdr", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: gzip\n"
                                       "data file: v.raw\n" + std::string(kDataSeparator, 4) +
                                       gz.substr(gz.find("\n\n") + 2)});
  } else if (harness == "metaimage") {
    s.push_back({"uint8.mha", written(seed_volume(ScalarType::UInt8, d, 10, 250), "v.mha", false)});
    s.push_back({"uint16-zlib.mha", written(seed_volume(ScalarType::UInt16, d, 0, 60000), "v.mha", true)});
    s.push_back({"float.mhd", written(seed_volume(ScalarType::Float32, d, -1, 1), "v.mhd", false)});
    s.push_back({"int32-zlib.mhd", written(seed_volume(ScalarType::Int32, d, -5, 5), "v.mhd", true)});
    s.push_back({"msb-headersize.mhd", "ObjectType = Image\nNDims = 3\nDimSize = 2 2 1\nElementSpacing = 1 2 3\n"
                                       "ElementByteOrderMSB = True\nHeaderSize = -1\nElementType = MET_SHORT\n"
                                       "ElementDataFile = v.raw\n" + std::string(kDataSeparator, 4) + "garbage" +
                                       std::string("\x01\x02\x03\x04\x05\x06\x07\x08", 8)});
    s.push_back({"rotated.mha", "ObjectType = Image\nNDims = 3\nTransformMatrix = 0 1 0 -1 0 0 0 0 1\nOffset = 10 -20 30\n"
                                "AnatomicalOrientation = ALI\nElementSpacing = 0.5 0.25 2\nDimSize = 2 2 2\n"
                                "ElementType = MET_UCHAR\nElementDataFile = LOCAL\nabcdefgh"});
    s.push_back({"elementsize.mha", "NDims = 3\nDimSize = 2 2 2\nElementSize = 0.3 0.3 0.6\nOffset = 1 2 3\n"
                                    "TransformMatrix = 1 0 0 0 1 0 0 0 1\nElementType = MET_CHAR\nElementDataFile = LOCAL\n"
                                    "ABCDEFGH"});
  } else if (harness == "nifti") {
    NiftiSpec n;
    n.dim[1] = 3, n.dim[2] = 2, n.dim[3] = 2;
    n.pixdim[1] = 0.5, n.pixdim[2] = 0.75, n.pixdim[3] = 2;
    s.push_back({"uint8.nii", nifti_header(n) + std::string("\x01\x02\x03\x04\x05\x06\x07\x08\x09\x0a\x0b\x0c", 12)});
    n.qform_code = 1, n.quatern[0] = 0.1, n.quatern[1] = -0.2, n.quatern[2] = 0.3, n.qoffset[0] = 5, n.qoffset[2] = -7;
    n.datatype = 4, n.bitpix = 16, n.big_endian = true;
    std::string be;
    for (int i = 0; i < 12; ++i) be += char(0), be += char(i * 20);
    s.push_back({"int16-qform-big-endian.nii", nifti_header(n) + be});
    NiftiSpec m;
    m.version = 2, m.sform_code = 2, m.datatype = 16, m.bitpix = 32;
    m.srow[0][1] = -0.5, m.srow[1][0] = 0.5, m.srow[2][2] = 1.5, m.srow[0][3] = 10, m.srow[1][3] = -20;
    m.scl_slope = 2, m.scl_inter = -1;
    std::string f;
    for (int i = 0; i < 8; ++i) {
      const float x = float(i) * 0.25f;
      f.append(reinterpret_cast<const char*>(&x), 4);
    }
    s.push_back({"float-sform-nifti2.nii", nifti_header(m) + f});
    NiftiSpec p;
    p.pair = true;
    s.push_back({"pair.hdr", nifti_header(p) + std::string(kDataSeparator, 4) + std::string(8, '\x11')});
  } else if (harness == "dicom") {
    // A 4x3x2 multi-frame volume (secondary capture with a patient-space
    // geometry), 8 and 16 bits, and Philips' Cartesian 3D+t layout.
    const auto image = [](unsigned bits, const std::string& samples) {
      return std::vector<DicomElement>{
          {0x0020, 0x0032, "DS", dicom_ds({-10, 5, 2.5})},
          {0x0020, 0x0037, "DS", dicom_ds({0.6, 0.8, 0, -0.8, 0.6, 0})},
          {0x0018, 0x0088, "DS", dicom_ds({1.5})},
          {0x0028, 0x0002, "US", dicom_u16(1)},
          {0x0028, 0x0004, "CS", "MONOCHROME2"},
          {0x0028, 0x0008, "IS", "2"},
          {0x0028, 0x0010, "US", dicom_u16(3)},
          {0x0028, 0x0011, "US", dicom_u16(4)},
          {0x0028, 0x0030, "DS", dicom_ds({0.5, 0.7})},
          {0x0028, 0x0100, "US", dicom_u16(std::uint16_t(bits))},
          {0x0028, 0x0101, "US", dicom_u16(std::uint16_t(bits))},
          {0x0028, 0x0102, "US", dicom_u16(std::uint16_t(bits - 1))},
          {0x0028, 0x0103, "US", dicom_u16(0)},
          {0x7fe0, 0x0010, bits == 8 ? "OB" : "OW", samples}};
    };
    std::string b8, b16;
    for (int i = 0; i < 24; ++i) {
      b8 += char(i * 10);
      b16 += dicom_u16(std::uint16_t(i * 1000));
    }
    s.push_back({"multiframe8.dcm", dicom_file("1.2.840.10008.5.1.4.1.1.7.2", image(8, b8))});
    s.push_back({"multiframe16.dcm", dicom_file("1.2.840.10008.5.1.4.1.1.7.3", image(16, b16))});
    std::vector<DicomElement> philips{{0x0018, 0x602c, "FD", dicom_f64({0.05})},
                                      {0x0018, 0x602e, "FD", dicom_f64({0.06})},
                                      {0x0028, 0x0002, "US", dicom_u16(1)},
                                      {0x0028, 0x0004, "CS", "MONOCHROME2"},
                                      {0x0028, 0x0008, "IS", "2"},
                                      {0x0028, 0x0010, "US", dicom_u16(3)},
                                      {0x0028, 0x0011, "US", dicom_u16(4)},
                                      {0x0028, 0x0100, "US", dicom_u16(8)},
                                      {0x3001, 0x1001, "UL", std::string("\x02\0\0\0", 4)},
                                      {0x3001, 0x1003, "FD", dicom_f64({0.07})},
                                      {0x7fe0, 0x0010, "OB", b8 + b8}};
    s.push_back({"philips-cartesian.dcm", dicom_file("1.2.840.113543.6.6.1.3.10002", philips)});
    std::vector<DicomElement> gray = image(8, b8);
    gray[4].value = "MONOCHROME1";
    s.push_back({"monochrome1.dcm", dicom_file("1.2.840.10008.5.1.4.1.1.7.2", gray)});
  } else if (harness == "kretz") {
    // Items: little-endian uint16 group, uint16 element, uint32 length.
    const auto item = [](unsigned g, unsigned e, const std::string& d) {
      std::string t;
      for (unsigned v : {g & 0xFFu, g >> 8, e & 0xFFu, e >> 8}) t += char(v);
      for (int i = 0; i < 4; ++i) t += char((d.size() >> (8 * i)) & 0xFF);
      return t + d;
    };
    const auto u16 = [](unsigned v) { return std::string{char(v & 0xFF), char(v >> 8)}; };
    const auto f64 = [](const std::vector<double>& v) {
      std::string t(8 * v.size(), '\0');
      for (std::size_t i = 0; i < v.size(); ++i) std::memcpy(&t[8 * i], &v[i], 8);  // little-endian hosts
      return t;
    };
    const std::string sig = "KRETZFILE 1.0   ";
    const std::string dims = item(0xC000, 1, u16(6)) + item(0xC000, 2, u16(4)) + item(0xC000, 3, u16(3));
    std::string samples;
    for (int i = 0; i < 72; ++i) samples += char(i * 3);
    const std::string fan = item(0xC100, 1, f64({0.0005})) + item(0xC200, 1, f64({10})) + item(0xC200, 2, f64({-4})) +
                            item(0xC300, 1, f64({1.4, 1.57, 1.74})) + item(0xC300, 2, f64({1.3, 1.5, 1.6, 1.8}));
    s.push_back({"fan.vol", sig + dims + fan + item(0xD000, 1, samples)});
    s.push_back({"fan-extra-items.vol", sig + item(0x0001, 2, "name") + dims + fan + item(0xD000, 1, samples) +
                                            item(0xD100, 1, "tail")});
    s.push_back({"cartesian.vol", sig + dims + item(0x0010, 0x0022, f64({0.6})) + item(0xD000, 1, samples)});
    s.push_back({"decreasing-angles.vol", sig + dims + item(0xC100, 1, f64({0.001})) + item(0xC200, 1, f64({5})) +
                                              item(0xC200, 2, f64({0})) + item(0xC300, 1, f64({1.8, 1.57, 1.3})) +
                                              item(0xC300, 2, f64({1.9, 1.6, 1.5, 1.2})) + item(0xD000, 1, samples)});
  } else if (harness == "vti") {
    const std::string head = "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\"";
    auto image = [](const std::string& extra, const std::string& arrays, const std::string& tail) {
      return ">\n<ImageData WholeExtent=\"0 2 0 1 0 1\" Origin=\"1 2 3\" Spacing=\"0.5 0.5 1\"" + extra +
             ">\n<Piece Extent=\"0 2 0 1 0 1\">\n<PointData Scalars=\"s\">\n" + arrays +
             "\n</PointData>\n</Piece>\n</ImageData>\n" + tail + "</VTKFile>\n";
    };
    s.push_back({"ascii.vti", head + image(" Direction=\"0 -1 0 1 0 0 0 0 1\"",
                                           "<DataArray type=\"Float32\" Name=\"s\" format=\"ascii\">0 1 2 3 4 5 6 7 8 9 10 11"
                                           "</DataArray>", "")});
    std::string u16;
    for (int i = 0; i < 12; ++i) u16 += char(i * 21), u16 += char(i);
    const std::string block = std::string("\x18\0\0\0", 4) + u16;
    static const char* a = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    auto b64 = [&](const std::string& in) {
      std::string out;
      for (std::size_t i = 0; i < in.size(); i += 3) {
        unsigned v = static_cast<unsigned char>(in[i]) << 16;
        if (i + 1 < in.size()) v |= static_cast<unsigned char>(in[i + 1]) << 8;
        if (i + 2 < in.size()) v |= static_cast<unsigned char>(in[i + 2]);
        out += a[(v >> 18) & 63], out += a[(v >> 12) & 63];
        out += i + 1 < in.size() ? a[(v >> 6) & 63] : '=';
        out += i + 2 < in.size() ? a[v & 63] : '=';
      }
      return out;
    };
    s.push_back({"binary.vti", head + image("", "<DataArray type=\"UInt16\" Name=\"s\" format=\"binary\">" + b64(block) +
                                                    "</DataArray>", "")});
    s.push_back({"appended-raw.vti", head + " header_type=\"UInt32\"" +
                                         image("", "<DataArray type=\"UInt16\" Name=\"s\" format=\"appended\" offset=\"0\"/>",
                                               "<AppendedData encoding=\"raw\">\n_" + block + "\n</AppendedData>\n")});
    s.push_back({"appended-base64.vti", head + image("", "<DataArray type=\"UInt16\" Name=\"s\" format=\"appended\" offset=\"0\"/>",
                                                     "<AppendedData encoding=\"base64\">\n_" + b64(block) +
                                                         "\n</AppendedData>\n")});
    uLongf n = compressBound(uLong(u16.size()));
    std::string z(n, '\0');
    compress(reinterpret_cast<Bytef*>(z.data()), &n, reinterpret_cast<const Bytef*>(u16.data()), uLong(u16.size()));
    z.resize(n);
    const std::string zhead = std::string("\x01\0\0\0\x18\0\0\0\0\0\0\0", 12) + char(n) + std::string(3, '\0');
    s.push_back({"zlib.vti", head + " compressor=\"vtkZLibDataCompressor\"" +
                                 image("", "<DataArray type=\"UInt16\" Name=\"s\" format=\"appended\" offset=\"0\"/>",
                                       "<AppendedData encoding=\"raw\">_" + zhead + z + "</AppendedData>\n")});
  } else if (harness == "raw") {
    for (int t = 0; t < 10; ++t) {
      std::string b(8, '\0');
      b[0] = char(t);
      b[1] = char(t & 1);
      b[2] = 2, b[3] = 1, b[4] = 0;  // 3 x 2 x 1
      b[5] = b[6] = b[7] = char(128);  // 1 mm
      static const int size[] = {1, 1, 2, 2, 4, 4, 8, 8, 4, 8};
      for (int i = 0; i < 6 * size[t]; ++i) b += char(i * 37 + t);
      s.push_back({"type" + std::to_string(t) + ".raw", b});
    }
    s.push_back({"dims.txt", "9,9,9\n"});
  } else if (harness == "classify") {
    for (int k = 0; k < 4; ++k) {
      std::string b(kClassifyHeader, '\0');
      b[0] = b[1] = b[2] = 5;  // 8^3
      b[3] = char(k % 3);      // uint8, uint16, float
      b[4] = 4;                // 1 mm
      b[5] = 2;
      b[6] = char(k == 3);     // levoy once
      b[7] = char(k % 2);      // mask auto / none
      b[8] = char(k == 1 ? 200 : 0);
      b[9] = 120;
      for (int i = 11; i <= 20; ++i) b[i] = char(100);
      b[21] = 19, b[22] = 7, b[24] = 3;
      b[25] = 60, b[26] = 50;
      // The shell functional near its defaults; the local rule with its
      // field, the near field removed, in turn the paper's functional.
      b[32] = char(k % 3), b[33] = 1;
      b[34] = 80, b[35] = 80, b[36] = 24, b[37] = 14, b[38] = 120, b[39] = 2, b[40] = 120, b[41] = 113, b[42] = 0;
      b[43] = 179, b[44] = 80, b[45] = char(k == 2);
      b[28] = 115, b[29] = 2;  // the field: 3 mm across the beam, 8 mm along z
      const Volume v = seed_volume(ScalarType::Float32, {8, 8, 8}, 5, 200);
      for (float x : v.data) {
        if (k % 3 == 0) b += char(int(x));
        if (k % 3 == 1) b += char(int(x * 100) & 255), b += char(int(x * 100) >> 8);
        if (k % 3 == 2) b.append(reinterpret_cast<const char*>(&x), 4);
      }
      s.push_back({"classify" + std::to_string(k), b});
    }
  }
  return s;
}

}  // namespace softshell::fuzz
