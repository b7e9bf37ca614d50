// The grooves mode in two passes (viewer/renderer.cpp beginGrooves, drawDeferredGrooves). A
// program's size costs llvmpipe on every pixel it shades, taken branches or not, so the carved
// cast runs only where it can differ from the height field:
//   1. the cells with grooves are drawn by the height field's march (GROOVES_DEFER); a pixel whose
//      hit lies within reach of a groove (the cell's gap field) is not drawn but deferred: its
//      cell, its class (0: the carved cast, its hit near a capsule; 1: the anti-aliasing of a
//      narrow groove's footprint draws it - the march's hit near the capsules, or in one where
//      every groove of the cell is narrower than the pixel, the footprint's centre ray's landing
//      in the groove's cross-section) and the march's hit go to one of DEFER_SLOTS slots of the
//      pixel; the pixel to the list of that slot and class;
//   2. per list: the cast (PIXEL_RAYS, its class's program; class 1 GROOVES_HIT_STANDS) runs on
//      the list's pixels packed densely, 16 to a 4x4 block of a target without attachments
//      (llvmpipe shades 8 pixels at a time, and a deferred pixel's 4x4 tile of the frame holds 6
//      of 16 on average), each pixel along its own ray from the march's hit, for the cell its slot
//      holds; it writes the frame's targets as images where its hit is nearer than the frame's
//      linear depth there (deferStore: the frame's depth test, which the frame's depth buffer
//      then lacks; the decomposition view's box edges take it from the linear depth).
// A pixel all of whose slots are taken keeps the height field for one more cell (counted).
layout(binding = 8) uniform usamplerBuffer grooveFields;  // gcast::gapField (a buffer texture: see grooves.glsl)
#define grooveField(i) texelFetch(grooveFields, int(i)).r
// Layers: slot 0's cell + 1 (bit 31: class 1), its march's hit (float bits, -1: a miss); slot 1's ...
layout(binding = 3, r32ui) uniform coherent uimage2DArray deferSlots;
#include "defer_lists.glsl"

const float kGapTexels = 32.0;  // gcast::kGapFieldTexels
const uint kGapWords = 3u;      // gcast::kGapFieldWords

// The first word of the field's texel under q (frame; clamped to the tile) and its centre.
uint grooveFieldTexel(Cell c, int cell, vec2 q, out vec2 centre) {
  ivec2 n = max(ivec2(c.boxW.zw), ivec2(1));
  vec2 size = c.boxUV.yw - c.boxUV.xz;
  ivec2 i = clamp(ivec2(floor((q - c.boxUV.xz) / size * vec2(n))), ivec2(0), n - 1);
  centre = c.boxUV.xz + (vec2(i) + 0.5) * size / vec2(n);
  return grooveField(cell) + 1u + kGapWords * uint(i.y * n.x + i.x);
}

// The most any of the cell's pieces measures across (gcast::widestAcross).
float grooveWidest(int cell) { return uintBitsToFloat(grooveField(grooveField(cell))); }

// The two pieces nearest the centre of the texel under q by (distance - half width) (~0u: none).
uvec2 grooveNear(Cell c, int cell, vec2 q) {
  vec2 centre;
  uint w = grooveFieldTexel(c, cell, q, centre);
  return uvec2(grooveField(w + 1u), grooveField(w + 2u));
}

// Lower bounds at q (frame) of min over the cell's pieces of (distance to the segment - lip), x,
// and of (distance - half width), y: the field holds them at the texel's centre (gcast::gapField),
// and both change by at most the distance moved, so q's distance from the centre comes off.
vec2 grooveGap(Cell c, int cell, vec2 q) {
  vec2 centre;
  uint w = grooveField(grooveFieldTexel(c, cell, q, centre));
  vec2 texel = (c.boxUV.yw - c.boxUV.xz) / vec2(max(ivec2(c.boxW.zw), ivec2(1)));
  float quantum = kGapTexels * min(texel.x, texel.y) / 65535.0;
  return vec2(float(w & 0xffffu), float(w >> 16u)) * quantum - length(q - centre);
}

#ifdef GROOVES_DEFER
// Claims a slot of this pixel for the cell; false when all hold other cells.
bool deferPixel(int cell, uint cls, float tHit) {
  ivec2 px = ivec2(gl_FragCoord.xy);
  uint id = (uint(cell) + 1u) | (cls << 31);
  for (int s = 0; s < DEFER_SLOTS; ++s) {
    uint old = imageAtomicCompSwap(deferSlots, ivec3(px, 2 * s), 0u, id);
    if (old != 0u && old != id) continue;
    imageStore(deferSlots, ivec3(px, 2 * s + 1), uvec4(floatBitsToUint(tHit)));
    if (old == 0u) {  // the pixel's first claim of the slot (a second fragment of the cell only moves the hit)
      uint list = 2u * uint(s) + cls;
      uint k = atomicAdd(packCount[list], 1u);
      deferItem[packedPixelItem(list, k)] = (uint(px.y) << 16) | uint(px.x);
      if ((k & 15u) == 0u) atomicAdd(packCmd[4u * list + 1u], 1u);  // a new 4x4 block of the pack target
    }
    atomicAdd(deferCount[0], 1u);
    return true;
  }
  atomicAdd(deferCount[1], 1u);
  return false;
}
#endif

#ifdef PIXEL_RAYS
uniform int deferSlot;
uniform uint deferClass;
uniform int deferList;
uniform vec3 rayBase, rayDx, rayDy;  // the pixel's ray (world): rayBase + rayDx x + rayDy y at the pixel's centre
uniform ivec2 packSize;              // the pack target's size (multiples of 4)
uniform bool wantCells;              // the frame's cell target is drawn (read back)

// The frame's targets (viewer/renderer.cpp ensureTargets).
layout(binding = 4, rgba8) uniform writeonly image2D frameColor;
layout(binding = 5, r32f) uniform coherent image2D frameLinear;
layout(binding = 6, rgba16f) uniform writeonly image2D frameNormal;
layout(binding = 7, r32ui) uniform writeonly uimage2D frameCell;

// The cell table as a buffer texture (8 texels a Cell): a deferred pixel's cell comes from its
// slot, and llvmpipe reads a storage buffer at a per-pixel index lane by lane.
layout(binding = 11) uniform samplerBuffer cellTexels;
Cell cellAt(int i) {
  Cell c;
  c.originHi = texelFetch(cellTexels, 8 * i);
  c.originLo = texelFetch(cellTexels, 8 * i + 1);
  c.axisU = texelFetch(cellTexels, 8 * i + 2);
  c.axisV = texelFetch(cellTexels, 8 * i + 3);
  c.axisW = texelFetch(cellTexels, 8 * i + 4);
  c.boxUV = texelFetch(cellTexels, 8 * i + 5);
  c.boxW = texelFetch(cellTexels, 8 * i + 6);
  c.tile = floatBitsToInt(texelFetch(cellTexels, 8 * i + 7));
  return c;
}

// The first cast of this pixel's ray takes the march's hit from its slot (then kNotDeferred: a
// shadow ray marches).
const float kNotDeferred = -2.0;
float deferredHit = kNotDeferred;
ivec2 deferredPixel;

// The frame pixel this fragment of the pack target casts (its list's k-th, k from the fragment's
// 4x4 block and place in it), the cell its slot holds (false: none, or one of the other class),
// the camera and the pixel's ray in the cell's frame.
bool deferredRay(out int cell, out Cell c, out int steps, out vec3 o, out vec3 d) {
  ivec2 sp = ivec2(gl_FragCoord.xy);
  uint blocksX = uint(packSize.x) >> 2;
  uint k = 16u * ((uint(sp.y) >> 2) * blocksX + (uint(sp.x) >> 2)) + 4u * (uint(sp.y) & 3u) + (uint(sp.x) & 3u);
  if (k >= packCount[deferList]) return false;
  uint item = deferItem[packedPixelItem(uint(deferList), k)];
  ivec2 px = ivec2(item & 0xffffu, item >> 16);
  deferredPixel = px;
  uint id = imageLoad(deferSlots, ivec3(px, 2 * deferSlot)).x;
  if (id == 0u || (id >> 31) != deferClass) return false;
  cell = int(id & 0x7fffffffu) - 1;
  steps = 0;
  deferredHit = uintBitsToFloat(imageLoad(deferSlots, ivec3(px, 2 * deferSlot + 1)).x);
  c = cellAt(cell);
  vec3 rel = cellRelativeToCamera(c);
  o = -vec3(dot(rel, c.axisU.xyz), dot(rel, c.axisV.xyz), dot(rel, c.axisW.xyz));
  vec3 w = rayBase + rayDx * (float(px.x) + 0.5) + rayDy * (float(px.y) + 0.5);
  d = normalize(vec3(dot(w, c.axisU.xyz), dot(w, c.axisV.xyz), dot(w, c.axisW.xyz)));
  return true;
}

// The cast's result onto its frame pixel where it is nearer than what the frame holds there (a
// pixel is in a list once, and the lists are drawn one after the other: no two writes race).
void deferStore(vec4 color, float viewDepth, vec4 normal, uint cellId) {
  ivec2 px = deferredPixel;
  if (!(viewDepth < imageLoad(frameLinear, px).r)) return;
  imageStore(frameColor, px, color);
  imageStore(frameLinear, px, vec4(viewDepth));
  if (wantNormals) imageStore(frameNormal, px, normal);
  if (wantCells) imageStore(frameCell, px, uvec4(cellId));
}
#endif
