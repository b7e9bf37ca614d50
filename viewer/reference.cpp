#include "viewer/reference.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "formats/ply.h"
#include "preprocess/raster.h"

namespace sa {
namespace {

class MeshSink : public BatchSink {
 public:
  explicit MeshSink(TriangleMesh& m) : m_(m) {}
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) {
      m_.positions.push_back(b.x[i]);
      m_.positions.push_back(b.y[i]);
      m_.positions.push_back(b.z[i]);
    }
    return Status::ok();
  }
  Status onTriangles(const uint32_t* idx, size_t n) override {
    m_.indices.insert(m_.indices.end(), idx, idx + 3 * n);
    return Status::ok();
  }

 private:
  TriangleMesh& m_;
};

}  // namespace

Result<TriangleMesh> loadMesh(const std::string& path) {
  TriangleMesh m;
  MeshSink sink(m);
  PlyReadOptions opt;
  Status s = readPly(path, opt, sink);
  if (!s) return s;
  if (m.indices.empty()) return Status::badInput(path + ": has no faces (a reference needs triangles)");
  return m;
}

std::vector<float> referenceDepth(const TriangleMesh& mesh, const Camera& cam) {
  const int W = cam.width, H = cam.height;
  std::vector<float> depth(size_t(W) * H, std::numeric_limits<float>::infinity());
  const Eigen::Vector3d f = cam.forward(), r = cam.right(), u = cam.trueUp();
  const double tanHalf = std::tan(cam.fovDeg * M_PI / 360.0), aspect = double(W) / H;
  const size_t nv = mesh.positions.size() / 3;
  std::vector<double> sx(nv), sy(nv), sz(nv);
  for (size_t i = 0; i < nv; ++i) {
    const Eigen::Vector3d p = Eigen::Vector3d(&mesh.positions[3 * i]) - cam.eye;
    const double z = p.dot(f);
    sz[i] = z;
    sx[i] = (p.dot(r) / (z * tanHalf * aspect) * 0.5 + 0.5) * W;
    sy[i] = (0.5 - p.dot(u) / (z * tanHalf) * 0.5) * H;
  }
  std::vector<double> best(depth.size(), std::numeric_limits<double>::infinity());
  for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
    const uint32_t a = mesh.indices[t], b = mesh.indices[t + 1], c = mesh.indices[t + 2];
    if (sz[a] <= 0 || sz[b] <= 0 || sz[c] <= 0) continue;  // no near clipping needed for our views
    const double x[3] = {sx[a], sx[b], sx[c]}, y[3] = {sy[a], sy[b], sy[c]};
    const double iz[3] = {1 / sz[a], 1 / sz[b], 1 / sz[c]};
    rasterizeTriangle(x, y, W, H, [&](int px, int py, double b0, double b1, double b2) {
      // 1/z is affine in screen space: perspective-correct depth.
      const double z = 1.0 / (b0 * iz[0] + b1 * iz[1] + b2 * iz[2]);
      double& d = best[size_t(py) * W + px];
      if (z < d) d = z;
    });
  }
  for (size_t i = 0; i < depth.size(); ++i) depth[i] = static_cast<float>(best[i]);
  return depth;
}

DepthComparison compareDepth(const std::vector<float>& test, const std::vector<float>& ref, double diagonal) {
  DepthComparison c;
  std::vector<double> err;
  for (size_t i = 0; i < std::min(test.size(), ref.size()); ++i) {
    const bool a = std::isfinite(test[i]), b = std::isfinite(ref[i]);
    if (a && b) {
      ++c.both;
      err.push_back(std::abs(double(test[i]) - double(ref[i])) / diagonal);
    } else if (a) {
      ++c.onlyTest;
    } else if (b) {
      ++c.onlyRef;
    }
  }
  const size_t uni = c.both + c.onlyTest + c.onlyRef;
  c.iou = uni ? double(c.both) / double(uni) : 1.0;
  if (!err.empty()) {
    std::sort(err.begin(), err.end());
    c.medianRelError = err[err.size() / 2];
    c.p95RelError = err[std::min(err.size() - 1, size_t(0.95 * double(err.size())))];
  }
  return c;
}

}  // namespace sa
