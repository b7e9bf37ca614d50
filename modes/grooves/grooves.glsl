// The `grooves` mode's cast (modes/grooves/groove_cast.cpp castGrooved is the same rule in
// double): grooves carved into the height field as path-based surface detail (seed 003 §3-5;
// Bosch & Patow's real-time form: per tile a grid of path-segment lists). The surface is
// min(h, floor_1 .. floor_n): floor_i is piece i's rim plane less its profile depth D(r) at the
// distance r from its segment, inside its capsule (r < half width; rounded ends, joints and
// crossings are the union of the grooves' air). From the box entry, the ray advances through the
// air of whatever piece it is in (to the piece's floor, or out of its capsule), the height field
// is marched (parallax_cast.glsl) where the ray is above it, until neither moves it: the hit's
// depth is exact to the profile (gl_FragDepth, so a pick measures a crack's depth) and a floor
// hit shades with its facet's normal. Masking is the cast itself; shadows are the same cast
// toward the light (003 eqs. 3-4 resolve the same order analytically). A groove narrower than
// two pixels is anti-aliased over the pixel's footprint (003 eq. 6's area ratios, here
// integrated by grooveSamples rays across the groove, each cast through the grooves' profiles
// on the rim plane). Cells without grooves cast their height field alone.
#define castCell parallaxCastCell
#define shadowRay parallaxShadowRay
#include "parallax_cast.glsl"
#undef castCell
#undef shadowRay

#define MODE_POST_SHADE 1
#define MODE_EXTENDS_BOX 1

layout(std430, binding = 6) readonly buffer GrooveEntries { uint grooveEntry[]; };  // block of each cell, ~0u: none
layout(std430, binding = 7) readonly buffer GrooveWords { uint grooveWord[]; };    // profiles, then the blocks

uniform bool grooveAA;       // anti-alias grooves under two pixels wide
uniform int grooveSamples;   // rays across such a groove per pixel
uniform float pixelAngle;    // radians per pixel
uniform vec3 camRight;       // world
uniform vec3 camUp;

const uint kNoGrooves = 0xffffffffu;

struct GPiece {
  vec2 a, e;      // start, unit direction (frame u, v)
  float len, hw;  // length, half width
  vec3 rim;       // w = rim.x + rim.y s + rim.z x
  uint prof;      // first word of its profile (9 depths)
};

float gWordF(uint w) { return uintBitsToFloat(grooveWord[w]); }

GPiece gPiece(uint blk, uint i) {
  uint w = blk + grooveWord[blk + 3u] + i * 12u;
  GPiece p;
  p.a = vec2(gWordF(w), gWordF(w + 1u));
  p.e = vec2(gWordF(w + 2u), gWordF(w + 3u));
  p.len = gWordF(w + 4u);
  p.hw = gWordF(w + 5u);
  p.rim = vec3(gWordF(w + 6u), gWordF(w + 7u), gWordF(w + 8u));
  p.prof = grooveWord[w + 9u];
  return p;
}

// Distance from q to the piece's segment; s, x: along and across.
float gDist(GPiece p, vec2 q, out float s, out float x) {
  vec2 r = q - p.a;
  s = dot(r, p.e);
  x = dot(r, vec2(-p.e.y, p.e.x));
  return length(r - p.e * clamp(s, 0.0, p.len));
}

float gDepth(uint prof, float r, float hw, out float slope) {
  slope = 0.0;
  if (!(r < hw)) return 0.0;
  float f = max(r, 0.0) / hw * 8.0;
  int k = min(int(f), 7);
  float d0 = gWordF(prof + uint(k)), d1 = gWordF(prof + uint(k) + 1u);
  slope = (d1 - d0) * 8.0 / hw;
  return mix(d0, d1, f - float(k));
}

float gFloor(GPiece p, vec2 q) {
  float s, x, sl;
  float r = gDist(p, q, s, x);
  return p.rim.x + p.rim.y * s + p.rim.z * x - gDepth(p.prof, r, p.hw, sl);
}

// The facet normal (frame) of the floor at q.
vec3 gNormal(GPiece p, vec2 q) {
  float s, x, sl;
  float r = gDist(p, q, s, x);
  float D = gDepth(p.prof, r, p.hw, sl);
  vec2 g = p.e * p.rim.y + vec2(-p.e.y, p.e.x) * p.rim.z;
  if (r > 0.0 && D > 0.0) g -= sl * (q - (p.a + p.e * clamp(s, 0.0, p.len))) / r;
  return normalize(vec3(-g, 1.0));
}

// Where the 2-D line q + t dq (inside the capsule at t = 0) leaves it.
float gCapsuleExit(GPiece p, vec2 q, vec2 dq) {
  float ex = -1e30;
  vec2 n = vec2(-p.e.y, p.e.x);
  vec2 r = q - p.a;
  vec2 v0 = vec2(dot(r, p.e), dot(r, n)), vd = vec2(dot(dq, p.e), dot(dq, n));
  vec2 lo = vec2(0.0, -p.hw), hi = vec2(p.len, p.hw);
  float tin = -1e30, tout = 1e30;
  for (int k = 0; k < 2; ++k) {
    if (abs(vd[k]) < 1e-30) {
      if (v0[k] < lo[k] || v0[k] > hi[k]) { tin = 1e30; tout = -1e30; }
      continue;
    }
    float ta = (lo[k] - v0[k]) / vd[k], tb = (hi[k] - v0[k]) / vd[k];
    tin = max(tin, min(ta, tb));
    tout = min(tout, max(ta, tb));
  }
  if (tin < tout) ex = max(ex, tout);
  for (int k = 0; k < 2; ++k) {
    vec2 c = k == 0 ? p.a : p.a + p.e * p.len;
    vec2 rc = q - c;
    float A = dot(dq, dq), B = dot(rc, dq), C = dot(rc, rc) - p.hw * p.hw;
    if (A < 1e-30) {
      if (C < 0.0) ex = 1e30;
      continue;
    }
    float disc = B * B - A * C;
    if (disc > 0.0) ex = max(ex, (-B + sqrt(disc)) / A);
  }
  return max(ex, 0.0);
}

// The ray inside piece p's air at t: where it meets the floor (a point on or under it), or just
// past the capsule's edge, at most t1.
float gAirExit(GPiece p, vec3 o, vec3 d, float t, float t1) {
  vec3 q0 = o + d * t;
  float te = t + gCapsuleExit(p, q0.xy, d.xy);
  float tEnd = min(te, t1);
  float ta = t, fa = q0.z - gFloor(p, q0.xy);
  for (int i = 1; i <= 16; ++i) {
    float tb = t + (tEnd - t) * float(i) / 16.0;
    vec3 qb = o + d * tb;
    float fb = qb.z - gFloor(p, qb.xy);
    if (fb <= 0.0) {
      for (int k = 0; k < 14; ++k) {
        float tm = 0.5 * (ta + tb);
        vec3 qm = o + d * tm;
        float fm = qm.z - gFloor(p, qm.xy);
        if (fm > 0.0) { ta = tm; fa = fm; } else { tb = tm; fb = fm; }
      }
      float ts = fa > fb ? ta + (tb - ta) * fa / (fa - fb) : tb;
      vec3 qs = o + d * ts;
      return qs.z - gFloor(p, qs.xy) <= 0.0 ? ts : tb;
    }
    ta = tb;
    fa = fb;
  }
  return te < t1 ? te + 1e-6 * p.hw + 1e-7 * abs(te) : t1;
}

int gBin(Cell c, uint blk, vec2 q) {
  int G = int(grooveWord[blk]);
  vec2 f = (q - c.boxUV.xz) / (c.boxUV.yw - c.boxUV.xz) * float(G);
  ivec2 b = clamp(ivec2(floor(f)), ivec2(0), ivec2(G - 1));
  return b.y * G + b.x;
}

// The first piece in whose air frame point q lies, -1 when none.
int gAirPiece(Cell c, uint blk, vec3 q) {
  int b = gBin(c, blk, q.xy);
  uint start = grooveWord[blk + 5u + 2u * uint(b)], n = grooveWord[blk + 6u + 2u * uint(b)];
  uint list = blk + grooveWord[blk + 2u] + start;
  for (uint k = 0u; k < n; ++k) {
    uint i = grooveWord[list + k];
    GPiece p = gPiece(blk, i);
    float s, x;
    if (gDist(p, q.xy, s, x) >= p.hw) continue;
    if (q.z > gFloor(p, q.xy)) return int(i);
  }
  return -1;
}

// The grooves cut below the height field's box: the cast runs down to the lowest floor.
void modeExtendBox(int cell, inout vec3 bmin, inout vec3 bmax) {
  uint blk = grooveEntry[cell];
  if (blk != kNoGrooves) bmin.z = min(bmin.z, gWordF(blk + 4u));
}

bool castCell(Cell c, int cell, int boxSteps, vec3 o, vec3 d, float tEnter, float tExit, out float tHit, out uint work) {
  uint blk = grooveEntry[cell];
  if (blk == kNoGrooves) return parallaxCastCell(c, cell, boxSteps, o, d, tEnter, tExit, tHit, work);
  vec2 texel = (c.boxUV.yw - c.boxUV.xz) / c.boxW.zw;
  float eps = 1e-3 * min(texel.x, texel.y);
  float t = tEnter;
  int last = -2;  // -1: arrived by the height field's cast; >= 0: by leaving that piece's air
  work = 0u;
  for (int it = 0; it < 32; ++it) {
    vec3 q = o + d * t;
    int pi = gAirPiece(c, blk, q);
    work += 1u;
    if (pi >= 0) {
      t = gAirExit(gPiece(blk, uint(pi)), o, d, t, tExit);
      if (t >= tExit) return false;
      last = pi;
      continue;
    }
    if (last == -1) break;
    if (last >= 0) {
      float h = sampleHeight(c, q.xy);
      if (h != kUncovered && q.z <= h + eps) break;
    }
    float th;
    uint w;
    bool hit = parallaxCastCell(c, cell, boxSteps, o, d, t, tExit, th, w);
    work += w;
    if (!hit) return false;
    t = th;
    last = -1;
  }
  tHit = t;
  if (last >= 0) {
    GPiece p = gPiece(blk, uint(last));
    vec3 q = o + d * t;
    float s, x;
    if (gDist(p, q.xy, s, x) < p.hw) {
      castNormal = gNormal(p, q.xy);
      castHasNormal = true;
    }
  }
  return true;
}

// Self-shadowing: the same carved cast from just above the hit toward the light (a crack's floor
// is shadowed by its walls).
bool shadowRay(Cell c, int cell, vec3 p, vec3 l) {
  if (l.z <= 0.0) return true;
  vec3 o;
  float tExit = shadowRayExit(c, p, l, o);
  if (tExit <= 0.0) return false;
  bool hasN = castHasNormal;
  vec3 n = castNormal;
  float t;
  uint work;
  bool r = castCell(c, cell, 0, o, l, 0.0, tExit, t, work);
  castHasNormal = hasN;
  castNormal = n;
  return r;
}

// One ray of the footprint: from the rim plane of piece p (where it meets it) through the
// grooves' air to a floor; shaded there, or as the surface where it is in no groove.
vec3 gFootprintSample(Cell c, uint blk, GPiece p, vec3 o, vec3 dk, vec3 rel, float t1) {
  vec2 n = vec2(-p.e.y, p.e.x);
  // The rim plane: z - rim.y (q - a).e - rim.z (q - a).n = rim.x.
  vec3 N = vec3(-p.rim.y * p.e - p.rim.z * n, 1.0);
  float off = p.rim.x - p.rim.y * dot(p.a, p.e) - p.rim.z * dot(p.a, n);
  float den = dot(N, dk);
  if (abs(den) < 1e-12) return vec3(-1.0);
  float t = (off - dot(N, o)) / den;
  if (t <= 0.0) return vec3(-1.0);
  int last = -1;
  for (int it = 0; it < 8; ++it) {
    int pi = gAirPiece(c, blk, o + dk * t);
    if (pi < 0) break;
    t = gAirExit(gPiece(blk, uint(pi)), o, dk, t, t + t1);
    last = pi;
  }
  vec3 q = o + dk * t;
  vec3 nWorld;
  float s, x;
  GPiece lp;
  if (last >= 0) lp = gPiece(blk, uint(last));
  if (last >= 0 && gDist(lp, q.xy, s, x) < lp.hw) {
    vec3 nf = gNormal(lp, q.xy);
    nWorld = c.axisU.xyz * nf.x + c.axisV.xyz * nf.y + c.axisW.xyz * nf.z;
  } else if (storedNormals) {
    nWorld = sampleNormal(c, q.xy);
  } else {
    vec3 nf = gradientNormal(c, q.xy);
    nWorld = c.axisU.xyz * nf.x + c.axisV.xyz * nf.y + c.axisW.xyz * nf.z;
  }
  vec3 world = rel + c.axisU.xyz * q.x + c.axisV.xyz * q.y + c.axisW.xyz * q.z;
  vec3 albedo = useColor ? sampleColor(c, q.xy) : baseColor;
  return shade(albedo, nWorld, world);
}

// Anti-aliasing of grooves narrower than two pixels (003 eq. 6): the narrow piece nearest the
// hit whose capsule the pixel's footprint reaches; grooveSamples rays spread across it over the
// pixel (weights: the pixel square's chord lengths across the groove's screen direction), each
// shaded where it lands; their weighted mean is the pixel's colour.
vec3 modePostShade(Cell c, int cell, vec3 o, vec3 d, float tS, vec3 color) {
  uint blk = grooveEntry[cell];
  if (!grooveAA || blk == kNoGrooves) return color;
  vec3 hit = o + d * tS;
  float foot = tS * pixelAngle;  // a pixel across the ray at the hit
  float reach = 1.5 * foot / max(abs(d.z), 0.2);
  int G = int(grooveWord[blk]);
  vec2 span = (c.boxUV.yw - c.boxUV.xz) / float(G);
  int best = -1;
  float bestGap = 1e30;
  ivec2 b0 = clamp(ivec2(floor((hit.xy - reach - c.boxUV.xz) / span)), ivec2(0), ivec2(G - 1));
  ivec2 b1 = clamp(ivec2(floor((hit.xy + reach - c.boxUV.xz) / span)), ivec2(0), ivec2(G - 1));
  b1 = min(b1, b0 + 2);
  for (int by = b0.y; by <= b1.y; ++by)
    for (int bx = b0.x; bx <= b1.x; ++bx) {
      uint b = uint(by * G + bx);
      uint start = grooveWord[blk + 5u + 2u * b], n = grooveWord[blk + 6u + 2u * b];
      uint list = blk + grooveWord[blk + 2u] + start;
      for (uint k = 0u; k < n; ++k) {
        uint i = grooveWord[list + k];
        GPiece p = gPiece(blk, i);
        float s, x;
        float gap = gDist(p, hit.xy, s, x) - p.hw;
        vec3 a3 = vec3(-p.e.y, p.e.x, p.rim.z);
        float wpx = 2.0 * p.hw * length(a3 - d * dot(a3, d)) / foot;
        if (wpx < 2.0 && gap < reach && gap < bestGap) {
          best = int(i);
          bestGap = gap;
        }
      }
    }
  if (best < 0) return color;
  GPiece p = gPiece(blk, uint(best));
  vec3 R = toFrame(c, camRight), U = toFrame(c, camUp);
  vec3 e3 = vec3(p.e, p.rim.y);
  vec2 g2 = vec2(dot(e3, R), dot(e3, U));
  if (dot(g2, g2) < 1e-12) return color;
  g2 = normalize(g2);
  vec2 q2 = vec2(-g2.y, g2.x);
  float hi = 0.5 * (abs(q2.x) + abs(q2.y)), lo = 0.5 * abs(abs(q2.x) - abs(q2.y));
  vec3 qf = R * q2.x + U * q2.y;
  vec3 rel = cellRelativeToCamera(c);
  float t1 = 16.0 * p.hw / max(abs(d.z), 0.02);
  vec3 sum = vec3(0.0);
  float wsum = 0.0;
  int n = clamp(grooveSamples, 1, 64);
  for (int k = 0; k < n; ++k) {
    float sg = (-1.0 + (2.0 * float(k) + 1.0) / float(n)) * hi;
    float wt = abs(sg) <= lo ? 1.0 : (hi - abs(sg)) / max(hi - lo, 1e-6);
    vec3 col = gFootprintSample(c, blk, p, o, normalize(d + qf * (sg * pixelAngle)), rel, t1);
    if (col.x < 0.0) continue;
    sum += wt * col;
    wsum += wt;
  }
  return wsum > 0.0 ? sum / wsum : color;
}
