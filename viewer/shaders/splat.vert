// Splat triangles (paper Section 4.1), three vertices per splat, no vertex
// buffers: gl_VertexID / 3 indexes the draw order, whose entry indexes the
// splat records (host/splats.hpp: 7 RGBA32F texels per splat). Lighting is
// computed per vertex (Gouraud, like OpenGL's fixed-function Phong-like
// model the paper used), so one normal gives a flat splat and three normals
// give three colours interpolated across it.
#version 330 core

uniform samplerBuffer u_splats;  // centre+alpha, normal, S, T, 3 midway normals
uniform usamplerBuffer u_order;  // splat indices, back to front
uniform mat4 u_view_proj;
uniform vec3 u_eye;              // camera position, mm
uniform int u_isotropic;         // 1: the triangle faces the viewer (S, T below)
uniform vec3 u_iso_s, u_iso_t;   // isotropic half-axes, mm (camera right / up times size)
uniform int u_three_normals;
uniform vec3 u_light;            // unit vector towards the light
uniform vec3 u_colour, u_colour2;  // ramp by the splat's T.w (0 from the generator)
uniform vec4 u_material;         // ambient, diffuse, specular, shininess
uniform vec3 u_crop_lo, u_crop_hi;  // splats with centres outside the box are dropped
uniform vec4 u_clip;             // and those with dot(xyz, centre) + w > 0
uniform vec3 u_depth;            // x = 1: colour by depth z in [y, z] mm instead of u_colour
uniform float u_occlusion;       // strength of the splats' ambient occlusion (records 4.w, 5.w), 0: ignored

out vec2 v_tex;
out vec4 v_colour;

// Texture-space corners (paper Figure 4): the equilateral triangle around
// the circle of radius 0.5; vertex k sits at centre + corner.x S + corner.y T.
// Depth colour map (SlicerHeart-style): light skin tones near the
// transducer, darker red-brown with depth along the beam (z).
vec3 depth_colour(float t) {
  t = clamp(t, 0.0, 1.0);
  return t < 0.5 ? mix(vec3(1.0, 0.9, 0.72), vec3(0.93, 0.55, 0.33), 2.0 * t)
                 : mix(vec3(0.93, 0.55, 0.33), vec3(0.5, 0.16, 0.12), 2.0 * t - 1.0);
}

const vec2 k_corner[3] = vec2[3](vec2(1.0, 0.0), vec2(-0.5, -0.8660254), vec2(-0.5, 0.8660254));

void main() {
  int corner = gl_VertexID % 3;
  int base = 7 * int(texelFetch(u_order, gl_VertexID / 3).r);
  vec4 c = texelFetch(u_splats, base);
  if (any(lessThan(c.xyz, u_crop_lo)) || any(greaterThan(c.xyz, u_crop_hi)) || dot(u_clip.xyz, c.xyz) + u_clip.w > 0.0) {
    gl_Position = vec4(0.0, 0.0, 2.0, 1.0);  // beyond the far plane: the whole triangle is clipped
    v_tex = vec2(0.0);
    v_colour = vec4(0.0);
    return;
  }
  vec4 t = texelFetch(u_splats, base + 3);
  vec3 S = u_isotropic != 0 ? u_iso_s : texelFetch(u_splats, base + 2).xyz;
  vec3 T = u_isotropic != 0 ? u_iso_t : t.xyz;
  vec3 colour = u_depth.x > 0.5 ? depth_colour((c.z - u_depth.y) / max(u_depth.z - u_depth.y, 1e-6))
                                 : mix(u_colour, u_colour2, t.w);
  vec2 k = k_corner[corner];
  vec3 p = c.xyz + k.x * S + k.y * T;
  gl_Position = u_view_proj * vec4(p, 1.0);
  v_tex = k;

  vec3 n = texelFetch(u_splats, base + (u_three_normals != 0 ? 4 + corner : 1)).xyz;
  vec3 v = normalize(u_eye - p);
  // Ambient occlusion of the side the viewer sees (records 4.w and 5.w).
  float open = 1.0;
  if (u_occlusion > 0.0) {  // 0 when the splats carry no occlusion: no extra fetches
    float occluded = dot(texelFetch(u_splats, base + 1).xyz, u_eye - c.xyz) >= 0.0 ? texelFetch(u_splats, base + 4).w
                                                                                 : texelFetch(u_splats, base + 5).w;
    open = 1.0 - u_occlusion * clamp(occluded, 0.0, 1.0);
  }
  if (dot(n, v) < 0.0) n = -n;  // two-sided: grad u points into the shell from both faces
  float diffuse = max(dot(n, u_light), 0.0);
  float specular = diffuse > 0.0 ? pow(max(dot(n, normalize(u_light + v)), 0.0), u_material.w) : 0.0;
  v_colour = vec4(open * (colour * (u_material.x + u_material.y * diffuse) + vec3(u_material.z * specular)), c.w);
}
