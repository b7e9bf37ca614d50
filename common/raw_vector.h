#pragma once
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

namespace sa {

// An allocator whose value-less construct default-initializes: resize(n) of a vector of
// trivially constructible elements then writes nothing, and the elements are what the caller
// writes next. For per-point arrays that a parallel loop fills at once: std::vector's resize
// zeroed them on one core first, and on the VM this project is measured on, those first touches
// (page faults and the kernel's clearing of fresh pages) were most of a pack's serial time.
template <class T>
struct DefaultInitAllocator : std::allocator<T> {
  using std::allocator<T>::allocator;
  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

// A vector whose resize leaves new elements of a trivial type unwritten (see above); every other
// operation (assign, insert, push_back, copies) behaves as std::vector's.
template <class T>
using RawVector = std::vector<T, DefaultInitAllocator<T>>;

}  // namespace sa
