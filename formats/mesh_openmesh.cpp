// The only file that includes OpenMesh (a heavy header set): its types stay inside.
#include "formats/mesh_openmesh.h"

// GCC 12 reports -Wmaybe-uninitialized inside OpenMesh's property containers (instantiated here).
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <new>
#include <sstream>
#include <vector>

#include "common/fileio.h"
#include "formats/isolate.h"

namespace sa {
namespace {

struct Traits : OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;  // read coordinates in double
  using Normal = OpenMesh::Vec3d;
};
using Mesh = OpenMesh::PolyMesh_ArrayKernelT<Traits>;

// OpenMesh reserves the counts an OFF header declares before reading a vertex (a 60-byte file
// declaring 2*10^9 vertices aborted with bad_alloc): check them against the file size first.
// An ascii vertex takes at least 6 bytes ("0 0 0\n") and a face 8 ("3 0 1 2\n"); binary
// records are larger. Binary STL's triangle count is checked by OpenMesh against the size.
Status checkOffCounts(const std::string& path) {
  BufferedReader in;
  SA_RETURN_IF_ERROR(in.open(path, 1 << 16));
  std::string line;
  int lineNo = 0;
  bool sawKeyword = false;
  while (in.readLine(line, 1 << 12) && lineNo < 1000) {
    ++lineNo;
    const size_t c = line.find('#');
    if (c != std::string::npos) line.resize(c);
    std::istringstream ss(line);
    std::string first;
    if (!(ss >> first)) continue;
    if (!sawKeyword && first.find("OFF") != std::string::npos) {
      sawKeyword = true;
      if (line.find("BINARY") != std::string::npos) return Status::ok();  // counts follow in binary; OpenMesh checks them
      if (ss >> first) {}  // counts may follow on the keyword line
      else continue;
    }
    std::istringstream counts(line.substr(line.find(first)));
    std::string nvText, nfText;
    counts >> nvText >> nfText;
    char* end = nullptr;
    const long double nv = std::strtold(nvText.c_str(), &end);
    const bool nvOk = !nvText.empty() && *end == 0;
    const long double nf = std::strtold(nfText.c_str(), &end);
    const bool nfOk = !nfText.empty() && *end == 0;
    if (!nvOk || !nfOk || !(nv >= 0) || !(nf >= 0))
      return Status::badInput(path + ": line " + std::to_string(lineNo) + ": expected the OFF vertex and face counts");
    const long double need = nv * 6 + nf * 8;
    if (need > static_cast<long double>(in.fileSize()))
      return Status::badInput(path + ": OFF header declares " + nvText.substr(0, 24) + " vertices and " +
                              nfText.substr(0, 24) + " faces but the file has only " + std::to_string(in.fileSize()) +
                              " bytes (truncated or header corrupt)");
    return Status::ok();
  }
  return Status::ok();
}

Status load(const std::string& path, Mesh& mesh, OpenMesh::IO::Options& opt) {
  if (!std::filesystem::exists(path)) return Status::badInput(path + ": no such file");
  if (lowerExtension(path) == ".off") SA_RETURN_IF_ERROR(checkOffCounts(path));
  mesh.request_vertex_normals();
  mesh.request_vertex_colors();
  // STL has facet normals only; vertex normals then come from the faces (area-weighted, in the
  // pipeline), not from whichever facet OpenMesh copied last.
  const bool stl = lowerExtension(path) == ".stl";
  opt = stl ? OpenMesh::IO::Options(OpenMesh::IO::Options::Default)
            : OpenMesh::IO::Options(OpenMesh::IO::Options::VertexNormal | OpenMesh::IO::Options::VertexColor);
  std::streambuf* old = std::cerr.rdbuf(nullptr);  // OpenMesh prints its own complaints
  bool ok = false;
  try {
    ok = OpenMesh::IO::read_mesh(mesh, path, opt);
  } catch (const std::bad_alloc&) {
    std::cerr.rdbuf(old);
    return Status::badInput(path + ": OpenMesh ran out of memory reading this mesh (counts in the file corrupt?)");
  } catch (const std::exception& e) {
    std::cerr.rdbuf(old);
    return Status::badInput(path + ": OpenMesh could not read this mesh: " + e.what());
  }
  std::cerr.rdbuf(old);
  if (!ok) return Status::badInput(path + ": OpenMesh could not read this mesh (malformed or not OBJ/OFF/STL)");
  if (mesh.n_vertices() == 0) return Status::badInput(path + ": the mesh has no vertices");
  return Status::ok();
}

}  // namespace

Status readMeshInProcess(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink) {
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

namespace {
// OpenMesh holds the whole mesh with its connectivity: a few hundred bytes per vertex.
uint64_t meshLimit(const std::string& path) {
  auto size = fileSize(path);
  return std::max<uint64_t>(uint64_t(2) << 30, 64 * (size ? *size : 0));
}
}  // namespace

Status readMesh(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink) {
  if (!std::filesystem::exists(path)) return Status::badInput(path + ": no such file");
  return runIsolated(
      path, meshLimit(path),
      [&](BatchSink& out, std::string&) { return readMeshInProcess(path, batchPoints, readTriangles, out); }, &sink,
      nullptr);
}

}  // namespace sa
