#version 450 core
#include "shading.glsl"
#include "clip.glsl"

flat in vec3 vNormal;
flat in vec3 vToEye;   // minus the splat's camera-relative position
flat in vec3 vColor;
in float vViewDepth;
flat in int vCell;

layout(location = 0) out vec4 outColor;
layout(location = 1) out float outDepth;
layout(location = 2) out vec4 outNormal;
layout(location = 3) out uint outCell;

void main() {
  if (isClipped(-vToEye)) discard;
  outColor = vec4(shade(vColor, vNormal, -vToEye), 1.0);
  outDepth = vViewDepth;
  outNormal = vec4(normalize(vNormal), 0.0);
  outCell = uint(vCell) + 1u;
}
