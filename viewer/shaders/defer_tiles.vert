#version 450 core
// The grooves mode's resolve (modes/grooves/grooves_defer.glsl): a 4-pixel point over each
// 4x4-pixel tile of one list the first pass made (llvmpipe shades a tile a point covers once;
// the two triangles of a quad each shade it under half a mask).
#include "defer_lists.glsl"

uniform int deferList;
uniform vec2 viewportSize;

void main() {
  uint t = deferItem[uint(deferList) * deferCapacity + uint(gl_InstanceID)];
  vec2 px = (vec2(float(t & 0xffffu), float(t >> 16u)) + 0.5) * 4.0;
  gl_Position = vec4(px / viewportSize * 2.0 - 1.0, 0.5, 1.0);
  gl_PointSize = 4.0;
}
