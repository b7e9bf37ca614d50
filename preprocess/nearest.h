// Distance from query points to the nearest of a fixed set of samples (FLANN kd-tree). Used by
// `scanatlas eval` for its reference-free accuracy measure: how far the rendered surface lies
// from every input point, in sample spacings (walls, skirts and columns become numbers).
#pragma once
#include <cstddef>
#include <memory>
#include <vector>

namespace sa {

class NearestSamples {
 public:
  // xyz: sample positions (interleaved), relative to any origin the queries share.
  explicit NearestSamples(std::vector<float> xyz);
  ~NearestSamples();
  NearestSamples(const NearestSamples&) = delete;
  NearestSamples& operator=(const NearestSamples&) = delete;
  size_t size() const { return xyz_.size() / 3; }
  // Euclidean distance from each of the m queries (xyz interleaved) to its nearest sample;
  // +inf when there are no samples. Runs on every core.
  void distances(const double* queries, size_t m, double* out) const;

 private:
  struct Index;
  std::vector<float> xyz_;
  std::unique_ptr<Index> index_;
};

// Summary of nearest-sample distances in units of the sample spacing.
struct FarStats {
  size_t pixels = 0;
  double median = 0, p99 = 0;
  double beyond3 = 0, beyond10 = 0;  // fractions of pixels
};
FarStats summarizeFar(const std::vector<double>& distancesInSpacings);

}  // namespace sa
