#include "formats/writers.h"

#include <charconv>
#include <cstring>
#include <vector>

namespace sa {
namespace {

// Buffers output and writes it through an AtomicFile at increasing offsets.
class Output {
 public:
  Status open(const std::string& path) {
    path_ = path;
    return file_.open(path);
  }
  void put(const void* p, size_t n) {
    const char* c = static_cast<const char*>(p);
    buf_.insert(buf_.end(), c, c + n);
  }
  void put(const std::string& s) { put(s.data(), s.size()); }
  Status flush(bool force = false) {
    if (buf_.empty() || (!force && buf_.size() < (4u << 20))) return Status::ok();
    SA_RETURN_IF_ERROR(file_.pwriteAll(buf_.data(), buf_.size(), offset_));
    offset_ += buf_.size();
    buf_.clear();
    return Status::ok();
  }
  Status patch(const std::string& s, uint64_t at) { return file_.pwriteAll(s.data(), s.size(), at); }
  Status commit() {
    SA_RETURN_IF_ERROR(flush(true));
    return file_.commit();
  }
  uint64_t offset() const { return offset_ + buf_.size(); }

 private:
  std::string path_;
  AtomicFile file_;
  std::vector<char> buf_;
  uint64_t offset_ = 0;
};

class PlyWriter : public PointWriter {
 public:
  PlyWriter(const PointLayout& l) : l_(l) {}
  Status open(const std::string& path) {
    SA_RETURN_IF_ERROR(out_.open(path));
    std::string h = "ply\nformat binary_little_endian 1.0\ncomment written by scanatlas convert\nelement vertex ";
    countAt_ = h.size();
    h += std::string(kCountWidth, ' ') + "\nproperty double x\nproperty double y\nproperty double z\n";
    if (l_.normals) h += "property float nx\nproperty float ny\nproperty float nz\n";
    if (l_.colors) h += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    if (l_.intensity) h += "property float intensity\n";
    if (l_.confidence) h += "property float confidence\n";
    if (l_.classification) h += "property uchar classification\n";
    h += "end_header\n";
    out_.put(h);
    return Status::ok();
  }
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) {
      const double p[3] = {b.x[i], b.y[i], b.z[i]};
      out_.put(p, sizeof(p));
      if (l_.normals) {
        const float n[3] = {b.nx[i], b.ny[i], b.nz[i]};
        out_.put(n, sizeof(n));
      }
      if (l_.colors) {
        const uint8_t c[3] = {b.r[i], b.g[i], b.b[i]};
        out_.put(c, 3);
      }
      if (l_.intensity) out_.put(&b.intensity[i], 4);
      if (l_.confidence) out_.put(&b.confidence[i], 4);
      if (l_.classification) out_.put(&b.classification[i], 1);
    }
    n_ += b.size();
    return out_.flush();
  }
  Status finish() override {
    std::string count = std::to_string(n_);
    count.resize(kCountWidth, ' ');
    SA_RETURN_IF_ERROR(out_.flush(true));
    SA_RETURN_IF_ERROR(out_.patch(count, countAt_));
    return out_.commit();
  }
  uint64_t written() const override { return n_; }

 private:
  static constexpr size_t kCountWidth = 20;  // the count is patched in at the end (spaces pad it)
  PointLayout l_;
  Output out_;
  uint64_t n_ = 0;
  size_t countAt_ = 0;
};

class TextWriter : public PointWriter {
 public:
  TextWriter(const PointLayout& l, char d) : l_(l), d_(d) {}
  Status open(const std::string& path) {
    SA_RETURN_IF_ERROR(out_.open(path));
    std::string h;
    auto col = [&](const char* name) {
      if (!h.empty()) h.push_back(d_);
      h.append(name);
    };
    col("x"); col("y"); col("z");
    if (l_.normals) { col("nx"); col("ny"); col("nz"); }
    if (l_.colors) { col("r"); col("g"); col("b"); }
    if (l_.intensity) col("intensity");
    if (l_.confidence) col("confidence");
    if (l_.classification) col("classification");
    out_.put(h + "\n");
    return Status::ok();
  }
  Status onPoints(const PointBatch& b) override {
    char buf[512];  // 12 numbers of at most 24 characters each, separators, newline
    for (size_t i = 0; i < b.size(); ++i) {
      char* p = buf;
      char* e = buf + sizeof(buf);
      auto num = [&](auto v, bool first = false) {
        if (!first) *p++ = d_;
        p = std::to_chars(p, e, v).ptr;  // shortest text that reads back to the same value
      };
      num(b.x[i], true); num(b.y[i]); num(b.z[i]);
      if (l_.normals) { num(b.nx[i]); num(b.ny[i]); num(b.nz[i]); }
      if (l_.colors) { num(int(b.r[i])); num(int(b.g[i])); num(int(b.b[i])); }
      if (l_.intensity) num(b.intensity[i]);
      if (l_.confidence) num(b.confidence[i]);
      if (l_.classification) num(int(b.classification[i]));
      out_.put(buf, size_t(p - buf));
      out_.put("\n", 1);
    }
    n_ += b.size();
    return out_.flush();
  }
  Status finish() override { return out_.commit(); }
  uint64_t written() const override { return n_; }

 private:
  PointLayout l_;
  char d_;
  Output out_;
  uint64_t n_ = 0;
};

}  // namespace

Result<std::unique_ptr<PointWriter>> openPlyWriter(const std::string& path, const PointLayout& layout) {
  auto w = std::make_unique<PlyWriter>(layout);
  SA_RETURN_IF_ERROR(w->open(path));
  return std::unique_ptr<PointWriter>(std::move(w));
}

Result<std::unique_ptr<PointWriter>> openTextWriter(const std::string& path, const PointLayout& layout, char delimiter) {
  auto w = std::make_unique<TextWriter>(layout, delimiter);
  SA_RETURN_IF_ERROR(w->open(path));
  return std::unique_ptr<PointWriter>(std::move(w));
}

}  // namespace sa
