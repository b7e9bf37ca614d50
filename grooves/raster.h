// Float images for groove detection: masked low-pass and Gaussian derivatives (grooves/raster.cpp).
#pragma once
#include <cstddef>
#include <vector>

namespace sa::grooves {

struct Img {
  int w = 0, h = 0;
  std::vector<float> a;
  Img() = default;
  Img(int W, int H, float v = 0) : w(W), h(H), a(size_t(W) * H, v) {}
  float& at(int x, int y) { return a[size_t(y) * w + x]; }
  float at(int x, int y) const { return a[size_t(y) * w + x]; }
  float bilinear(double x, double y) const;  // clamped to the image
};

// Gaussian-like low-pass of `value` where mask > 0 (three box passes, normalized by the blurred
// mask, so holes and borders do not pull it down). sigma in pixels.
Img maskedLowPass(const Img& value, const Img& mask, double sigma);

// Gaussian derivatives of `in` at scale sigma (pixels), zero outside the image.
struct Derivatives {
  Img x, y, xx, xy, yy;
};
Derivatives gaussianDerivatives(const Img& in, double sigma);

// Median of v (reorders it); 0 when empty.
float median(std::vector<float>& v);

}  // namespace sa::grooves
