// The `grooves` mode's cast (modes/grooves/groove_cast.cpp castGrooved is the same rule in
// double): grooves carved into the height field as path-based surface detail (seed 003 §3-5;
// Bosch & Patow's real-time form: per tile a grid of path-segment lists). Inside a groove's
// capsule (r < half width, r the distance to one of its pieces' segments: rounded ends, joints
// and crossings are the union of the grooves) the surface is the lowest floor there, floor_i =
// rim_i - D_i(r), the rim a parabola across the groove fitted to the height field just outside
// its lips and D the profile;
// elsewhere the height field. The height field is marched (parallax_cast.glsl), floors above it
// are caught before its hit, and from there the ray advances through the air of whatever piece
// it is in (to the piece's floor, or out of its capsule) until it is solid: the hit's
// depth is exact to the profile (gl_FragDepth, so a pick measures a crack's depth) and a floor
// hit shades with its facet's normal. Masking is the cast itself; shadows are the same cast
// toward the light (003 eqs. 3-4 resolve the same order analytically). A groove narrower than
// two pixels is anti-aliased over the pixel's footprint (003 eq. 6's area ratios, here
// integrated by grooveSamples rays across the groove, each cast through the grooves' profiles
// on the rim plane). Cells without grooves cast their height field alone.
// The renderer draws it in two passes (grooves_defer.glsl): the height field's march everywhere
// (GROOVES_DEFER), this cast only where it can differ.
#define PARALLAX_NO_CAST 1
#include "parallax_cast.glsl"

// The section's words as buffer textures, not storage buffers: llvmpipe reads a storage buffer at
// a per-pixel offset lane by lane, a buffer texture as one gather (the carved cast makes some 100
// reads a pixel; 1.30 -> 1.20 of parallax's frame 4x closer to the 1000-groove wall).
layout(binding = 9) uniform usamplerBuffer grooveEntries;  // block of each cell, ~0u: none
layout(binding = 10) uniform usamplerBuffer grooveWords;   // profiles, then the blocks
#define grooveEntry(i) texelFetch(grooveEntries, int(i)).r
#define grooveWord(i) texelFetch(grooveWords, int(i)).r
#include "grooves_defer.glsl"

uniform bool grooveAA;       // anti-alias grooves under two pixels wide
uniform int grooveSamples;   // rays across such a groove per pixel
uniform float pixelAngle;    // radians per pixel
uniform vec3 camRight;       // world
uniform vec3 camUp;

const uint kNoGrooves = 0xffffffffu;

struct GPiece {
  vec2 a, e;      // start, unit direction (frame u, v)
  float len, hw;  // length, half width
  vec3 rim0, rim1; // the rim across at the start and the end: q0 + q1 x + q2 x^2 (x across the line)
  float lip;      // the capsule's radius (half a width, a texel; for points two sample spacings more)
  uint prof;      // first word of its profile (9 depths)
};

float gWordF(uint w) { return uintBitsToFloat(grooveWord(w)); }

// How far from a hit at tS a groove's half width may lie and still be in the pixel's footprint
// (modeFootprintColor): its samples reach 0.71 pixel from the centre, on the surface that over the
// incidence's cosine (taken at least 0.1).
float gFootprintReach(float tS, vec3 d) { return 0.75 * tS * pixelAngle / max(abs(d.z), 0.1); }

GPiece gPiece(uint blk, uint i) {
  uint w = blk + grooveWord(blk + 3u) + i * 14u;
  GPiece p;
  p.a = vec2(gWordF(w), gWordF(w + 1u));
  p.e = vec2(gWordF(w + 2u), gWordF(w + 3u));
  p.len = gWordF(w + 4u);
  p.hw = gWordF(w + 5u);
  p.rim0 = vec3(gWordF(w + 6u), gWordF(w + 7u), gWordF(w + 8u));
  p.rim1 = vec3(gWordF(w + 9u), gWordF(w + 10u), gWordF(w + 11u));
  p.prof = grooveWord(w + 12u);
  p.lip = gWordF(w + 13u);
  return p;
}

// Distance from q to the piece's segment; s, x: along and across.
float gDist(GPiece p, vec2 q, out float s, out float x) {
  vec2 r = q - p.a;
  s = dot(r, p.e);
  x = dot(r, vec2(-p.e.y, p.e.x));
  return length(r - p.e * clamp(s, 0.0, p.len));
}

float gDepth(uint prof, float r, float hw) {
  if (!(r < hw)) return 0.0;
  float f = max(r, 0.0) / hw * 8.0;
  int k = min(int(f), 7);
  return mix(gWordF(prof + uint(k)), gWordF(prof + uint(k) + 1u), f - float(k));
}

// A profile's 9 depths held in registers: the narrow grooves' landings (gFootprintLand) walk them
// knot by knot for every ray of a footprint, and llvmpipe reads a buffer lane by lane.
struct GProf {
  vec4 lo, hi;  // depths 0-3, 4-7
  float last;   // depth 8 (at the half width)
};

GProf gLoadProf(uint prof) {
  GProf P;
  P.lo = vec4(gWordF(prof), gWordF(prof + 1u), gWordF(prof + 2u), gWordF(prof + 3u));
  P.hi = vec4(gWordF(prof + 4u), gWordF(prof + 5u), gWordF(prof + 6u), gWordF(prof + 7u));
  P.last = gWordF(prof + 8u);
  return P;
}

// Depth j (0-8).
float gKnot(GProf P, int j) {
  vec4 q = j < 4 ? P.lo : P.hi;
  int i = j & 3;
  float v = i == 0 ? q.x : i == 1 ? q.y : i == 2 ? q.z : q.w;
  return j >= 8 ? P.last : v;
}

// gDepth and gSmoothSlope on a loaded profile.
float gProfDepth(GProf P, float r, float hw) {
  if (!(r < hw)) return 0.0;
  float f = max(r, 0.0) / hw * 8.0;
  int k = min(int(f), 7);
  return mix(gKnot(P, k), gKnot(P, k + 1), f - float(k));
}

float gProfSmoothSlope(GProf P, float r, float hw) {
  if (!(r < hw)) return 0.0;
  float f = max(r, 0.0) / hw * 8.0 - 0.5;
  int k = clamp(int(floor(f)), 0, 6);
  float d0 = gKnot(P, k), d1 = gKnot(P, k + 1), d2 = gKnot(P, k + 2);
  return mix(d1 - d0, d2 - d1, clamp(f - float(k), 0.0, 1.0)) * 8.0 / hw;
}

// The rim at the point (s, x) of the piece's frame (groove_cast.cpp pieceRim): across, the
// parabola fitted outside the lips (x clamped to them); along, its coefficients linear between
// the ends and on past them; grad: its gradient (shading).
float gRim(GPiece p, float s, float x, out vec2 grad) {
  float fs = p.len > 0.0 ? s / p.len : 0.0;
  float xc = clamp(x, -p.lip, p.lip);
  vec3 b = vec3(1.0, xc, xc * xc);
  vec3 k = mix(p.rim0, p.rim1, fs);
  grad = abs(x) < p.lip ? vec2(-p.e.y, p.e.x) * (k.y + 2.0 * k.z * xc) : vec2(0.0);
  if (p.len > 0.0) grad += p.e * (dot(p.rim1, b) - dot(p.rim0, b)) / p.len;
  return dot(k, b);
}

// The profile's slope for shading at r (groove_cast.cpp smoothSlope): linear between its facets'
// centres.
float gSmoothSlope(uint prof, float r, float hw) {
  if (!(r < hw)) return 0.0;
  float f = max(r, 0.0) / hw * 8.0 - 0.5;
  int k = clamp(int(floor(f)), 0, 6);
  float s0 = (gWordF(prof + uint(k) + 1u) - gWordF(prof + uint(k))) * 8.0 / hw;
  float s1 = (gWordF(prof + uint(k) + 2u) - gWordF(prof + uint(k) + 1u)) * 8.0 / hw;
  return mix(s0, s1, clamp(f - float(k), 0.0, 1.0));
}

// rim - D(r); past the half width (D = 0) out to the lip the rim, which replaces the data's
// blurred crack there and meets the height field at the capsule's edge to first order.
float gFloor(Cell c, GPiece p, vec2 q) {
  float s, x;
  vec2 gr;
  float r = gDist(p, q, s, x);
  float rim = gRim(p, s, x, gr);
  return rim - gDepth(p.prof, r, p.hw);
}

// The same on the piece's profile loaded (the loops over one piece's floor).
float gFloorP(GPiece p, GProf P, vec2 q) {
  float s, x;
  vec2 gr;
  float r = gDist(p, q, s, x);
  return gRim(p, s, x, gr) - gProfDepth(P, r, p.hw);
}

// The floor's shading normal (frame) at q, smooth across the profile's facets; the rim's past the
// half width (the height field's normals there are those of the data's blurred crack).
vec3 gNormal(GPiece p, vec2 q) {
  float s, x;
  vec2 g;
  float r = gDist(p, q, s, x);
  gRim(p, s, x, g);
  if (r > 0.0 && r < p.hw) g -= gSmoothSlope(p.prof, r, p.hw) * (q - (p.a + p.e * clamp(s, 0.0, p.len))) / r;
  return normalize(vec3(-g, 1.0));
}

// Where the 2-D line q + t dq meets piece p's capsule (out to the lips): [entry, exit], entry >=
// exit when it misses.
vec2 gCapsuleSpan(GPiece p, vec2 q, vec2 dq) {
  float en = 1e30, ex = -1e30;
  vec2 n = vec2(-p.e.y, p.e.x);
  vec2 r = q - p.a;
  vec2 v0 = vec2(dot(r, p.e), dot(r, n)), vd = vec2(dot(dq, p.e), dot(dq, n));
  vec2 lo = vec2(0.0, -p.lip), hi = vec2(p.len, p.lip);
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
  if (tin < tout) {
    en = min(en, tin);
    ex = max(ex, tout);
  }
  for (int k = 0; k < 2; ++k) {
    vec2 c = k == 0 ? p.a : p.a + p.e * p.len;
    vec2 rc = q - c;
    float A = dot(dq, dq), B = dot(rc, dq), C = dot(rc, rc) - p.lip * p.lip;
    if (A < 1e-30) {
      if (C < 0.0) { en = -1e30; ex = 1e30; }
      continue;
    }
    float disc = B * B - A * C;
    if (disc > 0.0) {
      en = min(en, (-B - sqrt(disc)) / A);
      ex = max(ex, (-B + sqrt(disc)) / A);
    }
  }
  return vec2(en, ex);
}

// Where the 2-D line q + t dq (inside the capsule at t = 0) leaves it.
float gCapsuleExit(GPiece p, vec2 q, vec2 dq) { return max(gCapsuleSpan(p, q, dq).y, 0.0); }

// The ray inside piece p's air at t: where it meets the floor (a point on or under it), or just
// past the capsule's edge, at most t1.
float gAirExit(Cell c, GPiece p, vec3 o, vec3 d, float t, float t1) {
  vec3 q0 = o + d * t;
  float te = t + gCapsuleExit(p, q0.xy, d.xy);
  float tEnd = min(te, t1);
  GProf P = gLoadProf(p.prof);
  float ta = t, fa = q0.z - gFloorP(p, P, q0.xy);
  for (int i = 1; i <= 16; ++i) {
    float tb = t + (tEnd - t) * float(i) / 16.0;
    vec3 qb = o + d * tb;
    float fb = qb.z - gFloorP(p, P, qb.xy);
    if (fb <= 0.0) {
      for (int k = 0; k < 14; ++k) {
        float tm = 0.5 * (ta + tb);
        vec3 qm = o + d * tm;
        float fm = qm.z - gFloorP(p, P, qm.xy);
        if (fm > 0.0) { ta = tm; fa = fm; } else { tb = tm; fb = fm; }
      }
      float ts = fa > fb ? ta + (tb - ta) * fa / (fa - fb) : tb;
      vec3 qs = o + d * ts;
      return qs.z - gFloorP(p, P, qs.xy) <= 0.0 ? ts : tb;
    }
    ta = tb;
    fa = fb;
  }
  return te < t1 ? te + 1e-6 * p.hw + 1e-7 * abs(te) : t1;
}

// The list of pieces of the bin under q: its first word and length (0 for an empty bin). The bins
// are sparse (gcast::binMaskWords): a mask bit a bin, the held bins before each mask word, and
// each held bin's first list entry.
uint gBinList(Cell c, uint blk, vec2 q, out uint n) {
  uint G = grooveWord(blk);
  vec2 f = (q - c.boxUV.xz) / (c.boxUV.yw - c.boxUV.xz) * float(G);
  uvec2 b = uvec2(clamp(ivec2(floor(f)), ivec2(0), ivec2(G) - 1));
  uint k = b.y * G + b.x, M = (G * G + 31u) / 32u;
  uint word = grooveWord(blk + 6u + k / 32u), bit = k % 32u;
  n = 0u;
  if (((word >> bit) & 1u) == 0u) return 0u;
  uint held = grooveWord(blk + 6u + M + k / 32u) + uint(bitCount(word & ((1u << bit) - 1u)));
  uint starts = blk + 6u + 2u * M + held;
  uint start = grooveWord(starts);
  n = grooveWord(starts + 1u) - start;
  return blk + grooveWord(blk + 2u) + start;
}

// Whether q lies in any piece's capsule (out to its lips: there the surface is the lowest floor
// over q, the height field is not); air: a piece whose floor q is above (-1: none, q is solid); lowest: the piece
// with the lowest floor.
bool gCover(Cell c, uint blk, vec3 q, out int air, out int lowest) {
  uint n;
  uint list = gBinList(c, blk, q.xy, n);
  air = -1;
  lowest = -1;
  float low = 1e30;
  uint pieces = blk + grooveWord(blk + 3u);
  for (uint k = 0u; k < n; ++k) {
    uint i = grooveWord(list + k);
    // The capsule test from the piece's first six words; the rest only for a covering piece.
    uint w = pieces + i * 14u;
    vec2 a = vec2(gWordF(w), gWordF(w + 1u)), e = vec2(gWordF(w + 2u), gWordF(w + 3u));
    float hw = gWordF(w + 13u);  // the capsule reaches the lips
    vec2 r = q.xy - a;
    if (dot(r - e * clamp(dot(r, e), 0.0, gWordF(w + 4u)), r - e * clamp(dot(r, e), 0.0, gWordF(w + 4u))) >= hw * hw) continue;
    GPiece p = gPiece(blk, i);
    float f = gFloor(c, p, q.xy);
    if (q.z > f) air = int(i);
    if (f < low) {
      low = f;
      lowest = int(i);
    }
  }
  return lowest >= 0;
}

// The height field's first crossing from above after t0 (the ray left a groove's capsule above
// it): 32 steps and a bisection, lighter than the mode's march (a second call site of that one
// costs llvmpipe on every pixel).
bool gMarchOn(Cell c, vec3 o, vec3 d, float t0, float t1, out float tHit) {
  float tPrev = t0;
  vec3 p = o + d * t0;
  float h = sampleHeight(c, p.xy);
  bool above = h == kUncovered || p.z > h;
  for (int i = 1; i <= 32; ++i) {
    float t = mix(t0, t1, float(i) / 32.0);
    p = o + d * t;
    h = sampleHeight(c, p.xy);
    if (h != kUncovered && p.z <= h && above) {
      for (int k = 0; k < 12; ++k) {
        float tm = 0.5 * (tPrev + t);
        vec3 pm = o + d * tm;
        float hm = sampleHeight(c, pm.xy);
        if (hm != kUncovered && pm.z <= hm) t = tm; else tPrev = tm;
      }
      tHit = t;
      return true;
    }
    above = h == kUncovered || p.z > h;
    tPrev = t;
  }
  return false;
}

#ifdef GROOVES_DEFER
uniform bool deferAll;  // self-shadowing: every hit takes the carved cast (its shadow ray too)

// The first pass: the height field's march; a pixel where the carved cast can differ is deferred
// to the second (deferPixel) and not drawn here. It can differ only where the hit is inside a capsule, or within
// twice the stretch a floor above h is searched over of one (castCell's window, from either end);
// within the anti-aliasing's reach of a groove's half width (modeFootprintColor); or, where floors rise
// above h and the march misses, the same near the extended box's exit.
bool castCell(Cell c, int cell, int boxSteps, vec3 o, vec3 d, float tEnter, float tExit, out float tHit, out uint work) {
  bool hit = parallaxTrace(c, boxSteps, o, d, tEnter, tExit, tHit, work);
  uint blk = grooveEntry(cell);
  if (blk == kNoGrooves) return hit;
  float rise = gWordF(blk + 5u);
  // The stretch before the height field's hit (or, on a miss, the extended box's exit) where the
  // carved cast looks for a floor above h: no piece within the stretch's reach of its two ends.
  float window = rise > 0.0 ? 2.0 * length(d.xy) * 1.25 * rise / max(abs(d.z), 0.02) : 0.0;
  bool carve = deferAll && hit, footprint = false;
  if (!hit && rise > 0.0) {
    vec3 bmin = vec3(c.boxUV.x, c.boxUV.z, min(c.boxW.x, gWordF(blk + 4u))), bmax = vec3(c.boxUV.y, c.boxUV.w, c.boxW.y);
    vec3 t0 = (bmin - o) / d, t1 = (bmax - o) / d;
    vec3 tf = max(t0, t1);
    carve = grooveGap(c, cell, (o + d * min(min(tf.x, tf.y), tf.z)).xy).x <= window;
  } else if (hit && !deferAll) {
    vec2 gap = grooveGap(c, cell, (o + d * tHit).xy);
    carve = gap.x <= window;
    footprint = grooveAA && gap.y <= gFootprintReach(tHit, d);
    // Every groove of the cell narrower than two pixels here: the footprint's rays draw them all
    // and its centre ray finds the depth (class 1); no floor rises above h, so the height field's
    // hit is where the ray meets the surface around the groove.
    if (carve && grooveAA && rise == 0.0 && grooveWidest(cell) < 2.0 * tHit * pixelAngle) {
      carve = false;
      footprint = true;
    }
  }
  if (!(carve || footprint) || !deferPixel(cell, carve ? 0u : 1u, hit ? tHit : -1.0)) return hit;
  return false;  // counted as a ray with the march's work here; the second pass adds its own
}

bool shadowRay(Cell c, int cell, vec3 p, vec3 l) { return parallaxShadowRay(c, p, l); }
#else
#define MODE_FOOTPRINT 1
#define MODE_EXTENDS_BOX 1

// The grooves cut below the height field's box: the cast runs down to the lowest floor.
void modeExtendBox(int cell, inout vec3 bmin, inout vec3 bmax) {
  uint blk = grooveEntry(cell);
  if (blk != kNoGrooves) bmin.z = min(bmin.z, gWordF(blk + 4u));
}

// The piece the anti-aliasing draws at the hit tS (-1: none): of the two pieces nearest the hit's
// texel (the gap field's candidates: a search of the bins around every pixel cost llvmpipe more
// than the footprint's rays), the one of least (distance - half width) that is under two pixels
// wide as seen along d and whose half width the pixel's footprint reaches. Kept in aaPiece for
// modeFootprintColor.
const int kAAUnknown = -2;
int aaPiece = kAAUnknown;
// The anti-aliasing's piece (aaPiece) and its profile, read once a pixel.
int aaLoaded = -1;
GPiece aaP;
GProf aaProf;
void gLoadAA(int cell, int best) {
  if (aaLoaded == best) return;
  aaP = gPiece(grooveEntry(cell), uint(best));
  aaProf = gLoadProf(aaP.prof);
  aaLoaded = best;
}

int gAAPiece(Cell c, int cell, vec3 o, vec3 d, float tS) {
  uint blk = grooveEntry(cell);
  vec3 hit = o + d * tS;
  float foot = tS * pixelAngle;  // a pixel across the ray at the hit
  float reach = gFootprintReach(tS, d);
  uvec2 near = grooveNear(c, cell, hit.xy);
  int best = -1;
  float bestGap = 1e30;
  for (int k = 0; k < 2; ++k) {
    if (near[k] == kNoGrooves) continue;
    GPiece p = gPiece(blk, near[k]);
    float s, x;
    float gap = gDist(p, hit.xy, s, x) - p.hw;
    vec2 gr;
    gRim(p, s, x, gr);
    vec3 a3 = vec3(-p.e.y, p.e.x, dot(gr, vec2(-p.e.y, p.e.x)));
    float wpx = 2.0 * p.hw * length(a3 - d * dot(a3, d)) / foot;
    if (wpx < 2.0 && gap < reach && gap < bestGap) {
      best = int(near[k]);
      bestGap = gap;
      aaP = p;
    }
  }
  aaPiece = best;
  if (best >= 0) {  // gLoadAA's piece is the one just read
    aaProf = gLoadProf(aaP.prof);
    aaLoaded = best;
  }
  return best;
}

// Piece p's cross-section at q: the rim's point C over the centre line and its slopes along (ra)
// and across (rx) there.
void gSection(GPiece p, vec2 q, out vec3 C, out float ra, out float rx) {
  float s0, x0;
  vec2 gr;
  gDist(p, q, s0, x0);
  s0 = clamp(s0, 0.0, p.len);
  float z0 = gRim(p, s0, 0.0, gr);
  ra = dot(gr, p.e);
  rx = dot(gr, vec2(-p.e.y, p.e.x));
  C = vec3(p.a + p.e * s0, z0);
}

// Where the ray o + t dk lands in a narrow groove's cross-section (its profile on the rim's tangent
// plane through C, the groove straight over the pixel): the ray meets the rim plane at xk across
// the line, then goes down the profile to the first facet it reaches (masking: a ray enters
// between the walls and meets the far one). Returns its t (-1: it does not meet the plane) and the
// facet's slope across there (dDdx; 0 outside the half width, where it lands on the rim plane).
float gFootprintLand(GPiece p, GProf P, vec3 C, float ra, float rx, vec3 o, vec3 dk, out float xk, out float dDdx) {
  vec2 n = vec2(-p.e.y, p.e.x);
  vec3 N = vec3(-(ra * p.e + rx * n), 1.0);
  float den = dot(N, dk);
  xk = 1e30;
  dDdx = 0.0;
  if (abs(den) < 1e-12) return -1.0;
  float t = dot(N, C - o) / den;
  if (t <= 0.0) return -1.0;
  vec3 q = o + dk * t;
  xk = dot(q.xy - C.xy, n);
  if (abs(xk) < p.hw) {
    float dx = dot(dk.xy, n), dz = dk.z - ra * dot(dk.xy, p.e) - rx * dx;  // per unit along the ray, below the rim plane
    float xh = xk;
    if (abs(dx) > 1e-7 * abs(dz)) {
      // f(x) = height of the ray above the floor at x: (x - xk) dz / dx + D(|x|), linear between
      // knots. The first knot ahead of xk (more than 1e-4 of a step) in the ray's direction where
      // f <= 0, from a scan of all 17 with constant indices (a walk indexing the profile per step
      // cost llvmpipe most of the footprint's time); then the crossing on the stretch before it.
      float k = dz / dx, step = p.hw / 8.0, dir = sign(dx), ahead = xk + dir * 1e-4 * step;
      int hitM = -1;
      for (int m = 0; m <= 16; ++m) {
        float xm = float(m - 8) * step;
        bool cross = dir * (xm - ahead) > 0.0 && (xm - xk) * k + gKnot(P, abs(m - 8)) <= 0.0;
        if (cross && (dir < 0.0 || hitM < 0)) hitM = m;
      }
      xh = dir * p.hw;
      if (hitM >= 0) {
        float x1 = float(hitM - 8) * step, f1 = (x1 - xk) * k + gKnot(P, abs(hitM - 8));
        int prevM = clamp(hitM - int(dir), 0, 16);
        float xp = float(prevM - 8) * step;
        bool fromKnot = dir * (xp - ahead) > 0.0;
        float x0 = fromKnot ? xp : xk;
        float f0 = fromKnot ? (xp - xk) * k + gKnot(P, abs(prevM - 8)) : gProfDepth(P, abs(xk), p.hw);
        xh = x0 + (x1 - x0) * f0 / max(f0 - f1, 1e-30);
      }
      t += (xh - xk) / dx;
    } else {
      t += gProfDepth(P, abs(xk), p.hw) / max(-dz, 1e-30);  // straight down the groove
    }
    float sm = gProfSmoothSlope(P, abs(xh), p.hw);
    dDdx = xh < 0.0 ? -sm : sm;
  }
  return t;
}

// A class-1 pixel's surface (the second pass, GROOVES_HIT_STANDS): the march's hit tS, unless the
// anti-aliasing's narrow piece is under it and the pixel's centre ray lands inside that piece's
// capsule: then the landing (the profile, or the rim out to the lips), with its facet's normal.
float gNarrowLanding(Cell c, int cell, vec3 o, vec3 d, float tS) {
  int best = gAAPiece(c, cell, o, d, tS);
  if (best < 0) return tS;
  gLoadAA(cell, best);
  GPiece p = aaP;
  vec3 C;
  float ra, rx, xk, dDdx;
  gSection(p, (o + d * tS).xy, C, ra, rx);
  float t = gFootprintLand(p, aaProf, C, ra, rx, o, d, xk, dDdx), sl, xl;
  // Past a rounded end the straight cross-section has no groove: there the march's hit stands.
  if (t < 0.0 || !(abs(xk) < p.lip) || !(gDist(p, (o + d * t).xy, sl, xl) < p.lip)) return tS;
  castNormal = normalize(vec3(-(p.e * ra + vec2(-p.e.y, p.e.x) * (rx - dDdx)), 1.0));
  castHasNormal = true;
  return t;
}

// The first t in [t0, t1] where the ray is on or under piece p's floor inside its capsule, -1 when
// none: at the capsule's entry if it enters under the floor, else where it meets the floor.
float gFloorCrossing(Cell c, GPiece p, vec3 o, vec3 d, float t0, float t1) {
  vec2 span = gCapsuleSpan(p, o.xy, d.xy);
  float a = max(t0, span.x), b = min(t1, span.y);
  if (!(a < b)) return -1.0;
  vec3 qa = o + d * a;
  if (qa.z <= gFloor(c, p, qa.xy)) return a;
  float te = gAirExit(c, p, o, d, a, b);
  vec3 qe = o + d * te;
  float s, x;
  return te < b && gDist(p, qe.xy, s, x) < p.lip && qe.z <= gFloor(c, p, qe.xy) ? te : -1.0;
}

// Inside a groove's capsule the carved surface is the lowest floor there; elsewhere the height
// field. The height field's march finds tH; where it passed over a capsule whose floor lies above
// the height field (the data's blurred crack, wider than its profile, lies under the rim), the
// floor was crossed first: over the stretch of ray that can reach such floors before tH, each
// piece near it gives its first floor crossing inside its capsule. From tH, a point in a groove's air advances to that piece's floor or out of
// its capsule, until it is solid; out of every capsule and above the height field, the march
// goes on from there.
bool castCell(Cell c, int cell, int boxSteps, vec3 o, vec3 d, float tEnter, float tExit, out float tHit, out uint work) {
#ifdef GROOVES_HIT_STANDS
  // The second pass's class 1: the march's hit is the surface, or where a narrow groove is under
  // the pixel, the centre ray's landing in its cross-section (modeFootprintColor draws the colour).
  tHit = deferredHit;
  work = 0u;
  deferredHit = kNotDeferred;
  if (tHit >= 0.0) tHit = gNarrowLanding(c, cell, o, d, tHit);
  return tHit >= 0.0;
#else
  uint blk = grooveEntry(cell);
  if (blk == kNoGrooves) return parallaxTrace(c, boxSteps, o, d, tEnter, tExit, tHit, work);
  vec2 texel = (c.boxUV.yw - c.boxUV.xz) / c.boxW.zw;
  float eps = 1e-3 * min(texel.x, texel.y);
  // Before h's hit the ray is above h; a floor rises above h by at most `rise` (0: nowhere).
  float rise = gWordF(blk + 5u);
  float window = 1.25 * rise / max(abs(d.z), 0.02);
  float t = tEnter, th;
  // The height field's hit, outside any loop (llvmpipe pays for a march inside one on every pixel),
  // over the height field's own box (the same march as parallax's, not stretched to the floors).
  vec3 bmin = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x), bmax = vec3(c.boxUV.y, c.boxUV.w, c.boxW.y);
  vec3 t0 = (bmin - o) / d, t1 = (bmax - o) / d;
  vec3 tn = min(t0, t1), tf = max(t0, t1);
  float hEnter = max(max(max(tn.x, tn.y), tn.z), 0.0), hExit = min(min(tf.x, tf.y), tf.z);
  work = 0u;
#ifdef PIXEL_RAYS
  // The second pass: the first pass's march already found the height field's hit.
  bool hh;
  if (deferredHit != kNotDeferred) {
    th = deferredHit;
    hh = th >= 0.0;
    deferredHit = kNotDeferred;
  } else {
    hh = hEnter < hExit && parallaxTrace(c, boxSteps, o, d, hEnter, hExit, th, work);
  }
#else
  bool hh = hEnter < hExit && parallaxTrace(c, boxSteps, o, d, hEnter, hExit, th, work);
#endif
  int air, lowest;
  // The common case: no floor rises above the height field, and its hit is in no capsule.
  bool usual = hh && rise == 0.0 && !gCover(c, blk, o + d * th, air, lowest);
  if (usual) {
    tHit = th;
    return true;
  }
  int piece = -1;
  bool found = false;
  // (A loop, not an if: llvmpipe runs an if's body under a mask on every pixel, but leaves a loop
  // no lane is in at once.)
  for (int it = 0; it < (usual ? 0 : 8) && !found; ++it) {
    if (it > 0) hh = gMarchOn(c, o, d, t, tExit, th);  // on from where the ray left the capsules
    float tH = hh ? th : tExit;
    // A floor above the height field before tH.
    float ta = max(t, tH - window);
    // Only where a capsule comes within the stretch's reach of its ends (the bins hold the pieces
    // near them): each such piece's first floor crossing inside its capsule over the stretch.
    float reach = length(d.xy) * (tH - ta), best = 1e30;
    for (int e = 0; e < (rise > 0.0 ? 2 : 0); ++e) {
      vec2 qe = (o + d * (e == 0 ? tH : ta)).xy;
      uint n;
      uint list = gBinList(c, blk, qe, n);
      for (uint k = 0u; k < n; ++k) {
        GPiece p = gPiece(blk, grooveWord(list + k));
        float ps, px;
        if (gDist(p, qe, ps, px) >= p.lip + reach) continue;
        work += 1u;
        float tc = gFloorCrossing(c, p, o, d, ta, min(tH, best));
        if (tc >= 0.0) best = min(best, tc);
      }
    }

    if (best < tH) {
      // On a floor: solid unless in another groove's air (the advance below goes on from there).
      t = best;
      if (gCover(c, blk, o + d * t, air, lowest) && air < 0) {
        piece = lowest;
        found = true;
        break;
      }
    }
    if (found || (!hh && best >= tH)) break;
    bool fromFloor = best < tH;
    if (!fromFloor) t = tH;
    bool onward = false;
    for (int j = 0; j < 16; ++j) {
      vec3 q = o + d * t;
      work += 1u;
      if (!gCover(c, blk, q, air, lowest)) {
        // Out of every capsule: the height field's surface (its hit, or a capsule's edge under it).
        if ((j == 0 && !fromFloor) || (sampleHeight(c, q.xy) != kUncovered && q.z <= sampleHeight(c, q.xy) + eps)) found = true;
        else onward = true;
        break;
      }
      if (air < 0) {
        piece = lowest;
        found = true;
        break;
      }
      t = gAirExit(c, gPiece(blk, uint(air)), o, d, t, tExit);
      if (t >= tExit) return false;
    }
    if (!found && !onward) found = true;  // the iteration cap: take where it stopped
  }
  if (!found) return false;
  tHit = t;
  if (piece >= 0) {
    castNormal = gNormal(gPiece(blk, uint(piece)), (o + d * t).xy);
    castHasNormal = true;
  }
  return true;
#endif
}

// Self-shadowing: the same carved cast from just above the hit toward the light (a crack's floor
// is shadowed by its walls).
bool shadowRay(Cell c, int cell, vec3 p, vec3 l) {
  if (l.z <= 0.0) return true;
  vec3 o;
  float tExit = shadowRayExit(c, p, l, o);
  if (tExit <= 0.0) return false;
  // From a groove's floor the ray starts in its air, under the height field (the cast below looks
  // from the height field's hit on): through the air of the pieces it is in until solid (a wall
  // or another floor: shadowed) or out of every capsule (under h there: shadowed).
  uint blk = grooveEntry(cell);
  float t0 = 0.0;
  int air, lowest;
  for (int j = 0; j < (blk == kNoGrooves ? 0 : 16); ++j) {
    vec3 q = o + l * t0;
    if (!gCover(c, blk, q, air, lowest)) {
      float h = sampleHeight(c, q.xy);
      if (j > 0 && h != kUncovered && q.z <= h) return true;
      break;
    }
    if (air < 0) return true;
    t0 = gAirExit(c, gPiece(blk, uint(air)), o, l, t0, tExit);
    if (t0 >= tExit) return false;
  }
  bool hasN = castHasNormal;
  vec3 n = castNormal;
  float t;
  uint work;
  bool r = castCell(c, cell, 0, o, l, t0, tExit, t, work);
  castHasNormal = hasN;
  castNormal = n;
  return r;
}

// The colour of one ray of a narrow groove's footprint: where it lands in the cross-section
// (gFootprintLand), shaded with that facet's normal; outside the profile, the rim's surface.
vec3 gFootprintSample(Cell c, GPiece p, GProf P, vec3 C, float ra, float rx, vec3 o, vec3 dk, vec3 albedo, vec3 world) {
  float xk, dDdx;
  if (gFootprintLand(p, P, C, ra, rx, o, dk, xk, dDdx) < 0.0) return vec3(-1.0);
  vec2 g = p.e * ra + vec2(-p.e.y, p.e.x) * (rx - dDdx);
  vec3 nf = normalize(vec3(-g, 1.0));
  vec3 nWorld = c.axisU.xyz * nf.x + c.axisV.xyz * nf.y + c.axisW.xyz * nf.z;
  return shade(albedo, nWorld, world);
}

// The integral from 0 to s of the footprint's weight across a groove: the pixel square's chord
// length across the groove's screen direction, 1 out to lo and falling to 0 at hi (odd in s).
float gChordIntegral(float s, float lo, float hi) {
  float a = min(abs(s), hi), r = hi - a;
  float w = a <= lo ? a : lo + 0.5 * ((hi - lo) * (hi - lo) - r * r) / max(hi - lo, 1e-6);
  return s < 0.0 ? -w : w;
}

// The offsets s (pixels across the groove's screen direction) of the footprint's rays
// o + t (d + qs s) that meet piece p's rim plane (normal N through C) within its half width: where
// x(s) = x0 + a (ga + de s) / (al + be s), across the line, is -hw and hw, clamped to [-hi, hi].
// The whole [-hi, hi] where the rays do not all meet the plane from one side.
vec2 gInsideSpan(GPiece p, vec3 C, vec3 N, vec3 o, vec3 d, vec3 qs, float hi) {
  vec2 n = vec2(-p.e.y, p.e.x);
  float a = dot(N, C - o), al = dot(N, d), be = dot(N, qs);
  float x0 = dot(o.xy - C.xy, n), ga = dot(d.xy, n), de = dot(qs.xy, n);
  if (!(a / (al - be * hi) > 0.0 && a / (al + be * hi) > 0.0)) return vec2(-hi, hi);
  vec2 X = vec2(-p.hw, p.hw) - x0;
  vec2 den = a * de - X * be;
  if (!(abs(den.x) > 1e-20 && abs(den.y) > 1e-20)) return vec2(-hi, hi);
  vec2 sx = (X * al - a * ga) / den;
  return clamp(vec2(min(sx.x, sx.y), max(sx.x, sx.y)), -hi, hi);
}

// Anti-aliasing of grooves narrower than two pixels (003 eq. 6's footprint area ratios, integrated
// numerically): the piece gAAPiece picks (castCell's, where it chose one for this pixel). Across
// the groove's screen direction the pixel square's chord lengths weight the footprint. The stretch
// of it whose rays land inside the groove (gInsideSpan) takes grooveSamples rays, each followed
// down the groove's profile in its cross-section and shaded where it lands; the rest lands on the
// rim's tangent plane, one colour. The weighted mean is the pixel's colour (albedo and world: the
// hit's; false where no narrow groove draws the pixel). (Only one groove: where two narrow ones
// cross inside a pixel, one of them.)
bool modeFootprintColor(Cell c, int cell, vec3 o, vec3 d, float tS, vec3 albedo, vec3 world, out vec3 color) {
  color = vec3(0.0);
  uint blk = grooveEntry(cell);
  if (!grooveAA || blk == kNoGrooves) return false;
  int best = aaPiece != kAAUnknown ? aaPiece : gAAPiece(c, cell, o, d, tS);
  vec3 hit = o + d * tS;
  if (best < 0) return false;
  gLoadAA(cell, best);
  GPiece p = aaP;
  vec3 C;
  float ra, rx;
  gSection(p, hit.xy, C, ra, rx);
  vec3 R = toFrame(c, camRight), U = toFrame(c, camUp);
  vec3 e3 = vec3(p.e, ra);
  vec2 g2 = vec2(dot(e3, R), dot(e3, U));
  if (dot(g2, g2) < 1e-12) return false;
  g2 = normalize(g2);
  vec2 q2 = vec2(-g2.y, g2.x);
  float hi = 0.5 * (abs(q2.x) + abs(q2.y)), lo = 0.5 * abs(abs(q2.x) - abs(q2.y));
  vec3 qs = (R * q2.x + U * q2.y) * pixelAngle;
  vec2 rimSlope = p.e * ra + vec2(-p.e.y, p.e.x) * rx;
  vec2 span = gInsideSpan(p, C, vec3(-rimSlope, 1.0), o, d, qs, hi);
  float wIn = gChordIntegral(span.y, lo, hi) - gChordIntegral(span.x, lo, hi), wOut = hi + lo - wIn;
  vec3 sum = vec3(0.0);
  float wsum = 0.0;
  int n = clamp(grooveSamples, 1, 64);
  for (int k = 0; k < n; ++k) {
    float sg = mix(span.x, span.y, (float(k) + 0.5) / float(n));
    float wt = abs(sg) <= lo ? 1.0 : (hi - abs(sg)) / max(hi - lo, 1e-6);
    vec3 col = gFootprintSample(c, p, aaProf, C, ra, rx, o, normalize(d + qs * sg), albedo, world);
    if (col.x < 0.0) continue;
    sum += wt * col;
    wsum += wt;
  }
  if (!(wsum > 0.0)) return false;
  vec3 nRim = normalize(vec3(-rimSlope, 1.0));
  vec3 rim = shade(albedo, c.axisU.xyz * nRim.x + c.axisV.xyz * nRim.y + c.axisW.xyz * nRim.z, world);
  color = (sum / wsum * wIn + rim * wOut) / max(wIn + wOut, 1e-12);
  return true;
}
#endif
