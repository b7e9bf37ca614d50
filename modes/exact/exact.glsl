// The `exact` mode's cast (MODES.md §5; Tevs, Ihrke & Seidel 2008): the maximum-mipmap
// traversal of modes/exact/exact.cpp in single precision. Nodes the ray passes above (or, with
// nothing above to fall from, below) are skipped whole; each level-0 patch (quadrant pieces where
// a corner is uncovered, as sampleHeight) is solved in closed form: w(t) - h(t) is a quadratic
// in t. Same surface rule as the march: the first crossing from above to below inside the
// covered region.

layout(std430, binding = 3) readonly buffer ExactMaxima { uint mipWords[]; };   // a node a word: max | min << 16
layout(std430, binding = 4) readonly buffer ExactOffsets { uint mipOffset[]; };  // first node of each cell

// The corner heights (00, 10, 01, 11) of quadrant q's piece of the patch whose texels are h
// (kUncovered where none), first texel i0; false when the piece is uncovered.
bool exactPiece(Cell c, ivec2 i0, vec4 h, int q, out vec4 ph) {
  float hq = h[q];
  ph = h;
  if (hq == kUncovered) return false;
  if (!storedNormals) {
    ph = vec4(hq);
    return true;
  }
  ivec2 n = clamp(i0 + ivec2(q & 1, q >> 1), ivec2(0), ivec2(c.boxW.zw) - 1);
  vec2 s = tangentSlope(c, n);
  vec4 e = hq + vec4(dot(s, vec2(i0 - n)), dot(s, vec2(i0 + ivec2(1, 0) - n)), dot(s, vec2(i0 + ivec2(0, 1) - n)),
                     dot(s, vec2(i0 + ivec2(1, 1) - n)));
  for (int k = 0; k < 4; ++k)
    if (h[k] == kUncovered) ph[k] = e[k];
  return true;
}

// First s in (0, L] where A + B s + C s^2 falls through zero, or -1.
float exactDescendingRoot(float A, float B, float C, float L) {
  float r0 = -1.0, r1 = -1.0;
  if (C == 0.0) {
    if (B != 0.0) r0 = -A / B;
  } else {
    float disc = B * B - 4.0 * A * C;
    if (disc < 0.0) return -1.0;
    float q = -0.5 * (B + (B < 0.0 ? -1.0 : 1.0) * sqrt(disc));
    if (q != 0.0) r0 = A / q;
    r1 = q / C;
  }
  float best = -1.0;
  if (r0 > 0.0 && r0 <= L * 1.0001 && B + 2.0 * C * r0 <= 0.0) best = r0;
  if (r1 > 0.0 && r1 <= L * 1.0001 && B + 2.0 * C * r1 <= 0.0 && (best < 0.0 || r1 < best)) best = r1;
  return best < 0.0 ? -1.0 : min(best, L);
}

// Patch p over [ta, tb] of the ray S0 + dS t (patch coordinates), w = z0 + dz t.
bool exactPatch(Cell c, ivec2 p, vec2 S0, vec2 dS, float z0, float dz, float ta, float tb, inout bool prevAbove,
                out float tHit) {
  tHit = 0.0;
  ivec2 i0 = p - 1;
  vec4 h = vec4(texelHeight(c, i0), texelHeight(c, i0 + ivec2(1, 0)), texelHeight(c, i0 + ivec2(0, 1)),
                texelHeight(c, i0 + ivec2(1, 1)));
  bool mixed = min(min(h.x, h.y), min(h.z, h.w)) == kUncovered;
  float cut1 = tb, cut2 = tb;
  if (mixed) {  // the quadrant lines
    float qx = dS.x != 0.0 ? (float(p.x) + 0.5 - S0.x) / dS.x : tb;
    float qy = dS.y != 0.0 ? (float(p.y) + 0.5 - S0.y) / dS.y : tb;
    qx = qx > ta && qx < tb ? qx : tb;
    qy = qy > ta && qy < tb ? qy : tb;
    cut1 = min(qx, qy);
    cut2 = max(qx, qy);
  }
  float s0 = ta;
  for (int k = 0; k < 3; ++k) {
    float s1 = k == 0 ? cut1 : (k == 1 ? cut2 : tb);
    if (k > 0 && s1 <= s0) continue;
    vec4 ph = h;
    bool covered = true;
    if (mixed) {
      vec2 am = S0 + dS * (0.5 * (s0 + s1)) - vec2(p);
      covered = exactPiece(c, i0, h, (am.x >= 0.5 ? 1 : 0) + (am.y >= 0.5 ? 2 : 0), ph);
    }
    if (!covered) {
      prevAbove = false;
    } else {
      vec2 a0 = S0 + dS * s0 - vec2(p);
      float e = ph.x - ph.y - ph.z + ph.w;
      float hA = ph.x + (ph.y - ph.x) * a0.x + (ph.z - ph.x) * a0.y + e * a0.x * a0.y;
      float hB = (ph.y - ph.x) * dS.x + (ph.z - ph.x) * dS.y + e * (a0.x * dS.y + a0.y * dS.x);
      float A = z0 + dz * s0 - hA, B = dz - hB, C = -e * dS.x * dS.y;
      if (A <= 0.0 && prevAbove) {
        tHit = s0;
        return true;
      }
      float L = s1 - s0;
      float r = exactDescendingRoot(A, B, C, L);
      if (r > 0.0) {
        tHit = s0 + r;
        return true;
      }
      prevAbove = A + L * (B + L * C) > 0.0;
    }
    s0 = s1;
  }
  return false;
}

int exactNodeIndex(float S, float dS) { return dS >= 0.0 ? int(floor(S)) : int(ceil(S)) - 1; }

// work: nodes visited (more than the cap, exact.h maxNodeVisits, when the cap stopped the ray).
bool exactTrace(Cell c, int cell, vec3 o, vec3 d, float tEnter, float tExit, out float tHit, out uint work) {
  tHit = 0.0;
  ivec2 size = ivec2(c.boxW.zw);
  ivec2 N = size + 1;
  int top = 0;
  while (top < 17 && (N.x > (1 << top) || N.y > (1 << top))) ++top;  // the level of a single node
  uint base = mipOffset[cell];
  vec2 ext = c.boxUV.yw - c.boxUV.xz;
  vec2 scale = vec2(ext.x > 0.0 ? float(size.x) / ext.x : 0.0, ext.y > 0.0 ? float(size.y) / ext.y : 0.0);
  vec2 S0 = (o.xy - c.boxUV.xz) * scale + 0.5;
  vec2 dS = d.xy * scale;
  float wMin = c.boxW.x, wRange = c.boxW.y - c.boxW.x;
  ivec2 pos = clamp(ivec2(exactNodeIndex(S0.x + dS.x * tEnter, dS.x), exactNodeIndex(S0.y + dS.y * tEnter, dS.y)),
                    ivec2(0), N - 1);
  float run = max(abs(dS.x), abs(dS.y)) * (tExit - tEnter);
  int l = 0;
  uint off = 0u;  // the first code of level l (no local array: GPUs spill those to memory)
  while (l < top && float(1 << l) < run) {
    ivec2 wl = (N + (1 << l) - 1) >> l;
    off += uint(wl.x * wl.y);
    ++l;
  }
  bool prevAbove = false;
  float t = tEnter;
  work = 0u;
  int maxVisits = 4 * (size.x + size.y + 2) + 64;
  for (int visits = 0;; ++visits) {
    if (visits >= maxVisits) {
      work = 0xffffffffu;
      return false;
    }
    work = uint(visits) + 1u;
    ivec2 n = pos >> l;
    float txx = dS.x > 0.0 ? (float((n.x + 1) << l) - S0.x) / dS.x : (dS.x < 0.0 ? (float(n.x << l) - S0.x) / dS.x : 3.4e38);
    float tyy = dS.y > 0.0 ? (float((n.y + 1) << l) - S0.y) / dS.y : (dS.y < 0.0 ? (float(n.y << l) - S0.y) / dS.y : 3.4e38);
    float tOut = max(t, min(min(txx, tyy), tExit));
    int wl = (N.x + (1 << l) - 1) >> l;
    uint word = mipWords[base + off + uint(n.y * wl + n.x)];
    uint code = word & 0xffffu, floorCode = word >> 16;
    float nodeMax = code == 65535u ? 3.4e38 : wMin + (float(code) - 1.0) / 65534.0 * wRange;
    float nodeMin = floorCode == 0u ? -3.4e38 : wMin + (float(floorCode) - 1.0) / 65534.0 * wRange;
    float zA = o.z + d.z * t, zB = o.z + d.z * tOut;
    // Above every covered piece, or below all of them with nothing above to fall from.
    bool skip = code == 0u || min(zA, zB) > nodeMax || (!prevAbove && max(zA, zB) < nodeMin);
    if (!skip && l > 0) {
      // A descending ray is above the node's maximum until it reaches that height: no hit
      // before, so it moves there first (the position is kept inside this node).
      if (d.z < 0.0 && code != 65535u) {
        float tPlane = (nodeMax - o.z) / d.z;
        if (tPlane > t && tPlane < tOut) {
          t = tPlane;
          prevAbove = false;
          pos = clamp(ivec2(exactNodeIndex(S0.x + dS.x * t, dS.x), exactNodeIndex(S0.y + dS.y * t, dS.y)), n << l,
                      min(((n + 1) << l) - 1, N - 1));
        }
      }
      --l;
      ivec2 wd = (N + (1 << l) - 1) >> l;
      off -= uint(wd.x * wd.y);
      continue;
    }
    if (skip) {
      prevAbove = false;
    } else if (exactPatch(c, pos, S0, dS, o.z, d.z, t, tOut, prevAbove, tHit)) {
      return true;
    }
    if (tOut >= tExit) return false;
    t = tOut;
    bool xAxis = txx <= tyy;
    int a = xAxis ? 0 : 1;
    int b = 1 - a;
    pos[a] = dS[a] > 0.0 ? (n[a] + 1) << l : (n[a] << l) - 1;
    if (pos[a] < 0 || pos[a] >= N[a]) return false;
    pos[b] = clamp(exactNodeIndex(S0[b] + dS[b] * t, dS[b]), n[b] << l, min(((n[b] + 1) << l) - 1, N[b] - 1));
    int boundary = dS[a] > 0.0 ? pos[a] : pos[a] + 1;
    while (l < top && ((boundary >> (l + 1)) << (l + 1)) == boundary) {
      ivec2 wu = (N + (1 << l) - 1) >> l;
      off += uint(wu.x * wu.y);
      ++l;
    }
  }
}

// Self-shadowing: the traversal from just above hit point p toward the light l (frame, unit).
bool exactShadowRay(Cell c, int cell, vec3 p, vec3 l) {
  if (l.z <= 0.0) return true;  // the light is below the cell's plane
  vec3 o;
  float tExit = shadowRayExit(c, p, l, o);
  if (tExit <= 0.0) return false;
  float t;
  uint work;
  return exactTrace(c, cell, o, l, 0.0, tExit, t, work);
}

#ifndef EXACT_NO_CAST
bool shadowRay(Cell c, int cell, vec3 p, vec3 l) { return exactShadowRay(c, cell, p, l); }

bool castCell(Cell c, int cell, int boxSteps, vec3 o, vec3 d, float tEnter, float tExit, out float tHit, out uint work) {
  return exactTrace(c, cell, o, d, tEnter, tExit, tHit, work);
}
#endif
