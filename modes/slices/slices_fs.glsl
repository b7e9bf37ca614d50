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

in vec3 vFrame;
flat in int vCell;
flat in vec3 vCamFrame;

uniform float nearPlane;
uniform vec3 viewForward;   // world forward axis of the camera
uniform bool useColor;
uniform vec3 baseColor;

layout(location = 0) out vec4 outColor;
layout(location = 1) out float outDepth;  // linear view depth along the forward axis
layout(location = 2) out vec4 outNormal;  // world-space shading normal (eval)
layout(location = 3) out uint outCell;    // the cell's index + 1

void main() {
  Cell c = cells[vCell];
  vec3 p = vFrame;
  // Inside: under the covered surface (the height field's solid), reached through the surface:
  // a ray that entered the box already under it came through the sheet's side or underside,
  // which the cast modes do not draw either.
  float h = sampleHeight(c, p.xy);
  bool inside = h != kUncovered && p.z <= h;
  if (inside) {
    vec3 d = p - vCamFrame;
    vec3 bmin = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x), bmax = vec3(c.boxUV.y, c.boxUV.w, c.boxW.y);
    vec3 t0 = (bmin - vCamFrame) / d, t1 = (bmax - vCamFrame) / d;
    float tEnter = max(max(max(min(t0.x, t1.x), min(t0.y, t1.y)), min(t0.z, t1.z)), 0.0);
    vec3 e = vCamFrame + d * tEnter;
    float he = sampleHeight(c, e.xy);
    inside = he == kUncovered || e.z > he;
  }
  if (!inside) discard;
  vec3 nWorld;
  if (storedNormals) {
    nWorld = sampleNormal(c, p.xy);
  } else {
    vec3 nFrame = gradientNormal(c, p.xy);
    nWorld = c.axisU.xyz * nFrame.x + c.axisV.xyz * nFrame.y + c.axisW.xyz * nFrame.z;
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
