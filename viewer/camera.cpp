// Orbit camera.
#include "camera.hpp"

#include <algorithm>
#include <cmath>

#include <glm/gtc/matrix_transform.hpp>

namespace softshell::viewer {

void OrbitCamera::fit(const std::array<double, 3>& lo, const std::array<double, 3>& hi, float margin) {
  const glm::vec3 a{float(lo[0]), float(lo[1]), float(lo[2])}, b{float(hi[0]), float(hi[1]), float(hi[2])};
  target = 0.5f * (a + b);
  radius = std::max(0.5f * glm::length(b - a), 1e-3f);
  distance = margin * radius / std::sin(glm::radians(0.5f * fov_y));
  pan = glm::vec2(0.0f);
}

glm::vec3 OrbitCamera::forward() const {
  const float az = glm::radians(azimuth), el = glm::radians(std::clamp(elevation, -89.0f, 89.0f));
  // Eye offset from the target is -forward.
  const glm::vec3 e(std::sin(az) * std::cos(el), -std::sin(el), -std::cos(az) * std::cos(el));
  return -e;
}

glm::vec3 OrbitCamera::right() const { return glm::normalize(glm::cross(forward(), glm::vec3(0, -1, 0))); }
glm::vec3 OrbitCamera::up() const { return glm::cross(right(), forward()); }

glm::vec3 OrbitCamera::eye() const {
  const glm::vec3 t = target + pan.x * right() + pan.y * up();
  return t - distance * forward();
}

glm::mat4 OrbitCamera::view() const { return glm::lookAt(eye(), eye() + forward(), up()); }

glm::mat4 OrbitCamera::projection(float aspect) const {
  const float near_plane = std::max(distance - 2.0f * radius, 1e-2f * distance);
  const float far_plane = distance + 2.0f * radius;
  return glm::perspective(glm::radians(fov_y), aspect, near_plane, far_plane);
}

glm::vec3 OrbitCamera::to_world(const glm::vec3& d) const { return d.x * right() + d.y * up() - d.z * forward(); }

void OrbitCamera::rotate(float dx_px, float dy_px) {
  azimuth = std::fmod(azimuth + 0.3f * dx_px, 360.0f);
  elevation = std::clamp(elevation + 0.3f * dy_px, -89.0f, 89.0f);
}

void OrbitCamera::zoom(float wheel_steps) {
  distance = std::clamp(distance * std::pow(0.9f, wheel_steps), 0.05f * radius, 20.0f * radius);
}

void OrbitCamera::move(float dx_px, float dy_px, float viewport_height_px) {
  // One pixel at the target's depth, in mm.
  const float mm_per_px = 2.0f * distance * std::tan(glm::radians(0.5f * fov_y)) / std::max(viewport_height_px, 1.0f);
  pan.x -= dx_px * mm_per_px;
  pan.y += dy_px * mm_per_px;
}

}  // namespace softshell::viewer
