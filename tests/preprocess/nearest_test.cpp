// NearestSamples (eval's reference-free measure): the nearest sample and its distance, each
// sample's own area spacing, and the share of distances beyond 3 local spacings.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "preprocess/nearest.h"

namespace sa {
namespace {

// Two square grids side by side in z = 0: spacing 1 on x < 40, spacing 4 from x = 40 on.
std::vector<float> twoGrids() {
  std::vector<float> xyz;
  for (int j = 0; j < 40; ++j)
    for (int i = 0; i < 40; ++i) xyz.insert(xyz.end(), {float(i), float(j), 0.f});
  for (int j = 0; j < 10; ++j)
    for (int i = 0; i < 10; ++i) xyz.insert(xyz.end(), {float(40 + 4 * i), float(4 * j), 0.f});
  return xyz;
}

TEST(NearestSamples, NearestIndexDistanceAndAreaSpacings) {
  const NearestSamples s(twoGrids());
  const double q[6] = {10.2, 10.1, 0.5, 48.0, 9.0, 0.0};
  double d[2];
  uint32_t at[2];
  s.distances(q, 2, d, at);
  EXPECT_EQ(at[0], 10u * 40 + 10);
  EXPECT_NEAR(d[0], std::sqrt(0.04 + 0.01 + 0.25), 1e-6);
  EXPECT_EQ(at[1], 1600u + 2 * 10 + 2);  // (48, 8)
  EXPECT_NEAR(d[1], 1.0, 1e-6);
  // A square grid's 8th nearest lies at h sqrt 2: the area spacing is h sqrt(2 pi / 8).
  const std::vector<float> a = s.areaSpacings();
  ASSERT_EQ(a.size(), s.size());
  const double unit = std::sqrt(2 * M_PI / 8);
  EXPECT_NEAR(a[20 * 40 + 20], unit, 1e-5);
  EXPECT_NEAR(a[1600 + 5 * 10 + 5], 4 * unit, 1e-5);
}

TEST(NearestSamples, BeyondThreeLocalSpacingsUsesEachDistancesOwnSpacing) {
  const std::vector<double> d = {1, 4, 10, 0.5};
  const FarStats plain = summarizeFar(d);
  EXPECT_DOUBLE_EQ(plain.beyond3, 0.5);
  EXPECT_DOUBLE_EQ(plain.beyond3Local, -1);  // not measured
  const std::vector<double> wide = {1, 2, 4, 1}, narrow = {1, 1, 3, 1};
  EXPECT_DOUBLE_EQ(summarizeFar(d, &wide).beyond3Local, 0.0);
  EXPECT_DOUBLE_EQ(summarizeFar(d, &narrow).beyond3Local, 0.5);
}

}  // namespace
}  // namespace sa
