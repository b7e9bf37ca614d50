// The only file that includes OpenMesh (a heavy header set): its types stay inside.
#include "formats/mesh_openmesh.h"

// GCC 12 reports -Wmaybe-uninitialized inside OpenMesh's property containers (instantiated here).
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <filesystem>
#include <vector>

namespace sa {
namespace {

struct Traits : OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;  // read coordinates in double
  using Normal = OpenMesh::Vec3d;
};
using Mesh = OpenMesh::PolyMesh_ArrayKernelT<Traits>;

Status load(const std::string& path, Mesh& mesh, OpenMesh::IO::Options& opt) {
  if (!std::filesystem::exists(path)) return Status::badInput(path + ": no such file");
  mesh.request_vertex_normals();
  mesh.request_vertex_colors();
  // STL has facet normals only; vertex normals then come from the faces (area-weighted, in the
  // pipeline), not from whichever facet OpenMesh copied last.
  const bool stl = std::filesystem::path(path).extension() == ".stl" || std::filesystem::path(path).extension() == ".STL";
  opt = stl ? OpenMesh::IO::Options(OpenMesh::IO::Options::Default)
            : OpenMesh::IO::Options(OpenMesh::IO::Options::VertexNormal | OpenMesh::IO::Options::VertexColor);
  std::streambuf* old = std::cerr.rdbuf(nullptr);  // OpenMesh prints its own complaints
  const bool ok = OpenMesh::IO::read_mesh(mesh, path, opt);
  std::cerr.rdbuf(old);
  if (!ok) return Status::badInput(path + ": OpenMesh could not read this mesh (malformed or not OBJ/OFF/STL)");
  if (mesh.n_vertices() == 0) return Status::badInput(path + ": the mesh has no vertices");
  return Status::ok();
}

}  // namespace

Result<MeshInfo> readMeshInfo(const std::string& path) {
  Mesh mesh;
  OpenMesh::IO::Options opt;
  Status s = load(path, mesh, opt);
  if (!s) return s;
  MeshInfo info;
  info.vertices = mesh.n_vertices();
  for (auto f : mesh.faces()) info.triangles += mesh.valence(f) >= 3 ? mesh.valence(f) - 2 : 0;
  info.hasNormals = opt.check(OpenMesh::IO::Options::VertexNormal);
  info.hasColors = opt.check(OpenMesh::IO::Options::VertexColor);
  return info;
}

Status readMesh(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink) {
  Mesh mesh;
  OpenMesh::IO::Options opt;
  SA_RETURN_IF_ERROR(load(path, mesh, opt));
  const bool normals = opt.check(OpenMesh::IO::Options::VertexNormal);
  const bool colors = opt.check(OpenMesh::IO::Options::VertexColor);
  PointBatch b;
  const size_t n = mesh.n_vertices();
  for (size_t first = 0; first < n; first += batchPoints) {
    const size_t m = std::min(batchPoints, n - first);
    b.clear();
    b.firstIndex = first;
    for (size_t i = first; i < first + m; ++i) {
      const auto vh = mesh.vertex_handle(static_cast<unsigned>(i));
      const auto& p = mesh.point(vh);
      b.x.push_back(p[0]);
      b.y.push_back(p[1]);
      b.z.push_back(p[2]);
      if (normals) {
        const auto& nn = mesh.normal(vh);
        b.nx.push_back(float(nn[0]));
        b.ny.push_back(float(nn[1]));
        b.nz.push_back(float(nn[2]));
      }
      if (colors) {
        const auto& c = mesh.color(vh);
        b.r.push_back(c[0]);
        b.g.push_back(c[1]);
        b.b.push_back(c[2]);
      }
    }
    SA_RETURN_IF_ERROR(sink.onPoints(b));
  }
  if (!readTriangles) return Status::ok();
  std::vector<uint32_t> tris;
  for (auto f : mesh.faces()) {
    std::vector<uint32_t> idx;
    for (auto v : mesh.fv_range(f)) idx.push_back(uint32_t(v.idx()));
    for (size_t k = 2; k < idx.size(); ++k) tris.insert(tris.end(), {idx[0], idx[k - 1], idx[k]});
    if (tris.size() >= 3 * batchPoints) {
      SA_RETURN_IF_ERROR(sink.onTriangles(tris.data(), tris.size() / 3));
      tris.clear();
    }
  }
  if (!tris.empty()) SA_RETURN_IF_ERROR(sink.onTriangles(tris.data(), tris.size() / 3));
  return Status::ok();
}

}  // namespace sa
