// The parameters file (host/params_file.hpp).
#include "params_file.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "error.hpp"

namespace softshell {
namespace {

enum class Kind { Iso, Numbers, Word };
struct KeySpec {
  Kind kind;
  int count = 1;          // numbers per value
  double lo = 0, hi = 0;  // inclusive range
  bool open_lo = false;
  const char* words = "";  // Word: the choices, '|'-separated
};

const std::vector<std::pair<std::string, KeySpec>>& specs() {
  static const std::vector<std::pair<std::string, KeySpec>> s = {
      {"preset", {Kind::Word, 1, 0, 0, false, "default|face|bone|vessels"}},
      {"iso", {Kind::Iso}},
      {"sigma", {Kind::Numbers, 1, 0, 1e3}},
      {"alpha", {Kind::Numbers, 1, 0, 1e6}},
      {"beta", {Kind::Numbers, 1, 0, 1e6}},
      {"gamma", {Kind::Numbers, 1, 0, 1e6, true}},
      {"omega", {Kind::Numbers, 1, 0, 1}},
      {"delta", {Kind::Numbers, 1, 0, 1, true}},
      {"epsilon", {Kind::Numbers, 1, 1e-6, 1e6}},
      {"kappa", {Kind::Numbers, 1, 0, 1e6}},
      {"shell_shift", {Kind::Numbers, 1, 0, 10}},
      {"renderer", {Kind::Word, 1, 0, 0, false, "splat|isosplat|mc|raycast"}},
      {"threshold", {Kind::Numbers, 1, 0, 1, true}},
      {"mesh_level", {Kind::Numbers, 1, 0, 1, true}},
      {"light", {Kind::Numbers, 2, -90, 90}},
      {"colour", {Kind::Numbers, 3, 0, 1}},
      {"colour_map", {Kind::Word, 1, 0, 0, false, "solid|depth"}},
      {"background", {Kind::Numbers, 3, 0, 1}},
      {"crop", {Kind::Numbers, 6, 0, 1}},
      {"view", {Kind::Numbers, 2, -360, 360}},
      {"distance", {Kind::Numbers, 1, 0, 1e7, true}},
  };
  return s;
}

const KeySpec* spec(const std::string& key) {
  for (const auto& [k, s] : specs())
    if (k == key) return &s;
  return nullptr;
}

std::string trim(const std::string& s) {
  const auto a = s.find_first_not_of(" \t\r");
  if (a == std::string::npos) return "";
  return s.substr(a, s.find_last_not_of(" \t\r") - a + 1);
}

std::string key_list() {
  std::string out;
  for (const auto& [k, s] : specs()) out += (out.empty() ? "" : ", ") + k;
  return out;
}

std::vector<double> parse_numbers(const std::string& text, bool* ok) {
  std::vector<double> v;
  std::stringstream in(text);
  std::string item;
  *ok = true;
  while (std::getline(in, item, ',')) {
    item = trim(item);
    char* end = nullptr;
    const double x = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !std::isfinite(x)) *ok = false;
    v.push_back(x);
  }
  if (text.empty() || text.back() == ',') *ok = false;
  return v;
}

// An empty string when `value` suits `key`, else what is wrong.
std::string check_value(const std::string& key, const std::string& value) {
  const KeySpec* s = spec(key);
  if (!s) return "unknown key (keys: " + key_list() + ")";
  if (s->kind == Kind::Word) {
    std::stringstream in(s->words);
    std::string w;
    while (std::getline(in, w, '|'))
      if (w == value) return "";
    return "expected one of " + std::string(s->words) + ", got '" + value + "'";
  }
  if (s->kind == Kind::Iso && (value == "auto")) return "";
  bool ok = false;
  const std::vector<double> v = parse_numbers(value, &ok);
  std::ostringstream range;
  range << (s->open_lo ? "(" : "[") << s->lo << ", " << s->hi << "]";
  if (s->kind == Kind::Iso) return ok && v.size() == 1 ? "" : "expected a number (intensity units) or auto, got '" + value + "'";
  if (!ok || int(v.size()) != s->count)
    return "expected " + (s->count == 1 ? std::string("a number") : std::to_string(s->count) + " comma-separated numbers") +
           " in " + range.str() + ", got '" + value + "'";
  for (double x : v)
    if (x < s->lo || x > s->hi || (s->open_lo && x == s->lo))
      return "value out of range " + range.str() + ": '" + value + "'";
  return "";
}

std::string format_number(double x) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", x);
  return buf;
}

}  // namespace

const std::vector<std::string>& params_file_keys() {
  static const std::vector<std::string> keys = [] {
    std::vector<std::string> k;
    for (const auto& [key, s] : specs()) k.push_back(key);
    return k;
  }();
  return keys;
}

const std::string* ParamsFile::find(const std::string& key) const {
  for (const auto& [k, v] : entries)
    if (k == key) return &v;
  return nullptr;
}

std::optional<double> ParamsFile::number(const std::string& key) const {
  const std::string* v = find(key);
  if (!v || *v == "auto") return std::nullopt;
  return std::strtod(v->c_str(), nullptr);
}

std::optional<std::vector<double>> ParamsFile::numbers(const std::string& key) const {
  const std::string* v = find(key);
  if (!v) return std::nullopt;
  bool ok = false;
  return parse_numbers(*v, &ok);
}

void ParamsFile::set(const std::string& key, const std::string& value) {
  const std::string problem = check_value(key, value);
  if (!problem.empty()) throw InputError("parameters: key '" + key + "': " + problem);
  for (auto& [k, v] : entries)
    if (k == key) return void(v = value);
  entries.emplace_back(key, value);
}

void ParamsFile::set(const std::string& key, double value) { set(key, format_number(value)); }

void ParamsFile::set(const std::string& key, const std::vector<double>& values) {
  std::string text;
  for (double x : values) text += (text.empty() ? "" : ",") + format_number(x);
  set(key, text);
}

ParamsFile read_params_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw input_error(path, "cannot open the parameters file");
  ParamsFile p;
  p.path = path;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    line = trim(line);
    if (line.empty()) continue;
    const std::string where = path + ":" + std::to_string(n) + ": ";
    const auto eq = line.find('=');
    if (eq == std::string::npos) throw InputError(where + "expected 'key = value', got '" + line + "'");
    const std::string key = trim(line.substr(0, eq)), value = trim(line.substr(eq + 1));
    if (p.find(key)) throw InputError(where + "key '" + key + "' given twice");
    const std::string problem = check_value(key, value);
    if (!problem.empty()) throw InputError(where + "key '" + key + "': " + problem);
    p.entries.emplace_back(key, value);
  }
  if (in.bad()) throw input_error(path, "read error");
  return p;
}

void write_params_file(const std::string& path, const ParamsFile& p) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) throw input_error(path, "cannot write the parameters file");
    out << "# softshell parameters (docs/rendering.md, \"Parameters file\"): key = value, # comments.\n"
        << "# Read by `softshell classify IN --params FILE -o OUT` (iso and the weights) and\n"
        << "# `softshell view IN --params FILE` (all); options given on the command line win.\n";
    // In the documented order.
    for (const std::string& key : params_file_keys())
      if (const std::string* v = p.find(key)) out << key << " = " << *v << '\n';
    out.flush();
    if (!out) {
      std::filesystem::remove(tmp);
      throw input_error(path, "write error");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp);
    throw input_error(path, "cannot write the parameters file: " + ec.message());
  }
}

}  // namespace softshell
