#version 450 core
// The `slices` mode (Meyer & Neyret 1998, "Interactive Volumetric Textures"; MODES.md §3): per
// visible cell a stack of sliceCount quads across its box, from face to face, perpendicular to the
// frame axis along which they lie closest together on the view's line (004 §4.2: the axis
// switches per cell, so a grazing view never looks along the slices), ordered front to back so
// early depth rejection skips the hidden ones. The quads are rasterized (their depth is the
// slice's, written by the rasterizer); slices_fs.glsl keeps the fragments under the cell's height
// field. sliceCount 0 (auto, 004 §4.3): per cell the fewest slices, a power of two up to
// kAutoSlices, that lie no farther apart along the view than a pixel at the cell's distance or a
// texel, whichever is larger; the instance's other quads collapse to nothing.
#include "heightfield.glsl"

uniform mat3 viewRotation;  // world -> view rotation (no translation: camera at the origin)
uniform mat4 projection;    // infinite reverse-Z
uniform int sliceCount;     // 0: auto
uniform int sliceAxis;      // -1: per cell against the view; 0, 1, 2: always u, v or w
uniform float pixelAngle;   // the camera's field of view over its height in pixels (radians)
uniform int autoSlices;     // auto: at most this many (viewer/renderer.h kAutoSlices; auto mode: fewer)

layout(std430, binding = 1) readonly buffer DrawItems { uvec2 items[]; };  // (cell, steps)

out vec3 vFrame;            // the vertex in the cell's frame
flat out int vCell;
flat out vec3 vCamFrame;    // the camera in the cell's frame
flat out int vAxis;         // the slicing axis: 0 u, 1 v, 2 w
flat out float vSpacing;    // the slices' spacing along it

const int kQuad[6] = int[6](0, 1, 2, 2, 1, 3);  // two triangles over the quad's corners

void main() {
  uvec2 item = items[gl_InstanceID];
  Cell c = cells[item.x];
  vec3 lo = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x), hi = vec3(c.boxUV.y, c.boxUV.w, c.boxW.y);
  vec3 rel = cellRelativeToCamera(c);  // O - eye
  vec3 cam = -vec3(dot(rel, c.axisU.xyz), dot(rel, c.axisV.xyz), dot(rel, c.axisW.xyz));
  // The axis whose slices lie closest together along the view (004 §4.2, for boxes that are not
  // cubes): the largest view component over the box's extent along it.
  vec3 view = abs(0.5 * (lo + hi) - cam) / max(hi - lo, vec3(1e-30));
  int axis = sliceAxis >= 0 ? sliceAxis : (view.x >= view.y && view.x >= view.z ? 0 : (view.y >= view.z ? 1 : 2));
  int n = sliceCount, drawn = sliceCount;  // this cell's slices; the instance's slice quads
  if (sliceCount == 0) {
    vec3 toBox = 0.5 * (lo + hi) - cam;
    float texel = min((hi.x - lo.x) / c.boxW.z, (hi.y - lo.y) / c.boxW.w);
    float along = max(length(toBox) * pixelAngle, texel) * max(abs(toBox[axis]) / max(length(toBox), 1e-30), 1e-3);
    n = 2;
    while (n < autoSlices && (hi[axis] - lo[axis]) / float(n - 1) > along) n *= 2;
    drawn = autoSlices;
  }
  int s = gl_VertexID / 6, corner = kQuad[gl_VertexID % 6];
  int across = axis;
  float at;
  if (s >= n && s < drawn) {  // auto: more quads than this cell needs
    gl_Position = vec4(0.0, 0.0, 0.0, 1.0);
    return;
  }
  if (s < n) {
    if (cam[axis] > 0.5 * (lo[axis] + hi[axis])) s = n - 1 - s;  // front to back
    // From face to face: a ray that enters the solid meets a slice before it leaves the box
    // through the slicing axis' faces...
    at = n > 1 ? mix(lo[axis], hi[axis], float(s) / float(n - 1)) : 0.5 * (lo[axis] + hi[axis]);
  } else {
    // ...and the box's two far faces across the other axes close the last slab where a ray
    // leaves through them.
    across = (axis + 1 + s - drawn) % 3;
    at = cam[across] < 0.5 * (lo[across] + hi[across]) ? hi[across] : lo[across];
  }
  int a1 = (across + 1) % 3, a2 = (across + 2) % 3;
  vec3 f;
  f[across] = at;
  f[a1] = (corner & 1) != 0 ? hi[a1] : lo[a1];
  f[a2] = (corner & 2) != 0 ? hi[a2] : lo[a2];
  vec3 world = rel + c.axisU.xyz * f.x + c.axisV.xyz * f.y + c.axisW.xyz * f.z;
  gl_Position = projection * vec4(viewRotation * world, 1.0);
  vFrame = f;
  vCell = int(item.x);
  vCamFrame = cam;
  vAxis = axis;
  vSpacing = n > 1 ? (hi[axis] - lo[axis]) / float(n - 1) : hi[axis] - lo[axis];
}
