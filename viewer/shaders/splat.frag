#version 450 core
#include "shading.glsl"

flat in vec3 vNormal;
flat in vec3 vToEye;
flat in vec3 vColor;
in float vViewDepth;

layout(location = 0) out vec4 outColor;
layout(location = 1) out float outDepth;
layout(location = 2) out vec4 outNormal;

void main() {
  outColor = vec4(shadeLambert(vColor, vNormal, vToEye), 1.0);
  outDepth = vViewDepth;
  outNormal = vec4(normalize(vNormal), 0.0);
}
