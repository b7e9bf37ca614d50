#version 450 core
// Boxes smaller than about a pixel on screen: one point at the cell's frame origin (the
// centroid of its points, on its best-fit plane), shaded with the plane normal W, instead of
// a ray cast that would sample the same pixel.
#include "heightfield.glsl"

uniform mat3 viewRotation;
uniform mat4 projection;

layout(std430, binding = 1) readonly buffer DrawItems { uvec2 items[]; };

flat out vec3 vNormal;
flat out vec3 vToEye;
flat out vec3 vColor;
out float vViewDepth;
flat out int vCell;
uniform vec3 viewForward;
uniform bool useColor;
uniform vec3 baseColor;

void main() {
  Cell c = cells[items[gl_InstanceID].x];
  vCell = int(items[gl_InstanceID].x);
  vec3 rel = cellRelativeToCamera(c);
  gl_Position = projection * vec4(viewRotation * rel, 1.0);
  gl_PointSize = 1.0;
  vNormal = c.axisW.xyz;
  vToEye = -rel;
  vViewDepth = dot(rel, viewForward);
  vColor = useColor ? sampleColor(c, vec2(0.0)) : baseColor;
}
