// Presets (docs/rendering.md, "Presets"): named settings that set the
// classification and the rendering together, as ultrasound users know them
// from their scanners and from 3D Slicer's volume-rendering presets. Used by
// `view --preset`, `render --preset`, the viewer's panel, and the `preset`
// key of a parameters file (`classify --params` takes its classification
// part). What a command line or a parameters file gives explicitly wins.
#pragma once

#include <array>
#include <string>
#include <vector>

namespace softshell {

struct Preset {
  std::string name;   // "default", "face", "bone", "vessels"
  std::string what;   // one line for --help and the panel
  // Classification: the bone cue (classify's --bone-cue words).
  std::string bone_cue = "off";
  // Rendering.
  std::array<float, 3> colour{0.92f, 0.76f, 0.62f};
  bool depth_colour = false;          // --colour-map depth
  float light_azimuth = -30.0f, light_elevation = 30.0f;  // degrees from the view direction
  float specular = 0.18f;
  float threshold = 0.2f;             // splat epsilon
  bool rim_gaussian = true;           // --gaussian rim (false: paper)
  // Splat orientation (--orientation words). "data" needs the B-mode volume
  // (a raw input, or --volume); without it the tensor of u is used.
  std::string orientation = "tensor";
};

const std::vector<Preset>& presets();
// Null for an unknown name.
const Preset* find_preset(const std::string& name);
// "default, face, bone, vessels" (for messages and --help).
std::string preset_names();

}  // namespace softshell
