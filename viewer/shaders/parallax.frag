#version 450 core
// Per-pixel ray casting of one cell's height field: Lu, Low & Zheng §3.3. The ray is
// expressed in the cell's frame (M1, §3.2.2), clipped to the box analytically (so a camera
// inside the box still sees it when its back faces are rasterized), cast by the mode's
// castCell (the renderer includes the mode's unit where `#include <mode>` stands: the linear
// search of parallax_cast.glsl, the max-mipmap traversal of modes/exact/exact.glsl), and kept
// only if the hit is on a covered texel inside the box (the boundary test, §3.3.1); otherwise
// discarded so boxes behind show through. gl_FragDepth comes from the true hit point.
//
// FRONT_FACES (defined by the renderer for boxes the camera is outside of): the fragment is
// on the box's front face and the hit lies behind it, so with reverse-Z the written depth is
// never greater than the rasterized one; declaring that keeps early depth rejection.
#include "heightfield.glsl"
#include "shading.glsl"
#include "clip.glsl"
// Work counters, read back when asked (bench --json, eval, the panel, tests): [0] rays cast,
// [1] work summed (march samples or pyramid nodes), [2] the most one ray took, [3] rays stopped
// by the mode's cap, [4] hits, [5] vdm fallbacks, [6] vdm fast misses, [7] vdm top-face lookups,
// [8 + k] rays that took k (k >= 255 in the last).
layout(std430, binding = 5) buffer Counters { uint counters[]; };
uniform bool countWork;
uniform uint workCap;

void count(uint work, bool hit) {
  if (!countWork) return;
  atomicAdd(counters[0], 1u);
  atomicAdd(counters[1], work);
  atomicMax(counters[2], work);
  if (work > workCap) atomicAdd(counters[3], 1u);
  if (hit) atomicAdd(counters[4], 1u);
  atomicAdd(counters[8u + min(work, 255u)], 1u);
}

// A deferred ray's second pass (grooves_defer.glsl): the first counted the ray and its march.
void countMore(uint work, bool hit) {
  if (!countWork) return;
  atomicAdd(counters[1], work);
  if (hit) atomicAdd(counters[4], 1u);
}

void countEvent(uint k) {
  if (countWork) atomicAdd(counters[k], 1u);
}

// A mode whose surface is not the height field (gdm's surfels) sets the hit's normal here (frame).
vec3 castNormal = vec3(0.0, 0.0, 1.0);
bool castHasNormal = false;

uniform bool useColor;
uniform vec3 baseColor;
uniform bool wantNormals;  // the normal target is drawn (read back): set where a mode's footprint colour skips the normal

// The hit's shading normal (world): the mode's own, the stored normals, or the height field's gradient.
vec3 hitNormal(Cell c, vec3 hit) {
  if (castHasNormal) return c.axisU.xyz * castNormal.x + c.axisV.xyz * castNormal.y + c.axisW.xyz * castNormal.z;
  if (storedNormals) return sampleNormal(c, hit.xy);
  vec3 nFrame = gradientNormal(c, hit.xy);
  return c.axisU.xyz * nFrame.x + c.axisV.xyz * nFrame.y + c.axisW.xyz * nFrame.z;
}

#include <mode>

#ifdef FRONT_FACES
layout(depth_less) out float gl_FragDepth;
#endif

#ifndef PIXEL_RAYS
in vec3 vFrame;
flat in int vCell;
flat in int vSteps;
flat in vec3 vCamFrame;
#endif

uniform float nearPlane;
uniform bool shadows;       // self-shadowing: a second cast toward lightDir (shadowRay, the mode's unit)
uniform vec3 viewForward;   // world forward axis of the camera

#ifndef PIXEL_RAYS
layout(location = 0) out vec4 outColor;
layout(location = 1) out float outDepth;  // linear view depth along the forward axis
layout(location = 2) out vec4 outNormal;  // world-space shading normal (eval)
layout(location = 3) out uint outCell;    // the cell's index + 1 (eval, tests: which cell drew a pixel)
#endif

void main() {
#ifdef PIXEL_RAYS
  // A deferred pixel (grooves_defer.glsl): the cell its slot holds, along the pixel's ray.
  int cell, steps;
  Cell c;
  vec3 o, d;
  if (!deferredRay(cell, c, steps, o, d)) discard;
#else
  int cell = vCell, steps = vSteps;
  vec3 o = vCamFrame;
  vec3 d = normalize(vFrame - vCamFrame);
  Cell c = cells[cell];
#endif
  // Slab clip against the box [uMin,uMax] x [vMin,vMax] x [wMin,wMax].
  vec3 bmin = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x);
  vec3 bmax = vec3(c.boxUV.y, c.boxUV.w, c.boxW.y);
#ifdef MODE_EXTENDS_BOX
  modeExtendBox(cell, bmin, bmax);  // a mode whose surface reaches past the height field's box (grooves)
#endif
  vec3 inv = 1.0 / d;
  vec3 t0 = (bmin - o) * inv, t1 = (bmax - o) * inv;
  vec3 tn = min(t0, t1), tf = max(t0, t1);
  float tEnter = max(max(max(tn.x, tn.y), tn.z), 0.0);
  float tExit = min(min(tf.x, tf.y), tf.z);
  if (tEnter >= tExit) discard;

  float tS;
  uint work;
  bool found = castCell(c, cell, steps, o, d, tEnter, tExit, tS, work);
#ifdef PIXEL_RAYS
  countMore(work, found);
#else
  count(work, found);
#endif
  if (!found) discard;
  vec3 hit = o + d * tS;
  // Boundary test (§3.3.1): inside the box (castCell answers only on covered texels).
  if (any(lessThan(hit, bmin - 1e-6 * (bmax - bmin))) || any(greaterThan(hit, bmax + 1e-6 * (bmax - bmin))))
    discard;

  // Camera-relative world position of the hit, then its depth.
  vec3 rel = cellRelativeToCamera(c);
  vec3 world = rel + c.axisU.xyz * hit.x + c.axisV.xyz * hit.y + c.axisW.xyz * hit.z;
  float viewDepth = dot(world, viewForward);
  if (viewDepth <= nearPlane || isClipped(world)) discard;
#ifndef PIXEL_RAYS
  gl_FragDepth = nearPlane / viewDepth;  // reverse-Z, matches `projection`
#endif

  vec3 albedo = useColor ? sampleColor(c, hit.xy) : baseColor;
#ifdef SHADOWS
  if (shadows) inShadow = shadowRay(c, cell, hit, normalize(toFrame(c, lightDir)));
#endif
  // A mode may draw the pixel's colour over its footprint (grooves narrower than ~2 pixels): the
  // hit's own normal is then needed only for the normal target.
  vec3 color = vec3(0.0);
  bool footprint = false;
#ifdef MODE_FOOTPRINT
  footprint = modeFootprintColor(c, cell, o, d, tS, albedo, world, color);
#endif
  vec3 nWorld = vec3(0.0, 0.0, 1.0);
  if (!footprint || wantNormals) nWorld = hitNormal(c, hit);
  if (!footprint) color = shade(albedo, nWorld, world);
#ifdef PIXEL_RAYS
  // A deferred pixel: onto the frame's targets where the frame's depth test would keep it.
  deferStore(vec4(color, 1.0), viewDepth, vec4(normalize(nWorld), inShadow ? 1.0 : 0.0), uint(cell) + 1u);
#else
  outColor = vec4(color, 1.0);
  outDepth = viewDepth;
  outNormal = vec4(normalize(nWorld), inShadow ? 1.0 : 0.0);
  outCell = uint(cell) + 1u;
#endif
}
