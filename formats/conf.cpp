#include "formats/conf.h"

#include <Eigen/Geometry>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "common/fileio.h"

namespace sa {

Result<std::vector<ScanEntry>> readConf(const std::string& path) {
  BufferedReader in;
  SA_RETURN_IF_ERROR(in.open(path, 1 << 16));
  if (in.fileSize() > (64u << 20)) return Status::badInput(path + ": too large for a .conf file");
  std::vector<ScanEntry> scans;
  std::string line;
  int lineNo = 0;
  const std::string dir = directoryOf(path);
  while (in.readLine(line)) {
    ++lineNo;
    std::istringstream is(line);
    std::string kw;
    if (!(is >> kw) || kw[0] == '#') continue;
    if (kw == "camera" || kw == "mesh") continue;
    const std::string where = path + ":" + std::to_string(lineNo) + ": ";
    if (kw != "bmesh") return Status::badInput(where + "unknown keyword '" + kw + "' (expected bmesh, mesh or camera)");
    std::string file;
    double v[7];
    if (!(is >> file)) return Status::badInput(where + "bmesh line without a file name");
    for (int i = 0; i < 7; ++i) {
      std::string tok;
      if (!(is >> tok)) return Status::badInput(where + "bmesh line needs 7 numbers: tx ty tz q0 q1 q2 q3");
      auto [p, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v[i]);
      if (ec != std::errc() || p != tok.data() + tok.size() || !std::isfinite(v[i]))
        return Status::badInput(where + "number " + std::to_string(i + 1) + " is not a finite number: '" + tok + "'");
    }
    Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);  // Eigen takes (w, x, y, z)
    if (q.norm() < 1e-6) return Status::badInput(where + "quaternion has zero length");
    q.normalize();
    ScanEntry e;
    e.path = std::filesystem::path(file).is_absolute() ? file : joinPath(dir, file);
    e.rotation = q.toRotationMatrix().transpose();
    e.translation = Eigen::Vector3d(v[0], v[1], v[2]);
    e.towardScanner = e.rotation * Eigen::Vector3d(0, 0, 1);
    scans.push_back(std::move(e));
    if (scans.size() > 65535) return Status::badInput(where + "more than 65535 scans");
  }
  if (scans.empty()) return Status::badInput(path + ": no bmesh lines: not a scan set");
  return scans;
}

}  // namespace sa
