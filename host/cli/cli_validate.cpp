// Argument checks shared by every command (cli_validate.hpp).
#include "cli_validate.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sstream>

#include "error.hpp"
#include "io.hpp"

namespace softshell::cli {
namespace {

namespace fs = std::filesystem;

// Validators of ours carry this name, so the safety net knows which options
// are already checked.
const char* const kChecked = "softshell-checked";

std::string number_text(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// "in [lo, hi] unit", ">= lo unit", "<= hi", or "" (any finite number).
std::string range_text(double lo, double hi, const std::string& unit, Ends ends) {
  const bool lo_open = ends == Ends::OpenLow || ends == Ends::Open, hi_open = ends == Ends::OpenHigh || ends == Ends::Open;
  const std::string u = unit.empty() ? "" : " " + unit;
  const bool has_lo = std::isfinite(lo), has_hi = std::isfinite(hi);
  if (has_lo && has_hi)
    return "in " + std::string(lo_open ? "(" : "[") + number_text(lo) + ", " + number_text(hi) + (hi_open ? ")" : "]") + u;
  if (has_lo) return std::string(lo_open ? "> " : ">= ") + number_text(lo) + u;
  if (has_hi) return std::string(hi_open ? "< " : "<= ") + number_text(hi) + u;
  return unit.empty() ? "" : "(" + unit + ")";
}

// The whole text is one finite number (strtod: also accepts hex and
// exponents; refuses nan, inf and overflow).
bool parse_finite(const std::string& text, double& v) {
  if (text.empty() || std::isspace(static_cast<unsigned char>(text[0]))) return false;
  errno = 0;
  char* end = nullptr;
  v = std::strtod(text.c_str(), &end);
  return *end == '\0' && errno != ERANGE && std::isfinite(v);
}

std::string extension_of(const std::string& path) {
  std::string e = fs::path(path).extension().string();
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

void collect_unranged(const CLI::App& app, std::vector<std::string>& names) {
  for (const CLI::Option* opt : app.get_options()) {
    if (opt->get_type_name().rfind("FLOAT", 0) != 0) continue;
    bool checked = false;
    try {
      const_cast<CLI::Option*>(opt)->get_validator(kChecked);
      checked = true;
    } catch (const CLI::OptionNotFound&) {
    }
    if (!checked) names.push_back(opt->get_name());
  }
  // Option groups are nameless subcommands of their command.
  for (const CLI::App* g : app.get_subcommands([](const CLI::App* a) { return a->get_name().empty(); }))
    collect_unranged(*g, names);
}

void add_finite_checks(CLI::App& app) {
  for (CLI::Option* opt : app.get_options()) {
    if (opt->get_type_name().rfind("FLOAT", 0) != 0) continue;
    try {
      opt->get_validator(kChecked);
    } catch (const CLI::OptionNotFound&) {
      opt->check(CLI::Validator(
          [](std::string& input) {
            double v = 0;
            return parse_finite(input, v) ? std::string() : "must be a finite number, got '" + input + "'";
          },
          "", kChecked));
    }
  }
  for (CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) add_finite_checks(*sub);
}

}  // namespace

CLI::Validator real_range(double lo, double hi, const std::string& unit, Ends ends) {
  const std::string range = range_text(lo, hi, unit, ends);
  const bool lo_open = ends == Ends::OpenLow || ends == Ends::Open, hi_open = ends == Ends::OpenHigh || ends == Ends::Open;
  return CLI::Validator(
      [=](std::string& input) {
        double v = 0;
        const bool ok = parse_finite(input, v) && (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
        return ok ? std::string() : "must be a finite number" + (range.empty() ? "" : " " + range) + ", got '" + input + "'";
      },
      range.empty() ? "finite" : range, kChecked);
}

CLI::Validator int_range(long long lo, long long hi, const std::string& unit) {
  const std::string range = "[" + std::to_string(lo) + ", " + std::to_string(hi) + "]" + (unit.empty() ? "" : " " + unit);
  return CLI::Validator(
      [=](std::string& input) {
        errno = 0;
        char* end = nullptr;
        const long long v = input.empty() ? 0 : std::strtoll(input.c_str(), &end, 10);
        const bool ok = !input.empty() && *end == '\0' && errno != ERANGE && v >= lo && v <= hi;
        return ok ? std::string() : "must be an integer in " + range + ", got '" + input + "'";
      },
      "in " + range, kChecked);
}

std::string choice_list(const std::vector<std::string>& choices) {
  std::string s;
  for (std::size_t i = 0; i < choices.size(); ++i)
    s += (i == 0 ? "" : i + 1 == choices.size() ? " or " : ", ") + choices[i];
  return s;
}

CLI::Validator one_of(const std::vector<std::string>& choices) {
  const std::string list = choice_list(choices);
  return CLI::Validator(
      [=](std::string& input) {
        for (const std::string& c : choices)
          if (input == c) return std::string();
        return "unknown value '" + input + "' (expected " + list + ")";
      },
      "one of: " + list, kChecked);
}

CLI::Option* add_beam_axis_option(CLI::App* sub, std::string& word, const std::string& help) {
  return sub->add_option("--beam-axis", word, help)
      ->capture_default_str()
      ->type_name("auto|x|y|z")
      ->check(one_of({"auto", "x", "y", "z"}));
}

void require_checked_numbers(CLI::App& app) { add_finite_checks(app); }

std::vector<std::string> unranged_number_options(const CLI::App& sub) {
  std::vector<std::string> names;
  collect_unranged(sub, names);
  return names;
}

void check_output(const std::string& path, OutputKind kind, const std::string& option) {
  const std::string who = option + " " + path;
  if (path.empty()) throw InputError(option + ": expected a path, got an empty one");
  std::vector<std::string> extensions;
  const char* what = "";
  switch (kind) {
    case OutputKind::Volume: what = "a volume"; break;  // io.hpp: is_volume_output
    case OutputKind::Png: extensions = {".png"}, what = "a PNG image"; break;
    case OutputKind::Ply: extensions = {".ply"}, what = "a PLY mesh"; break;
    case OutputKind::Directory: break;
  }
  if (kind == OutputKind::Directory) {
    // The nearest existing ancestor must be a directory we can write in
    // (the command creates the rest).
    std::error_code ec;
    fs::path p = fs::absolute(fs::path(path), ec);
    if (fs::exists(p, ec) && !fs::is_directory(p, ec))
      throw InputError(who + ": exists and is not a directory");
    while (!p.empty() && !fs::exists(p, ec)) {
      if (p == p.parent_path()) break;
      p = p.parent_path();
    }
    if (!fs::is_directory(p, ec)) throw InputError(who + ": " + p.string() + " is not a directory");
    if (::access(p.c_str(), W_OK | X_OK) != 0)
      throw InputError(who + ": cannot write in " + p.string() + ": " + std::strerror(errno));
    return;
  }
  // A probe temporary beside the target: exactly what the real write will
  // create first; removed when it goes out of scope. First, so that a
  // device or directory in the target's place is named as such.
  for (const std::string& f : kind == OutputKind::Volume ? output_files(path) : std::vector<std::string>{path}) {
    try {
      io_detail::AtomicFile probe(f);
    } catch (const InputError& e) {
      throw InputError(option + " " + e.what());
    }
  }
  const std::string ext = extension_of(path);
  bool known = kind == OutputKind::Volume && is_volume_output(path);
  for (const std::string& e : extensions) known = known || ext == e;
  if (!known) {
    std::string list = kind == OutputKind::Volume ? volume_output_extensions() : "";
    for (const std::string& e : extensions) list += (list.empty() ? "" : ", ") + e;
    throw InputError(who + ": " + (ext.empty() ? std::string("no extension") : "unknown extension '" + ext + "'") +
                     " for " + what + " (writes " + list + ")");
  }
}

}  // namespace softshell::cli
