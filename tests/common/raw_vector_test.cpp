// Vectors resized without zeroing (common/raw_vector.h).
#include <gtest/gtest.h>

#include <cstring>
#include <string>

#include "common/raw_vector.h"

namespace sa {
namespace {

// construct(p) with no value writes nothing: the bytes there stay what they were (value
// initialization, std::allocator's, would zero them).
TEST(RawVector, ConstructWithoutAValueWritesNothing) {
  alignas(double) unsigned char bytes[sizeof(double)];
  std::memset(bytes, 0xab, sizeof bytes);
  DefaultInitAllocator<double> a;
  a.construct(reinterpret_cast<double*>(bytes));
  for (unsigned char b : bytes) EXPECT_EQ(b, 0xab);
  a.construct(reinterpret_cast<double*>(bytes), 2.5);
  double v;
  std::memcpy(&v, bytes, sizeof v);
  EXPECT_EQ(v, 2.5) << "a value given is constructed";
}

// Everything but a value-less resize behaves as std::vector: what it is given, it keeps.
TEST(RawVector, KeepsWhatItIsGiven) {
  RawVector<int> v(3, 7);
  EXPECT_EQ(v, (RawVector<int>{7, 7, 7}));
  v.push_back(1);
  v.resize(1000);
  for (size_t i = 0; i < 1000; ++i) v[i] = int(i) * 3;  // written before read, as the pack's loops do
  v.resize(2);
  EXPECT_EQ(v, (RawVector<int>{0, 3}));
  v.resize(4, 9);
  EXPECT_EQ(v, (RawVector<int>{0, 3, 9, 9}));
  const RawVector<int> copy = v;
  EXPECT_EQ(copy, v);
  RawVector<std::string> s(2, "x");  // not trivial: constructed as std::vector would
  s.emplace_back(3, 'y');
  EXPECT_EQ(s.back(), "yyy");
  s.resize(5);
  EXPECT_TRUE(s[4].empty());
}

}  // namespace
}  // namespace sa
