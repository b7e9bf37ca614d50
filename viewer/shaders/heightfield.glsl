// Shared height-field declarations: the cell table and height-map sampling.
// Lu, Low & Zheng, "Fast Visualization of Complex 3D Models Using Displacement Mapping".

struct Cell {
  vec4 originHi;  // xyz: cell frame origin O relative to the pack origin, high float part
  vec4 originLo;  // xyz: O - originHi (the low part)
  vec4 axisU;     // xyz: U          (rows of M1, §3.2.2)
  vec4 axisV;     // xyz: V
  vec4 axisW;     // xyz: W, the height direction
  vec4 boxUV;     // uMin, uMax, vMin, vMax
  vec4 boxW;      // wMin, wMax, tile width, tile height (texels)
  ivec4 tile;     // page, first interior texel x, y, flags
};

layout(std430, binding = 0) readonly buffer Cells { Cell cells[]; };

// R16UI, 0 = not covered; with COVER_MASKS (--gpu-budget) RG16UI, g the texel's 4 x 4 coverage
// mask (TileImage::cover in atlas/tile_levels.h: bit 4 b + a for column a, row b of its
// sixteenths; level 0's all set).
layout(binding = 0) uniform usampler2DArray heightPages;
layout(binding = 1) uniform sampler2DArray colorPages;    // RGBA8
layout(binding = 2) uniform sampler2DArray normalPages;   // RG16 unorm: octahedral world normal
uniform bool storedNormals;                               // the pack has normal pages (FORMAT.md)

// Camera position relative to the pack origin, split into high and low float parts, so
// that (O - camera) is formed without ever holding an absolute coordinate in float32.
uniform vec3 camHi;
uniform vec3 camLo;

const float kUncovered = -1e30;

vec3 cellRelativeToCamera(Cell c) {
  return (c.originHi.xyz - camHi) + (c.originLo.xyz - camLo);
}

float decodeHeight(Cell c, uint k) {
  if (k == 0u) return kUncovered;
  return c.boxW.x + (float(k) - 1.0) / 65534.0 * (c.boxW.y - c.boxW.x);
}

// Height at texel (i, j) of the tile in frame units, kUncovered where no surface is.
// i in [-1, W], j in [-1, H]: the one-texel gutter repeats the edge (docs/FORMAT.md).
float texelHeight(Cell c, ivec2 ij) { return decodeHeight(c, texelFetch(heightPages, ivec3(c.tile.yz + ij, c.tile.x), 0).r); }

// Continuous texel coordinates of frame point (u, v): texel centres at integers.
vec2 texelCoord(Cell c, vec2 uv) {
  vec2 size = c.boxW.zw;
  return (uv - c.boxUV.xz) / (c.boxUV.yw - c.boxUV.xz) * size - 0.5;
}

// Stored normal of texel (i, j), world coordinates (FORMAT.md: octahedral).
vec3 texelNormal(Cell c, ivec2 ij) {
  vec2 p = texelFetch(normalPages, ivec3(c.tile.yz + ij, c.tile.x), 0).rg * 2.0 - 1.0;
  float z = 1.0 - abs(p.x) - abs(p.y);
  vec2 xy = z < 0.0 ? (1.0 - abs(p.yx)) * vec2(p.x < 0.0 ? -1.0 : 1.0, p.y < 0.0 ? -1.0 : 1.0) : p;
  return normalize(vec3(xy, z));
}

// A world vector in the cell's frame (M1 of §3.2.2 without the translation).
vec3 toFrame(Cell c, vec3 w) { return vec3(dot(w, c.axisU.xyz), dot(w, c.axisV.xyz), dot(w, c.axisW.xyz)); }

// The slope of covered texel n's tangent plane (its stored normal) in frame units per
// texel: continued over an uncovered neighbour ij, hn + dot(slope, ij - n) stands in for its
// height. Without it a coverage edge is a flat step half a texel wide, which a grazing ray
// enters from the side and misses.
vec2 tangentSlope(Cell c, ivec2 n) {
  vec3 nn = toFrame(c, texelNormal(c, n));
  vec2 texel = (c.boxUV.yw - c.boxUV.xz) / c.boxW.zw;
  return -nn.xy / max(nn.z, 0.05) * texel;
}

// Bilinear height at (u, v). Where any of the four texels is uncovered, the nearest texel
// decides coverage (so coverage edges stay sharp and holes stay open), and the uncovered ones
// take its tangent plane (with stored normals; else its height). With masks, the nearest
// texel's mask decides first.
float sampleHeight(Cell c, vec2 uv) {
  vec2 size = c.boxW.zw;
  vec2 f = clamp(texelCoord(c, uv), vec2(-0.5), size - 0.5);
  ivec2 i0 = ivec2(floor(f));
  vec2 a = f - vec2(i0);
  // .g is the texel's coverage mask with COVER_MASKS; without, the texture is R16UI and .g reads 0.
  uvec2 t00 = texelFetch(heightPages, ivec3(c.tile.yz + i0, c.tile.x), 0).rg;
  uvec2 t10 = texelFetch(heightPages, ivec3(c.tile.yz + i0 + ivec2(1, 0), c.tile.x), 0).rg;
  uvec2 t01 = texelFetch(heightPages, ivec3(c.tile.yz + i0 + ivec2(0, 1), c.tile.x), 0).rg;
  uvec2 t11 = texelFetch(heightPages, ivec3(c.tile.yz + i0 + ivec2(1, 1), c.tile.x), 0).rg;
#ifdef COVER_MASKS
  // The nearest texel's mask: the sixteenth of it that f lies in.
  uint m = a.y < 0.5 ? (a.x < 0.5 ? t00.g : t10.g) : (a.x < 0.5 ? t01.g : t11.g);
  ivec2 nm = clamp(i0 + ivec2(step(0.5, a)), ivec2(0), ivec2(size) - 1);
  ivec2 q = clamp(ivec2(floor((f + 0.5 - vec2(nm)) * 4.0)), ivec2(0), ivec2(3));
  if (((m >> uint(4 * q.y + q.x)) & 1u) == 0u) return kUncovered;
#endif
  uvec4 k = uvec4(t00.r, t10.r, t01.r, t11.r);
  float h00 = decodeHeight(c, k.x);
  float h10 = decodeHeight(c, k.y);
  float h01 = decodeHeight(c, k.z);
  float h11 = decodeHeight(c, k.w);
  if (min(min(h00, h10), min(h01, h11)) == kUncovered) {
    // The nearest texel (one of the four; at the tile's edge the gutter repeats it).
    float hn = a.y < 0.5 ? (a.x < 0.5 ? h00 : h10) : (a.x < 0.5 ? h01 : h11);
    if (hn == kUncovered || !storedNormals) return hn;
    ivec2 n = clamp(ivec2(floor(f + 0.5)), ivec2(0), ivec2(size) - 1);
    // One normal fetch for all four corners (SIMD lanes that take this branch make the
    // others wait: it must stay short).
    vec2 s = tangentSlope(c, n);
    vec4 e = hn + vec4(dot(s, vec2(i0 - n)), dot(s, vec2(i0 + ivec2(1, 0) - n)), dot(s, vec2(i0 + ivec2(0, 1) - n)),
                       dot(s, vec2(i0 + ivec2(1, 1) - n)));
    if (h00 == kUncovered) h00 = e.x;
    if (h10 == kUncovered) h10 = e.y;
    if (h01 == kUncovered) h01 = e.z;
    if (h11 == kUncovered) h11 = e.w;
  }
  return mix(mix(h00, h10, a.x), mix(h01, h11, a.x), a.y);
}

// Stored normal at (u, v), world coordinates: bilinear over the four texels around it (decoded
// vectors, not bytes), the uncovered ones left out. Normals come from the data (the mesh's triangles, or the points' smooth normal field), so
// they agree across cell borders where heights' gradients cannot.
vec3 sampleNormal(Cell c, vec2 uv) {
  vec2 size = c.boxW.zw;
  vec2 f = clamp(texelCoord(c, uv), vec2(-0.5), size - 0.5);
  ivec2 i0 = ivec2(floor(f));
  vec2 a = f - vec2(i0);
  vec3 n = vec3(0.0);
  for (int k = 0; k < 4; ++k) {
    ivec2 o = ivec2(k & 1, k >> 1);
    float w = (o.x == 1 ? a.x : 1.0 - a.x) * (o.y == 1 ? a.y : 1.0 - a.y);
    if (texelHeight(c, i0 + o) != kUncovered) n += w * texelNormal(c, i0 + o);
  }
  if (dot(n, n) == 0.0) return texelNormal(c, clamp(ivec2(floor(f + 0.5)), ivec2(0), ivec2(size) - 1));
  return normalize(n);
}

// Normal from the height gradient (packs without normal pages), in the cell's frame: central
// differences over a texel, one-sided where a neighbour is uncovered.
vec3 gradientNormal(Cell c, vec2 uv) {
  vec2 texel = (c.boxUV.yw - c.boxUV.xz) / c.boxW.zw;
  float h = sampleHeight(c, uv);
  float hx0 = sampleHeight(c, uv - vec2(texel.x, 0.0)), hx1 = sampleHeight(c, uv + vec2(texel.x, 0.0));
  float hy0 = sampleHeight(c, uv - vec2(0.0, texel.y)), hy1 = sampleHeight(c, uv + vec2(0.0, texel.y));
  float ddu = 0.0, ddv = 0.0;
  if (hx0 != kUncovered && hx1 != kUncovered) ddu = (hx1 - hx0) / (2.0 * texel.x);
  else if (hx1 != kUncovered) ddu = (hx1 - h) / texel.x;
  else if (hx0 != kUncovered) ddu = (h - hx0) / texel.x;
  if (hy0 != kUncovered && hy1 != kUncovered) ddv = (hy1 - hy0) / (2.0 * texel.y);
  else if (hy1 != kUncovered) ddv = (hy1 - h) / texel.y;
  else if (hy0 != kUncovered) ddv = (h - hy0) / texel.y;
  return normalize(vec3(-ddu, -ddv, 1.0));
}

vec3 sampleColor(Cell c, vec2 uv) {
  ivec2 n = clamp(ivec2(floor(texelCoord(c, uv) + 0.5)), ivec2(0), ivec2(c.boxW.zw) - 1);
  return texelFetch(colorPages, ivec3(c.tile.yz + n, c.tile.x), 0).rgb;
}

// A self-shadow ray from hit point p toward the light l (frame, unit, l.z > 0): its start o just
// above p, and where it leaves the box.
float shadowRayExit(Cell c, vec3 p, vec3 l, out vec3 o) {
  vec2 texel = (c.boxUV.yw - c.boxUV.xz) / c.boxW.zw;
  o = p + vec3(0.0, 0.0, 0.05 * min(texel.x, texel.y));
  vec3 bmin = vec3(c.boxUV.x, c.boxUV.z, c.boxW.x), bmax = vec3(c.boxUV.y, c.boxUV.w, c.boxW.y);
  vec3 t1 = max((bmin - o) / l, (bmax - o) / l);
  return min(min(t1.x, t1.y), t1.z);
}

// The coverage edge between tOut (uncovered) and tIn (covered), by bisection to well under a
// texel: returns a covered t next to the edge.
float coverageEdge(Cell c, vec3 o, vec3 d, float tOut, float tIn) {
  for (int i = 0; i < 10; ++i) {
    float tm = 0.5 * (tOut + tIn);
    vec3 p = o + d * tm;
    if (sampleHeight(c, p.xy) != kUncovered) tIn = tm; else tOut = tm;
  }
  return tIn;
}

// Ray march through one height field (Lu, Low & Zheng §3.3): `steps` linear steps over
// [tEnter, tExit], then `refine` bisection steps and a secant step. The surface is one-sided
// and exists only where covered: a hit is a crossing from above to below inside the covered
// region. Entering the covered region already below the surface means the ray came through
// the side of the sheet (a scan edge, a hole's rim, an open mesh border) - not a surface, so
// no hit; leaving it, the crossing may lie just before the edge, so the edge is checked.
// The stepping loop only finds the next such event; events are resolved outside it, so the
// bisections do not run inside the loop (SIMD lanes would all pay for them at every step).
// Up to 16 events: with fine steps a ray can pass several side entries and scan edges first.
bool marchHeightField(Cell c, vec3 o, vec3 d, float tEnter, float tExit, int steps, int refine, out float tHit) {
  float dt = (tExit - tEnter) / float(steps);
  vec3 p = o + d * tEnter;
  float h = sampleHeight(c, p.xy);
  float tPrev = tEnter, gPrev = p.z - h;
  bool covPrev = h != kUncovered;
  float tLo = 0.0, tHi = 0.0, gLo = 0.0, gHi = 0.0;
  bool found = false;
  int i = 1;
  for (int events = 0; events < 16 && !found; ++events) {
    float t = tPrev, g = gPrev;
    bool cov = covPrev, event = false;
    for (; i <= steps; ++i) {
      t = tEnter + dt * float(i);
      p = o + d * t;
      h = sampleHeight(c, p.xy);
      cov = h != kUncovered;
      g = p.z - h;
      if ((cov && g <= 0.0 && (!covPrev || gPrev > 0.0)) || (!cov && covPrev && gPrev > 0.0)) {
        event = true;
        break;
      }
      tPrev = t;
      gPrev = g;
      covPrev = cov;
    }
    if (!event) return false;
    ++i;
    if (cov && covPrev) {  // a crossing from above
      tLo = tPrev; gLo = gPrev; tHi = t; gHi = g;
      found = true;
    } else if (cov) {  // into the covered region, below the surface: above at the edge?
      float te = coverageEdge(c, o, d, tPrev, t);
      vec3 pe = o + d * te;
      float ge = pe.z - sampleHeight(c, pe.xy);
      if (ge > 0.0) {
        tLo = te; gLo = ge; tHi = t; gHi = g;
        found = true;
      }
    } else {  // out of the covered region from above: below before the edge?
      float te = coverageEdge(c, o, d, t, tPrev);
      vec3 pe = o + d * te;
      float ge = pe.z - sampleHeight(c, pe.xy);
      if (ge <= 0.0) {
        tLo = tPrev; gLo = gPrev; tHi = te; gHi = ge;
        found = true;
      }
    }
    tPrev = t;
    gPrev = g;
    covPrev = cov;
  }
  if (!found) return false;
  // Refinement: bisection keeps the bracket (an uncovered midpoint counts as above: a hole
  // inside the bracket), a last secant step lands on the surface.
  for (int k = 0; k < refine; ++k) {
    float tm = 0.5 * (tLo + tHi);
    vec3 pm = o + d * tm;
    float hm = sampleHeight(c, pm.xy);
    float gm = pm.z - hm;
    if (hm == kUncovered || gm > 0.0) {
      tLo = tm;
      if (hm != kUncovered) gLo = gm;
    } else {
      tHi = tm;
      gHi = gm;
    }
  }
  tHit = (gLo > 0.0 && gHi <= 0.0) ? mix(tLo, tHi, gLo / (gLo - gHi)) : tHi;
  return true;
}
