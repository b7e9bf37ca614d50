#include "atlas/pack_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <sstream>
#include <thread>

namespace sa {
namespace {

uint64_t alignUp(uint64_t v) { return (v + kSectionAlign - 1) / kSectionAlign * kSectionAlign; }

// zlib's crc32 continued over n bytes (any size).
uLong crc32Of(uLong c, const uint8_t* p, uint64_t n) {
  while (n > 0) {
    uInt take = static_cast<uInt>(std::min<uint64_t>(n, 1u << 30));
    c = crc32(c, p, take);
    p += take;
    n -= take;
  }
  return c;
}

uint32_t crcOf(const uint8_t* p, uint64_t n) { return static_cast<uint32_t>(crc32Of(crc32(0L, Z_NULL, 0), p, n)); }

uint32_t crcOfFile(int fd, uint64_t off, uint64_t n) {
  std::vector<uint8_t> buf(1 << 20);
  uLong c = crc32(0L, Z_NULL, 0);
  while (n > 0) {
    size_t take = static_cast<size_t>(std::min<uint64_t>(n, buf.size()));
    ssize_t r = ::pread(fd, buf.data(), take, static_cast<off_t>(off));
    if (r <= 0) return 0;
    c = crc32(c, buf.data(), static_cast<uInt>(r));
    off += static_cast<uint64_t>(r);
    n -= static_cast<uint64_t>(r);
  }
  return static_cast<uint32_t>(c);
}

SectionEntry makeSection(const char* id, uint64_t off, uint64_t size, uint32_t crc) {
  SectionEntry e{};
  std::memcpy(e.id, id, 4);
  e.offset = off;
  e.size = size;
  e.crc = crc;
  return e;
}

// Runs f(i) for i in [0, n) on every core (interleaved: neighbouring cells' tiles differ in size).
template <class F>
void parallelFor(size_t n, F f) {
  const size_t threads = std::clamp<size_t>(std::thread::hardware_concurrency(), 1, 64);
  std::vector<std::thread> pool;
  for (size_t t = 1; t < std::min(threads, n); ++t)
    pool.emplace_back([&, t] {
      for (size_t i = t; i < n; i += threads) f(i);
    });
  for (size_t i = 0; i < n; i += threads) f(i);
  for (std::thread& th : pool) th.join();
}

// A page section's compressed form (FORMAT.md): u32 tile count, u32 zero, per tile its blob's
// offset from the section start and size (u64 each), then the blobs in cell order.
constexpr size_t kTileIndexHead = 8, kTileIndexEntry = 16;

// Coded tile bytes copied into the final file per write.
constexpr uint64_t kCopyBatchBytes = uint64_t(8) << 20;

// The header and section table at the start of `f`.
Status writeHeader(AtomicFile& f, const std::vector<SectionEntry>& sec, uint64_t fileSize) {
  PackHeader h{};
  std::memcpy(h.magic, kPackMagic, 8);
  h.version = kPackVersion;
  h.byteOrder = kByteOrderMark;
  h.sectionCount = static_cast<uint32_t>(sec.size());
  h.headerSize = sizeof(PackHeader);
  h.fileSize = fileSize;
  h.sectionTableOffset = sizeof(PackHeader);
  h.sectionTableCrc = crcOf(reinterpret_cast<const uint8_t*>(sec.data()), sec.size() * sizeof(SectionEntry));
  SA_RETURN_IF_ERROR(f.pwriteAll(&h, sizeof(h), 0));
  return f.pwriteAll(sec.data(), sec.size() * sizeof(SectionEntry), sizeof(h));
}

}  // namespace

void PackWriter::layOut(const PackMeta& meta, std::vector<CellRecord> cells, const std::string& note) {
  meta_ = meta;
  meta_.cellCount = static_cast<uint32_t>(cells.size());
  cells_ = std::move(cells);
  note_ = note;
  const uint64_t pageTexels = static_cast<uint64_t>(meta_.pageWidth) * meta_.pageHeight;
  metaOff_ = kSectionAlign;
  cellOff_ = alignUp(metaOff_ + sizeof(PackMeta));
  hghtOff_ = alignUp(cellOff_ + cells_.size() * sizeof(CellRecord));
  uint64_t end = hghtOff_ + pageTexels * meta_.pageCount * 2;
  if (meta_.flags & kPackHasNormals) {
    nrmlOff_ = alignUp(end);
    end = nrmlOff_ + pageTexels * meta_.pageCount * kNormalBytes;
  }
  if (meta_.flags & kPackHasColor) {
    colrOff_ = alignUp(end);
    end = colrOff_ + pageTexels * meta_.pageCount * 4;
  }
  noteOff_ = alignUp(end);
  fileSize_ = noteOff_ + note_.size();
}

Status PackWriter::open(const std::string& path, const PackMeta& meta, std::vector<CellRecord> cells,
                        const std::string& note) {
  layOut(meta, std::move(cells), note);
  path_ = path;
  SA_RETURN_IF_ERROR(file_.open(path));
  if (compress_) {
    blobs_.assign(cells_.size(), CellBlobs{});
    return Status::ok();
  }
  // Sparse: untouched page texels read as 0 (= not covered).
  if (ftruncate(file_.fd(), static_cast<off_t>(fileSize_)) != 0)
    return Status::internal(file_.tempPath() + ": cannot size output file: " + std::strerror(errno));
  return Status::ok();
}

Status PackWriter::join(const std::string& tempPath, const PackMeta& meta, std::vector<CellRecord> cells,
                        const std::string& note) {
  layOut(meta, std::move(cells), note);
  return file_.join(tempPath);
}

Status PackWriter::leave() {
  if (!compress_) return file_.leave();
  if (file_.fd() >= 0 && fsync(file_.fd()) != 0)
    return Status::internal(file_.tempPath() + ": fsync failed: " + std::strerror(errno));
  return Status::ok();
}

void PackWriter::adoptBlobs(const std::string& path, const std::vector<uint32_t>& ids,
                            const std::vector<CellBlobs>& refs) {
  sources_.push_back(path);
  const uint32_t source = static_cast<uint32_t>(sources_.size());
  for (size_t k = 0; k < ids.size() && k < refs.size(); ++k) {
    if (ids[k] >= blobs_.size()) continue;
    blobs_[ids[k]] = refs[k];
    for (BlobRef& b : blobs_[ids[k]]) b.source = source;
  }
}

namespace {

// A tile (w x h texels of `bytes` bytes, row-major; null: all zero) with its one-texel gutter
// repeating the edge texels: (w + 2) x (h + 2) texels.
std::vector<uint8_t> withGutter(const uint8_t* src, uint32_t w, uint32_t h, size_t bytes) {
  std::vector<uint8_t> out(size_t(w + 2) * (h + 2) * bytes, 0);
  if (!src) return out;
  for (uint32_t j = 0; j < h + 2; ++j) {
    const uint32_t sj = std::clamp<uint32_t>(j, 1, h) - 1;
    uint8_t* row = &out[size_t(j) * (w + 2) * bytes];
    std::memcpy(row + bytes, src + size_t(sj) * w * bytes, size_t(w) * bytes);
    std::memcpy(row, row + bytes, bytes);
    std::memcpy(row + size_t(w + 1) * bytes, row + size_t(w) * bytes, bytes);
  }
  return out;
}

}  // namespace

Status PackWriter::writeTile(uint32_t cellIndex, const uint16_t* heights, const uint8_t* normals, const uint8_t* rgba,
                             std::span<const uint8_t> normalPyramid, std::span<const uint8_t> rgbaPyramid) {
  if (!(meta_.flags & kPackHasNormals)) normals = nullptr;
  if (!(meta_.flags & kPackHasColor)) rgba = nullptr;
  return compress_ ? writeCodedTile(cellIndex, heights, normals, rgba, normals ? normalPyramid : std::span<const uint8_t>{},
                                    rgba ? rgbaPyramid : std::span<const uint8_t>{})
                   : writeRawTile(cellIndex, heights, normals, rgba);
}

Status PackWriter::writeRawTile(uint32_t cellIndex, const uint16_t* heights, const uint8_t* normals, const uint8_t* rgba) {
  const CellRecord& c = cells_[cellIndex];
  const uint32_t W = c.tileW, H = c.tileH, P = meta_.pageWidth;
  const uint64_t pageTexels = static_cast<uint64_t>(P) * meta_.pageHeight;
  const uint64_t row0 = pageTexels * c.page + static_cast<uint64_t>(c.tileY - 1) * P + (c.tileX - 1);
  struct Layer {
    const uint8_t* src;
    size_t bytes;
    uint64_t off;
  };
  const Layer layers[3] = {{reinterpret_cast<const uint8_t*>(heights), 2, hghtOff_},
                           {normals, size_t(kNormalBytes), nrmlOff_},
                           {rgba, 4, colrOff_}};
  for (const Layer& l : layers) {
    if (!l.src) continue;
    const std::vector<uint8_t> t = withGutter(l.src, W, H, l.bytes);
    const size_t rowBytes = size_t(W + 2) * l.bytes;
    for (uint32_t j = 0; j < H + 2; ++j)
      SA_RETURN_IF_ERROR(file_.pwriteAll(&t[j * rowBytes], rowBytes, l.off + (row0 + uint64_t(j) * P) * l.bytes));
  }
  return Status::ok();
}

// The tile's three layers coded (the section's layout) and appended to this process's
// temporary, and (storeLevels) its stored coarser levels; a layer the pack has but the call
// lacks is coded as zeros, as raw pages hold it.
Status PackWriter::writeCodedTile(uint32_t cellIndex, const uint16_t* heights, const uint8_t* normals,
                                  const uint8_t* rgba, std::span<const uint8_t> normalPyramid,
                                  std::span<const uint8_t> rgbaPyramid) {
  const CellRecord& c = cells_[cellIndex];
  const TileRegion whole{0, 0, c.tileW + 2u, c.tileH + 2u};
  const uint8_t* src[3] = {reinterpret_cast<const uint8_t*>(heights), normals, rgba};
  const bool present[3] = {true, (meta_.flags & kPackHasNormals) != 0, (meta_.flags & kPackHasColor) != 0};
  const TexelLayout layouts[3] = {kHeightTexels, kNormalTexels, kColorTexels};
  const std::span<const uint8_t> pyramids[3] = {{}, normalPyramid, rgbaPyramid};
  TileImage level0;  // the tile as a reader decodes it, for its coarser levels
  level0.w = c.tileW;
  level0.h = c.tileH;
  auto append = [&](const std::vector<uint8_t>& blob, int layer) -> Status {
    const uint64_t at = blobEnd_.fetch_add(blob.size());
    SA_RETURN_IF_ERROR(file_.pwriteAll(blob.data(), blob.size(), at));
    blobs_[cellIndex][size_t(layer)] = BlobRef{at, blob.size(), 0, 0};
    return Status::ok();
  };
  for (int l = 0; l < 3; ++l) {
    if (!present[l]) continue;
    std::vector<uint8_t> t = withGutter(src[l], c.tileW, c.tileH, size_t(layouts[l].texelBytes()));
    const TileForm form = l == 1 ? normalForm_ : TileForm::kSmaller;
    SA_RETURN_IF_ERROR(append(encodeTile(t.data(), whole.w, whole, layouts[l], level_, form, pyramids[l]), l));
    if (!storeLevels_) continue;
    if (l == 0) {
      level0.heights.resize(t.size() / 2);
      std::memcpy(level0.heights.data(), t.data(), t.size());
    } else {
      (l == 1 ? level0.normals : level0.rgba) = std::move(t);
    }
  }
  if (storeLevels_) SA_RETURN_IF_ERROR(append(encodeStoredLevels(std::move(level0), level_), 3));
  return Status::ok();
}

Status PackWriter::finish() {
  if (compress_) return finishCompressed();
  const uint64_t pageTexels = static_cast<uint64_t>(meta_.pageWidth) * meta_.pageHeight;
  SA_RETURN_IF_ERROR(file_.pwriteAll(&meta_, sizeof(meta_), metaOff_));
  SA_RETURN_IF_ERROR(file_.pwriteAll(cells_.data(), cells_.size() * sizeof(CellRecord), cellOff_));
  if (!note_.empty()) SA_RETURN_IF_ERROR(file_.pwriteAll(note_.data(), note_.size(), noteOff_));
  std::vector<SectionEntry> sec;
  sec.push_back(makeSection("META", metaOff_, sizeof(PackMeta),
                            crcOf(reinterpret_cast<const uint8_t*>(&meta_), sizeof(meta_))));
  sec.push_back(makeSection("CELL", cellOff_, cells_.size() * sizeof(CellRecord),
                            crcOf(reinterpret_cast<const uint8_t*>(cells_.data()), cells_.size() * sizeof(CellRecord))));
  const uint64_t hSize = pageTexels * meta_.pageCount * 2;
  sec.push_back(makeSection("HGHT", hghtOff_, hSize, crcOfFile(file_.fd(), hghtOff_, hSize)));
  if (meta_.flags & kPackHasNormals)
    sec.push_back(makeSection("NRML", nrmlOff_, hSize / 2 * kNormalBytes, crcOfFile(file_.fd(), nrmlOff_, hSize / 2 * kNormalBytes)));
  if (meta_.flags & kPackHasColor) {
    const uint64_t cSize = pageTexels * meta_.pageCount * 4;
    sec.push_back(makeSection("COLR", colrOff_, cSize, crcOfFile(file_.fd(), colrOff_, cSize)));
  }
  sec.push_back(makeSection("NOTE", noteOff_, note_.size(),
                            crcOf(reinterpret_cast<const uint8_t*>(note_.data()), note_.size())));
  SA_RETURN_IF_ERROR(writeHeader(file_, sec, fileSize_));
  return file_.commit();
}

// The final file from the coded tiles: META, CELL, the page sections (each tile's blob read
// back from the temporary that holds it, in cell order), NOTE; then the temporaries removed.
Status PackWriter::finishCompressed() {
  std::vector<int> fds{file_.fd()};
  Status s = Status::ok();
  for (const std::string& p : sources_) {
    fds.push_back(::open(p.c_str(), O_RDONLY | O_CLOEXEC));
    if (fds.back() < 0 && s) s = Status::internal(p + ": cannot read a cluster rank's coded tiles: " + std::strerror(errno));
  }
  AtomicFile out;
  if (s) s = out.open(path_);
  const size_t count = 3 + size_t((meta_.flags & kPackHasNormals) != 0) + size_t((meta_.flags & kPackHasColor) != 0) +
                       size_t(storeLevels_);
  uint64_t off = alignUp(sizeof(PackHeader) + count * sizeof(SectionEntry));
  std::vector<SectionEntry> sec;
  auto put = [&](const char* id, const void* data, uint64_t size) {
    if (s && size) s = out.pwriteAll(data, size, off);
    sec.push_back(makeSection(id, off, size, crcOf(static_cast<const uint8_t*>(data), size)));
    off = alignUp(off + size);
  };
  put("META", &meta_, sizeof(meta_));
  put("CELL", cells_.data(), cells_.size() * sizeof(CellRecord));
  const char* ids[4] = {"HGTZ", "NRMZ", "COLZ", "MIPZ"};
  const bool present[4] = {true, (meta_.flags & kPackHasNormals) != 0, (meta_.flags & kPackHasColor) != 0, storeLevels_};
  for (int l = 0; l < 4 && s; ++l) {
    if (!present[l]) continue;
    sec.emplace_back();
    s = copySection(out, fds, l, ids[l], off, sec.back());
    off = alignUp(sec.back().offset + sec.back().size);
  }
  put("NOTE", note_.data(), note_.size());
  for (size_t i = 1; i < fds.size(); ++i)
    if (fds[i] >= 0) ::close(fds[i]);
  if (s) s = writeHeader(out, sec, off);
  if (s && ::ftruncate(out.fd(), off_t(off)) != 0)
    s = Status::internal(out.tempPath() + ": cannot size the file: " + std::strerror(errno));
  if (s) s = out.commit();
  file_.abandon();
  for (const std::string& p : sources_) ::unlink(p.c_str());
  return s;
}

// One page section (FORMAT.md, "Compressed pages") at `off` of `out`: u32 tile count, u32 zero,
// per tile its blob's offset from the section start and size, then the blobs in cell order,
// read from the temporaries `fds` (by each blob's source) in batches.
Status PackWriter::copySection(AtomicFile& out, const std::vector<int>& fds, int layer, const char* id, uint64_t off,
                               SectionEntry& entry) {
  std::vector<uint8_t> index(kTileIndexHead + kTileIndexEntry * cells_.size(), 0);
  const uint32_t count = uint32_t(cells_.size());
  std::memcpy(index.data(), &count, 4);
  uint64_t at = index.size();  // from the section start
  for (size_t i = 0; i < cells_.size(); ++i) {
    const BlobRef& b = blobs_[i][size_t(layer)];
    if (b.size == 0 || b.source >= fds.size())
      return Status::internal(path_ + ": cell " + std::to_string(i) + " has no coded tile in " + id);
    const uint64_t e[2] = {at, b.size};
    std::memcpy(index.data() + kTileIndexHead + kTileIndexEntry * i, e, sizeof e);
    at += b.size;
  }
  SA_RETURN_IF_ERROR(out.pwriteAll(index.data(), index.size(), off));
  uLong crc = crc32(crc32(0L, Z_NULL, 0), index.data(), uInt(index.size()));
  std::vector<uint8_t> buf;
  uint64_t written = index.size();
  auto flush = [&]() -> Status {
    crc = crc32Of(crc, buf.data(), buf.size());
    SA_RETURN_IF_ERROR(out.pwriteAll(buf.data(), buf.size(), off + written));
    written += buf.size();
    buf.clear();
    return Status::ok();
  };
  for (size_t i = 0; i < cells_.size(); ++i) {
    const BlobRef& b = blobs_[i][size_t(layer)];
    const size_t at0 = buf.size();
    buf.resize(at0 + b.size);
    if (::pread(fds[b.source], buf.data() + at0, b.size, off_t(b.offset)) != ssize_t(b.size))
      return Status::internal(path_ + ": cannot read back the coded tile of cell " + std::to_string(i));
    if (buf.size() >= kCopyBatchBytes) SA_RETURN_IF_ERROR(flush());
  }
  SA_RETURN_IF_ERROR(flush());
  entry = makeSection(id, off, at, static_cast<uint32_t>(crc));
  return Status::ok();
}

PackReader::~PackReader() {
  if (base_) munmap(const_cast<uint8_t*>(base_), size_);
}

const SectionEntry* PackReader::find(const char id[4]) const {
  for (uint32_t i = 0; i < header_->sectionCount; ++i)
    if (std::memcmp(sections_[i].id, id, 4) == 0) return &sections_[i];
  return nullptr;
}

TileRegion gutteredTile(const CellRecord& c) { return {c.tileX - 1u, c.tileY - 1u, c.tileW + 2u, c.tileH + 2u}; }

Status PackReader::mapFile(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0) return Status::badInput(path + ": cannot open: " + std::strerror(errno));
  struct stat st;
  if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return Status::badInput(path + ": not a regular file");
  }
  size_ = static_cast<uint64_t>(st.st_size);
  if (size_ < sizeof(PackHeader)) {
    ::close(fd);
    return Status::badInput(path + ": too short to be a pack (" + std::to_string(size_) + " bytes)");
  }
  void* m = mmap(nullptr, size_, PROT_READ, MAP_SHARED, fd, 0);
  ::close(fd);
  if (m == MAP_FAILED) return Status::badInput(path + ": cannot map: " + std::strerror(errno));
  base_ = static_cast<const uint8_t*>(m);
  header_ = reinterpret_cast<const PackHeader*>(base_);
  return Status::ok();
}

Status PackReader::checkHeader() const {
  const std::string& path = path_;
  if (std::memcmp(header_->magic, kPackMagic, 8) != 0)
    return Status::badInput(path + ": not a ScanAtlas pack (bad magic); packs are made by 'scanatlas pack'");
  if (header_->byteOrder != kByteOrderMark)
    return Status::badInput(path + ": byte-order mark mismatch (file written for another byte order)");
  if (header_->version > kPackVersion)
    return Status::badInput(path + ": pack format version " + std::to_string(header_->version) +
                            " is newer than this program understands (version " + std::to_string(kPackVersion) +
                            "); update scanatlas");
  if (header_->version == 0) return Status::badInput(path + ": invalid pack format version 0");
  if (header_->version < kPackVersion)
    return Status::badInput(path + ": pack format version " + std::to_string(header_->version) +
                            " was made by an older scanatlas; pack its sources again (this program writes and reads "
                            "version " + std::to_string(kPackVersion) + ")");
  if (header_->fileSize != size_)
    return Status::badInput(path + ": file is " + std::to_string(size_) + " bytes but its header says " +
                            std::to_string(header_->fileSize) + " (truncated or appended to)");
  return Status::ok();
}

Status PackReader::checkSectionTable() {
  if (header_->sectionCount == 0 || header_->sectionCount > 64 ||
      header_->sectionTableOffset < sizeof(PackHeader) || header_->sectionTableOffset > size_ ||
      uint64_t(header_->sectionCount) * sizeof(SectionEntry) > size_ - header_->sectionTableOffset)
    return Status::badInput(path_ + ": corrupt section table");
  sections_ = reinterpret_cast<const SectionEntry*>(base_ + header_->sectionTableOffset);
  if (crcOf(reinterpret_cast<const uint8_t*>(sections_), header_->sectionCount * sizeof(SectionEntry)) !=
      header_->sectionTableCrc)
    return Status::badInput(path_ + ": section table checksum mismatch (file corrupt)");
  for (uint32_t i = 0; i < header_->sectionCount; ++i) {
    const SectionEntry& s = sections_[i];
    if (s.offset > size_ || s.size > size_ - s.offset || s.offset % 8 != 0)
      return Status::badInput(path_ + ": section " + std::string(s.id, 4) + " lies outside the file");
  }
  return Status::ok();
}

Status PackReader::checkMetaAndCells(bool haveHeights) {
  const SectionEntry* meta = find("META");
  const SectionEntry* cell = find("CELL");
  if (!meta || !cell || !haveHeights)
    return Status::badInput(path_ + ": missing a required section (META, CELL, HGHT or HGTZ)");
  if (meta->size != sizeof(PackMeta)) return Status::badInput(path_ + ": META section has the wrong size");
  if (crcOf(base_ + meta->offset, meta->size) != meta->crc)
    return Status::badInput(path_ + ": META checksum mismatch (file corrupt)");
  meta_ = reinterpret_cast<const PackMeta*>(base_ + meta->offset);
  if (cell->size != uint64_t(meta_->cellCount) * sizeof(CellRecord))
    return Status::badInput(path_ + ": CELL section size does not match the cell count");
  if (crcOf(base_ + cell->offset, cell->size) != cell->crc)
    return Status::badInput(path_ + ": CELL checksum mismatch (file corrupt)");
  cells_ = reinterpret_cast<const CellRecord*>(base_ + cell->offset);
  const uint32_t P = meta_->pageWidth, PH = meta_->pageHeight;
  for (uint32_t d : {P, PH})
    if (d == 0 || d > 65536 || (d & (d - 1)))
      return Status::badInput(path_ + ": page size " + std::to_string(P) + "x" + std::to_string(PH) +
                              " is not a power of two <= 65536 on each side");
  return Status::ok();
}

// Decoded pages take memory the file does not hold: bound them by the cells and the file.
Status PackReader::checkCodedPages() const {
  const uint64_t pageTexels = uint64_t(meta_->pageWidth) * meta_->pageHeight;
  const uint64_t perTexel = 2 + ((meta_->flags & kPackHasNormals) ? kNormalBytes : 0) + ((meta_->flags & kPackHasColor) ? 4 : 0);
  const uint64_t limit = std::max<uint64_t>(uint64_t(256) << 20, 4096 * size_);
  if (meta_->pageCount > std::max<uint32_t>(1, meta_->cellCount) || meta_->pageCount > limit / (pageTexels * perTexel))
    return Status::badInput(path_ + ": " + std::to_string(meta_->pageCount) + " pages of " + std::to_string(meta_->pageWidth) + "x" +
                            std::to_string(meta_->pageHeight) + " is more than its " + std::to_string(meta_->cellCount) +
                            " cells and " + std::to_string(size_) + " bytes can hold");
  for (const char* id : {"NRMZ", "COLZ"}) {
    const bool wanted = (meta_->flags & (id[0] == 'N' ? kPackHasNormals : kPackHasColor)) != 0;
    if (wanted && !find(id))
      return Status::badInput(path_ + ": " + (id[0] == 'N' ? "normal" : "colour") + std::string(" flag set but section ") + id + " missing");
  }
  return Status::ok();
}

Status PackReader::checkRawPages(const SectionEntry& hght) {
  const uint64_t pageTexels = uint64_t(meta_->pageWidth) * meta_->pageHeight;
  // pageTexels * pageCount * 4 can pass 2^64 for hostile headers; bound the count by the file first.
  if (meta_->pageCount > size_ / (pageTexels * 2) || hght.size != pageTexels * meta_->pageCount * 2)
    return Status::badInput(path_ + ": HGHT section size does not match page size and count");
  hght_ = reinterpret_cast<const uint16_t*>(base_ + hght.offset);
  if (meta_->flags & kPackHasNormals) {
    const SectionEntry* nrml = find("NRML");
    if (!nrml || nrml->size != pageTexels * meta_->pageCount * kNormalBytes)
      return Status::badInput(path_ + ": normal flag set but NRML section missing or of the wrong size");
    nrml_ = base_ + nrml->offset;
  }
  if (meta_->flags & kPackHasColor) {
    const SectionEntry* colr = find("COLR");
    if (!colr || colr->size != pageTexels * meta_->pageCount * 4)
      return Status::badInput(path_ + ": colour flag set but COLR section missing or of the wrong size");
    colr_ = base_ + colr->offset;
  }
  return Status::ok();
}

Status PackReader::checkCellRecords() const {
  const uint32_t P = meta_->pageWidth, PH = meta_->pageHeight;
  for (uint32_t i = 0; i < meta_->cellCount; ++i) {
    const CellRecord& c = cells_[i];
    if (c.page >= meta_->pageCount || c.tileW == 0 || c.tileH == 0 || c.tileX < 1 || c.tileY < 1 ||
        uint64_t(c.tileX) + c.tileW + 1 > P || uint64_t(c.tileY) + c.tileH + 1 > PH)
      return Status::badInput(path_ + ": cell " + std::to_string(i) + " has a tile outside its page");
    for (double d : c.box)
      if (!std::isfinite(d)) return Status::badInput(path_ + ": cell " + std::to_string(i) + " has a non-finite box");
    if (!(c.box[1] >= c.box[0] && c.box[3] >= c.box[2] && c.box[5] >= c.box[4]))
      return Status::badInput(path_ + ": cell " + std::to_string(i) + " has an inverted box");
  }
  return Status::ok();
}

Status PackReader::open(const std::string& path, PageLoad pages) {
  path_ = path;
  SA_RETURN_IF_ERROR(mapFile(path));
  SA_RETURN_IF_ERROR(checkHeader());
  SA_RETURN_IF_ERROR(checkSectionTable());
  const SectionEntry* hght = find("HGHT");
  const bool compressed = !hght && find("HGTZ");
  SA_RETURN_IF_ERROR(checkMetaAndCells(hght || compressed));
  SA_RETURN_IF_ERROR(compressed ? checkCodedPages() : checkRawPages(*hght));
  SA_RETURN_IF_ERROR(checkCellRecords());
  if (!compressed || pages == PageLoad::kNone) return Status::ok();
  SA_RETURN_IF_ERROR(checkTileIndexes());
  if (pages == PageLoad::kTiles) return Status::ok();
  SA_RETURN_IF_ERROR(reservePages());
  if (pages == PageLoad::kOnDemand) {
    onDemand_ = true;
    return Status::ok();
  }
  SA_RETURN_IF_ERROR(decodePages("HGTZ", kHeightTexels, hOwn_.data));
  if (nrml_) SA_RETURN_IF_ERROR(decodePages("NRMZ", kNormalTexels, nOwn_.data));
  if (colr_) SA_RETURN_IF_ERROR(decodePages("COLZ", kColorTexels, cOwn_.data));
  return Status::ok();
}

PackReader::OwnedPages::~OwnedPages() { std::free(data); }

Status PackReader::OwnedPages::allocate(uint64_t bytes) {
  std::free(data);
  data = bytes <= SIZE_MAX ? static_cast<uint8_t*>(std::calloc(size_t(std::max<uint64_t>(bytes, 1)), 1)) : nullptr;
  return data ? Status::ok() : Status::badInput("not enough memory");
}

namespace {
struct PageSection {
  const char* id;
  TexelLayout layout;
  uint32_t flag;  // 0: always there
};
constexpr PageSection kPageSections[] = {
    {"HGTZ", kHeightTexels, 0}, {"NRMZ", kNormalTexels, kPackHasNormals}, {"COLZ", kColorTexels, kPackHasColor}};
}  // namespace

// That each compressed section the pack has indexes its tiles.
Status PackReader::checkTileIndexes() {
  const uint32_t n = meta_->cellCount;
  for (const PageSection& x : kPageSections) {
    if (x.flag && !(meta_->flags & x.flag)) continue;
    const std::span<const uint8_t> sec = section(x.id);
    uint32_t count = 0;
    if (sec.size() >= 4) std::memcpy(&count, sec.data(), 4);
    if (sec.size() < kTileIndexHead + kTileIndexEntry * uint64_t(n) || count != n)
      return Status::badInput(path_ + ": section " + x.id + " does not index the pack's " + std::to_string(n) + " tiles");
  }
  const std::span<const uint8_t> mips = section("MIPZ");  // optional: packs before it, pack --no-levels
  uint32_t count = 0;
  if (!mips.empty() && mips.size() >= 4) std::memcpy(&count, mips.data(), 4);
  if (!mips.empty() && (mips.size() < kTileIndexHead + kTileIndexEntry * uint64_t(n) || count != n))
    return Status::badInput(path_ + ": section MIPZ does not index the pack's " + std::to_string(n) + " tiles");
  tilesIndexed_ = true;
  return Status::ok();
}

// Cell i's blob in a compressed section whose index was checked; empty where it lies outside.
std::span<const uint8_t> PackReader::tileBlob(const char id[4], uint32_t i) const {
  const std::span<const uint8_t> sec = section(id);
  uint64_t e[2];
  std::memcpy(e, sec.data() + kTileIndexHead + kTileIndexEntry * uint64_t(i), sizeof e);
  if (e[0] > sec.size() || e[1] > sec.size() - e[0]) return {};
  return sec.subspan(e[0], e[1]);
}

bool PackReader::hasStoredLevels() const { return tilesIndexed_ && find("MIPZ"); }

uint32_t PackReader::storedLevelAtMost(uint32_t i, uint32_t atMost) const {
  if (!hasStoredLevels() || i >= meta_->cellCount) return 0;
  return sa::storedLevelAtMost(tileBlob("MIPZ", i), atMost);
}

Status PackReader::decodeStoredLevel(uint32_t i, uint32_t level, TileImage& out) const {
  if (!hasStoredLevels() || i >= meta_->cellCount) return Status::internal(path_ + ": no stored level of cell " + std::to_string(i));
  const CellRecord& c = cells_[i];
  const Status s = sa::decodeStoredLevel(tileBlob("MIPZ", i), c.tileW, c.tileH, level, hasNormals(), hasColor(), out);
  if (s) return s;
  return Status::badInput(path_ + ": section MIPZ, cell " + std::to_string(i) + ": " + s.message());
}

// Memory for the decoded pages of every compressed section (their indexes checked).
Status PackReader::reservePages() {
  OwnedPages* own[] = {&hOwn_, &nOwn_, &cOwn_};
  for (int k = 0; k < 3; ++k) {
    const PageSection& x = kPageSections[k];
    if (x.flag && !(meta_->flags & x.flag)) continue;
    if (!own[k]->allocate(pageTexels() * meta_->pageCount * x.layout.texelBytes()))
      return Status::badInput(path_ + ": not enough memory to decode " + x.id);
  }
  hght_ = reinterpret_cast<const uint16_t*>(hOwn_.data);
  nrml_ = nOwn_.data;
  colr_ = cOwn_.data;
  return Status::ok();
}

// Decodes cell i's tile of a compressed section (its index checked) into region r of `out`,
// `stride` texels a row.
Status PackReader::decodeTileOf(const char id[4], TexelLayout layout, uint8_t* out, uint32_t stride, TileRegion r,
                                uint32_t i) const {
  const std::span<const uint8_t> blob = tileBlob(id, i);
  Status s = blob.empty() ? Status::badInput("lies outside the section") : decodeTile(blob, out, stride, r, layout);
  if (s) return s;
  return Status::badInput(path_ + ": section " + std::string(id, 4) + ", tile of cell " + std::to_string(i) + ": " +
                          s.message());
}

// Cell i's tile into its place in `pages`.
Status PackReader::decodeTileOf(const char id[4], TexelLayout layout, uint8_t* pages, uint32_t i) const {
  const CellRecord& c = cells_[i];
  uint8_t* page = pages + uint64_t(c.page) * pageTexels() * layout.texelBytes();
  return decodeTileOf(id, layout, page, meta_->pageWidth, gutteredTile(c), i);
}

Status PackReader::decodeCellInto(uint32_t i, uint16_t* heights, uint8_t* normals, uint8_t* rgba) const {
  if (i >= meta_->cellCount) return Status::internal(path_ + ": decodeCellInto(" + std::to_string(i) + ") past the cells");
  const CellRecord& c = cells_[i];
  const TileRegion g = gutteredTile(c), at{0, 0, g.w, g.h};
  if (!hasNormals()) normals = nullptr;
  if (!hasColor()) rgba = nullptr;
  if (compressedPages() && !(hght_ && !onDemand_)) {  // from the coded sections
    if (!tilesIndexed_) return Status::internal(path_ + ": decodeCellInto on a pack opened for its metadata only");
    SA_RETURN_IF_ERROR(decodeTileOf("HGTZ", kHeightTexels, reinterpret_cast<uint8_t*>(heights), g.w, at, i));
    if (normals) SA_RETURN_IF_ERROR(decodeTileOf("NRMZ", kNormalTexels, normals, g.w, at, i));
    if (rgba) SA_RETURN_IF_ERROR(decodeTileOf("COLZ", kColorTexels, rgba, g.w, at, i));
    return Status::ok();
  }
  const uint32_t PW = meta_->pageWidth;  // raw (mapped) or decoded pages: a copy
  for (uint32_t j = 0; j < g.h; ++j) {
    const uint64_t p = uint64_t(g.y + j) * PW + g.x;
    std::memcpy(heights + size_t(j) * g.w, heightPage(c.page) + p, size_t(g.w) * 2);
    if (normals) std::memcpy(normals + size_t(j) * g.w * kNormalBytes, normalPage(c.page) + p * kNormalBytes, size_t(g.w) * kNormalBytes);
    if (rgba) std::memcpy(rgba + size_t(j) * g.w * 4, colorPage(c.page) + p * 4, size_t(g.w) * 4);
  }
  return Status::ok();
}

Status PackReader::decodeCell(uint32_t i) const {
  if (!onDemand_) return Status::ok();
  if (i >= meta_->cellCount) return Status::internal(path_ + ": decodeCell(" + std::to_string(i) + ") past the cells");
  SA_RETURN_IF_ERROR(decodeTileOf("HGTZ", kHeightTexels, hOwn_.data, i));
  if (nrml_) SA_RETURN_IF_ERROR(decodeTileOf("NRMZ", kNormalTexels, nOwn_.data, i));
  if (colr_) SA_RETURN_IF_ERROR(decodeTileOf("COLZ", kColorTexels, cOwn_.data, i));
  return Status::ok();
}

Status PackReader::decodeCells(std::span<const uint32_t> cells) const {
  if (!onDemand_ || cells.empty()) return Status::ok();
  for (uint32_t i : cells)
    if (i >= meta_->cellCount) return Status::internal(path_ + ": decodeCells(" + std::to_string(i) + ") past the cells");
  SA_RETURN_IF_ERROR(decodePages("HGTZ", kHeightTexels, hOwn_.data, cells));
  if (nrml_) SA_RETURN_IF_ERROR(decodePages("NRMZ", kNormalTexels, nOwn_.data, cells));
  if (colr_) SA_RETURN_IF_ERROR(decodePages("COLZ", kColorTexels, cOwn_.data, cells));
  return Status::ok();
}

// Decodes the tiles of a compressed section into `pages`, on all cores: the cells listed, or
// every cell; the error of the first failing one in that order.
Status PackReader::decodePages(const char id[4], TexelLayout layout, uint8_t* pages, std::span<const uint32_t> cells) const {
  std::mutex mu;
  Status first = Status::ok();
  size_t firstAt = SIZE_MAX;
  const size_t n = cells.empty() ? meta_->cellCount : cells.size();
  parallelFor(n, [&](size_t k) {
    Status s = decodeTileOf(id, layout, pages, cells.empty() ? uint32_t(k) : cells[k]);
    if (s) return;
    std::lock_guard<std::mutex> lock(mu);
    if (k < firstAt) {
      firstAt = k;
      first = s;
    }
  });
  return first;
}

Status PackReader::verifyPages() const {
  for (uint32_t i = 0; i < header_->sectionCount; ++i) {
    const SectionEntry& s = sections_[i];
    if (crcOf(base_ + s.offset, s.size) != s.crc)
      return Status::badInput(path_ + ": section " + std::string(s.id, 4) + " checksum mismatch (file corrupt)");
  }
  return Status::ok();
}

const uint16_t* PackReader::heightPage(uint32_t page) const {
  return hght_ ? hght_ + uint64_t(page) * pageTexels() : nullptr;
}

const uint8_t* PackReader::colorPage(uint32_t page) const {
  return colr_ ? colr_ + uint64_t(page) * pageTexels() * 4 : nullptr;
}

const uint8_t* PackReader::normalPage(uint32_t page) const {
  return nrml_ ? nrml_ + uint64_t(page) * pageTexels() * kNormalBytes : nullptr;
}

std::span<const uint8_t> PackReader::section(const char id[4]) const {
  const SectionEntry* e = find(id);
  if (!e) return {};
  return {base_ + e->offset, size_t(e->size)};
}

Status rewritePackWithSections(const PackReader& in, const std::string& out, const std::vector<ExtraSection>& add) {
  std::vector<SectionEntry> sec;
  std::vector<const uint8_t*> src;
  for (const SectionEntry& e : in.sectionTable()) {
    bool replaced = false;
    for (const ExtraSection& a : add) replaced = replaced || std::memcmp(a.id, e.id, 4) == 0;
    if (replaced) continue;
    sec.push_back(e);
    src.push_back(in.base_ + e.offset);
  }
  for (const ExtraSection& a : add) {
    sec.push_back(makeSection(a.id, 0, a.bytes.size(), crcOf(a.bytes.data(), a.bytes.size())));
    src.push_back(a.bytes.data());
  }
  if (sec.size() > 64) return Status::badInput(in.path() + ": a pack holds at most 64 sections");
  uint64_t off = alignUp(sizeof(PackHeader) + sec.size() * sizeof(SectionEntry)), end = off;
  for (SectionEntry& e : sec) {
    e.offset = off;
    end = off + e.size;
    off = alignUp(end);
  }
  AtomicFile file;
  SA_RETURN_IF_ERROR(file.open(out));
  for (size_t i = 0; i < sec.size(); ++i)
    if (sec[i].size) SA_RETURN_IF_ERROR(file.pwriteAll(src[i], sec[i].size, sec[i].offset));
  PackHeader h = *in.header_;
  h.sectionCount = uint32_t(sec.size());
  h.fileSize = off;
  h.sectionTableCrc = crcOf(reinterpret_cast<const uint8_t*>(sec.data()), sec.size() * sizeof(SectionEntry));
  SA_RETURN_IF_ERROR(file.pwriteAll(&h, sizeof(h), 0));
  SA_RETURN_IF_ERROR(file.pwriteAll(sec.data(), sec.size() * sizeof(SectionEntry), sizeof(h)));
  // The file ends where its last section ends, padded to the alignment.
  (void)end;
  if (::ftruncate(file.fd(), off_t(off)) != 0) return Status::internal(out + ": cannot size the file: " + std::strerror(errno));
  return file.commit();
}

std::string PackReader::note() const {
  const SectionEntry* n = find("NOTE");
  return n ? std::string(reinterpret_cast<const char*>(base_ + n->offset), n->size) : std::string();
}

std::vector<std::string> packSources(const PackReader& pack, std::string& columns) {
  std::vector<std::string> out;
  std::istringstream in(pack.note());
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("source: ", 0) == 0) out.push_back(line.substr(8));
    if (line.rfind("columns: ", 0) == 0) columns = line.substr(9);
  }
  return out;
}

}  // namespace sa
