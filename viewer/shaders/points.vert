#version 450 core
// The conventional baseline: every source point drawn as a GL point splat whose size comes
// from the sample spacing, the way scan viewers draw clouds. Positions are float offsets
// from the pack origin; the camera offset is subtracted in two parts (high, low).
layout(location = 0) in vec3 position;  // relative to the pack origin
layout(location = 1) in vec4 color;

uniform vec3 camHi;
uniform vec3 camLo;
uniform mat3 viewRotation;
uniform mat4 projection;
uniform vec3 viewForward;
uniform float spacingPixels;  // sample spacing times the focal length in pixels
uniform bool useColor;
uniform vec3 baseColor;

out vec3 vColor;
out float vViewDepth;
out vec3 vRel;

void main() {
  vec3 rel = (position - camHi) - camLo;
  vViewDepth = dot(rel, viewForward);
  vRel = rel;
  gl_Position = projection * vec4(viewRotation * rel, 1.0);
  gl_PointSize = clamp(1.5 * spacingPixels / max(vViewDepth, 1e-30), 1.0, 64.0);
  vColor = useColor ? color.rgb : baseColor;
}
