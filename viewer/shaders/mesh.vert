// Marching Cubes mesh (host/mesh.hpp): positions in mm and per-vertex normals, drawn with a depth
// test; lighting per fragment in mesh.frag with the splat renderer's material and light.
#version 330 core

layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;

uniform mat4 u_view_proj;

out vec3 v_position;
out vec3 v_normal;

void main() {
  v_position = a_position;
  v_normal = a_normal;
  gl_Position = u_view_proj * vec4(a_position, 1.0);
}
