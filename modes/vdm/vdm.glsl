// The `vdm` mode's cast (MODES.md §1; modes/vdm/vdm.cpp `lookup` is the same rule on the CPU).
// A ray entering a baked cell through its top face looks its distance up: the hit bits of the 16
// samples around (texel, direction); all miss -> no hit (over holes, O(1)); all hit -> the
// interpolated PCA-compressed distance, verified within +-1.5 texels and refined by false
// position; mixed or failed -> the exact traversal (a fallback, counted). Side entries, cameras
// inside and cells that were not baked go to the exact traversal directly.
#define EXACT_NO_CAST 1
#include "exact.glsl"

layout(std430, binding = 6) readonly buffer VdmEntries { uint vdmEntry[]; };  // block of each cell, ~0u: none
layout(std430, binding = 7) readonly buffer VdmWords { uint vdmWord[]; };

const int kVdmThetas = 8;
const int kVdmPhis = 32;
const float kVdmThetaStep = 87.0 / 7.0 * 3.14159265358979 / 180.0;
const float kVdmPhiStep = 2.0 * 3.14159265358979 / 32.0;

float vdmHalf(uint base, uint i) { return unpackHalf2x16(vdmWord[base + (i >> 1)] >> ((i & 1u) * 16u)).x; }

bool vdmHit(uint hitBase, uint texel, uint dir) {
  return ((vdmWord[hitBase + texel * 8u + (dir >> 5)] >> (dir & 31u)) & 1u) != 0u;
}

// The verify step: a crossing from above to below within the bracket around the prediction
// (distances s from the top-face point p), refined by three false-position steps.
bool vdmVerify(Cell c, vec3 p, vec3 d, float lo, float hi, out float s) {
  s = 0.0;
  vec3 a = p + d * lo, b = p + d * hi;
  float ha = sampleHeight(c, a.xy), hb = sampleHeight(c, b.xy);
  if (ha == kUncovered || hb == kUncovered) return false;
  float ga = a.z - ha, gb = b.z - hb;
  if (!(ga > 0.0 && gb <= 0.0)) return false;
  for (int k = 0; k < 3; ++k) {
    float m = lo + (hi - lo) * ga / (ga - gb);
    vec3 q = p + d * m;
    float hm = sampleHeight(c, q.xy);
    if (hm == kUncovered) return false;
    float gm = q.z - hm;
    if (gm > 0.0) { lo = m; ga = gm; } else { hi = m; gb = gm; }
  }
  s = ga > 0.0 && gb <= 0.0 ? lo + (hi - lo) * ga / (ga - gb) : hi;
  return true;
}

// The lookup from top-face point p (frame, z = wMax) along d over [0, span]: 0 miss, 1 hit at
// distance s, 2 undecided (mixed hit bits or a failed verify: the caller falls back).
int vdmLookup(Cell c, uint blk, vec3 p, vec3 d, float span, out float s) {
  s = 0.0;
  uint rank = vdmWord[blk];
  uint meanOff = blk + vdmWord[blk + 2u], basisOff = blk + vdmWord[blk + 3u];
  uint weightOff = blk + vdmWord[blk + 4u], hitOff = blk + vdmWord[blk + 5u];
  float texel = uintBitsToFloat(vdmWord[blk + 6u]);
  ivec2 size = ivec2(c.boxW.zw);
  // Bilinear over the four texel centres and over the direction grid.
  vec2 f = clamp(texelCoord(c, p.xy), vec2(0.0), vec2(size - 1));
  ivec2 i0 = min(ivec2(f), max(size - 2, ivec2(0)));
  ivec2 i1 = min(i0 + 1, size - 1);
  vec2 a = f - vec2(i0);
  float theta = acos(clamp(-d.z, -1.0, 1.0));
  float phi = atan(d.y, d.x);
  if (phi < 0.0) phi += 2.0 * 3.14159265358979;
  float ft = clamp(theta / kVdmThetaStep, 0.0, float(kVdmThetas - 1));
  int t0 = min(int(ft), kVdmThetas - 2);
  float at = ft - float(t0);
  float fp = phi / kVdmPhiStep;
  int p0 = int(floor(fp)) % kVdmPhis;
  int p1 = (p0 + 1) % kVdmPhis;
  float ap = fp - floor(fp);
  uint tex[4] = uint[4](uint(i0.y * size.x + i0.x), uint(i0.y * size.x + i1.x), uint(i1.y * size.x + i0.x),
                        uint(i1.y * size.x + i1.x));
  float wt[4] = float[4]((1.0 - a.x) * (1.0 - a.y), a.x * (1.0 - a.y), (1.0 - a.x) * a.y, a.x * a.y);
  uint dirs[4] = uint[4](uint(t0 * kVdmPhis + p0), uint(t0 * kVdmPhis + p1), uint((t0 + 1) * kVdmPhis + p0),
                         uint((t0 + 1) * kVdmPhis + p1));
  float wd[4] = float[4]((1.0 - at) * (1.0 - ap), (1.0 - at) * ap, at * (1.0 - ap), at * ap);
  int hits = 0;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) hits += vdmHit(hitOff, tex[i], dirs[j]) ? 1 : 0;
  if (hits == 0) return 0;
  if (hits < 16) return 2;
  // d = sum_b wd_b mean_b + sum_k (sum_a wt_a W_ak) (sum_b wd_b E_kb)
  float dist = 0.0;
  for (int j = 0; j < 4; ++j) dist += wd[j] * vdmHalf(meanOff, dirs[j]);
  for (uint k = 0u; k < rank; ++k) {
    float w = 0.0, e = 0.0;
    for (int i = 0; i < 4; ++i) w += wt[i] * vdmHalf(weightOff, tex[i] * rank + k);
    for (int j = 0; j < 4; ++j) e += wd[j] * vdmHalf(basisOff + k * 128u, dirs[j]);
    dist += w * e;
  }
  float t = dist * texel;
  return vdmVerify(c, p, d, max(0.0, t - 1.5 * texel), min(span, t + 1.5 * texel), s) ? 1 : 2;
}

bool castCell(Cell c, int cell, int boxSteps, vec3 o, vec3 d, float tEnter, float tExit, out float tHit, out uint work) {
  tHit = 0.0;
  uint blk = vdmEntry[cell];
  bool topEntry = blk != 0xffffffffu && d.z < 0.0 && o.z > c.boxW.y && (c.boxW.y - o.z) / d.z >= tEnter * (1.0 - 1e-6);
  if (!topEntry) return exactTrace(c, cell, o, d, tEnter, tExit, tHit, work);
  countEvent(7u);
  work = 4u;
  float s;
  int r = vdmLookup(c, blk, vec3((o + d * tEnter).xy, c.boxW.y), d, tExit - tEnter, s);
  if (r == 0) {
    countEvent(6u);
    work = 1u;
    return false;
  }
  if (r == 1) {
    tHit = tEnter + s;
    return true;
  }
  countEvent(5u);
  uint nodes;
  bool found = exactTrace(c, cell, o, d, tEnter, tExit, tHit, nodes);
  work = 1u + nodes;
  return found;
}

// Self-shadowing (001 §3.2): the light ray toward hit point p enters the box top at q; a lookup
// from q along -l that meets the surface before p (by more than half a texel) is a shadow.
bool shadowRay(Cell c, int cell, vec3 p, vec3 l) {
  if (l.z <= 0.0) return true;  // the light is below the cell's plane
  uint blk = vdmEntry[cell];
  float sTop = (c.boxW.y - p.z) / l.z;
  vec3 q = p + l * sTop;
  bool inside = all(greaterThanEqual(q.xy, c.boxUV.xz)) && all(lessThanEqual(q.xy, c.boxUV.yw));
  if (blk == 0xffffffffu || !inside) return exactShadowRay(c, cell, p, l);
  float texel = uintBitsToFloat(vdmWord[blk + 6u]);
  float s;
  int r = vdmLookup(c, blk, vec3(q.xy, c.boxW.y), -l, sTop, s);
  if (r == 0) return false;
  if (r == 1) return s < sTop - 0.5 * texel;
  return exactShadowRay(c, cell, p, l);
}
