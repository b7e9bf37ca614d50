// The `parallax` mode's cast: Lu, Low & Zheng's linear search with bisection
// (marchHeightField, heightfield.glsl). work: the height samples the search took.

uniform int refineSteps;
uniform int maxSteps;  // the --iterations bound

bool parallaxTrace(Cell c, int boxSteps, vec3 o, vec3 d, float tEnter, float tExit, out float tHit, out uint work) {
  // Steps: about one per 1.5 texels this ray crosses (finer steps than the surface's own
  // resolution find nothing new, coarser ones step over bumps at grazing angles), at least the
  // box's estimate from its size on screen, at most the --iterations bound.
  vec2 texel = (c.boxUV.yw - c.boxUV.xz) / c.boxW.zw;
  float crossed = length(d.xy) * (tExit - tEnter) / min(texel.x, texel.y);
  int steps = clamp(int(ceil(crossed / 1.5)), max(boxSteps, 1), max(maxSteps, 1));
  work = uint(steps + refineSteps);
  if (!marchHeightField(c, o, d, tEnter, tExit, steps, refineSteps, tHit)) return false;
  // The secant step may land past a coverage edge: keep only hits on a covered texel (§3.3.1).
  vec3 p = o + d * tHit;
  return sampleHeight(c, p.xy) != kUncovered;
}

// Self-shadowing: the march from just above hit point p toward the light l (frame, unit) to the box.
bool parallaxShadowRay(Cell c, vec3 p, vec3 l) {
  if (l.z <= 0.0) return true;  // the light is below the cell's plane
  vec3 o;
  float tExit = shadowRayExit(c, p, l, o);
  if (tExit <= 0.0) return false;
  float t;
  uint work;
  return parallaxTrace(c, 0, o, l, 0.0, tExit, t, work);
}

#ifndef PARALLAX_NO_CAST
bool castCell(Cell c, int cell, int boxSteps, vec3 o, vec3 d, float tEnter, float tExit, out float tHit, out uint work) {
  return parallaxTrace(c, boxSteps, o, d, tEnter, tExit, tHit, work);
}

bool shadowRay(Cell c, int cell, vec3 p, vec3 l) { return parallaxShadowRay(c, p, l); }
#endif
