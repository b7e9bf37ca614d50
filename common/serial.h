// Byte buffers for what the ranks of a cluster pack exchange (preprocess/cluster.h): values,
// strings and vectors of trivially copyable types, in this machine's byte order (every rank of
// one job runs the same binary).
#pragma once
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "common/error.h"

namespace sa {

class ByteWriter {
 public:
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    append(&v, sizeof(T));
  }
  void put(const std::string& s) {
    put<uint64_t>(s.size());
    append(s.data(), s.size());
  }
  template <class T>
  void put(const std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    put<uint64_t>(v.size());
    append(v.data(), v.size() * sizeof(T));
  }
  template <class A, class B>
  void put(const std::vector<std::pair<A, B>>& v) {
    put<uint64_t>(v.size());
    for (const auto& [a, b] : v) put(a), put(b);
  }
  void put(const std::vector<std::string>& v) {
    put<uint64_t>(v.size());
    for (const std::string& s : v) put(s);
  }
  // io(): the same call reads (ByteReader) or writes, so one function lists a record's fields.
  template <class T>
  void io(const T& v) {
    put(v);
  }
  std::vector<uint8_t>& bytes() { return bytes_; }

 private:
  void append(const void* p, size_t n) {
    const size_t at = bytes_.size();
    bytes_.resize(at + n);
    if (n) std::memcpy(bytes_.data() + at, p, n);
  }
  std::vector<uint8_t> bytes_;
};

// Reads what a ByteWriter wrote, in the same order. A buffer that ends early is a programming
// mistake (both sides are this binary): SA_CHECK.
class ByteReader {
 public:
  explicit ByteReader(const std::vector<uint8_t>& b) : p_(b.data()), end_(b.data() + b.size()) {}
  template <class T>
  void get(T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    take(&v, sizeof(T));
  }
  void get(std::string& s) {
    uint64_t n = 0;
    get(n);
    SA_CHECK(n <= size_t(end_ - p_));
    s.assign(reinterpret_cast<const char*>(p_), n);
    p_ += n;
  }
  template <class T>
  void get(std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    uint64_t n = 0;
    get(n);
    SA_CHECK(n <= size_t(end_ - p_) / (sizeof(T) ? sizeof(T) : 1));
    v.resize(n);
    take(v.data(), n * sizeof(T));
  }
  template <class A, class B>
  void get(std::vector<std::pair<A, B>>& v) {
    uint64_t n = 0;
    get(n);
    SA_CHECK(n <= size_t(end_ - p_) / (sizeof(A) + sizeof(B)));
    v.resize(n);
    for (auto& [a, b] : v) get(a), get(b);
  }
  void get(std::vector<std::string>& v) {
    uint64_t n = 0;
    get(n);
    SA_CHECK(n <= size_t(end_ - p_) / sizeof(uint64_t));
    v.resize(n);
    for (std::string& s : v) get(s);
  }
  template <class T>
  void io(T& v) {
    get(v);
  }
  bool done() const { return p_ == end_; }

 private:
  void take(void* out, size_t n) {
    SA_CHECK(n <= size_t(end_ - p_));
    if (n) std::memcpy(out, p_, n);
    p_ += n;
  }
  const uint8_t* p_;
  const uint8_t* end_;
};

}  // namespace sa
