// The gdm mode's voxel grids on the GPU (GDMV, docs/FORMAT.md): the buffers, a voxel's surfel and
// the DDA that finds the first surfel along a ray (gdm.cpp walk). Shared by gdm.glsl and the
// slices mode (forced cells' slices are opaque where this walk meets a surfel).
layout(std430, binding = 6) readonly buffer GdmEntries { uint gdmEntry[]; };  // block of each cell, ~0u: none
layout(std430, binding = 7) readonly buffer GdmWords { uint gdmWord[]; };

vec3 gdmNormal(uint v, vec3 vs, out float offset) {
  vec2 p = vec2(float(v & 255u), float((v >> 8) & 255u)) / 127.5 - 1.0;
  float z = 1.0 - abs(p.x) - abs(p.y);
  vec2 xy = z < 0.0 ? (1.0 - abs(p.yx)) * vec2(p.x < 0.0 ? -1.0 : 1.0, p.y < 0.0 ? -1.0 : 1.0) : p;
  int q = int(v >> 16);
  if (q >= 32768) q -= 65536;
  offset = float(q) / 32767.0 * 0.5 * length(vs);
  return normalize(vec3(xy, z));
}

// The DDA from t0 to t1 (gdm.cpp walk): a surfel hit counts from tAccept on (in the first voxel
// from where the ray entered it). touched: the ray passed an occupied voxel (whether or not it
// met the surfel).
bool gdmWalk(Cell c, uint blk, vec3 o, vec3 d, float t0, float t1, float tAccept, out float tHit, out vec3 nHit,
             out uint steps, inout bool touched) {
  tHit = 0.0;
  nHit = vec3(0.0, 0.0, 1.0);
  ivec3 N = ivec3(gdmWord[blk], gdmWord[blk + 1u], gdmWord[blk + 2u]);
  vec3 vs = vec3(uintBitsToFloat(gdmWord[blk + 3u]), uintBitsToFloat(gdmWord[blk + 4u]), uintBitsToFloat(gdmWord[blk + 5u]));
  uint base = blk + 8u;
  vec3 lo = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x);
  vec3 p = o + d * t0 - lo;
  ivec3 idx = clamp(ivec3(floor(p / vs)), ivec3(0), N - 1);
  ivec3 stp = ivec3(sign(d));
  vec3 tDelta = vec3(d.x != 0.0 ? vs.x / abs(d.x) : 3.4e38, d.y != 0.0 ? vs.y / abs(d.y) : 3.4e38, d.z != 0.0 ? vs.z / abs(d.z) : 3.4e38);
  vec3 tMax;
  float entry = -3.4e38;
  for (int k = 0; k < 3; ++k) {
    tMax[k] = d[k] != 0.0 ? t0 + ((float(idx[k]) + (stp[k] > 0 ? 1.0 : 0.0)) * vs[k] - p[k]) / d[k] : 3.4e38;
    if (d[k] != 0.0) entry = max(entry, tMax[k] - tDelta[k]);
  }
  float margin = 0.25 * min(min(vs.x, vs.y), vs.z);
  float t = max(min(entry, t0), tAccept);
  int cap = N.x + N.y + N.z + 4;
  steps = 0u;
  for (int n = 0; n < cap; ++n) {
    steps = uint(n + 1);
    int a = tMax.x <= tMax.y ? (tMax.x <= tMax.z ? 0 : 2) : (tMax.y <= tMax.z ? 1 : 2);
    float tNext = min(max(tMax[a], t), t1);
    uint v = gdmWord[base + uint((idx.z * N.y + idx.y) * N.x + idx.x)];
    if (v != 0u) {
      touched = true;
      float off;
      vec3 nn = gdmNormal(v, vs, off);
      vec3 centre = lo + (vec3(idx) + 0.5) * vs;
      float den = dot(d, nn);
      if (abs(den) > 1e-12) {
        float tp = (off - dot(o - centre, nn)) / den;
        if (tp >= t - margin && tp <= tNext + margin && tp >= tAccept && tp <= t1) {
          tHit = tp;
          nHit = den > 0.0 ? -nn : nn;
          return true;
        }
      }
    }
    if (tNext >= t1) return false;
    idx[a] += stp[a];
    if (idx[a] < 0 || idx[a] >= N[a]) return false;
    t = tNext;
    tMax[a] += tDelta[a];
  }
  return false;
}

