#include "viewer/reference.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "formats/conf.h"
#include "formats/ply.h"
#include "formats/source.h"
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
  // Every mesh format pack reads (PLY, OBJ, OFF, STL, Draco), through the same readers.
  auto input = InputSet::open({path});
  if (!input) return input.status();
  if (!input->hasTriangles()) return Status::badInput(path + ": has no faces (a reference needs triangles)");
  TriangleMesh m;
  m.positions.reserve(3 * input->pointCount());
  MeshSink sink(m);
  SA_RETURN_IF_ERROR(input->stream(sink, true));
  if (m.indices.empty()) return Status::badInput(path + ": has no faces (a reference needs triangles)");
  const size_t nv = m.positions.size() / 3;
  for (uint32_t v : m.indices)
    if (v >= nv) return Status::badInput(path + ": a face names vertex " + std::to_string(v) + " of " + std::to_string(nv));
  return m;
}

Result<TriangleMesh> loadReference(const std::string& path, double maxEdge) {
  if (path.size() < 5 || path.substr(path.size() - 5) != ".conf") {
    auto m = loadMesh(path);
    if (m) m->description = "mesh " + path + " (" + std::to_string(m->indices.size() / 3) + " triangles)";
    return m;
  }
  auto scans = readConf(path);
  if (!scans) return scans.status();
  TriangleMesh all;
  for (const ScanEntry& s : *scans) {
    TriangleMesh m;
    MeshSink sink(m);
    PlyReadOptions opt;
    opt.readFaces = false;
    opt.rangeGridTriangles = true;
    SA_RETURN_IF_ERROR(readPly(s.path, opt, sink));
    const uint32_t base = static_cast<uint32_t>(all.positions.size() / 3);
    for (size_t i = 0; i < m.positions.size(); i += 3) {
      const Eigen::Vector3d p = s.rotation * Eigen::Vector3d(&m.positions[i]) + s.translation;
      all.positions.insert(all.positions.end(), {p.x(), p.y(), p.z()});
    }
    for (uint32_t v : m.indices) all.indices.push_back(base + v);
  }
  // Long edges join samples across depth jumps (silhouettes, occlusions): drop them.
  std::vector<double> longest(all.indices.size() / 3);
  for (size_t t = 0; t < longest.size(); ++t) {
    double l = 0;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d a(&all.positions[3 * size_t(all.indices[3 * t + k])]);
      const Eigen::Vector3d b(&all.positions[3 * size_t(all.indices[3 * t + (k + 1) % 3])]);
      l = std::max(l, (a - b).norm());
    }
    longest[t] = l;
  }
  if (longest.empty()) return Status::badInput(path + ": the scans' range grids hold no triangles");
  if (maxEdge <= 0) {
    std::vector<double> tmp = longest;
    std::nth_element(tmp.begin(), tmp.begin() + tmp.size() / 2, tmp.end());
    maxEdge = 3 * tmp[tmp.size() / 2];
  }
  TriangleMesh out;
  out.positions = std::move(all.positions);
  for (size_t t = 0; t < longest.size(); ++t)
    if (longest[t] <= maxEdge) out.indices.insert(out.indices.end(), &all.indices[3 * t], &all.indices[3 * t] + 3);
  char buf[256];
  std::snprintf(buf, sizeof(buf), " (%zu range scans triangulated on their grids, %zu triangles, max edge %.4g)",
                scans->size(), out.indices.size() / 3, maxEdge);
  out.description = "scan set " + path + buf;
  return out;
}

std::vector<float> referenceDepth(const TriangleMesh& mesh, const Camera& cam) { return referenceView(mesh, cam).depth; }

ReferenceView referenceView(const TriangleMesh& mesh, const Camera& cam) {
  const int W = cam.width, H = cam.height;
  ReferenceView view;
  std::vector<float>& depth = view.depth;
  depth.assign(size_t(W) * H, std::numeric_limits<float>::infinity());
  std::vector<uint32_t> triOf(depth.size(), UINT32_MAX);
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
      if (z < d) {
        d = z;
        triOf[size_t(py) * W + px] = static_cast<uint32_t>(t / 3);
      }
    });
  }
  view.normals.assign(depth.size() * 3, 0.f);
  for (size_t i = 0; i < depth.size(); ++i) {
    depth[i] = static_cast<float>(best[i]);
    if (triOf[i] == UINT32_MAX) continue;
    const uint32_t* tri = &mesh.indices[3 * size_t(triOf[i])];
    const Eigen::Vector3d a(&mesh.positions[3 * size_t(tri[0])]), b(&mesh.positions[3 * size_t(tri[1])]),
        c(&mesh.positions[3 * size_t(tri[2])]);
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    for (int k = 0; k < 3; ++k) view.normals[3 * i + k] = float(n[k]);
  }
  return view;
}

Image shadeReference(const ReferenceView& v, const Camera& cam, const float base[3], const float bg[3]) {
  Image img;
  img.width = cam.width;
  img.height = cam.height;
  img.rgba.resize(size_t(cam.width) * cam.height * 4);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const size_t i = size_t(y) * cam.width + x;
      float c[3] = {bg[0], bg[1], bg[2]};
      if (std::isfinite(v.depth[i])) {
        const Eigen::Vector3d n(v.normals[3 * i], v.normals[3 * i + 1], v.normals[3 * i + 2]);
        const double ndl = std::abs(n.dot(cam.rayDirection(x + 0.5, y + 0.5)));
        for (int k = 0; k < 3; ++k) c[k] = float(base[k] * (0.12 + 0.88 * ndl));
      }
      for (int k = 0; k < 3; ++k) img.rgba[4 * i + k] = static_cast<uint8_t>(std::clamp(c[k] * 255.f + 0.5f, 0.f, 255.f));
      img.rgba[4 * i + 3] = 255;
    }
  return img;
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
