#version 450 core
// Instanced cell boxes (Lu, Low & Zheng §3.3, step 1). Each instance is one visible cell
// from the frame's draw list; the 36 vertices of its box come from gl_VertexID. Positions
// are camera-relative.
#include "heightfield.glsl"

uniform mat3 viewRotation;  // world -> view rotation (no translation: camera at the origin)
uniform mat4 projection;    // infinite reverse-Z

layout(std430, binding = 1) readonly buffer DrawItems { uvec2 items[]; };  // (cell, steps)

out vec3 vFrame;            // the vertex in the cell's frame (u, v, w): M1 applied
flat out int vCell;
flat out int vSteps;
flat out vec3 vCamFrame;    // the camera in the cell's frame

const int kCubeIndex[36] = int[36](0, 2, 1, 1, 2, 3,  4, 5, 6, 5, 7, 6,  0, 1, 4, 1, 5, 4,
                                   2, 6, 3, 3, 6, 7,  0, 4, 2, 2, 4, 6,  1, 3, 5, 3, 7, 5);

void main() {
  uvec2 item = items[gl_InstanceID];
  Cell c = cells[item.x];
  int k = kCubeIndex[gl_VertexID];
  vec3 corner = vec3(k & 1, (k >> 1) & 1, (k >> 2) & 1);
  vec3 f = vec3(mix(c.boxUV.x, c.boxUV.y, corner.x), mix(c.boxUV.z, c.boxUV.w, corner.y),
                mix(c.boxW.x, c.boxW.y, corner.z));
  vec3 rel = cellRelativeToCamera(c);  // O - eye
  vec3 world = rel + c.axisU.xyz * f.x + c.axisV.xyz * f.y + c.axisW.xyz * f.z;
  gl_Position = projection * vec4(viewRotation * world, 1.0);
  vFrame = f;
  vCell = int(item.x);
  vSteps = int(item.y);
  vCamFrame = -vec3(dot(rel, c.axisU.xyz), dot(rel, c.axisV.xyz), dot(rel, c.axisW.xyz));
}
