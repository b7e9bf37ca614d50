// Shading shared by the surface modes: Lambert with a head light.
vec3 shadeLambert(vec3 albedo, vec3 normal, vec3 toEye) {
  float ndl = abs(dot(normalize(normal), normalize(toEye)));
  return albedo * (0.12 + 0.88 * ndl);
}
