#version 450 core
// The grooves mode's resolve (grooves_defer.glsl): over one list's 4x4 tiles of the frame, each
// pixel the list's cast drew takes that fragment's outputs from the pack target, and the depth
// the cast wrote (reverse-Z from the linear view depth, as parallax.frag writes it), so the
// frame's depth test treats it as the cast's own fragment.
layout(binding = 3, r32ui) uniform readonly uimage2DArray deferSlots;
layout(binding = 4) uniform sampler2D packColor;
layout(binding = 5) uniform sampler2D packLinear;
layout(binding = 6) uniform sampler2D packNormal;
layout(binding = 7) uniform usampler2D packCell;
uniform int deferSlot;
uniform uint deferClass;
uniform float nearPlane;

layout(location = 0) out vec4 outColor;
layout(location = 1) out float outDepth;
layout(location = 2) out vec4 outNormal;
layout(location = 3) out uint outCell;

const uint kNotPacked = 0xffffffffu;

void main() {
  ivec2 px = ivec2(gl_FragCoord.xy);
  uint id = imageLoad(deferSlots, ivec3(px, 2 * deferSlot)).x;
  if (id == 0u || (id >> 31) != deferClass) discard;
  uint at = imageLoad(deferSlots, ivec3(px, 2 * deferSlot + 1)).x;
  if (at == kNotPacked) discard;
  ivec2 sp = ivec2(at & 0xffffu, at >> 16);
  outColor = texelFetch(packColor, sp, 0);
  outDepth = texelFetch(packLinear, sp, 0).r;
  outNormal = texelFetch(packNormal, sp, 0);
  outCell = texelFetch(packCell, sp, 0).r;
  gl_FragDepth = nearPlane / outDepth;
}
