// Physics of the phantom in physical units (`softshell phantom --physics`):
// the named presets, the random draw, validation, overrides and JSON. The
// image formation itself: host/phantom_scan.cpp, kernels/phantom_scan.cl;
// every parameter and distribution: docs/phantom.md.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <iomanip>
#include <sstream>

#include "error.hpp"
#include "phantom.hpp"
#include "text.hpp"

namespace softshell {
namespace {

// One scalar parameter: its phantom.json name and where it lives.
struct Field {
  std::string name;
  double* (*get)(PhantomPhysics&);
};

#define FIELD(member) \
  Field { #member, [](PhantomPhysics& p) { return &p.member; } }
#define FIELD_AT(member, i) \
  Field { #member "[" #i "]", [](PhantomPhysics& p) { return &p.member[i]; } }

// In the order of PhantomPhysics (and phantom.json); "geometry" is handled apart.
const std::vector<Field>& fields() {
  static const std::vector<Field> f = {
      FIELD(fov_mm), FIELD(probe_radius_mm), FIELD(sector_deg), FIELD(sector_y_deg), FIELD(scan_depth_mm),
      FIELD(jitter_mm), FIELD(psf_lateral_mm), FIELD(psf_axial_mm), FIELD(psf_elevation_mm), FIELD(focus_depth_mm),
      FIELD(beam_spread), FIELD(scatterers_per_cell), FIELD(texture), FIELD(contrast_db), FIELD(specular),
      FIELD(skull_db), FIELD(bone_atten_db_mm), FIELD(frequency_mhz), FIELD(attenuation_db_cm_mhz),
      FIELD(tgc_slope_db), FIELD(tgc_bow_db), FIELD(dynamic_range_db), FIELD(tissue_grey), FIELD(noise_db),
      FIELD(near_field_mm), FIELD(skin_mm), FIELD(fat_mm), FIELD(near_field_db), FIELD(fat_db),
      FIELD(near_field_specular), FIELD(near_field_wave), FIELD(near_field_wavelength_mm),
      FIELD_AT(near_field_dir_deg, 0), FIELD_AT(near_field_dir_deg, 1), FIELD_AT(near_field_phase_deg, 0),
      FIELD_AT(near_field_phase_deg, 1), FIELD_AT(near_field_phase_deg, 2), FIELD_AT(near_field_phase_deg, 3),
      FIELD_AT(near_field_phase_deg, 4), FIELD_AT(near_field_phase_deg, 5), FIELD_AT(near_field_phase_deg, 6),
      FIELD_AT(near_field_phase_deg, 7), FIELD(reverb_db), FIELD(yaw_deg), FIELD(pitch_deg), FIELD(roll_deg),
      FIELD_AT(shift_mm, 0), FIELD_AT(shift_mm, 1), FIELD_AT(shift_mm, 2),
  };
  return f;
}
#undef FIELD
#undef FIELD_AT

std::string num(double v) {
  std::ostringstream s;
  s << std::setprecision(10) << v;
  return s.str();
}

// A deterministic stream of uniforms from the seed (splitmix64): the random
// physics draws its parameters from it in a fixed order.
class Draw {
 public:
  explicit Draw(std::uint64_t seed) : state_(seed * 0xD1B54A32D192ED03ull + 0x8CB92BA72F3D8DD7ull) {}
  double uniform01() {
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return static_cast<double>(z >> 11) * (1.0 / 9007199254740992.0);  // [0, 1), 53 bits
  }
  double uniform(double a, double b) { return a + (b - a) * uniform01(); }
  double log_uniform(double a, double b) { return a * std::pow(b / a, uniform01()); }
  bool chance(double p) { return uniform01() < p; }

 private:
  std::uint64_t state_;
};

// The frequency (MHz) at which soft tissue of `alpha` dB/cm/MHz (one-way)
// loses `loss_db` two-way over `depth_mm`: two-way dB/mm = alpha f / 5.
double frequency_for_loss(double loss_db, double alpha, double depth_mm) {
  return std::clamp(loss_db * 5.0 / (alpha * depth_mm), 1.0, 20.0);
}

// Pose limits that keep the object inside the field of view and clear of the
// near field (docs/phantom.md): the spine tilts less (its ends would rise).
double tilt_limit_deg(PhantomShape s) { return s == PhantomShape::Spine ? 10.0 : 20.0; }

PhantomPhysics draw_random(PhantomShape shape, std::uint64_t seed) {
  Draw r(seed);
  PhantomPhysics p;
  // Geometry and scale of the anatomy.
  const double u = r.uniform01();
  p.geometry = u < 0.4 ? BeamGeometry::Linear : (u < 0.7 ? BeamGeometry::Fan : BeamGeometry::Fan3d);
  switch (shape) {
    case PhantomShape::Face:
      p.fov_mm = r.uniform(80, 115);
      break;
    case PhantomShape::Spine:
      p.fov_mm = r.uniform(55, 80);
      break;
    case PhantomShape::Sphere:
      p.fov_mm = r.uniform(80, 110);
      break;
  }
  const bool fan = p.geometry != BeamGeometry::Linear;
  p.probe_radius_mm = p.geometry == BeamGeometry::Fan3d ? r.uniform(25, 50) : r.uniform(20, 60);
  p.sector_deg = r.uniform(25, 38);
  p.sector_y_deg = r.uniform(22, 35);
  p.scan_depth_mm = fan ? p.fov_mm * r.uniform(0.9, 1.1) : p.fov_mm;
  const double jitter = r.uniform(0.1, 0.5);
  p.jitter_mm = p.geometry != BeamGeometry::Fan3d && r.chance(0.5) ? jitter : 0.0;
  // Point-spread function.
  p.psf_lateral_mm = r.log_uniform(0.35, 1.3);
  p.psf_axial_mm = p.psf_lateral_mm * r.uniform(0.25, 0.7);
  p.psf_elevation_mm = p.psf_lateral_mm * r.uniform(1.0, 2.5);
  p.focus_depth_mm = p.scan_depth_mm * r.uniform(0.25, 0.6);
  p.beam_spread = fan ? r.uniform(0.5, 2.0) : r.uniform(0.0, 0.8);
  // Scattering.
  p.scatterers_per_cell = r.log_uniform(0.5, 50);
  p.texture = r.uniform(0.1, 0.5);
  // Bone always reflects: the spine's boundary echoes are never off, and its
  // contrast is that of bone over muscle; soft tissue in fluid may show a
  // plain step in echogenicity (specular 0) one time in five.
  const bool spine = shape == PhantomShape::Spine;
  p.contrast_db = spine ? r.uniform(6, 16) : r.uniform(18, 40);
  const double specular = spine ? r.log_uniform(0.7, 3.0) : r.log_uniform(0.2, 3.0);
  const bool plain = r.chance(0.2);
  p.specular = plain && !spine ? 0.0 : specular;
  p.skull_db = r.uniform(6, 14);
  p.bone_atten_db_mm = r.log_uniform(1.5, 10);
  // Attenuation: the soft tissue's two-way loss over the scan depth is drawn
  // (8-30 dB, what a user's choice of probe and frequency keeps it near);
  // the frequency follows from it and the attenuation coefficient.
  p.attenuation_db_cm_mhz = r.uniform(0.3, 0.8);
  const double loss_db = r.uniform(8, 30);
  p.frequency_mhz = frequency_for_loss(loss_db, p.attenuation_db_cm_mhz, p.scan_depth_mm);
  p.tgc_slope_db = r.uniform(-10, 10);
  p.tgc_bow_db = r.uniform(-5, 5);
  // Display.
  p.dynamic_range_db = r.uniform(30, 60);
  p.tissue_grey = r.uniform(60, 220);
  p.noise_db = r.uniform(-40, -12);
  // Near field.
  const double thickness = r.uniform(3, 11);
  p.near_field_mm = r.chance(0.1) ? 0.0 : thickness;
  p.skin_mm = std::min(r.uniform(0.8, 2.0), 0.3 * thickness);
  p.fat_mm = (thickness - p.skin_mm) * r.uniform(0.25, 0.6);
  if (p.near_field_mm == 0) p.skin_mm = p.fat_mm = 0;
  p.near_field_db = r.uniform(3, 14);
  p.fat_db = r.uniform(-10, -3);
  p.near_field_specular = r.log_uniform(0.3, 3.0);
  p.near_field_wave = r.uniform(0.03, 0.15);
  p.near_field_wavelength_mm = r.uniform(15, 40);
  for (double& d : p.near_field_dir_deg) d = r.uniform(0, 180);
  for (double& d : p.near_field_phase_deg) d = r.uniform(0, 360);
  p.reverb_db = r.uniform(-35, -15);
  // Pose.
  const double tilt = tilt_limit_deg(shape);
  p.yaw_deg = r.uniform(-30, 30);
  p.pitch_deg = r.uniform(-tilt, tilt);
  p.roll_deg = r.uniform(-tilt, tilt);
  p.shift_mm[0] = p.fov_mm * r.uniform(-0.06, 0.06);
  p.shift_mm[1] = p.fov_mm * r.uniform(-0.06, 0.06);
  p.shift_mm[2] = p.fov_mm * r.uniform(0.0, 0.06);
  return p;
}

// The named presets. Lengths that scale with the anatomy are given as
// fractions of the shape's default field of view.
PhantomPhysics preset(const std::string& name, PhantomShape shape) {
  PhantomPhysics p;
  const double fov = phantom_default_fov(shape);
  const bool spine = shape == PhantomShape::Spine;
  const double tilt = tilt_limit_deg(shape) / 20.0;  // presets' tilts are for the face; the spine gets half
  p.fov_mm = fov;
  p.scan_depth_mm = fov;
  double loss = 25;  // soft tissue's two-way loss over the scan depth, dB: sets the frequency (below)
  if (name == "clean") {  // an easy reference: linear, fully developed speckle, nothing in the way
    p.geometry = BeamGeometry::Linear;
    p.psf_lateral_mm = 1.0, p.psf_axial_mm = 0.45, p.psf_elevation_mm = 1.5;
    p.focus_depth_mm = 0.4 * fov, p.beam_spread = 0.3;
    p.scatterers_per_cell = 20, p.texture = 0.3, p.contrast_db = spine ? 12 : 32, p.specular = 1;
    p.skull_db = 10, p.bone_atten_db_mm = 4;
    p.attenuation_db_cm_mhz = 0.5, loss = 25;
    p.dynamic_range_db = 50, p.tissue_grey = 160, p.noise_db = -35;
    p.near_field_mm = 0, p.skin_mm = 0, p.fat_mm = 0;
  } else if (name == "obstetric") {  // a volume probe through the abdominal wall
    p.geometry = BeamGeometry::Fan3d;
    p.probe_radius_mm = 40, p.sector_deg = 35, p.sector_y_deg = 30, p.scan_depth_mm = 1.0 * fov;
    p.psf_lateral_mm = 0.9, p.psf_axial_mm = 0.35, p.psf_elevation_mm = 1.6;
    p.focus_depth_mm = 0.45 * fov, p.beam_spread = 1.5;
    p.scatterers_per_cell = 15, p.texture = 0.3, p.contrast_db = spine ? 10 : 32, p.specular = 1.2;
    p.skull_db = 10, p.bone_atten_db_mm = 5;
    p.attenuation_db_cm_mhz = 0.5, loss = 25;
    p.tgc_slope_db = -4, p.tgc_bow_db = 3;
    p.dynamic_range_db = 50, p.tissue_grey = 150, p.noise_db = -32;
    p.near_field_mm = 8, p.skin_mm = 1.5, p.fat_mm = 3, p.near_field_db = 6, p.fat_db = -6;
    p.near_field_specular = 1.5, p.near_field_wave = 0.08, p.near_field_wavelength_mm = 25, p.reverb_db = -28;
    p.yaw_deg = 12, p.pitch_deg = -8 * tilt, p.roll_deg = 6 * tilt;
    p.shift_mm[0] = 0.03 * fov, p.shift_mm[1] = -0.02 * fov, p.shift_mm[2] = 0.02 * fov;
  } else if (name == "spine") {  // a linear probe swept freehand along the back
    p.geometry = BeamGeometry::Linear;
    p.jitter_mm = 0.3;
    p.psf_lateral_mm = 0.5, p.psf_axial_mm = 0.2, p.psf_elevation_mm = 1.2;
    p.focus_depth_mm = 0.35 * fov, p.beam_spread = 0.6;
    p.scatterers_per_cell = 8, p.texture = 0.4, p.contrast_db = spine ? 10 : 30, p.specular = 2;
    p.skull_db = 10, p.bone_atten_db_mm = 8;
    p.attenuation_db_cm_mhz = 0.6, loss = 30;
    p.tgc_slope_db = 6, p.tgc_bow_db = -3;
    p.dynamic_range_db = 45, p.tissue_grey = 130, p.noise_db = -35;
    p.near_field_mm = 10, p.skin_mm = 1.5, p.fat_mm = 3.5, p.near_field_db = 9, p.fat_db = -5;
    p.near_field_specular = 2, p.near_field_wave = 0.1, p.near_field_wavelength_mm = 30, p.reverb_db = -22;
    p.yaw_deg = -8, p.pitch_deg = 4 * tilt, p.roll_deg = 3 * tilt;
  } else if (name == "curvilinear") {  // a curvilinear probe swept freehand
    p.geometry = BeamGeometry::Fan;
    p.probe_radius_mm = 50, p.sector_deg = 32, p.scan_depth_mm = 1.05 * fov;
    p.jitter_mm = 0.2;
    p.psf_lateral_mm = 1.1, p.psf_axial_mm = 0.4, p.psf_elevation_mm = 2.0;
    p.focus_depth_mm = 0.4 * fov, p.beam_spread = 1.5;
    p.scatterers_per_cell = 12, p.texture = 0.3, p.contrast_db = spine ? 10 : 28, p.specular = 1.2;
    p.skull_db = 10, p.bone_atten_db_mm = 5;
    p.attenuation_db_cm_mhz = 0.6, loss = 25;
    p.tgc_slope_db = 6, p.tgc_bow_db = -4;
    p.dynamic_range_db = 45, p.tissue_grey = 140, p.noise_db = -30;
    p.near_field_mm = 6, p.skin_mm = 1.2, p.fat_mm = 2.5, p.near_field_db = 4, p.fat_db = -6;
    p.near_field_specular = 1, p.near_field_wave = 0.1, p.near_field_wavelength_mm = 20, p.reverb_db = -25;
    p.yaw_deg = -15, p.pitch_deg = 10 * tilt, p.roll_deg = -5 * tilt;
    p.shift_mm[0] = -0.04 * fov, p.shift_mm[1] = 0.03 * fov, p.shift_mm[2] = 0.03 * fov;
  } else if (name == "harsh") {  // low dynamic range, saturated, a thick bright near field, sparse scatterers
    p.geometry = BeamGeometry::Fan;
    p.probe_radius_mm = 30, p.sector_deg = 36, p.scan_depth_mm = 0.95 * fov;
    p.jitter_mm = 0.5;
    p.psf_lateral_mm = 1.4, p.psf_axial_mm = 0.6, p.psf_elevation_mm = 2.4;
    p.focus_depth_mm = 0.3 * fov, p.beam_spread = 2;
    p.scatterers_per_cell = 1, p.texture = 0.5, p.contrast_db = spine ? 6 : 18, p.specular = 0.7;
    p.skull_db = 14, p.bone_atten_db_mm = 10;
    p.attenuation_db_cm_mhz = 0.8, loss = 30;
    p.tgc_slope_db = -10, p.tgc_bow_db = 5;
    p.dynamic_range_db = 30, p.tissue_grey = 200, p.noise_db = -18;
    p.near_field_mm = 11, p.skin_mm = 1.8, p.fat_mm = 3.5, p.near_field_db = 12, p.fat_db = -4;
    p.near_field_specular = 3, p.near_field_wave = 0.15, p.near_field_wavelength_mm = 18, p.reverb_db = -15;
    p.yaw_deg = 25, p.pitch_deg = -18 * tilt, p.roll_deg = 15 * tilt;
    p.shift_mm[0] = 0.05 * fov, p.shift_mm[1] = -0.04 * fov, p.shift_mm[2] = 0.04 * fov;
  }
  p.frequency_mhz = frequency_for_loss(loss, p.attenuation_db_cm_mhz, p.scan_depth_mm);
  return p;
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::size_t start = 0;
  for (std::size_t i = 0; i <= s.size(); ++i)
    if (i == s.size() || s[i] == sep) {
      out.push_back(s.substr(start, i - start));
      start = i + 1;
    }
  return out;
}

std::string join(const std::vector<std::string>& items, const std::string& sep) {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) out += (i ? sep : "") + items[i];
  return out;
}

double parse_number(const std::string& name, const std::string& text) {
  const std::string s = trim(text);
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || *end != '\0' || errno != 0 || !std::isfinite(v))
    throw InputError("--physics-set " + name + "='" + text + "': not a number");
  return v;
}

}  // namespace

const char* beam_geometry_name(BeamGeometry g) {
  switch (g) {
    case BeamGeometry::Linear:
      return "linear";
    case BeamGeometry::Fan:
      return "fan";
    case BeamGeometry::Fan3d:
      return "fan3d";
  }
  return "?";
}

bool parse_beam_geometry(const std::string& name, BeamGeometry& out) {
  for (BeamGeometry g : {BeamGeometry::Linear, BeamGeometry::Fan, BeamGeometry::Fan3d})
    if (name == beam_geometry_name(g)) {
      out = g;
      return true;
    }
  return false;
}

const std::vector<std::string>& phantom_physics_names() {
  static const std::vector<std::string> names = {"default", "clean",       "obstetric", "spine",
                                                 "curvilinear", "harsh", "random"};
  return names;
}

std::optional<PhantomPhysics> phantom_physics(const std::string& name, PhantomShape shape, std::uint64_t seed) {
  if (name == "default") return std::nullopt;
  if (name == "random") return draw_random(shape, seed);
  const auto& names = phantom_physics_names();
  if (std::find(names.begin(), names.end(), name) == names.end())
    throw InputError("--physics '" + name + "' is not one of " + join(names, ", "));
  return preset(name, shape);
}

void validate_phantom_physics(const PhantomPhysics& p) {
  auto check = [](double v, double lo, double hi, const char* name) {
    if (!(v >= lo && v <= hi))
      throw InputError(std::string("physics ") + name + " = " + num(v) + " is out of range [" + num(lo) + ", " +
                       num(hi) + "]");
  };
  check(p.fov_mm, 10, 2000, "fov_mm");
  check(p.probe_radius_mm, 5, 500, "probe_radius_mm");
  check(p.sector_deg, 1, 44, "sector_deg");
  check(p.sector_y_deg, 1, 44, "sector_y_deg");
  check(p.scan_depth_mm, 0.1 * p.fov_mm, 3 * p.fov_mm, "scan_depth_mm (x fov: 0.1-3)");
  check(p.jitter_mm, 0, 5, "jitter_mm");
  check(p.psf_lateral_mm, 0.01, 20, "psf_lateral_mm");
  check(p.psf_axial_mm, 0.01, 20, "psf_axial_mm");
  check(p.psf_elevation_mm, 0.01, 20, "psf_elevation_mm");
  check(p.focus_depth_mm, 0, 3 * p.fov_mm, "focus_depth_mm");
  check(p.beam_spread, 0, 10, "beam_spread");
  check(p.scatterers_per_cell, 0.01, 10000, "scatterers_per_cell");
  check(p.texture, 0, 0.9, "texture");
  check(p.contrast_db, -40, 60, "contrast_db");
  check(p.specular, 0, 100, "specular");
  check(p.skull_db, -40, 40, "skull_db");
  check(p.bone_atten_db_mm, 0, 100, "bone_atten_db_mm");
  check(p.frequency_mhz, 0.1, 100, "frequency_mhz");
  check(p.attenuation_db_cm_mhz, 0, 10, "attenuation_db_cm_mhz");
  check(p.tgc_slope_db, -60, 60, "tgc_slope_db");
  check(p.tgc_bow_db, -60, 60, "tgc_bow_db");
  check(p.dynamic_range_db, 10, 100, "dynamic_range_db");
  check(p.tissue_grey, 0, 255, "tissue_grey");
  check(p.noise_db, -120, 20, "noise_db");
  check(p.near_field_mm, 0, 60, "near_field_mm");
  check(p.skin_mm, 0, p.near_field_mm, "skin_mm (<= near_field_mm)");
  check(p.fat_mm, 0, p.near_field_mm - p.skin_mm, "fat_mm (<= near_field_mm - skin_mm)");
  check(p.near_field_db, -30, 40, "near_field_db");
  check(p.fat_db, -40, 20, "fat_db");
  check(p.near_field_specular, 0, 100, "near_field_specular");
  check(p.near_field_wave, 0, 0.15, "near_field_wave");
  check(p.near_field_wavelength_mm, 1, 10000, "near_field_wavelength_mm");
  for (double d : p.near_field_dir_deg) check(d, -360, 360, "near_field_dir_deg");
  for (double d : p.near_field_phase_deg) check(d, -360, 360, "near_field_phase_deg");
  check(p.reverb_db, -200, 0, "reverb_db");
  check(p.yaw_deg, -180, 180, "yaw_deg");
  check(p.pitch_deg, -180, 180, "pitch_deg");
  check(p.roll_deg, -180, 180, "roll_deg");
  for (double s : p.shift_mm) check(s, -0.5 * p.fov_mm, 0.5 * p.fov_mm, "shift_mm (x fov: -0.5-0.5)");
}

void set_physics_parameter(PhantomPhysics& p, const std::string& name, const std::string& value) {
  if (name == "geometry") {
    if (!parse_beam_geometry(trim(value), p.geometry))
      throw InputError("--physics-set geometry='" + value + "' is not one of linear, fan, fan3d");
    return;
  }
  for (const Field& f : fields())
    if (f.name == name) {
      *f.get(p) = parse_number(name, value);
      return;
    }
  throw InputError("--physics-set: unknown parameter '" + name + "' (the names of phantom.json's \"physics_parameters\")");
}

void apply_physics_settings(PhantomPhysics& p, const std::string& settings) {
  for (const std::string& item : split(settings, ',')) {
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos)
      throw InputError("--physics-set '" + item + "': expected NAME=VALUE (e.g. near_field_mm=0)");
    set_physics_parameter(p, trim(item.substr(0, eq)), item.substr(eq + 1));
  }
}

std::string phantom_physics_json(const PhantomPhysics& p, int indent) {
  const std::string pad(static_cast<std::size_t>(indent), ' ');
  std::ostringstream j;
  j << pad << "\"geometry\": \"" << beam_geometry_name(p.geometry) << "\"";
  PhantomPhysics copy = p;
  for (const Field& f : fields()) {
    const std::string& n = f.name;
    const std::size_t bracket = n.find('[');
    if (bracket == std::string::npos) {
      j << ",\n" << pad << '"' << n << "\": " << num(*f.get(copy));
    } else if (n.compare(bracket, 3, "[0]") == 0) {  // arrays as one entry
      const std::string base = n.substr(0, bracket);
      j << ",\n" << pad << '"' << base << "\": [";
      std::size_t k = 0;
      for (const Field& g : fields())
        if (g.name.compare(0, bracket + 1, base + "[") == 0) j << (k++ ? ", " : "") << num(*g.get(copy));
      j << ']';
    }
  }
  return j.str();
}

}  // namespace softshell
