#include "test_util.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace sa::test {

bool haveSharedData() { return std::filesystem::exists(std::string(SA_SHARED_DATA) + "/PROVENANCE.md"); }

std::string sharedData(const std::string& relative) {
  const std::string p = std::string(SA_SHARED_DATA) + "/" + relative;
  if (!std::filesystem::exists(p))
    ADD_FAILURE() << "real test data missing: " << p
                  << " (tests read ../shared/data beside the checkout; it is absent here)";
  return p;
}

TempDir::TempDir() {
  std::string tmpl = (std::filesystem::temp_directory_path() / "scanatlas-test-XXXXXX").string();
  std::vector<char> buf(tmpl.begin(), tmpl.end());
  buf.push_back('\0');
  path_ = mkdtemp(buf.data());
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

void writeText(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

void writeBytes(const std::string& path, const std::vector<char>& bytes) {
  std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
}

void writePointsPly(const std::string& path, const std::vector<Eigen::Vector3d>& pts,
                    const std::vector<Eigen::Vector3d>* normals) {
  std::ofstream f(path, std::ios::binary);
  f << "ply\nformat binary_little_endian 1.0\nelement vertex " << pts.size()
    << "\nproperty double x\nproperty double y\nproperty double z\n";
  if (normals) f << "property float nx\nproperty float ny\nproperty float nz\n";
  f << "end_header\n";
  for (size_t i = 0; i < pts.size(); ++i) {
    f.write(reinterpret_cast<const char*>(pts[i].data()), 24);
    if (normals) {
      const float n[3] = {float((*normals)[i].x()), float((*normals)[i].y()), float((*normals)[i].z())};
      f.write(reinterpret_cast<const char*>(n), 12);
    }
  }
}

void spherePoints(int n, double radius, const Eigen::Vector3d& center, std::vector<Eigen::Vector3d>& pts,
                  std::vector<Eigen::Vector3d>& normals) {
  const double golden = M_PI * (3 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double y = 1 - 2 * (i + 0.5) / n;
    const double r = std::sqrt(1 - y * y);
    const Eigen::Vector3d d(std::cos(golden * i) * r, y, std::sin(golden * i) * r);
    normals.push_back(d);
    pts.push_back(center + radius * d);
  }
}

}  // namespace sa::test
