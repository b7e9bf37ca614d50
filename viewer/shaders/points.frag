#version 450 core
// Round splats; unlit (the baseline has no normals unless the source had them).
#include "clip.glsl"

in vec3 vColor;
in float vViewDepth;
in vec3 vRel;

layout(location = 0) out vec4 outColor;
layout(location = 1) out float outDepth;
layout(location = 2) out vec4 outNormal;
layout(location = 3) out uint outCell;    // no cell: the source points

void main() {
  vec2 d = gl_PointCoord * 2.0 - 1.0;
  if (dot(d, d) > 1.0 || isClipped(vRel)) discard;
  outColor = vec4(vColor * 0.9, 1.0);
  outDepth = vViewDepth;
  outNormal = vec4(0.0);
  outCell = 0u;
}
