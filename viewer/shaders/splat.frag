// The windowed Gaussian of the paper: alpha = u * exp(-(x^2 + y^2) / lambda)
// inside the circle of radius 0.5 in texture space, 0 outside. Computed
// analytically instead of sampled from a texture (same function, no
// filtering error); the interpolation of v_tex is perspective-correct.
#version 330 core

uniform float u_lambda;  // -0.25 ln epsilon

in vec2 v_tex;
in vec4 v_colour;
out vec4 frag_colour;

void main() {
  float r2 = dot(v_tex, v_tex);
  if (r2 > 0.25) discard;
  frag_colour = vec4(v_colour.rgb, v_colour.a * exp(-r2 / u_lambda));
}
