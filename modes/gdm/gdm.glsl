// The `gdm` mode's cast (modes/gdm/gdm.cpp `traceGuided` is the same rule on the CPU): a cell
// with a voxel grid (a forced cell) looks up its generalized displacement function where the ray
// enters the box - any face, or the camera inside - and walks voxels (Amanatides & Woo) from the
// predicted point, or from the entry where the prediction fails a check; the first crossing of the
// cell's implicit surface from outside to inside is the hit, its gradient the normal
// (gdm_voxels.glsl). A ray that passes no known voxel at all (samples too sparse for the band to
// reach: scan edges, cracks the pack's pull-push closed) takes the cell's height field instead.
// Other cells: the exact traversal (with RenderSettings::gdmParallaxElsewhere the renderer draws
// them by parallax's programs instead, and only the forced cells by this one).
#define EXACT_NO_CAST 1
#include "exact.glsl"
#include "gdm_voxels.glsl"

float gdmHalf(uint base, uint h) {
  vec2 v = unpackHalf2x16(gdmWord[base + (h >> 1u)]);
  return (h & 1u) == 0u ? v.x : v.y;
}

// The direction function at voxel idx for direction d (gdm.cpp lookup): the nearest bin's value,
// sum over k of u[(y nx + x) 32 + phi bin][k] v[z 16 + theta bin][k], in units of the smallest voxel side.
float gdmLookup(uint blk, ivec3 N, ivec3 idx, vec3 d) {
  uint rank = gdmWord[blk + 6u];
  uint uBase = blk + gdmWord[blk + 7u];
  uint vBase = uBase + (uint(N.x * N.y * 32) * rank + 1u) / 2u;
  int i = clamp(int(acos(clamp(d.z / length(d), -1.0, 1.0)) / 3.14159265 * 16.0), 0, 15);
  int j = d.x == 0.0 && d.y == 0.0 ? 0 : int(floor(atan(d.y, d.x) / 6.28318531 * 32.0 + 0.5)) & 31;
  uint r = uint((idx.y * N.x + idx.x) * 32 + j) * rank, q = uint(idx.z * 16 + i) * rank;
  float s = 0.0;
  for (uint k = 0u; k < rank; ++k) s += gdmHalf(uBase, r + k) * gdmHalf(vBase, q + k);
  return s;
}

// gdm.cpp traceGuided: a ray crossing 12 voxels or more (gdm.h kDirectVoxels) jumps by the
// function up to 4 times (kMaxJumps), each jump taken only where the voxel half a voxel before its
// landing point is empty, then walks from there. Counters: [7] rays that looked up, [6] misses
// after jumping, [5] rays with a jump refused.
bool gdmTrace(Cell c, uint blk, vec3 o, vec3 d, float t0, float t1, out float tHit, out vec3 nHit, out uint steps,
              out bool touched) {
  touched = false;
  ivec3 N = ivec3(gdmWord[blk], gdmWord[blk + 1u], gdmWord[blk + 2u]);
  vec3 vs = vec3(uintBitsToFloat(gdmWord[blk + 3u]), uintBitsToFloat(gdmWord[blk + 4u]), uintBitsToFloat(gdmWord[blk + 5u]));
  float crossed = (t1 - t0) * dot(abs(d), 1.0 / vs);
  if (gdmWord[blk + 6u] == 0u || crossed < 12.0)
    return gdmWalk(c, blk, o, d, t0, t1, t0, tHit, nHit, steps, touched);
  countEvent(7u);
  vec3 lo = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x);
  float unit = min(min(vs.x, vs.y), vs.z), len = length(d);
  float t = t0;
  uint jumps = 0u;
  bool failed = false;
  while (jumps < 4u && t < t1) {
    ivec3 idx = clamp(ivec3(floor((o + d * t - lo) / vs)), ivec3(0), N - 1);
    ++jumps;
    float skip = (gdmLookup(blk, N, idx, d) - 0.5) * unit / len;
    if (skip < unit / len) break;
    float tn = min(t + skip, t1);
    ivec3 b = clamp(ivec3(floor((o + d * (tn - 0.5 * unit / len) - lo) / vs)), ivec3(0), N - 1);
    if (gdmState(blk, N, b) != 0u) {
      failed = true;
      break;
    }
    t = tn;
  }
  uint walked = 0u;
  bool hit = t < t1 && gdmWalk(c, blk, o, d, t, t1, t0, tHit, nHit, walked, touched);
  if (failed) countEvent(5u);
  else if (!hit) countEvent(6u);
  steps = walked + jumps;
  return hit;
}

bool castCell(Cell c, int cell, int boxSteps, vec3 o, vec3 d, float tEnter, float tExit, out float tHit, out uint work) {
  uint blk = gdmEntry[cell];
  if (blk == 0xffffffffu) return exactTrace(c, cell, o, d, tEnter, tExit, tHit, work);
  vec3 n;
  bool touched;
  if (gdmTrace(c, blk, o, d, tEnter, tExit, tHit, n, work, touched)) {
    castNormal = n;
    castHasNormal = true;
    return true;
  }
  if (touched) return false;  // it passed near the samples and met no surface: nothing there
  uint nodes;
  bool found = exactTrace(c, cell, o, d, tEnter, tExit, tHit, nodes);
  work += nodes;
  return found;
}

bool shadowRay(Cell c, int cell, vec3 p, vec3 l) {
  uint blk = gdmEntry[cell];
  if (blk == 0xffffffffu) return exactShadowRay(c, cell, p, l);
  vec3 vs = vec3(uintBitsToFloat(gdmWord[blk + 3u]), uintBitsToFloat(gdmWord[blk + 4u]), uintBitsToFloat(gdmWord[blk + 5u]));
  float start = 0.75 * length(vs);  // off the hit's own surface
  vec3 bmin = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x), bmax = vec3(c.boxUV.y, c.boxUV.w, c.boxW.y);
  vec3 t1 = max((bmin - p) / l, (bmax - p) / l);
  float tExit = min(min(t1.x, t1.y), t1.z);
  if (tExit <= start) return false;
  float t;
  vec3 n;
  uint steps;
  bool touched = false;
  return gdmWalk(c, blk, p, l, start, tExit, start, t, n, steps, touched);
}
