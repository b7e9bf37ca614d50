// Runs a third-party reader in a forked child process. libdraco and OpenMesh are not hardened
// against hostile files: fuzzing found small inputs that make libdraco allocate gigabytes and
// OpenMesh's OBJ reader abort on an assertion. In the child, under an address-space limit, such
// a file costs a failed child; here it becomes a bad-input error naming the file. The child
// sends the points back over a pipe in batches, so this process never holds the decoded file.
// The child's stderr goes to /dev/null (set SA_READER_STDERR=1 to see it).
#pragma once
#include <cstdint>
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

// What a reader delivered (batches, triangles), recorded in an unlinked temporary file that
// disappears with the process, even after kill -9. InputSet records Draco and OBJ/OFF/STL
// inputs while it reads their description and replays the recording for the later passes of
// `pack` (bounds, then distribution) and `info`, instead of decoding the file again: libdraco
// and OpenMesh decode whole files, so one decode replaces three. The counts are kept even when
// the file cannot be written (no temporary directory, disk full, over the size cap); then
// replayable() is false and callers decode again.
class StreamRecording : public BatchSink {
 public:
  // batchPoints: the batch size the reader is called with (replays deliver the same batches).
  explicit StreamRecording(size_t batchPoints);
  ~StreamRecording() override;
  StreamRecording(const StreamRecording&) = delete;
  StreamRecording& operator=(const StreamRecording&) = delete;

  Status onPoints(const PointBatch& b) override;
  Status onTriangles(const uint32_t* indices, size_t count) override;
  void finish();  // the reader delivered everything

  bool replayable(size_t batchPoints) const;
  // Delivers the recorded batches (and the triangles when `triangles`) to `sink`.
  Status replay(BatchSink& sink, bool triangles) const;

  uint64_t points() const { return points_; }
  uint64_t triangles() const { return triangles_; }
  bool anyNormals() const { return normals_; }
  bool anyColors() const { return colors_; }
  uint64_t bytes() const { return bytes_; }

  // Bytes a recording may take: SA_RECORDING_MAX_MB, else 4 GiB (512 MiB where the temporary
  // directory is in memory, tmpfs).
  static uint64_t capBytes();

 private:
  void write(const void* p, size_t n);
  size_t batchPoints_;
  int fd_ = -1;
  bool ok_ = false, finished_ = false, normals_ = false, colors_ = false;
  uint64_t points_ = 0, triangles_ = 0, bytes_ = 0, cap_ = 0;
};

}  // namespace sa
