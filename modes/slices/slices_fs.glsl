#version 450 core
// The `slices` mode's fragments (slices_vs.glsl): the cell's volume is the solid under its
// covered height field, so a slice is opaque where its points lie under the surface - a
// threshold of the heights, no storage beyond the tile (MODES.md §3). Front to back, the first
// slice a ray meets inside the solid lies within one spacing of the surface along the slicing
// axis, at most sqrt(3) spacings along the view (004 §4.1) since that axis is the one nearest
// the view. The depth is the slice's (the rasterizer's: early depth rejection works).
#include "heightfield.glsl"
#include "shading.glsl"
#include "clip.glsl"
#include "gdm_voxels.glsl"

uniform bool forcedVoxels;  // the pack's gdm voxels are bound: forced cells slice them

in vec3 vFrame;
flat in int vCell;
flat in vec3 vCamFrame;
flat in int vAxis;
flat in float vSpacing;

uniform float nearPlane;
uniform vec3 viewForward;   // world forward axis of the camera
uniform bool useColor;
uniform vec3 baseColor;

layout(location = 0) out vec4 outColor;
layout(location = 1) out float outDepth;  // linear view depth along the forward axis
layout(location = 2) out vec4 outNormal;  // world-space shading normal (eval)
layout(location = 3) out uint outCell;    // the cell's index + 1

// The slab of the ray before p: from the previous slice plane along it (p is at t = 1; on a
// slice itself, the one before) or, before the first, from where the ray entered the box.
float slabStart(Cell c, vec3 p, vec3 d) {
  vec3 bmin = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x), bmax = vec3(c.boxUV.y, c.boxUV.w, c.boxW.y);
  vec3 t0 = (bmin - vCamFrame) / d, t1 = (bmax - vCamFrame) / d;
  float tEnter = max(max(max(min(t0.x, t1.x), min(t0.y, t1.y)), min(t0.z, t1.z)), 0.0);
  int a = vAxis;
  float k = (p[a] - bmin[a]) / max(vSpacing, 1e-30) - 1e-3 * sign(d[a]);
  float prev = bmin[a] + (d[a] > 0.0 ? ceil(k) - 1.0 : floor(k) + 1.0) * vSpacing;
  float tPrev = d[a] != 0.0 ? (prev - vCamFrame[a]) / d[a] : -1.0;
  return min(max(tPrev, tEnter), 1.0);
}

void main() {
  Cell c = cells[vCell];
  vec3 p = vFrame;
  vec3 d = p - vCamFrame;
  vec3 nWorld;
  uint blk = forcedVoxels ? gdmEntry[vCell] : 0xffffffffu;
  if (blk != 0xffffffffu) {
    // A forced cell with voxels from its source points (gdm's bake): opaque where the ray crossed
    // into the surface since the slab began; the surface's normal there shades.
    float tHit;
    vec3 nFrame;
    uint steps;
    bool touched = false;
    float t0 = slabStart(c, p, d);
    if (!gdmWalk(c, blk, vCamFrame, d, t0, 1.0, t0, tHit, nFrame, steps, touched)) discard;
    nWorld = c.axisU.xyz * nFrame.x + c.axisV.xyz * nFrame.y + c.axisW.xyz * nFrame.z;
  } else {
    // Inside: under the covered surface (the height field's solid), and the first slice inside
    // after a point above it: where the slab began the ray was above the surface or off it. A
    // ray that entered the box under the surface meets the sheet's side or underside first,
    // which the cast modes do not draw either; one that rises out of the solid and falls back
    // in is drawn where it falls back.
    float h = sampleHeight(c, p.xy);
    if (h == kUncovered || p.z > h) discard;
    vec3 q = vCamFrame + d * slabStart(c, p, d);
    float hq = sampleHeight(c, q.xy);
    if (hq != kUncovered && q.z <= hq) discard;
    if (storedNormals) {
      nWorld = sampleNormal(c, p.xy);
    } else {
      vec3 nFrame = gradientNormal(c, p.xy);
      nWorld = c.axisU.xyz * nFrame.x + c.axisV.xyz * nFrame.y + c.axisW.xyz * nFrame.z;
    }
  }
  vec3 world = cellRelativeToCamera(c) + c.axisU.xyz * p.x + c.axisV.xyz * p.y + c.axisW.xyz * p.z;
  float viewDepth = dot(world, viewForward);
  if (viewDepth <= nearPlane || isClipped(world)) discard;
  vec3 albedo = useColor ? sampleColor(c, p.xy) : baseColor;
  outColor = vec4(shade(albedo, nWorld, world), 1.0);
  outDepth = viewDepth;
  outNormal = vec4(normalize(nWorld), 0.0);
  outCell = uint(vCell) + 1u;
}
