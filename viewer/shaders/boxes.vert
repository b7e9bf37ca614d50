#version 450 core
// Cell boxes as wireframes, coloured by the orientation of the cell's height axis W (as in
// Lu, Low & Zheng's Fig. 4): |W| as RGB. The decomposition view.
#include "heightfield.glsl"

uniform mat3 viewRotation;
uniform mat4 projection;
layout(std430, binding = 1) readonly buffer DrawItems { uvec2 items[]; };
flat out vec3 vColor;

const int kEdges[24] = int[24](0, 1, 2, 3, 4, 5, 6, 7, 0, 2, 1, 3, 4, 6, 5, 7, 0, 4, 1, 5, 2, 6, 3, 7);

void main() {
  Cell c = cells[items[gl_InstanceID].x];
  int k = kEdges[gl_VertexID];
  vec3 corner = vec3(k & 1, (k >> 1) & 1, (k >> 2) & 1);
  vec3 f = vec3(mix(c.boxUV.x, c.boxUV.y, corner.x), mix(c.boxUV.z, c.boxUV.w, corner.y),
                mix(c.boxW.x, c.boxW.y, corner.z));
  vec3 rel = cellRelativeToCamera(c);
  vec3 world = rel + c.axisU.xyz * f.x + c.axisV.xyz * f.y + c.axisW.xyz * f.z;
  gl_Position = projection * vec4(viewRotation * world, 1.0);
  vColor = abs(c.axisW.xyz);
}
