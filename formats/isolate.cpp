#include "formats/isolate.h"

#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/statfs.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <new>
#include <vector>

namespace sa {
namespace {

enum Message : uint8_t { kBatch = 1, kTriangles = 2, kInfo = 3, kDone = 4, kError = 5 };

bool writeAll(int fd, const void* p, size_t n) {
  const char* c = static_cast<const char*>(p);
  while (n > 0) {
    const ssize_t w = ::write(fd, c, n);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    c += w;
    n -= size_t(w);
  }
  return true;
}

bool readAll(int fd, void* p, size_t n) {
  char* c = static_cast<char*>(p);
  while (n > 0) {
    const ssize_t r = ::read(fd, c, n);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    c += r;
    n -= size_t(r);
  }
  return true;
}

// The wire form of a batch (the child's pipe and the recordings): kind, first index, count,
// attribute flags, then each present array.
void encodeBatch(const PointBatch& b, std::string& buf) {
  buf.clear();
  const uint8_t kind = kBatch;
  const uint64_t first = b.firstIndex;
  const uint32_t n = uint32_t(b.size());
  const uint8_t flags = uint8_t(b.hasNormals() | b.hasColors() << 1 | b.hasIntensity() << 2 | b.hasConfidence() << 3 |
                                b.hasClassification() << 4 | !b.scan.empty() << 5);
  auto put = [&](const void* p, size_t k) { buf.append(static_cast<const char*>(p), k); };
  auto putVec = [&](const auto& v) { put(v.data(), v.size() * sizeof(v[0])); };
  put(&kind, 1);
  put(&first, 8);
  put(&n, 4);
  put(&flags, 1);
  putVec(b.x); putVec(b.y); putVec(b.z); putVec(b.nx); putVec(b.ny); putVec(b.nz);
  putVec(b.r); putVec(b.g); putVec(b.b);
  putVec(b.intensity); putVec(b.confidence); putVec(b.classification); putVec(b.scan);
}

// The child's sink: serializes batches and triangles onto the pipe.
class PipeSink : public BatchSink {
 public:
  explicit PipeSink(int fd) : fd_(fd) {}
  Status onPoints(const PointBatch& b) override {
    encodeBatch(b, buf_);
    return writeAll(fd_, buf_.data(), buf_.size()) ? Status::ok() : Status::internal("pipe closed");
  }
  Status onTriangles(const uint32_t* idx, size_t count) override {
    const uint8_t kind = kTriangles;
    const uint32_t n = uint32_t(count);
    bool ok = writeAll(fd_, &kind, 1) && writeAll(fd_, &n, 4) && writeAll(fd_, idx, size_t(n) * 12);
    return ok ? Status::ok() : Status::internal("pipe closed");
  }

 private:
  int fd_;
  std::string buf_;
};

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr bool kAddressSanitizer = true;
#else
constexpr bool kAddressSanitizer = false;
#endif
#else
constexpr bool kAddressSanitizer = false;
#endif

template <class T>
bool readVec(int fd, std::vector<T>& v, size_t n) {
  v.resize(n);
  return n == 0 || readAll(fd, v.data(), n * sizeof(T));
}

}  // namespace

uint64_t readerCpuLimitSeconds(const std::string& path) {
  if (const char* e = std::getenv("SA_READER_CPU_S")) {
    char* end = nullptr;
    const unsigned long long v = std::strtoull(e, &end, 10);
    if (end != e && *end == 0 && v > 0) return v;
  }
  struct stat st;
  const uint64_t mib = ::stat(path.c_str(), &st) == 0 ? uint64_t(st.st_size) >> 20 : 0;
  // The slowest reader measured (OpenMesh on OBJ) parses ~4 MiB/s on this project's 2-core
  // machine; 2 minutes plus 4 s per MiB leaves more than 10x headroom.
  return 120 + 4 * mib;
}

namespace {

// Reads the messages a PipeSink wrote (from the child's pipe or a recording) into `sink`.
// `done` tells whether the end marker came; a sink error or the reader's error message is
// returned; a broken stream just stops (done stays false).
Status readMessages(const std::string& path, int fd, BatchSink* sink, std::string* info, bool triangles, bool& done) {
  Status result = Status::ok();
  done = false;
  PointBatch b;
  std::vector<uint32_t> tris;
  while (!done && result.isOk()) {
    uint8_t kind = 0;
    if (!readAll(fd, &kind, 1)) break;
    if (kind == kBatch) {
      uint32_t n = 0;
      uint8_t flags = 0;
      if (!readAll(fd, &b.firstIndex, 8) || !readAll(fd, &n, 4) || !readAll(fd, &flags, 1) || n > (1u << 26)) break;
      b.clear();
      const size_t nn = flags & 1 ? n : 0, nc = flags & 2 ? n : 0;
      if (!readVec(fd, b.x, n) || !readVec(fd, b.y, n) || !readVec(fd, b.z, n) || !readVec(fd, b.nx, nn) ||
          !readVec(fd, b.ny, nn) || !readVec(fd, b.nz, nn) || !readVec(fd, b.r, nc) || !readVec(fd, b.g, nc) ||
          !readVec(fd, b.b, nc) || !readVec(fd, b.intensity, flags & 4 ? n : 0) ||
          !readVec(fd, b.confidence, flags & 8 ? n : 0) || !readVec(fd, b.classification, flags & 16 ? n : 0) ||
          !readVec(fd, b.scan, flags & 32 ? n : 0))
        break;
      if (sink) result = sink->onPoints(b);
    } else if (kind == kTriangles) {
      uint32_t n = 0;
      if (!readAll(fd, &n, 4) || n > (1u << 26) || !readVec(fd, tris, size_t(n) * 3)) break;
      if (sink && triangles) result = sink->onTriangles(tris.data(), n);
    } else if (kind == kInfo) {
      uint32_t n = 0;
      std::string blob;
      if (!readAll(fd, &n, 4) || n > (1u << 20)) break;
      blob.resize(n);
      if (n && !readAll(fd, blob.data(), n)) break;
      if (info) *info = std::move(blob);
    } else if (kind == kError) {
      uint32_t n = 0;
      std::string msg;
      if (readAll(fd, &n, 4) && n < (1u << 16)) {
        msg.resize(n);
        if (!readAll(fd, msg.data(), n)) msg.clear();
      }
      result = Status::badInput(msg.empty() ? path + ": the reader failed" : msg);
    } else if (kind == kDone) {
      done = true;
    } else {
      break;
    }
  }
  return result;
}

[[noreturn]] void childMain(int fd, const std::string& path, uint64_t memLimit,
                            const std::function<Status(BatchSink&, std::string&)>& produce) {
  std::signal(SIGPIPE, SIG_IGN);
  // The libraries print their own complaints (OpenMesh's failed assertions): this process
  // reports the failure instead.
  if (!std::getenv("SA_READER_STDERR")) {
    const int devnull = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
    if (devnull >= 0) ::dup2(devnull, 2);
  }
  auto fail = [&](const std::string& msg) {
    const uint8_t kind = kError;
    const uint32_t n = uint32_t(msg.size());
    (void)(writeAll(fd, &kind, 1) && writeAll(fd, &n, 4) && writeAll(fd, msg.data(), n));
    ::_exit(3);
  };
  try {
    // The limit covers what this process already maps plus the reader's budget.
    if (!kAddressSanitizer) {
      long pages = 0;
      if (std::FILE* f = std::fopen("/proc/self/statm", "r")) {
        if (std::fscanf(f, "%ld", &pages) != 1) pages = 0;
        std::fclose(f);
      }
      const uint64_t now = uint64_t(pages) * uint64_t(sysconf(_SC_PAGESIZE));
      struct rlimit rl;
      rl.rlim_cur = rl.rlim_max = rlim_t(now + memLimit);
      setrlimit(RLIMIT_AS, &rl);
    }
    {
      // A file that makes the library loop must not hang `pack`: SIGXCPU at the soft limit,
      // SIGKILL a little later if that is caught.
      struct rlimit rl;
      rl.rlim_cur = rlim_t(readerCpuLimitSeconds(path));
      rl.rlim_max = rl.rlim_cur + 5;
      setrlimit(RLIMIT_CPU, &rl);
    }
    PipeSink sink(fd);
    std::string info;
    Status s = produce(sink, info);
    if (!s) fail(s.message());
    const uint8_t kind = kInfo;
    const uint32_t n = uint32_t(info.size());
    if (!writeAll(fd, &kind, 1) || !writeAll(fd, &n, 4) || !writeAll(fd, info.data(), n)) ::_exit(4);
    const uint8_t done = kDone;
    (void)writeAll(fd, &done, 1);
    ::_exit(0);
  } catch (const std::bad_alloc&) {
    fail(path + ": reading this file needed more than " + std::to_string(memLimit >> 20) +
         " MiB (corrupt or hostile file)");
  } catch (const std::exception& e) {
    fail(path + ": the reader failed: " + e.what());
  } catch (...) {
    fail(path + ": the reader failed");
  }
  ::_exit(5);
}

}  // namespace

Status runIsolated(const std::string& path, uint64_t memLimit,
                   const std::function<Status(BatchSink& sink, std::string& info)>& produce, BatchSink* sink,
                   std::string* info) {
  int fds[2];
  if (::pipe(fds) != 0) return Status::internal(path + ": cannot create a pipe for the reader process");
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    return Status::internal(path + ": cannot start the reader process");
  }
  if (pid == 0) {
    ::close(fds[0]);
    childMain(fds[1], path, memLimit, produce);
  }
  ::close(fds[1]);
  const int fd = fds[0];
  bool done = false;
  Status result = readMessages(path, fd, sink, info, true, done);
  ::close(fd);
  if (!done) ::kill(pid, SIGKILL);  // stopped early: the child may still be writing
  int status = 0;
  struct rusage ru {};
  while (::wait4(pid, &status, 0, &ru) < 0 && errno == EINTR) {
  }
  const double cpuSeconds = double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
                            1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  if (!result.isOk()) return result;
  if (!done) {
    if (WIFSIGNALED(status) && (WTERMSIG(status) == SIGXCPU || cpuSeconds >= double(readerCpuLimitSeconds(path))))
      return Status::badInput(path + ": the reader used more than " + std::to_string(readerCpuLimitSeconds(path)) +
                              " s of CPU time on this file and was stopped; the file is corrupt or hostile "
                              "(SA_READER_CPU_S=SECONDS raises the limit)");
    if (WIFSIGNALED(status))
      return Status::badInput(path + ": the reader crashed on this file (signal " + std::to_string(WTERMSIG(status)) +
                              "); the file is corrupt or hostile");
    return Status::badInput(path + ": the reader stopped on this file (exit " + std::to_string(WEXITSTATUS(status)) +
                            "); the file is corrupt or hostile");
  }
  return Status::ok();
}

namespace {
constexpr long kTmpfsMagic = 0x01021994;

std::string tempDir() {
  std::error_code ec;
  auto d = std::filesystem::temp_directory_path(ec);
  return ec ? std::string("/tmp") : d.string();
}
}  // namespace

uint64_t StreamRecording::capBytes() {
  if (const char* e = std::getenv("SA_RECORDING_MAX_MB")) {
    char* end = nullptr;
    const unsigned long long v = std::strtoull(e, &end, 10);
    if (end != e && *end == 0) return uint64_t(v) << 20;
  }
  struct statfs fs;
  if (::statfs(tempDir().c_str(), &fs) == 0 && long(fs.f_type) == kTmpfsMagic) return uint64_t(512) << 20;
  return uint64_t(4) << 30;
}

StreamRecording::StreamRecording(size_t batchPoints) : batchPoints_(batchPoints), cap_(capBytes()) {
  if (cap_ == 0) return;
  const std::string dir = tempDir();
  fd_ = ::open(dir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (fd_ < 0) {  // filesystems without O_TMPFILE: create, then unlink at once
    std::string tmpl = dir + "/scanatlas-recording-XXXXXX";
    fd_ = ::mkostemp(tmpl.data(), O_CLOEXEC);
    if (fd_ >= 0) ::unlink(tmpl.c_str());
  }
  ok_ = fd_ >= 0;
}

StreamRecording::~StreamRecording() {
  if (fd_ >= 0) ::close(fd_);
}

void StreamRecording::write(const void* p, size_t n) {
  if (!ok_) return;
  if (bytes_ + n > cap_ || !writeAll(fd_, p, n)) {
    ok_ = false;  // give the disk space back; later passes decode again
    if (::ftruncate(fd_, 0) != 0) {
    }
    return;
  }
  bytes_ += n;
}

Status StreamRecording::onPoints(const PointBatch& b) {
  points_ += b.size();
  normals_ = normals_ || b.hasNormals();
  colors_ = colors_ || b.hasColors();
  if (!ok_) return Status::ok();
  std::string buf;
  encodeBatch(b, buf);
  write(buf.data(), buf.size());
  return Status::ok();
}

Status StreamRecording::onTriangles(const uint32_t* idx, size_t count) {
  triangles_ += count;
  const uint8_t kind = kTriangles;
  const uint32_t n = uint32_t(count);
  write(&kind, 1);
  write(&n, 4);
  write(idx, size_t(n) * 12);
  return Status::ok();
}

void StreamRecording::finish() {
  const uint8_t done = kDone;
  write(&done, 1);
  finished_ = ok_;
}

bool StreamRecording::replayable(size_t batchPoints) const {
  return finished_ && ok_ && batchPoints == batchPoints_;
}

Status StreamRecording::replay(BatchSink& sink, bool triangles) const {
  // A descriptor of its own (its own file offset), so replays never disturb each other.
  const std::string self = "/proc/self/fd/" + std::to_string(fd_);
  const int fd = ::open(self.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Status::internal("cannot reopen the decoded-input recording: " + std::string(std::strerror(errno)));
  bool done = false;
  Status s = readMessages("recording", fd, &sink, nullptr, triangles, done);
  ::close(fd);
  if (s.isOk() && !done) return Status::internal("the decoded-input recording is incomplete");
  return s;
}

}  // namespace sa
