// Clip box and section plane (the viewer's Clip panel), camera-relative like everything else.
uniform int clipFlags;       // bit 0: clip box, bit 1: section plane
uniform vec3 clipBoxMin;     // camera-relative
uniform vec3 clipBoxMax;
uniform vec4 clipPlane;      // keep p where dot(clipPlane.xyz, p) + clipPlane.w >= 0 (p camera-relative)

bool isClipped(vec3 p) {
  if ((clipFlags & 1) != 0 && (any(lessThan(p, clipBoxMin)) || any(greaterThan(p, clipBoxMax)))) return true;
  if ((clipFlags & 2) != 0 && dot(clipPlane.xyz, p) + clipPlane.w < 0.0) return true;
  return false;
}
