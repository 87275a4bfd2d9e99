// The parameters file that `softshell view` saves and `classify --params` /
// `view --params` read (docs/rendering.md, "Parameters file"): plain text,
// one `key = value` a line, `#` starts a comment. Every key is checked on
// reading: an unknown key, a repeated key or a bad value is an InputError
// naming the file, the line and the key. Numbers are written with 9
// significant digits, so a float read back is the float written.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace softshell {

// The keys, in the order they are written.
//   preset     default | face | bone | vessels (host/presets.hpp): its settings, under the file's own keys
//   iso        number (the input's intensity units) or auto
//   sigma alpha beta gamma omega delta epsilon kappa   classification weights (classify's options)
//   renderer   splat | isosplat | mc | raycast
//   threshold  splat threshold on u, (0, 1)
//   mesh_level Marching Cubes level, (0, 1)
//   light      AZ,EL degrees;  colour, background  R,G,B in [0, 1];  colour_map  solid | depth
//   crop       X0,X1,Y0,Y1,Z0,Z1 fractions;  view  AZ,EL degrees;  distance  camera distance, mm
const std::vector<std::string>& params_file_keys();

struct ParamsFile {
  std::string path;
  std::vector<std::pair<std::string, std::string>> entries;  // checked key, value text

  const std::string* find(const std::string& key) const;
  // The value as a number, or numbers; nullopt when the key is absent.
  std::optional<double> number(const std::string& key) const;
  std::optional<std::vector<double>> numbers(const std::string& key) const;
  void set(const std::string& key, const std::string& value);  // checks like a read
  void set(const std::string& key, double value);
  void set(const std::string& key, const std::vector<double>& values);
};

// Reads and checks `path` (InputError: "FILE:LINE: key 'x': ...").
ParamsFile read_params_file(const std::string& path);
// Writes the entries with a header comment (through a temporary file, so a
// failed write leaves no half-written file). InputError when it cannot.
void write_params_file(const std::string& path, const ParamsFile& p);

}  // namespace softshell
