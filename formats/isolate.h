// Runs a third-party reader in a forked child process. libdraco and OpenMesh are not hardened
// against hostile files: fuzzing found small inputs that make libdraco allocate gigabytes and
// OpenMesh's OBJ reader abort on an assertion. In the child, under an address-space limit, such
// a file costs a failed child; here it becomes a bad-input error naming the file. The child
// sends the points back over a pipe in batches, so this process never holds the decoded file.
// The child's stderr goes to /dev/null (set SA_READER_STDERR=1 to see it).
#pragma once
#include <functional>
#include <string>

#include "formats/points.h"

namespace sa {

// `produce` runs in the child: it streams into the sink it is given and may fill `info` with a
// small blob to send back. `sink` (here) receives the batches and triangles; `info` the blob.
// memLimit: bytes of address space the child may add to what it inherits (ignored under
// AddressSanitizer, which reserves terabytes of shadow memory).
// The child also runs under a CPU-time limit (readerCpuLimitSeconds), so a file that makes a
// library loop becomes a bad-input error instead of a hung `pack`.
Status runIsolated(const std::string& path, uint64_t memLimit,
                   const std::function<Status(BatchSink& sink, std::string& info)>& produce, BatchSink* sink,
                   std::string* info);

// CPU seconds the reader child may use on `path`: 120 + 4 per MiB of file, or SA_READER_CPU_S.
uint64_t readerCpuLimitSeconds(const std::string& path);

}  // namespace sa
