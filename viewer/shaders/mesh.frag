// Two-sided Blinn-Phong with the splat renderer's parameters (viewer/splat_renderer.hpp
// RenderSettings), so meshes and splats are lit alike. Fragments outside the crop box (mm) are
// discarded.
#version 330 core

uniform vec3 u_eye;
uniform vec3 u_light;      // unit vector towards the light
uniform vec3 u_colour;
uniform vec4 u_material;   // ambient, diffuse, specular, shininess
uniform vec3 u_crop_lo, u_crop_hi;
uniform vec3 u_depth;      // x = 1: colour by depth z in [y, z] mm instead of u_colour

in vec3 v_position;
in vec3 v_normal;
out vec4 frag_colour;

// Depth colour map (SlicerHeart-style): light skin tones near the
// transducer, darker red-brown with depth along the beam (z).
vec3 depth_colour(float t) {
  t = clamp(t, 0.0, 1.0);
  return t < 0.5 ? mix(vec3(1.0, 0.9, 0.72), vec3(0.93, 0.55, 0.33), 2.0 * t)
                 : mix(vec3(0.93, 0.55, 0.33), vec3(0.5, 0.16, 0.12), 2.0 * t - 1.0);
}

void main() {
  if (any(lessThan(v_position, u_crop_lo)) || any(greaterThan(v_position, u_crop_hi))) discard;
  vec3 n = normalize(v_normal);
  vec3 v = normalize(u_eye - v_position);
  if (dot(n, v) < 0.0) n = -n;
  float diffuse = max(dot(n, u_light), 0.0);
  float specular = diffuse > 0.0 ? pow(max(dot(n, normalize(u_light + v)), 0.0), u_material.w) : 0.0;
  vec3 colour = u_depth.x > 0.5 ? depth_colour((v_position.z - u_depth.y) / max(u_depth.z - u_depth.y, 1e-6)) : u_colour;
  frag_colour = vec4(colour * (u_material.x + u_material.y * diffuse) + vec3(u_material.z * specular), 1.0);
}
