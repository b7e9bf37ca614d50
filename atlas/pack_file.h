// Writing and reading pack files (docs/FORMAT.md). The writer lays the file out up front
// (the cell table and tile placements are known before any height map exists), then height
// maps are written tile by tile with pwrite (compressed pages: coded per tile and appended to a
// temporary), so the atlas is never held in memory. The reader maps the file; page sections
// are used in place.
#pragma once
#include <array>
#include <atomic>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_format.h"
#include "atlas/tile_codec.h"
#include "atlas/tile_levels.h"
#include "common/error.h"
#include "common/fileio.h"

namespace sa {

class PackWriter {
 public:
  // Where a cell's coded tile of one page section lies: which blob file (0: this process's),
  // its offset there and its size.
  struct BlobRef {
    uint64_t offset = 0, size = 0;
    uint32_t source = 0, pad = 0;
  };
  using CellBlobs = std::array<BlobRef, 4>;  // heights, normals, colours, stored levels (MIPZ)

  // `cells` must already carry their tile placements; `meta` the page size and count. With
  // compressed pages (setCompressPages first) every process of a cluster pack opens its own
  // writer: the coded tiles go to a temporary beside `path`, and finish() writes `path`.
  Status open(const std::string& path, const PackMeta& meta, std::vector<CellRecord> cells,
              const std::string& note);
  // Raw pages: writes tiles into the temporary another process opened with the same meta,
  // cells and note (a cluster pack's other ranks); leave() instead of finish().
  Status join(const std::string& tempPath, const PackMeta& meta, std::vector<CellRecord> cells,
              const std::string& note);
  // A cluster rank other than 0 after its tiles: syncs what it wrote, which rank 0 then reads
  // (compressed pages: this process's temporary stays until the writer is destroyed).
  Status leave();
  // Writes one tile (tileW x tileH, row-major) and its gutter: heights, encoded normals
  // (kNormalBytes per texel; may be null when the pack has no normal pages) and colours (4 bytes; may be null
  // when the pack has no colour). Compressed pages: codes the tile at once (tile_codec.h) and
  // appends it to the temporary, so raw pages are never written. Thread-safe for different cells.
  // normalPyramid, rgbaPyramid: those layers' pyramid payloads where snapToPyramid made them
  // (encodeTile's `pyramid`), empty where not.
  Status writeTile(uint32_t cellIndex, const uint16_t* heights, const uint8_t* normals, const uint8_t* rgba,
                   std::span<const uint8_t> normalPyramid = {}, std::span<const uint8_t> rgbaPyramid = {});
  // Widens a cell's height range before its tile is written (not thread-safe for the same
  // cell; different cells may be updated concurrently).
  void setCellHeights(uint32_t cellIndex, double wMin, double wMax) {
    cells_[cellIndex].box[4] = wMin;
    cells_[cellIndex].box[5] = wMax;
  }
  // Updates META (e.g. timings) before finish().
  void setMeta(const PackMeta& meta) {
    const uint32_t cells = meta_.cellCount;
    meta_ = meta;
    meta_.cellCount = cells;
  }
  // Compressed pages (FORMAT.md): HGTZ, NRMZ, COLZ instead of HGHT, NRML, COLR. Before open().
  // level: zstd's for the coded tiles (kDefaultTileLevel).
  // storeLevels: also a MIPZ section of each tile's coarser levels (tile_levels.h).
  // normalForm: how the normal tiles are coded (TileForm::kPyramid where they were snapped to
  // the pyramid).
  void setCompressPages(bool on, int level = kDefaultTileLevel, bool storeLevels = true,
                        TileForm normalForm = TileForm::kSmaller) {
    compress_ = on;
    level_ = level;
    storeLevels_ = storeLevels;
    normalForm_ = normalForm;
  }
  // Computes checksums, writes header, META and CELL, fsyncs and renames into place (with
  // compressed pages: the final file from the coded tiles, in cell order, and the temporaries
  // removed).
  Status finish();
  const std::string& tempPath() const { return file_.tempPath(); }
  const CellRecord& cell(uint32_t i) const { return cells_[i]; }
  // Compressed pages: a cell's coded tiles in this process's temporary, and the bytes coded so far.
  const CellBlobs& blobs(uint32_t i) const { return blobs_[i]; }
  uint64_t codedBytes() const { return blobEnd_.load(); }
  // Compressed pages, rank 0 of a cluster pack: another rank's temporary and the coded tiles
  // it holds of cells `ids` (their refs' source is ignored).
  void adoptBlobs(const std::string& path, const std::vector<uint32_t>& ids, const std::vector<CellBlobs>& refs);

 private:
  void layOut(const PackMeta& meta, std::vector<CellRecord> cells, const std::string& note);
  Status writeRawTile(uint32_t cellIndex, const uint16_t* heights, const uint8_t* normals, const uint8_t* rgba);
  Status writeCodedTile(uint32_t cellIndex, const uint16_t* heights, const uint8_t* normals, const uint8_t* rgba,
                        std::span<const uint8_t> normalPyramid, std::span<const uint8_t> rgbaPyramid);
  Status finishCompressed();
  Status copySection(AtomicFile& out, const std::vector<int>& fds, int layer, const char* id, uint64_t off,
                     SectionEntry& entry);
  AtomicFile file_;  // raw pages: the output's temporary; compressed: this process's coded tiles
  std::string path_;
  PackMeta meta_{};
  std::vector<CellRecord> cells_;
  std::string note_;
  bool compress_ = false;
  int level_ = kDefaultTileLevel;
  bool storeLevels_ = true;
  TileForm normalForm_ = TileForm::kSmaller;
  uint64_t metaOff_ = 0, cellOff_ = 0, hghtOff_ = 0, nrmlOff_ = 0, colrOff_ = 0, noteOff_ = 0, fileSize_ = 0;
  std::atomic<uint64_t> blobEnd_{0};
  std::vector<CellBlobs> blobs_;
  std::vector<std::string> sources_;  // adopted temporaries: source 1, 2, ...
};

// A cell's tile with its one-texel gutter: what a page holds of it.
TileRegion gutteredTile(const CellRecord& c);

// An optional section to add to a pack (a mode's bake, FORMAT.md).
struct ExtraSection {
  char id[4];
  std::vector<uint8_t> bytes;
};

// The axis-aligned bounds, relative to the pack origin, of a cell's box grown by pad (frame units)
// on every side: the box's eight corners through its frame.
inline void cellBounds(const CellRecord& c, double pad, Eigen::Vector3d& lo, Eigen::Vector3d& hi) {
  const Eigen::Vector3d O(c.origin), U(c.u), V(c.v), W(c.w);
  lo = Eigen::Vector3d::Constant(INFINITY);
  hi = -lo;
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d p = O + U * ((k & 1) ? c.box[1] + pad : c.box[0] - pad) + V * ((k & 2) ? c.box[3] + pad : c.box[2] - pad) +
                              W * ((k & 4) ? c.box[5] + pad : c.box[4] - pad);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
}

class PackReader;
// Writes `out` (atomically; it may be the input's own path): every section of `in` except
// those `add` replaces, then `add`. Nothing else changes, so the pack's hash stays valid.
Status rewritePackWithSections(const PackReader& in, const std::string& out, const std::vector<ExtraSection>& add);

// What PackReader::open does with compressed pages (raw pages are mapped in place either way).
enum class PageLoad {
  kAll,       // decode every tile at open, on all cores
  kNone,      // metadata only: the page accessors return null
  kOnDemand,  // page memory reserved (untouched until written), each cell's tile decoded by decodeCell
  kTiles,     // no page memory (packs larger than RAM): the page accessors return null, each cell's
              // tile is decoded into the caller's memory by decodeCellInto
};

class PackReader {
 public:
  PackReader() = default;
  ~PackReader();
  PackReader(const PackReader&) = delete;
  PackReader& operator=(const PackReader&) = delete;

  // Maps the file and runs the cheap checks: magic, version, sizes, every section inside
  // the file, META and CELL checksums, cell tiles inside their pages. Compressed pages are
  // decoded as `pages` says.
  Status open(const std::string& path, PageLoad pages = PageLoad::kAll);
  // PageLoad::kOnDemand: decodes cell i's tile (with its gutter) into its page; until then the
  // tile's texels are zero. Thread-safe for different cells; a no-op when the pages are raw or
  // already decoded. An error names the file, the section and the cell.
  Status decodeCell(uint32_t i) const;
  // decodeCell for each cell listed, on every core, a section at a time as open decodes a whole
  // pack (so a tile costs what it costs there); the error of the first failing cell in the list.
  Status decodeCells(std::span<const uint32_t> cells) const;
  // Cell i's tile with its gutter, (tileW + 2) x (tileH + 2) texels row-major, into the caller's
  // buffers (normals: kNormalBytes a texel, rgba: 4; either may be null and is then not written;
  // the pack's own channels only). Any PageLoad but kNone for compressed pages; thread-safe.
  Status decodeCellInto(uint32_t i, uint16_t* heights, uint8_t* normals, uint8_t* rgba) const;
  // Whether tiles wait for decodeCell (compressed pages opened with PageLoad::kOnDemand).
  bool onDemand() const { return onDemand_; }
  // Stored coarser levels (MIPZ, tile_levels.h): whether the pack has them (compressed pages
  // opened with tiles), the finest a cell stores no finer than atMost (0: none), and one decoded.
  bool hasStoredLevels() const;
  uint32_t storedLevelAtMost(uint32_t i, uint32_t atMost) const;
  Status decodeStoredLevel(uint32_t i, uint32_t level, TileImage& out) const;
  // Checks the checksums of the large sections too (reads every byte).
  Status verifyPages() const;

  const std::string& path() const { return path_; }
  const PackMeta& meta() const { return *meta_; }
  std::span<const CellRecord> cells() const { return {cells_, meta_->cellCount}; }
  const uint16_t* heightPage(uint32_t page) const;
  const uint8_t* colorPage(uint32_t page) const;   // null when the pack has no colour
  const uint8_t* normalPage(uint32_t page) const;  // null when the pack has no normal pages
  bool hasColor() const { return (meta_->flags & kPackHasColor) != 0; }
  bool hasNormals() const { return (meta_->flags & kPackHasNormals) != 0; }
  // Whether the pages are stored compressed (HGTZ; FORMAT.md).
  bool compressedPages() const { return find("HGTZ") != nullptr; }
  uint64_t pageTexels() const { return uint64_t(meta_->pageWidth) * meta_->pageHeight; }
  // The pack's up axis (unit, world), or zero when unknown.
  Eigen::Vector3d up() const { return Eigen::Vector3d(meta_->up[0], meta_->up[1], meta_->up[2]); }
  // The default up of every view: the pack's, else +y.
  Eigen::Vector3d viewUp() const { return up().norm() > 0.5 ? Eigen::Vector3d(up().normalized()) : Eigen::Vector3d::UnitY(); }
  uint64_t fileBytes() const { return size_; }
  std::string note() const;
  // The bytes of an optional section (a mode's, FORMAT.md), empty when the pack has none.
  std::span<const uint8_t> section(const char id[4]) const;
  std::vector<SectionEntry> sectionTable() const {
    return std::vector<SectionEntry>(sections_, sections_ + header_->sectionCount);
  }

  // Height of cell c at texel (i, j) of its tile (0 = uncovered).
  uint16_t texel(const CellRecord& c, int i, int j) const {
    return heightPage(c.page)[(size_t)(c.tileY + j) * meta_->pageWidth + (c.tileX + i)];
  }
  // Encoded normal of cell c at texel (i, j) (kNormalBytes; FORMAT.md); needs hasNormals().
  const uint8_t* normalTexel(const CellRecord& c, int i, int j) const {
    return normalPage(c.page) + kNormalBytes * ((size_t)(c.tileY + j) * meta_->pageWidth + (c.tileX + i));
  }

 private:
  friend Status rewritePackWithSections(const PackReader&, const std::string&, const std::vector<ExtraSection>&);
  const SectionEntry* find(const char id[4]) const;
  // Page memory for decoded sections: calloc'd, so the OS commits only what tiles are written to.
  struct OwnedPages {
    uint8_t* data = nullptr;
    OwnedPages() = default;
    OwnedPages(const OwnedPages&) = delete;
    OwnedPages& operator=(const OwnedPages&) = delete;
    ~OwnedPages();
    Status allocate(uint64_t bytes);
  };
  // open()'s steps, in order: each checks what the next relies on.
  Status mapFile(const std::string& path);
  Status checkHeader() const;
  Status checkSectionTable();
  Status checkMetaAndCells(bool haveHeights);  // HGHT or HGTZ found
  Status checkCodedPages() const;
  Status checkRawPages(const SectionEntry& hght);
  Status checkCellRecords() const;
  Status checkTileIndexes();
  Status reservePages();
  std::span<const uint8_t> tileBlob(const char id[4], uint32_t i) const;
  Status decodeTileOf(const char id[4], TexelLayout layout, uint8_t* out, uint32_t stride, TileRegion r, uint32_t i) const;
  Status decodeTileOf(const char id[4], TexelLayout layout, uint8_t* pages, uint32_t i) const;
  Status decodePages(const char id[4], TexelLayout layout, uint8_t* pages, std::span<const uint32_t> cells = {}) const;
  std::string path_;
  const uint8_t* base_ = nullptr;
  uint64_t size_ = 0;
  const PackHeader* header_ = nullptr;
  const SectionEntry* sections_ = nullptr;
  const PackMeta* meta_ = nullptr;
  const CellRecord* cells_ = nullptr;
  const uint16_t* hght_ = nullptr;
  const uint8_t* colr_ = nullptr;
  const uint8_t* nrml_ = nullptr;
  OwnedPages hOwn_, nOwn_, cOwn_;  // decoded compressed pages
  bool onDemand_ = false;
  bool tilesIndexed_ = false;  // the compressed sections' tile indexes were checked
};

// The source files the pack was made from (its NOTE's "source:" lines) and the --columns spec of
// text inputs ("columns:"), for bakes and commands that go back to the raw points.
std::vector<std::string> packSources(const PackReader& pack, std::string& columns);
inline std::vector<std::string> packSources(const PackReader& pack) {
  std::string columns;
  return packSources(pack, columns);
}

}  // namespace sa
