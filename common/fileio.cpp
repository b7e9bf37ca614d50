#include "common/fileio.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>

namespace sa {

BufferedReader::~BufferedReader() {
  if (f_) std::fclose(f_);
}

Status BufferedReader::open(const std::string& path, size_t bufferBytes) {
  path_ = path;
  f_ = std::fopen(path.c_str(), "rb");
  if (!f_) return Status::badInput(path + ": cannot open: " + std::strerror(errno));
  struct stat st;
  if (fstat(fileno(f_), &st) != 0 || !S_ISREG(st.st_mode))
    return Status::badInput(path + ": not a regular file");
  fileSize_ = static_cast<uint64_t>(st.st_size);
  // No bigger than the file (small inputs, and fuzzing, open many files).
  buf_.resize(static_cast<size_t>(std::min<uint64_t>(bufferBytes, fileSize_ + 1)));
  return Status::ok();
}

bool BufferedReader::refill() {
  bufferStart_ += len_;
  pos_ = 0;
  len_ = std::fread(buf_.data(), 1, buf_.size(), f_);
  return len_ > 0;
}

bool BufferedReader::read(void* dst, size_t n) {
  char* out = static_cast<char*>(dst);
  while (n > 0) {
    if (pos_ == len_ && !refill()) return false;
    size_t take = std::min(n, len_ - pos_);
    std::memcpy(out, buf_.data() + pos_, take);
    pos_ += take;
    out += take;
    n -= take;
  }
  return true;
}

bool BufferedReader::skip(uint64_t n) {
  uint64_t inBuf = len_ - pos_;
  if (n <= inBuf) {
    pos_ += n;
    return true;
  }
  uint64_t target = offset() + n;
  if (target > fileSize_) return false;
  if (fseeko(f_, static_cast<off_t>(target), SEEK_SET) != 0) return false;
  bufferStart_ = target;
  pos_ = len_ = 0;
  return true;
}

bool BufferedReader::readLine(std::string& line, size_t maxLen) {
  line.clear();
  int c = get();
  if (c < 0) return false;
  while (c >= 0 && c != '\n') {
    if (line.size() < maxLen) line.push_back(static_cast<char>(c));
    c = get();
  }
  if (!line.empty() && line.back() == '\r') line.pop_back();
  return true;
}

AtomicFile::~AtomicFile() { abandon(); }

Status AtomicFile::open(const std::string& path) {
  path_ = path;
  // The writer's PID in the name lets a later run recognise leftovers of a killed writer.
  std::string tmpl = path + ".tmp-" + std::to_string(getpid()) + "-XXXXXX";
  std::vector<char> buf(tmpl.begin(), tmpl.end());
  buf.push_back('\0');
  fd_ = mkstemp(buf.data());
  if (fd_ < 0) return Status::badInput(path + ": cannot create output file: " + std::strerror(errno));
  tmp_ = buf.data();
  return Status::ok();
}

Status AtomicFile::pwriteAll(const void* data, size_t n, uint64_t offset) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    ssize_t w = ::pwrite(fd_, p, n, static_cast<off_t>(offset));
    if (w < 0) {
      if (errno == EINTR) continue;
      return Status::internal(tmp_ + ": write failed: " + std::strerror(errno));
    }
    p += w;
    n -= static_cast<size_t>(w);
    offset += static_cast<uint64_t>(w);
  }
  return Status::ok();
}

Status AtomicFile::commit() {
  if (fd_ < 0) return Status::internal(path_ + ": commit without open file");
  if (fsync(fd_) != 0) return Status::internal(tmp_ + ": fsync failed: " + std::strerror(errno));
  fchmod(fd_, 0644);
  ::close(fd_);
  fd_ = -1;
  if (std::rename(tmp_.c_str(), path_.c_str()) != 0) {
    std::string err = std::strerror(errno);
    ::unlink(tmp_.c_str());
    return Status::internal(path_ + ": cannot rename temporary file into place: " + err);
  }
  tmp_.clear();
  return Status::ok();
}

void AtomicFile::abandon() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!tmp_.empty() && owner_) ::unlink(tmp_.c_str());
  tmp_.clear();
}

Status AtomicFile::join(const std::string& tempPath) {
  abandon();
  owner_ = false;
  fd_ = ::open(tempPath.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd_ < 0) return Status::internal(tempPath + ": cannot open the output being written: " + std::strerror(errno));
  tmp_ = path_ = tempPath;
  return Status::ok();
}

Status AtomicFile::leave() {
  if (fd_ < 0) return Status::ok();
  const bool synced = fsync(fd_) == 0;
  const std::string err = std::strerror(errno);
  ::close(fd_);
  fd_ = -1;
  tmp_.clear();
  return synced ? Status::ok() : Status::internal(path_ + ": fsync failed: " + err);
}

ScratchDir::~ScratchDir() {
  if (!path_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
}

Status ScratchDir::create(const std::string& parent, const std::string& prefix) {
  std::string tmpl = joinPath(parent, prefix + std::to_string(getpid()) + "-XXXXXX");
  std::vector<char> buf(tmpl.begin(), tmpl.end());
  buf.push_back('\0');
  if (!mkdtemp(buf.data()))
    return Status::badInput(parent + ": cannot create scratch directory: " + std::strerror(errno));
  path_ = buf.data();
  return Status::ok();
}

size_t removeStaleTemporaries(const std::string& dir, const std::string& prefix) {
  size_t removed = 0;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    // <prefix><pid>-XXXXXX
    const std::string rest = name.substr(prefix.size());
    const size_t dash = rest.find('-');
    if (dash == std::string::npos || dash == 0) continue;
    const std::string pidText = rest.substr(0, dash);  // `end` points into it: keep it alive
    char* end = nullptr;
    const long pid = std::strtol(pidText.c_str(), &end, 10);
    if (!end || *end != '\0' || pid <= 0) continue;
    if (kill(pid_t(pid), 0) == 0 || errno != ESRCH) continue;  // the writer is alive (or not ours to judge)
    std::error_code rec;
    if (std::filesystem::remove_all(e.path(), rec) > 0 && !rec) ++removed;
  }
  return removed;
}

std::string directoryOf(const std::string& path) {
  std::filesystem::path p(path);
  auto parent = p.parent_path();
  return parent.empty() ? std::string(".") : parent.string();
}

std::string joinPath(const std::string& dir, const std::string& name) {
  return (std::filesystem::path(dir) / name).string();
}

Status writeFileAtomic(const std::string& path, const void* data, size_t n) {
  AtomicFile f;
  SA_RETURN_IF_ERROR(f.open(path));
  SA_RETURN_IF_ERROR(f.pwriteAll(data, n, 0));
  return f.commit();
}

Result<uint64_t> fileSize(const std::string& path) {
  struct stat st;
  if (stat(path.c_str(), &st) != 0) return Status::badInput(path + ": " + std::strerror(errno));
  return static_cast<uint64_t>(st.st_size);
}

std::string lowerExtension(const std::string& path) {
  std::string e = std::filesystem::path(path).extension().string();
  for (auto& c : e) c = char(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

Status checkNotAnInput(const std::string& output, const std::vector<std::string>& inputs, const std::string& what) {
  struct stat out;
  if (::stat(output.c_str(), &out) != 0) return Status::ok();  // not there yet: cannot be an input
  for (const std::string& in : inputs) {
    struct stat st;
    if (::stat(in.c_str(), &st) == 0 && st.st_dev == out.st_dev && st.st_ino == out.st_ino)
      return Status::badInput(what + " " + output + " is " + (in == output ? "an input of this command" : "the input " + in) +
                              "; refusing to overwrite it (choose another output name)");
  }
  return Status::ok();
}

}  // namespace sa
