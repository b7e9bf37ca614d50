// The byte buffers the ranks of a cluster pack exchange (common/serial.h): what is written
// reads back field for field, and a buffer cut short is caught rather than read past its end.
#include <gtest/gtest.h>

#include <array>

#include "common/serial.h"

namespace sa {
namespace {

struct Record {
  std::vector<uint32_t> ids;
  std::vector<std::pair<uint32_t, uint32_t>> pairs;
  std::vector<std::string> names;
  std::string path;
  std::array<double, 3> xyz{};
  bool flag = false;
  template <class IO>
  void io(IO& b) {
    b.io(ids), b.io(pairs), b.io(names), b.io(path), b.io(xyz), b.io(flag);
  }
};

TEST(Serial, WhatIsWrittenReadsBackFieldForField) {
  Record a;
  a.ids = {1, 2, 4000000000u};
  a.pairs = {{7, 8}, {9, 10}};
  a.names = {"", "chunk-17.bin", std::string(3, '\0')};
  a.path = "/scratch/x";
  a.xyz = {1.5, -2e300, 3};
  a.flag = true;
  ByteWriter w;
  a.io(w);
  w.put<uint32_t>(99);
  Record b;
  ByteReader r(w.bytes());
  b.io(r);
  uint32_t tail = 0;
  r.get(tail);
  EXPECT_TRUE(r.done());
  EXPECT_EQ(b.ids, a.ids);
  EXPECT_EQ(b.pairs, a.pairs);
  EXPECT_EQ(b.names, a.names);
  EXPECT_EQ(b.path, a.path);
  EXPECT_EQ(b.xyz, a.xyz);
  EXPECT_EQ(b.flag, a.flag);
  EXPECT_EQ(tail, 99u);
}

TEST(Serial, ABufferCutShortIsCaught) {
  ByteWriter w;
  w.put(std::vector<double>(1000, 1.0));
  std::vector<uint8_t> cut(w.bytes().begin(), w.bytes().begin() + 100);
  EXPECT_DEATH(
      {
        ByteReader r(cut);
        std::vector<double> v;
        r.get(v);
      },
      "");
}

}  // namespace
}  // namespace sa
