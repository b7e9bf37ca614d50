// Shading shared by the surface modes.
uniform int shadingMode;   // 0 Lambert with head light, 1 normals, 2 height colour ramp
uniform vec3 upAxis;       // world up, for the height ramp
uniform float heightLo;    // ramp range, heights along upAxis relative to the camera
uniform float heightHi;
uniform bool headLight;    // true: the light sits at the eye; false: lightDir
uniform vec3 lightDir;     // direction toward the light (world), when not a head light
bool inShadow = false;     // set by the caller: the point's own cell blocks the light (--shadows)

vec3 shadeLambert(vec3 albedo, vec3 normal, vec3 toEye) {
  // Height-field normals face the cell's W side; turn them toward the viewer so the light
  // test is two-sided like the head light's.
  vec3 n = normalize(normal);
  if (dot(n, toEye) < 0.0) n = -n;
  float ndl = headLight ? abs(dot(n, normalize(toEye))) : (inShadow ? 0.0 : max(dot(n, normalize(lightDir)), 0.0));
  return albedo * (0.12 + 0.88 * ndl);
}

// A perceptually ordered ramp (blue - cyan - green - yellow - red).
vec3 heightRamp(float t) {
  t = clamp(t, 0.0, 1.0);
  vec3 c = vec3(smoothstep(0.5, 0.8, t), smoothstep(0.0, 0.35, t) * (1.0 - smoothstep(0.8, 1.0, t)),
                1.0 - smoothstep(0.25, 0.55, t));
  return c;
}

// worldRel: the shaded point relative to the camera.
vec3 shade(vec3 albedo, vec3 normal, vec3 worldRel) {
  if (shadingMode == 1) return normalize(normal) * 0.5 + 0.5;
  if (shadingMode == 2) {
    float t = (dot(worldRel, upAxis) - heightLo) / max(heightHi - heightLo, 1e-30);
    return shadeLambert(heightRamp(t), normal, -worldRel);
  }
  return shadeLambert(albedo, normal, -worldRel);
}
