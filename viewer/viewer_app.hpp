// The interactive viewer behind `softshell view`: a GLFW window (OpenGL 3.3
// core), the splat renderer (or the Marching Cubes mesh, or the OpenCL ray
// caster), an orbit camera and a Dear ImGui panel.
// Hooks as in the OpenCL-SDK interop samples: init GL, init CL, update
// (compute: re-solve, splat generation), render (draw), events.
#pragma once

#include <string>

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
};

// Runs until the window closes, Esc, or `frames` frames. Returns 0.
int run_viewer(Runtime& rt, OpacityInput input, const ViewerOptions& options);

}  // namespace softshell::viewer
