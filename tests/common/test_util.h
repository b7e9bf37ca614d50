// Helpers shared by the tests: temporary directories, the shared real-data folder, PLY
// writers for synthetic fixtures.
#pragma once
#include <string>
#include <vector>

#include <Eigen/Core>

namespace sa::test {

// ../shared/data; fails the current test with a clear message when it is missing.
std::string sharedData(const std::string& relative);
bool haveSharedData();

class TempDir {
 public:
  TempDir();
  ~TempDir();
  const std::string& path() const { return path_; }
  std::string file(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

void writeText(const std::string& path, const std::string& text);
void writeBytes(const std::string& path, const std::vector<char>& bytes);

// Binary little-endian PLY with double xyz (+ float normals when given).
void writePointsPly(const std::string& path, const std::vector<Eigen::Vector3d>& pts,
                    const std::vector<Eigen::Vector3d>* normals = nullptr);

// Points on a sphere (Fibonacci lattice) with outward normals.
void spherePoints(int n, double radius, const Eigen::Vector3d& center, std::vector<Eigen::Vector3d>& pts,
                  std::vector<Eigen::Vector3d>& normals);

}  // namespace sa::test
