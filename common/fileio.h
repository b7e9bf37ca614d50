// Small file utilities: a buffered sequential reader that knows its byte offset, an atomic
// output file (temporary file in the target directory + rename), and a scratch directory
// that removes itself.
#pragma once
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "common/error.h"

namespace sa {

// Sequential reader with a fixed-size buffer: memory does not depend on the file size.
class BufferedReader {
 public:
  BufferedReader() = default;
  ~BufferedReader();
  BufferedReader(const BufferedReader&) = delete;
  BufferedReader& operator=(const BufferedReader&) = delete;

  Status open(const std::string& path, size_t bufferBytes = 1 << 20);
  const std::string& path() const { return path_; }
  uint64_t fileSize() const { return fileSize_; }
  uint64_t offset() const { return bufferStart_ + pos_; }
  uint64_t remaining() const { return fileSize_ - offset(); }
  // Copies n bytes; false at end of file (then nothing is consumed meaningfully).
  bool read(void* dst, size_t n);
  bool skip(uint64_t n);
  // Next byte or -1 at end of file.
  int get() {
    if (pos_ == len_ && !refill()) return -1;
    return static_cast<unsigned char>(buf_[pos_++]);
  }
  int peek() {
    if (pos_ == len_ && !refill()) return -1;
    return static_cast<unsigned char>(buf_[pos_]);
  }
  // Reads one line without the terminator (handles \n and \r\n); false at end of file.
  bool readLine(std::string& line, size_t maxLen = 1 << 16);

 private:
  bool refill();
  std::FILE* f_ = nullptr;
  std::string path_;
  std::vector<char> buf_;
  size_t pos_ = 0, len_ = 0;
  uint64_t bufferStart_ = 0, fileSize_ = 0;
};

// Writes to "<path>.tmp-XXXXXX" beside the target; commit() renames it into place.
// Destroyed without commit(), the temporary file is removed: no half-written output.
class AtomicFile {
 public:
  AtomicFile() = default;
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  Status open(const std::string& path);
  int fd() const { return fd_; }
  const std::string& tempPath() const { return tmp_; }
  const std::string& path() const { return path_; }
  Status pwriteAll(const void* data, size_t n, uint64_t offset);
  Status commit();
  void abandon();
  // Another process's temporary (the ranks of a cluster pack write their tiles into rank 0's):
  // opened for writing; leave() syncs and closes it, and it is never renamed or removed here.
  Status join(const std::string& tempPath);
  Status leave();

 private:
  std::string path_, tmp_;
  int fd_ = -1;
  bool owner_ = true;
};

// A private scratch directory removed (with its files) on destruction.
class ScratchDir {
 public:
  ScratchDir() = default;
  ~ScratchDir();
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  Status create(const std::string& parent, const std::string& prefix);
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// Removes entries of `dir` named <prefix><pid>-... whose writer process no longer exists (left by
// a killed run). Returns how many were removed.
size_t removeStaleTemporaries(const std::string& dir, const std::string& prefix);

std::string directoryOf(const std::string& path);
// The extension with its dot, lower-cased (".ply" for "Scan.PLY"); empty when there is none.
std::string lowerExtension(const std::string& path);
std::string joinPath(const std::string& dir, const std::string& name);
Status writeFileAtomic(const std::string& path, const void* data, size_t n);
// A bad-input error when `output` is the same file as one of `inputs` (also through a symbolic
// or hard link): a command must never overwrite what it reads. `what` names the output option.
Status checkNotAnInput(const std::string& output, const std::vector<std::string>& inputs, const std::string& what);
Result<uint64_t> fileSize(const std::string& path);

}  // namespace sa
