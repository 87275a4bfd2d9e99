// Shared pieces of the CLI's commands (see cli_common.hpp).
#include "cli_common.hpp"

#include <cmath>

#include "error.hpp"

namespace softshell::cli {

void RawOptions::add_to(CLI::App* app) {
  app->add_option("--raw", dims, "Read IN as headerless raw data of these dimensions")->type_name("X,Y,Z");
  app->add_option("--type", type, "Sample type of raw data: uint8|uint16|int16|float|double")->type_name("T");
  app->add_option("--spacing", spacing, "Voxel spacing of raw data in mm (default 1,1,1)")->type_name("X,Y,Z");
  app->add_flag("--big-endian", big_endian, "Raw data is big-endian (default little)");
  app->add_option("--frame", frame, "One frame (0-based) of a 3D+t sequence (a 4-D NRRD of frames; `info` counts them)")
      ->type_name("K");
}

std::optional<RawSpec> RawOptions::spec() const {
  if (dims.empty()) {
    if (!type.empty() || !spacing.empty() || big_endian)
      throw InputError("--type, --spacing and --big-endian describe raw input and need --raw X,Y,Z");
    return std::nullopt;
  }
  RawSpec r;
  r.dims = parse_dims(dims, "--raw");
  if (type.empty()) throw InputError("--raw needs --type uint8|uint16|int16|float|double");
  const auto t = parse_scalar_type(type);
  if (!t) throw InputError("--type: unknown sample type '" + type + "' (use uint8, uint16, int16, float or double)");
  r.type = *t;
  if (!spacing.empty()) r.spacing = parse_vec3(spacing, "--spacing");
  r.big_endian = big_endian;
  return r;
}

void NonFiniteOption::add_to(CLI::App* app) {
  app->add_option("--replace-non-finite", value,
                  "Replace NaN and infinite samples by this value (file units); without it they are refused")
      ->type_name("V");
}

void NonFiniteOption::apply(Volume& v, const std::string& path) const {
  if (!value) return require_finite(v, path, "give --replace-non-finite V to replace them");
  if (!std::isfinite(*value)) throw InputError("--replace-non-finite: expected a finite number");
  replace_non_finite(v, static_cast<float>(*value));
}

void add_device_option(CLI::App* app, std::string& device) {
  app->add_option("--device", device,
                  "OpenCL device: index or name substring from `softshell devices`, or cpu/gpu "
                  "(default: $SOFTSHELL_DEVICE, else the first GPU, else the first CPU)")
      ->type_name("I|NAME");
}

}  // namespace softshell::cli
