// The interactive viewer behind `softshell view`: a GLFW window (OpenGL 3.3
// core), the splat renderer (or the Marching Cubes mesh, or the OpenCL ray
// caster), an orbit camera and a Dear ImGui panel.
// Hooks as in the OpenCL-SDK interop samples: init GL, init CL, update
// (compute: re-solve, splat generation), render (draw), events.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "cl_runtime.hpp"
#include "opacity_input.hpp"
#include "splat_renderer.hpp"
#include "splats.hpp"

namespace softshell::viewer {

// What the viewer draws: splats (oriented or isotropic, RenderSettings::method),
// the Marching Cubes mesh of u at a level, or the OpenCL ray caster's image of u.
enum class ViewRenderer { Splats, Mesh, Raycast };

struct ViewerOptions {
  int width = 1200, height = 800;
  float azimuth = 0, elevation = 0;
  RenderSettings settings;
  SplatParams params;
  ViewRenderer renderer = ViewRenderer::Splats;
  float mesh_level = 0.2f;  // Marching Cubes level (ViewRenderer::Mesh)
  int frames = 0;           // > 0: draw this many frames, then quit (tests, scripts)
  std::string screenshot;   // with frames: save the last frame's scene here
  bool screenshot_panel = false;  // ... with the ImGui panel drawn on it
  bool quiet = false;
  // The slice views: the 3-D cursor (voxel indices; -1: the centre) and the
  // opacity of the u overlay on the B-mode slices.
  std::array<int, 3> cursor{-1, -1, -1};
  float overlay = 0.5f;
  std::string iso_text = "auto";  // how the isovalue was given (the parameters file keeps "auto")
  // With frames: written at the end (u as float, the mesh at mesh_level, the parameters file).
  std::string save_params, save_u, save_mesh;
  // From a parameters file: camera distance (mm), light AZ,EL, colours R,G,B.
  std::optional<float> distance;
  std::optional<std::vector<double>> light, colour, background;
  // A 3D+t opacity sequence: play it at this many frames per second from
  // the start (0: paused; the panel's frame slider and play button);
  // with `frames` (scripted), one sequence frame per drawn frame.
  double play_fps = 0;
  // The preset the settings came from (host/presets.hpp; empty: none): the
  // panel's preset menu starts on it and the parameters file names it.
  std::string preset;
};

// Runs until the window closes, Esc, or `frames` frames. Returns 0.
int run_viewer(Runtime& rt, OpacityInput input, const ViewerOptions& options);

}  // namespace softshell::viewer
