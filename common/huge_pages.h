#pragma once
#include <cstddef>

namespace sa {

// Large allocations are backed by transparent huge pages where the kernel offers them on request
// (/sys/kernel/mm/transparent_hugepage/enabled "madvise", the common default, or "always").
// First touches of a packing run's large buffers (kd grids, chunk records, per-point arrays) then
// fault 2 MiB at a time instead of 4 KiB: on the 2-core VM this project is measured on, page
// faults were about a tenth of a pack's CPU samples, most of them on one core between parallel
// loops. Allocations of at least this many bytes are advised:
constexpr size_t kHugePageAdviseBytes = size_t(2) << 20;

// madvise(MADV_HUGEPAGE) over the whole 2 MiB pages inside [p, p + n); false where none lies
// inside or the kernel refused (no THP support). Harmless on memory already touched.
bool adviseHugePages(void* p, size_t n);

}  // namespace sa
