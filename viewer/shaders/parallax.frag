#version 450 core
// Per-pixel ray casting of one cell's height field: Lu, Low & Zheng §3.3. The ray is
// expressed in the cell's frame (M1, §3.2.2), clipped to the box analytically (so a camera
// inside the box still sees it when its back faces are rasterized), marched with the box's
// linear steps, refined by bisection + a final secant step, and kept only if the hit is on a
// covered texel inside the box (the boundary test, §3.3.1); otherwise discarded so boxes
// behind show through. gl_FragDepth comes from the true hit point.
//
// FRONT_FACES (defined by the renderer for boxes the camera is outside of): the fragment is
// on the box's front face and the hit lies behind it, so with reverse-Z the written depth is
// never greater than the rasterized one; declaring that keeps early depth rejection.
#include "heightfield.glsl"
#include "shading.glsl"
#include "clip.glsl"

#ifdef FRONT_FACES
layout(depth_less) out float gl_FragDepth;
#endif

in vec3 vFrame;
flat in int vCell;
flat in int vSteps;
flat in vec3 vCamFrame;

uniform int refineSteps;
uniform float nearPlane;
uniform vec3 viewForward;   // world forward axis of the camera
uniform bool useColor;
uniform vec3 baseColor;

layout(location = 0) out vec4 outColor;
layout(location = 1) out float outDepth;  // linear view depth along the forward axis
layout(location = 2) out vec4 outNormal;  // world-space shading normal (eval)

void main() {
  Cell c = cells[vCell];
  vec3 o = vCamFrame;
  vec3 d = normalize(vFrame - vCamFrame);
  // Slab clip against the box [uMin,uMax] x [vMin,vMax] x [wMin,wMax].
  vec3 bmin = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x);
  vec3 bmax = vec3(c.boxUV.y, c.boxUV.w, c.boxW.y);
  vec3 inv = 1.0 / d;
  vec3 t0 = (bmin - o) * inv, t1 = (bmax - o) * inv;
  vec3 tn = min(t0, t1), tf = max(t0, t1);
  float tEnter = max(max(max(tn.x, tn.y), tn.z), 0.0);
  float tExit = min(min(tf.x, tf.y), tf.z);
  if (tEnter >= tExit) discard;

  // Linear search: the first sample below the surface after one above it. A ray that
  // starts below the surface sees the sheet from behind: the surface is one-sided.
  int iterations = max(vSteps, 1);
  float dt = (tExit - tEnter) / float(iterations);
  float tPrev = tEnter;
  vec3 p = o + d * tEnter;
  float gPrev = p.z - sampleHeight(c, p.xy);  // > 0: above the surface
  float tHit = -1.0;
  float tLo = 0.0, tHi = 0.0, gLo = 0.0, gHi = 0.0;
  for (int i = 1; i <= iterations; ++i) {
    float t = tEnter + dt * float(i);
    p = o + d * t;
    float g = p.z - sampleHeight(c, p.xy);
    if (gPrev > 0.0 && g <= 0.0 && g > -1e29) {
      tLo = tPrev; gLo = gPrev; tHi = t; gHi = g;
      tHit = t;
      break;
    }
    tPrev = t;
    gPrev = g;
  }
  if (tHit < 0.0) discard;
  // Refinement: bisection keeps the bracket, a last secant step lands on the surface.
  for (int i = 0; i < refineSteps; ++i) {
    float tm = 0.5 * (tLo + tHi);
    vec3 pm = o + d * tm;
    float gm = pm.z - sampleHeight(c, pm.xy);
    if (gm > 0.0 || gm < -1e29) { tLo = tm; gLo = gm > 0.0 ? gm : gLo; } else { tHi = tm; gHi = gm; }
  }
  float tS = (gLo > 0.0 && gHi <= 0.0) ? mix(tLo, tHi, gLo / (gLo - gHi)) : tHi;
  vec3 hit = o + d * tS;
  // Boundary test (§3.3.1): inside the box and on a covered texel.
  if (any(lessThan(hit, bmin - 1e-6 * (bmax - bmin))) || any(greaterThan(hit, bmax + 1e-6 * (bmax - bmin))))
    discard;
  float hh = sampleHeight(c, hit.xy);
  if (hh == kUncovered) discard;

  // Normal from the height gradient (central differences, one texel).
  vec2 texel = (c.boxUV.yw - c.boxUV.xz) / c.boxW.zw;
  float hx0 = sampleHeight(c, hit.xy - vec2(texel.x, 0.0)), hx1 = sampleHeight(c, hit.xy + vec2(texel.x, 0.0));
  float hy0 = sampleHeight(c, hit.xy - vec2(0.0, texel.y)), hy1 = sampleHeight(c, hit.xy + vec2(0.0, texel.y));
  float ddu = (hx0 == kUncovered || hx1 == kUncovered) ? 0.0 : (hx1 - hx0) / (2.0 * texel.x);
  float ddv = (hy0 == kUncovered || hy1 == kUncovered) ? 0.0 : (hy1 - hy0) / (2.0 * texel.y);
  vec3 nFrame = normalize(vec3(-ddu, -ddv, 1.0));
  vec3 nWorld = c.axisU.xyz * nFrame.x + c.axisV.xyz * nFrame.y + c.axisW.xyz * nFrame.z;

  // Camera-relative world position of the hit, then its depth.
  vec3 rel = cellRelativeToCamera(c);
  vec3 world = rel + c.axisU.xyz * hit.x + c.axisV.xyz * hit.y + c.axisW.xyz * hit.z;
  float viewDepth = dot(world, viewForward);
  if (viewDepth <= nearPlane || isClipped(world)) discard;
  gl_FragDepth = nearPlane / viewDepth;  // reverse-Z, matches `projection`

  vec3 albedo = useColor ? sampleColor(c, hit.xy) : baseColor;
  outColor = vec4(shade(albedo, nWorld, world), 1.0);
  outDepth = viewDepth;
  outNormal = vec4(normalize(nWorld), 0.0);
}
