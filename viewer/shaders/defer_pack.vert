#version 450 core
// The grooves mode's cast over one list's deferred pixels packed densely (grooves_defer.glsl): a
// 4-pixel point over each 4x4 block of the pack target, block i holding the list's pixels 16 i to
// 16 i + 15 (llvmpipe shades a block a point covers once, 8 pixels at a time).
uniform ivec2 packSize;

void main() {
  int blocksX = packSize.x >> 2;
  vec2 px = (vec2(float(gl_InstanceID % blocksX), float(gl_InstanceID / blocksX)) + 0.5) * 4.0;
  gl_Position = vec4(px / vec2(packSize) * 2.0 - 1.0, 0.5, 1.0);
  gl_PointSize = 4.0;
}
