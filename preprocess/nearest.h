// Distance from query points to the nearest of a fixed set of samples (FLANN kd-tree). Used by
// `scanatlas eval` for its reference-free accuracy measure: how far the rendered surface lies
// from every input point, in sample spacings (walls, skirts and columns become numbers).
#pragma once
#include <cstddef>
#include <cstdint>
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
  // +inf when there are no samples. Runs on every core. nearest (may be null): that sample's
  // index, or UINT32_MAX.
  void distances(const double* queries, size_t m, double* out, uint32_t* nearest = nullptr) const;
  // Per sample, the side of the area it stands for: the distance to its 8th nearest other
  // sample times sqrt(pi / 8) (the packer's area spacing, preprocess/normals.h); 0 when there
  // are fewer. Runs on every core.
  std::vector<float> areaSpacings() const;

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
  // Fraction of pixels beyond 3 local spacings: the nearest sample's own area spacing where it
  // exceeds the pack's (a surface sampled more sparsely than the rest), else the pack's. -1:
  // not measured.
  double beyond3Local = -1;
};
// localSpacings (may be null): per distance, the local spacing it is measured against, in the
// same units (at least 1 where the pack's spacing is the unit).
FarStats summarizeFar(const std::vector<double>& distancesInSpacings, const std::vector<double>* localSpacings = nullptr);

}  // namespace sa
