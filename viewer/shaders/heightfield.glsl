// Shared height-field declarations: the cell table and height-map sampling.
// Lu, Low & Zheng, "Fast Visualization of Complex 3D Models Using Displacement Mapping".

struct Cell {
  vec4 originHi;  // xyz: cell frame origin O relative to the pack origin, high float part
  vec4 originLo;  // xyz: O - originHi (the low part)
  vec4 axisU;     // xyz: U          (rows of M1, §3.2.2)
  vec4 axisV;     // xyz: V
  vec4 axisW;     // xyz: W, the height direction
  vec4 boxUV;     // uMin, uMax, vMin, vMax
  vec4 boxW;      // wMin, wMax, tile width, tile height (texels)
  ivec4 tile;     // page, first interior texel x, y, flags
};

layout(std430, binding = 0) readonly buffer Cells { Cell cells[]; };

layout(binding = 0) uniform usampler2DArray heightPages;  // R16UI, 0 = not covered
layout(binding = 1) uniform sampler2DArray colorPages;    // RGBA8

// Camera position relative to the pack origin, split into high and low float parts, so
// that (O - camera) is formed without ever holding an absolute coordinate in float32.
uniform vec3 camHi;
uniform vec3 camLo;

const float kUncovered = -1e30;

vec3 cellRelativeToCamera(Cell c) {
  return (c.originHi.xyz - camHi) + (c.originLo.xyz - camLo);
}

// Height at texel (i, j) of the tile in frame units, kUncovered where no surface is.
// i in [-1, W], j in [-1, H]: the one-texel gutter repeats the edge (docs/FORMAT.md).
float texelHeight(Cell c, ivec2 ij) {
  uint k = texelFetch(heightPages, ivec3(c.tile.yz + ij, c.tile.x), 0).r;
  if (k == 0u) return kUncovered;
  return c.boxW.x + (float(k) - 1.0) / 65534.0 * (c.boxW.y - c.boxW.x);
}

// Continuous texel coordinates of frame point (u, v): texel centres at integers.
vec2 texelCoord(Cell c, vec2 uv) {
  vec2 size = c.boxW.zw;
  return (uv - c.boxUV.xz) / (c.boxUV.yw - c.boxUV.xz) * size - 0.5;
}

// Bilinear height at (u, v). Where any of the four texels is uncovered, the nearest
// texel decides (so coverage edges stay sharp and holes stay open).
float sampleHeight(Cell c, vec2 uv) {
  vec2 size = c.boxW.zw;
  vec2 f = clamp(texelCoord(c, uv), vec2(-0.5), size - 0.5);
  ivec2 i0 = ivec2(floor(f));
  vec2 a = f - vec2(i0);
  float h00 = texelHeight(c, i0);
  float h10 = texelHeight(c, i0 + ivec2(1, 0));
  float h01 = texelHeight(c, i0 + ivec2(0, 1));
  float h11 = texelHeight(c, i0 + ivec2(1, 1));
  if (min(min(h00, h10), min(h01, h11)) == kUncovered) {
    ivec2 n = ivec2(floor(f + 0.5));
    return texelHeight(c, clamp(n, ivec2(0), ivec2(size) - 1));
  }
  return mix(mix(h00, h10, a.x), mix(h01, h11, a.x), a.y);
}

vec3 sampleColor(Cell c, vec2 uv) {
  ivec2 n = clamp(ivec2(floor(texelCoord(c, uv) + 0.5)), ivec2(0), ivec2(c.boxW.zw) - 1);
  return texelFetch(colorPages, ivec3(c.tile.yz + n, c.tile.x), 0).rgb;
}
