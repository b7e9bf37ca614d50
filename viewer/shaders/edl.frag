#version 450 core
// Eye-dome lighting (Boucheny, "Interactive scientific visualization of large datasets",
// 2009): each pixel is darkened by how much nearer its neighbours are, in log depth, which
// brings out relief and silhouettes without normals.
layout(binding = 0) uniform sampler2D colorTex;
layout(binding = 1) uniform sampler2D depthTex;  // linear view depth, +inf = background
uniform float strength;
uniform float radius;   // pixels
in vec2 vUv;
layout(location = 0) out vec4 outColor;

void main() {
  vec4 c = texture(colorTex, vUv);
  float d = texture(depthTex, vUv).r;
  if (isinf(d)) { outColor = c; return; }
  vec2 px = radius / vec2(textureSize(depthTex, 0));
  float ld = log2(d);
  float sum = 0.0;
  const vec2 dirs[8] = vec2[8](vec2(1, 0), vec2(-1, 0), vec2(0, 1), vec2(0, -1),
                               vec2(0.707, 0.707), vec2(-0.707, 0.707), vec2(0.707, -0.707), vec2(-0.707, -0.707));
  for (int i = 0; i < 8; ++i) {
    float n = texture(depthTex, vUv + dirs[i] * px).r;
    float ln = isinf(n) ? ld + 1.0 : log2(n);   // background counts as far
    sum += max(0.0, ld - ln);
  }
  float shade = exp(-sum / 8.0 * 300.0 * strength);
  outColor = vec4(c.rgb * shade, 1.0);
}
