// One entry point for every input a user names: PLY files and Stanford .conf scan sets,
// several at once. Headers are read up front (cheap, validated); stream() delivers batches.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "formats/points.h"

namespace sa {

enum class InputFormat { kPly, kLas, kText, kMesh, kPcd, kDraco };

const char* formatName(InputFormat f);

class StreamRecording;

struct InputFile {
  std::string path;
  InputFormat format = InputFormat::kPly;
  uint64_t points = 0;
  bool hasNormals = false, hasColors = false, hasFaces = false;
  bool hasIntensity = false, hasConfidence = false, hasClassification = false;
  std::string detail;           // format details for `info` (encoding, organization, version)
  bool transformed = false;     // member of a scan set
  std::string columns;          // text inputs: the --columns spec (may be empty)
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  int scanIndex = -1;           // index into InputSet::towardScanner, or -1
  // The up axis the file's format implies (zero: none). A convention (upIsConvention: LAS +z,
  // Stanford scan sets +y, an organized PCD's camera -y) is relied on; otherwise it is the
  // format's usual default (PLY, OBJ, OFF, Draco, text +y; STL +z), used when the data says
  // nothing. upFromCamera: the convention is a camera's, only roughly up.
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  bool upIsConvention = false, upFromCamera = false;
  // Draco and OBJ/OFF/STL: what the (whole-file) decode in open() delivered, replayed by stream().
  std::shared_ptr<const StreamRecording> recording;
};

class InputSet {
 public:
  // textColumns: the --columns spec for XYZ/PTS/CSV inputs (empty: header or column count).
  static Result<InputSet> open(const std::vector<std::string>& paths, const std::string& textColumns = "");

  const std::vector<InputFile>& files() const { return files_; }
  uint64_t pointCount() const;
  bool allHaveNormals() const;
  bool anyHasColors() const;
  // Scanner attributes are kept when every file has them.
  bool allHaveIntensity() const;
  bool allHaveConfidence() const;
  bool allHaveClassification() const;
  // Triangles are used when the input is exactly one file with faces.
  bool hasTriangles() const { return files_.size() == 1 && files_[0].hasFaces; }
  // Per scan: direction from the surface toward the scanner (aligned coordinates).
  const std::vector<Eigen::Vector3d>& towardScanner() const { return towardScanner_; }
  const std::vector<std::string>& warnings() const { return warnings_; }
  // File and index within it of the point with global index `i` (as in PointBatch::firstIndex).
  std::pair<std::string, uint64_t> locate(uint64_t i) const;
  // The paths the user named (absolute), before scan sets were expanded.
  const std::vector<std::string>& sourcePaths() const { return sourcePaths_; }
  // Every file this input reads: the named ones and a scan set's scans (for checking that an
  // output is none of them).
  std::vector<std::string> allPaths() const {
    std::vector<std::string> out = sourcePaths_;
    for (const InputFile& f : files_) out.push_back(f.path);
    return out;
  }

  // Streams every file in order. Point batches carry aligned positions, the scan index when
  // the input is a scan set, normals, intensity, confidence and classification only when every
  // file has them, and colours when any file has them (white elsewhere). PCD entries without
  // finite coordinates (organized clouds' holes) are left out, so a PCD file may deliver fewer
  // points than InputFile::points. Triangles only when hasTriangles() and readTriangles.
  Status stream(BatchSink& sink, bool readTriangles, size_t batchPoints = kDefaultBatchPoints) const;

 private:
  // One path's files (a .conf scan set adds one per scan).
  Status add(const std::string& path, const std::string& textColumns);
  Status addConf(const std::string& path);
  Status addLasFile(const std::string& path);
  std::vector<InputFile> files_;
  std::vector<Eigen::Vector3d> towardScanner_;
  std::vector<std::string> warnings_;
  std::vector<std::string> sourcePaths_;
};

}  // namespace sa
