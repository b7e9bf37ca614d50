// The gdm mode's voxel grids on the GPU (GDMV, docs/FORMAT.md): the buffers, a voxel's field and
// the DDA that finds the first crossing of the surface along a ray (gdm.cpp walk). Shared by
// gdm.glsl and the slices mode (forced cells' slices are opaque where this walk meets the surface).
// The surface is the zero set of the trilinear interpolation of a signed distance stored at the
// voxels' corners (the cell's source samples' algebraic spheres for points, APSS; their implicit
// moving-least-squares surface for triangles, Kolluri 2008), negative inside; a hit is where the ray crosses it, either way (a camera inside a
// thin part sees its walls), shaded with the side that faces the ray.
layout(std430, binding = 6) readonly buffer GdmEntries { uint gdmEntry[]; };  // block of each cell, ~0u: none
layout(std430, binding = 7) readonly buffer GdmWords { uint gdmWord[]; };

// 0: a corner unknown (no sample near), 1: known and outside, 3: the surface may pass (gdm.h).
uint gdmState(uint blk, ivec3 N, ivec3 idx) {
  uint i = uint((idx.z * N.y + idx.y) * N.x + idx.x);
  return (gdmWord[blk + 8u + (i >> 4u)] >> ((i & 15u) * 2u)) & 3u;
}

// A corner's value (in the grid's units: only signs and ratios matter here).
float gdmCorner(uint cornerBase, ivec3 N, int x, int y, int z) {
  uint i = uint((z * (N.y + 1) + y) * (N.x + 1) + x);
  uint w = gdmWord[cornerBase + (i >> 1u)];
  return float((i & 1u) == 0u ? int(w << 16u) >> 16 : int(w) >> 16);
}

float gdmTrilinear(float f[8], vec3 s) {
  vec4 x = mix(vec4(f[0], f[2], f[4], f[6]), vec4(f[1], f[3], f[5], f[7]), s.x);
  vec2 y = mix(x.xz, x.yw, s.y);
  return mix(y.x, y.y, s.z);
}

vec3 gdmGradient(float f[8], vec3 s, vec3 vs) {
  float gx = mix(mix(f[1] - f[0], f[3] - f[2], s.y), mix(f[5] - f[4], f[7] - f[6], s.y), s.z);
  float gy = mix(mix(f[2] - f[0], f[3] - f[1], s.x), mix(f[6] - f[4], f[7] - f[5], s.x), s.z);
  float gz = mix(mix(f[4] - f[0], f[5] - f[1], s.x), mix(f[6] - f[2], f[7] - f[3], s.x), s.y);
  return vec3(gx, gy, gz) / vs;
}

// The DDA from t0 to t1 (gdm.cpp walk): a crossing counts from tAccept on (in the first voxel
// from where the ray entered it); within a voxel, 4 even steps find the first interval whose ends
// differ in sign, then 10 bisections and a secant step (gdm.cpp crossing). touched: the
// ray passed a known voxel (whether or not it met the surface).
bool gdmWalk(Cell c, uint blk, vec3 o, vec3 d, float t0, float t1, float tAccept, out float tHit, out vec3 nHit,
             out uint steps, inout bool touched) {
  tHit = 0.0;
  nHit = vec3(0.0, 0.0, 1.0);
  ivec3 N = ivec3(gdmWord[blk], gdmWord[blk + 1u], gdmWord[blk + 2u]);
  vec3 vs = vec3(uintBitsToFloat(gdmWord[blk + 3u]), uintBitsToFloat(gdmWord[blk + 4u]), uintBitsToFloat(gdmWord[blk + 5u]));
  uint cornerBase = blk + 8u + (uint(N.x * N.y * N.z) + 15u) / 16u;
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
  float t = max(min(entry, t0), tAccept);
  int cap = N.x + N.y + N.z + 4;
  steps = 0u;
  for (int n = 0; n < cap; ++n) {
    steps = uint(n + 1);
    int a = tMax.x <= tMax.y ? (tMax.x <= tMax.z ? 0 : 2) : (tMax.y <= tMax.z ? 1 : 2);
    float tNext = min(max(tMax[a], t), t1);
    uint st = gdmState(blk, N, idx);
    if (st != 0u) touched = true;
    if (st == 3u) {
      float f[8];
      for (int k = 0; k < 8; ++k) f[k] = gdmCorner(cornerBase, N, idx.x + (k & 1), idx.y + ((k >> 1) & 1), idx.z + (k >> 2));
      vec3 vlo = lo + vec3(idx) * vs;
      float ta = t, fa = gdmTrilinear(f, (o + d * ta - vlo) / vs);
      for (int i = 1; i <= 4; ++i) {
        float tb = t + (tNext - t) * float(i) / 4.0;
        float fb = gdmTrilinear(f, (o + d * tb - vlo) / vs);
        if ((fa > 0.0) != (fb > 0.0)) {
          for (int k = 0; k < 10; ++k) {
            float tm = 0.5 * (ta + tb), fm = gdmTrilinear(f, (o + d * tm - vlo) / vs);
            if ((fm > 0.0) == (fa > 0.0)) { ta = tm; fa = fm; } else { tb = tm; fb = fm; }
          }
          tHit = ta + (tb - ta) * fa / (fa - fb);
          vec3 g = gdmGradient(f, (o + d * tHit - vlo) / vs, vs);
          nHit = dot(g, g) > 0.0 ? normalize(g) * (dot(g, d) > 0.0 ? -1.0 : 1.0) : -normalize(d);
          return true;
        }
        ta = tb;
        fa = fb;
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
