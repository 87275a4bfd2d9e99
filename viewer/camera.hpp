// Orbit camera (GLM): looks at a target from a distance along a direction
// given by azimuth and elevation, perspective projection.
//
// Convention (ultrasound): azimuth 0, elevation 0 looks down the beam (+z)
// from the transducer side, with x to the right and -y up, i.e. the mid-depth
// C-plane slice as `softshell slices` shows it. Azimuth turns the camera
// about the up axis (90: from +x), elevation raises it towards -y (90: from
// above the -y face).
#pragma once

#include <array>

#include <glm/glm.hpp>

namespace softshell::viewer {

struct OrbitCamera {
  glm::vec3 target{0.0f};
  float distance = 100.0f;   // mm
  float azimuth = 0.0f;      // degrees
  float elevation = 0.0f;    // degrees, kept in (-89, 89)
  float fov_y = 30.0f;       // degrees, vertical field of view
  glm::vec2 pan{0.0f};       // target offset along the camera's right / up, mm
  float radius = 50.0f;      // radius of the scene's bounding sphere (near / far planes)

  // Frames the box [lo, hi] (mm): target at its centre, distance so that its
  // bounding sphere fills the view with `margin` (1: touching).
  void fit(const std::array<double, 3>& lo, const std::array<double, 3>& hi, float margin = 1.05f);

  glm::vec3 eye() const;
  glm::vec3 forward() const;  // unit, from the eye towards the target
  glm::vec3 up() const;       // unit, camera up
  glm::vec3 right() const;    // unit, camera right
  glm::mat4 view() const;
  glm::mat4 projection(float aspect) const;
  // A direction in camera space (x right, y up, z towards the viewer) in world space.
  glm::vec3 to_world(const glm::vec3& camera_dir) const;

  // Interactive controls: drag (pixels) rotates, wheel zooms, right-drag pans.
  void rotate(float dx_px, float dy_px);
  void zoom(float wheel_steps);
  void move(float dx_px, float dy_px, float viewport_height_px);
};

}  // namespace softshell::viewer
