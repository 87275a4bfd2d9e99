// Two-sided Blinn-Phong with the splat renderer's parameters (viewer/splat_renderer.hpp
// RenderSettings), so meshes and splats are lit alike. Fragments outside the crop box (mm) are
// discarded.
#version 330 core

uniform vec3 u_eye;
uniform vec3 u_light;      // unit vector towards the light
uniform vec3 u_colour;
uniform vec4 u_material;   // ambient, diffuse, specular, shininess
uniform vec3 u_crop_lo, u_crop_hi;

in vec3 v_position;
in vec3 v_normal;
out vec4 frag_colour;

void main() {
  if (any(lessThan(v_position, u_crop_lo)) || any(greaterThan(v_position, u_crop_hi))) discard;
  vec3 n = normalize(v_normal);
  vec3 v = normalize(u_eye - v_position);
  if (dot(n, v) < 0.0) n = -n;
  float diffuse = max(dot(n, u_light), 0.0);
  float specular = diffuse > 0.0 ? pow(max(dot(n, normalize(u_light + v)), 0.0), u_material.w) : 0.0;
  frag_colour = vec4(u_colour * (u_material.x + u_material.y * diffuse) + vec3(u_material.z * specular), 1.0);
}
