#version 450 core
// The frame's depth buffer from its linear depth, for the decomposition view's box edges after
// the grooves mode's second pass (grooves_defer.glsl writes the frame's targets as images, not
// its depth buffer): reverse-Z, as parallax.frag writes it.
layout(binding = 12) uniform sampler2D linearDepth;
uniform float nearPlane;

void main() {
  float lin = texelFetch(linearDepth, ivec2(gl_FragCoord.xy), 0).r;
  if (isinf(lin)) discard;
  gl_FragDepth = nearPlane / lin;
}
