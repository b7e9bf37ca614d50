// The program's replacement of the global operator new (linked into the scanatlas binary only):
// malloc, as the default one, and large blocks advised for transparent huge pages
// (common/huge_pages.h). operator delete stays the default one, which calls free. Left out of
// sanitizer builds, whose runtimes replace these operators themselves.
#include <cstdlib>
#include <new>

#include "common/huge_pages.h"

#if defined(__SANITIZE_ADDRESS__)
#define SA_REPLACE_NEW 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(memory_sanitizer) || __has_feature(thread_sanitizer)
#define SA_REPLACE_NEW 0
#endif
#endif
#ifndef SA_REPLACE_NEW
#define SA_REPLACE_NEW 1
#endif

#if SA_REPLACE_NEW

namespace {

// As the standard's operator new: the new-handler, where one is set, until malloc succeeds.
void* allocate(std::size_t n) {
  void* p;
  while (!(p = std::malloc(n ? n : 1))) {
    const std::new_handler h = std::get_new_handler();
    if (!h) throw std::bad_alloc();
    h();
  }
  if (n >= sa::kHugePageAdviseBytes) sa::adviseHugePages(p, n);
  return p;
}

}  // namespace

void* operator new(std::size_t n) { return allocate(n); }
void* operator new[](std::size_t n) { return allocate(n); }

#endif
