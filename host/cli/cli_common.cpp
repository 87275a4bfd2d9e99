// Shared pieces of the CLI's commands (see cli_common.hpp).
#include "cli_common.hpp"

#include <glob.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
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

namespace {

// Natural order: digit runs compare by value ("f2" < "f10"), the rest by character.
bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i])) != 0;
    const bool db = std::isdigit(static_cast<unsigned char>(b[j])) != 0;
    if (da && db) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      std::size_t i0 = i, j0 = j;  // leading zeros do not count
      while (i0 + 1 < ie && a[i0] == '0') ++i0;
      while (j0 + 1 < je && b[j0] == '0') ++j0;
      if (ie - i0 != je - j0) return ie - i0 < je - j0;
      const int c = a.compare(i0, ie - i0, b, j0, je - j0);
      if (c != 0) return c < 0;
      if (ie - i != je - j) return ie - i < je - j;  // "01" before "001"... then by padding
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

bool exists(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0;
}

}  // namespace

std::vector<std::string> expand_input_files(const std::vector<std::string>& args) {
  std::vector<std::string> files;
  for (const std::string& arg : args) {
    const bool pattern = arg.find_first_of("*?[") != std::string::npos;
    if (!pattern || exists(arg)) {  // a file whose name holds '*' is that file
      files.push_back(arg);
      continue;
    }
    glob_t g{};
    const int rc = ::glob(arg.c_str(), GLOB_NOSORT, nullptr, &g);
    std::vector<std::string> matched;
    if (rc == 0)
      for (std::size_t i = 0; i < g.gl_pathc; ++i) matched.emplace_back(g.gl_pathv[i]);
    ::globfree(&g);
    if (rc == GLOB_NOSPACE) throw InputError(arg + ": out of memory expanding the pattern");
    if (matched.empty()) throw InputError(arg + ": no file matches this pattern");
    std::sort(matched.begin(), matched.end(), natural_less);
    files.insert(files.end(), matched.begin(), matched.end());
  }
  return files;
}

void check_frame_pattern(const std::string& pattern, const std::string& option) {
  const std::size_t first = pattern.find('#');
  const std::size_t end = first == std::string::npos ? first : pattern.find_first_not_of('#', first);
  if (first == std::string::npos || (end != std::string::npos && pattern.find('#', end) != std::string::npos))
    throw InputError(option + " " + pattern + ": expected one run of '#' for the frame number (e.g. u-###.nrrd)");
  if (!is_volume_output(pattern))
    throw InputError(option + " " + pattern + ": unknown extension (expected " + volume_output_extensions() + ")");
}

std::string frame_path(const std::string& pattern, std::size_t k, std::size_t n) {
  const std::size_t first = pattern.find('#');
  if (first == std::string::npos) return pattern;
  std::size_t end = pattern.find_first_not_of('#', first);
  if (end == std::string::npos) end = pattern.size();
  std::size_t width = end - first;
  const std::size_t digits = std::to_string(n > 0 ? n - 1 : 0).size();
  width = std::max(width, digits);
  std::string number = std::to_string(k);
  if (number.size() < width) number.insert(0, width - number.size(), '0');
  return pattern.substr(0, first) + number + pattern.substr(end);
}

}  // namespace softshell::cli
