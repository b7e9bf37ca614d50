// The only file that includes Draco.
#include "formats/draco.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#include <draco/core/varint_decoding.h>
#include <draco/metadata/geometry_metadata.h>
#include <draco/metadata/metadata_decoder.h>
#include <draco/point_cloud/point_cloud.h>

#include "common/fileio.h"
#include "formats/isolate.h"

namespace sa {
namespace {

constexpr uint64_t kMaxDracoFile = uint64_t(1) << 32;
// Draco allocates its attribute arrays from the point count in the stream before it reads
// any point (a 39-byte file claiming 10^9 points asked for 13 GB when fuzzed). Even the
// best-compressing encodings need more than a sixteenth of a byte per point in practice.
constexpr uint64_t kMaxPointsPerByte = 16;

// Reads the point count a version-2 point cloud or sequential mesh declares, the way Draco's
// decoders will (header, optional metadata, then the count), and refuses counts the file
// cannot plausibly hold. Edgebreaker meshes check their counts against the buffer themselves.
Status checkDeclaredCount(const std::string& path, const char* data, size_t size) {
  if (size < 11) return Status::badInput(path + ": Draco header truncated (" + std::to_string(size) + " bytes)");
  const uint8_t major = uint8_t(data[5]), type = uint8_t(data[7]), method = uint8_t(data[8]);
  uint16_t flags;
  std::memcpy(&flags, data + 9, 2);
  if (major != 2) return Status::ok();
  draco::DecoderBuffer buf;
  buf.Init(data + 11, size - 11);
  if (flags & 0x8000) {
    draco::MetadataDecoder md;
    draco::GeometryMetadata gm;
    if (!md.DecodeGeometryMetadata(&buf, &gm)) return Status::badInput(path + ": Draco metadata is corrupt");
  }
  uint64_t points = 0;
  if (type == draco::POINT_CLOUD) {
    int32_t n = 0;
    if (!buf.Decode(&n) || n < 0) return Status::badInput(path + ": Draco point count missing or negative");
    points = uint64_t(n);
  } else if (type == draco::TRIANGULAR_MESH && method == 0 && uint8_t(data[6]) >= 2) {
    uint32_t faces = 0, n = 0;
    if (!draco::DecodeVarint(&faces, &buf) || !draco::DecodeVarint(&n, &buf))
      return Status::badInput(path + ": Draco mesh counts missing");
    points = n;
  } else {
    return Status::ok();
  }
  if (points > kMaxPointsPerByte * size + 4096)
    return Status::badInput(path + ": Draco stream declares " + std::to_string(points) + " points in a " +
                            std::to_string(size) + "-byte file (corrupt or hostile; refused before decoding)");
  return Status::ok();
}

bool usable(const draco::PointAttribute* a);
const draco::PointAttribute* named(const draco::PointCloud& pc, draco::GeometryAttribute::Type t);

struct Decoded {
  std::unique_ptr<draco::PointCloud> pc;
  const draco::Mesh* mesh = nullptr;  // pc downcast when the file holds a mesh
  double origin[3] = {0, 0, 0};
  bool shifted = false;
};

Result<Decoded> decodeInProcess(const std::string& path) {
  auto size = fileSize(path);
  if (!size) return size.status();
  if (*size > kMaxDracoFile) return Status::badInput(path + ": Draco files over 4 GiB are not supported");
  std::vector<char> bytes(*size);
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return Status::badInput(path + ": cannot open");
  const size_t got = bytes.empty() ? 0 : std::fread(bytes.data(), 1, bytes.size(), f);
  std::fclose(f);
  if (got != bytes.size()) return Status::badInput(path + ": read error");
  if (bytes.size() < 5 || std::memcmp(bytes.data(), "DRACO", 5) != 0)
    return Status::badInput(path + ": not a Draco file (no DRACO signature at byte 0)");
  SA_RETURN_IF_ERROR(checkDeclaredCount(path, bytes.data(), bytes.size()));
  draco::DecoderBuffer buf;
  buf.Init(bytes.data(), bytes.size());
  auto type = draco::Decoder::GetEncodedGeometryType(&buf);
  if (!type.ok()) return Status::badInput(path + ": Draco header: " + type.status().error_msg_string());
  Decoded d;
  draco::Decoder dec;
  if (type.value() == draco::TRIANGULAR_MESH) {
    auto m = dec.DecodeMeshFromBuffer(&buf);
    if (!m.ok()) return Status::badInput(path + ": Draco mesh: " + m.status().error_msg_string());
    d.pc = std::move(m).value();
    d.mesh = static_cast<const draco::Mesh*>(d.pc.get());
  } else if (type.value() == draco::POINT_CLOUD) {
    auto p = dec.DecodePointCloudFromBuffer(&buf);
    if (!p.ok()) return Status::badInput(path + ": Draco point cloud: " + p.status().error_msg_string());
    d.pc = std::move(p).value();
  } else {
    return Status::badInput(path + ": Draco geometry type " + std::to_string(int(type.value())) + " is not supported");
  }
  if (!named(*d.pc, draco::GeometryAttribute::POSITION))
    return Status::badInput(path + ": the Draco file has no usable position attribute");
  if (const auto* md = d.pc->GetMetadata()) {
    std::vector<double> o;
    if (md->GetEntryDoubleArray("scanatlas_origin", &o) && o.size() == 3 && std::isfinite(o[0]) &&
        std::isfinite(o[1]) && std::isfinite(o[2])) {
      std::copy(o.begin(), o.end(), d.origin);
      d.shifted = true;
    }
  }
  return d;
}

// Attributes of a type ScanAtlas can convert (Draco's own conversion reads DT_BOOL bytes as
// bool, which is undefined for bytes other than 0 and 1).
bool usable(const draco::PointAttribute* a) {
  return a && a->num_components() >= 1 && a->data_type() != draco::DT_BOOL && a->data_type() != draco::DT_INVALID &&
         a->data_type() < draco::DT_TYPES_COUNT;
}

const draco::PointAttribute* named(const draco::PointCloud& pc, draco::GeometryAttribute::Type t) {
  const draco::PointAttribute* a = pc.GetNamedAttribute(t);
  return usable(a) ? a : nullptr;
}

const draco::PointAttribute* generic(const draco::PointCloud& pc, const char* name) {
  const int id = pc.GetAttributeIdByMetadataEntry("name", name);
  if (id < 0) return nullptr;
  const draco::PointAttribute* a = pc.attribute(id);
  return usable(a) ? a : nullptr;
}

DracoInfo infoOf(const Decoded& d) {
  const draco::PointCloud& pc = *d.pc;
  DracoInfo info;
  info.points = pc.num_points();
  info.triangles = d.mesh ? d.mesh->num_faces() : 0;
  const auto* n = named(pc, draco::GeometryAttribute::NORMAL);
  const auto* c = named(pc, draco::GeometryAttribute::COLOR);
  info.hasNormals = n && n->num_components() == 3;
  info.hasColors = c && c->num_components() >= 3;
  info.hasIntensity = generic(pc, "intensity") != nullptr;
  info.hasConfidence = generic(pc, "confidence") != nullptr;
  info.hasClassification = generic(pc, "classification") != nullptr;
  info.shifted = d.shifted;
  return info;
}

Status streamDecoded(const std::string& path, const Decoded& d, size_t batchPoints, bool readTriangles, BatchSink& sink) {
  const draco::PointCloud& pc = *d.pc;
  using GA = draco::GeometryAttribute;
  const auto* pos = named(pc, GA::POSITION);
  const auto* nor = named(pc, GA::NORMAL);
  const auto* col = named(pc, GA::COLOR);
  if (nor && nor->num_components() != 3) nor = nullptr;
  if (col && col->num_components() < 3) col = nullptr;
  const auto* inten = generic(pc, "intensity");
  const auto* conf = generic(pc, "confidence");
  const auto* cls = generic(pc, "classification");
  const bool colFloat = col && (col->data_type() == draco::DT_FLOAT32 || col->data_type() == draco::DT_FLOAT64);
  const int colShift = col && (col->data_type() == draco::DT_UINT16) ? 8 : 0;
  const uint64_t n = pc.num_points();
  batchPoints = std::max<size_t>(1, batchPoints);
  PointBatch b;
  for (uint64_t done = 0; done < n; done += batchPoints) {
    const size_t m = size_t(std::min<uint64_t>(batchPoints, n - done));
    b.clear();
    b.firstIndex = done;
    for (size_t k = 0; k < m; ++k) {
      const draco::PointIndex pi(static_cast<uint32_t>(done + k));
      double p[3] = {0, 0, 0};
      if (!pos->ConvertValue<double>(pos->mapped_index(pi), 3, p))
        return Status::badInput(path + ": point " + std::to_string(done + k) + ": unreadable position");
      b.x.push_back(p[0] + d.origin[0]);
      b.y.push_back(p[1] + d.origin[1]);
      b.z.push_back(p[2] + d.origin[2]);
      if (nor) {
        float v[3] = {0, 0, 1};
        nor->ConvertValue<float>(nor->mapped_index(pi), 3, v);
        b.nx.push_back(v[0]); b.ny.push_back(v[1]); b.nz.push_back(v[2]);
      }
      if (col) {
        uint8_t rgb[3];
        if (colFloat) {
          float v[3] = {1, 1, 1};
          col->ConvertValue<float>(col->mapped_index(pi), 3, v);
          for (int c = 0; c < 3; ++c) rgb[c] = uint8_t(std::clamp(v[c] * 255.0f + 0.5f, 0.0f, 255.0f));
        } else {
          uint32_t v[3] = {255, 255, 255};
          col->ConvertValue<uint32_t>(col->mapped_index(pi), 3, v);
          for (int c = 0; c < 3; ++c) rgb[c] = uint8_t(std::min<uint32_t>(255, v[c] >> colShift));
        }
        b.r.push_back(rgb[0]); b.g.push_back(rgb[1]); b.b.push_back(rgb[2]);
      }
      auto scalar = [&](const draco::PointAttribute* a) {
        float v = 0;
        a->ConvertValue<float>(a->mapped_index(pi), 1, &v);
        return std::isfinite(v) ? v : 0.0f;
      };
      if (inten) b.intensity.push_back(scalar(inten));
      if (conf) b.confidence.push_back(scalar(conf));
      if (cls) b.classification.push_back(uint8_t(std::clamp(scalar(cls), 0.0f, 255.0f)));
    }
    SA_RETURN_IF_ERROR(sink.onPoints(b));
  }
  if (readTriangles && d.mesh) {
    std::vector<uint32_t> tris;
    const uint32_t faces = d.mesh->num_faces();
    for (uint32_t f = 0; f < faces; ++f) {
      const auto& face = d.mesh->face(draco::FaceIndex(f));
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = face[k].value();
        if (v >= n) return Status::badInput(path + ": face " + std::to_string(f) + " refers to point " + std::to_string(v) + " of " + std::to_string(n));
        tris.push_back(v);
      }
      if (tris.size() >= 3 * batchPoints) {
        SA_RETURN_IF_ERROR(sink.onTriangles(tris.data(), tris.size() / 3));
        tris.clear();
      }
    }
    if (!tris.empty()) SA_RETURN_IF_ERROR(sink.onTriangles(tris.data(), tris.size() / 3));
  }
  return Status::ok();
}

// libdraco needs about the decoded size; hostile streams asked for gigabytes (fuzzing).
uint64_t limitFor(uint64_t fileBytes) { return std::max<uint64_t>(uint64_t(2) << 30, 64 * fileBytes); }

}  // namespace

Result<DracoInfo> readDracoInfo(const std::string& path) {
  auto size = fileSize(path);
  if (!size) return size.status();
  std::string blob;
  SA_RETURN_IF_ERROR(runIsolated(
      path, limitFor(*size),
      [&](BatchSink&, std::string& info) {
        auto d = decodeInProcess(path);
        if (!d) return d.status();
        const DracoInfo di = infoOf(*d);
        info.assign(reinterpret_cast<const char*>(&di), sizeof(di));
        return Status::ok();
      },
      nullptr, &blob));
  if (blob.size() != sizeof(DracoInfo)) return Status::internal(path + ": the Draco reader sent no description");
  DracoInfo info;
  std::memcpy(&info, blob.data(), sizeof(info));
  return info;
}

Status readDraco(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink,
                 DracoInfo* info) {
  auto size = fileSize(path);
  if (!size) return size.status();
  std::string blob;
  SA_RETURN_IF_ERROR(runIsolated(
      path, limitFor(*size),
      [&](BatchSink& out, std::string& infoOut) {
        auto d = decodeInProcess(path);
        if (!d) return d.status();
        const DracoInfo di = infoOf(*d);
        infoOut.assign(reinterpret_cast<const char*>(&di), sizeof(di));
        return streamDecoded(path, *d, std::max<size_t>(1, batchPoints), readTriangles, out);
      },
      &sink, &blob));
  if (info) {
    if (blob.size() != sizeof(DracoInfo)) return Status::internal(path + ": the Draco reader sent no description");
    std::memcpy(info, blob.data(), sizeof(DracoInfo));
  }
  return Status::ok();
}

Status readDracoInProcess(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink) {
  auto d = decodeInProcess(path);
  if (!d) return d.status();
  return streamDecoded(path, *d, std::max<size_t>(1, batchPoints), readTriangles, sink);
}

Status DracoWriter::onPoints(const PointBatch& in) {
  auto append = [](auto& dst, const auto& src, bool keep) {
    if (keep) dst.insert(dst.end(), src.begin(), src.end());
    else dst.clear();
  };
  if (first_) {
    all_ = in;
    all_.scan.clear();
    first_ = false;
    return Status::ok();
  }
  append(all_.x, in.x, true);
  append(all_.y, in.y, true);
  append(all_.z, in.z, true);
  const bool n = all_.hasNormals() && in.hasNormals();
  append(all_.nx, in.nx, n); append(all_.ny, in.ny, n); append(all_.nz, in.nz, n);
  const bool c = all_.hasColors() && in.hasColors();
  append(all_.r, in.r, c); append(all_.g, in.g, c); append(all_.b, in.b, c);
  append(all_.intensity, in.intensity, all_.hasIntensity() && in.hasIntensity());
  append(all_.confidence, in.confidence, all_.hasConfidence() && in.hasConfidence());
  append(all_.classification, in.classification, all_.hasClassification() && in.hasClassification());
  return Status::ok();
}

Result<uint64_t> DracoWriter::write(const std::string& path, bool* shiftedOut) {
  const size_t n = all_.size();
  if (n == 0) return Status::badInput(path + ": nothing to write (no finite points)");
  if (n > size_t(std::numeric_limits<int32_t>::max())) return Status::badInput(path + ": too many points for one Draco file");
  // Float32 positions: shift to a local origin when float rounding would exceed 1e-6 of the extent.
  double lo[3], hi[3], maxAbs = 0;
  for (int a = 0; a < 3; ++a) { lo[a] = std::numeric_limits<double>::max(); hi[a] = -lo[a]; }
  const std::vector<double>* axes[3] = {&all_.x, &all_.y, &all_.z};
  for (int a = 0; a < 3; ++a)
    for (double v : *axes[a]) {
      lo[a] = std::min(lo[a], v);
      hi[a] = std::max(hi[a], v);
      maxAbs = std::max(maxAbs, std::abs(v));
    }
  const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-30});
  const double ulp = maxAbs * std::ldexp(1.0, -24);
  const bool shift = ulp > 1e-6 * extent;
  double origin[3] = {0, 0, 0};
  if (shift)
    for (int a = 0; a < 3; ++a) origin[a] = std::floor(lo[a]);
  if (shiftedOut) *shiftedOut = shift;

  // A mesh when triangles came in, else a point cloud; attributes are added the same way.
  std::unique_ptr<draco::PointCloud> pc;
  draco::Mesh* mesh = nullptr;
  if (!tris_.empty()) {
    auto m = std::make_unique<draco::Mesh>();
    mesh = m.get();
    pc = std::move(m);
  } else {
    pc = std::make_unique<draco::PointCloud>();
  }
  pc->set_num_points(static_cast<uint32_t>(n));
  using GA = draco::GeometryAttribute;
  auto addAttribute = [&](GA::Type type, int comps, draco::DataType dt, const void* values, size_t elemBytes,
                          const char* name) {
    GA ga;
    ga.Init(type, nullptr, uint8_t(comps), dt, false, int64_t(elemBytes), 0);
    const int id = pc->AddAttribute(ga, true, static_cast<uint32_t>(n));
    draco::PointAttribute* att = pc->attribute(id);
    const uint8_t* v = static_cast<const uint8_t*>(values);
    for (size_t i = 0; i < n; ++i) att->SetAttributeValue(draco::AttributeValueIndex(uint32_t(i)), v + i * elemBytes);
    if (name) {
      auto md = std::make_unique<draco::AttributeMetadata>();
      md->AddEntryString("name", name);
      pc->AddAttributeMetadata(id, std::move(md));
    }
  };
  {
    std::vector<float> p(3 * n);
    for (size_t i = 0; i < n; ++i) {
      p[3 * i] = float(all_.x[i] - origin[0]);
      p[3 * i + 1] = float(all_.y[i] - origin[1]);
      p[3 * i + 2] = float(all_.z[i] - origin[2]);
    }
    addAttribute(GA::POSITION, 3, draco::DT_FLOAT32, p.data(), 12, nullptr);
  }
  if (all_.hasNormals()) {
    std::vector<float> v(3 * n);
    for (size_t i = 0; i < n; ++i) { v[3 * i] = all_.nx[i]; v[3 * i + 1] = all_.ny[i]; v[3 * i + 2] = all_.nz[i]; }
    addAttribute(GA::NORMAL, 3, draco::DT_FLOAT32, v.data(), 12, nullptr);
  }
  if (all_.hasColors()) {
    std::vector<uint8_t> v(3 * n);
    for (size_t i = 0; i < n; ++i) { v[3 * i] = all_.r[i]; v[3 * i + 1] = all_.g[i]; v[3 * i + 2] = all_.b[i]; }
    addAttribute(GA::COLOR, 3, draco::DT_UINT8, v.data(), 3, nullptr);
  }
  if (all_.hasIntensity()) addAttribute(GA::GENERIC, 1, draco::DT_FLOAT32, all_.intensity.data(), 4, "intensity");
  if (all_.hasConfidence()) addAttribute(GA::GENERIC, 1, draco::DT_FLOAT32, all_.confidence.data(), 4, "confidence");
  if (all_.hasClassification())
    addAttribute(GA::GENERIC, 1, draco::DT_UINT8, all_.classification.data(), 1, "classification");
  if (mesh) {
    mesh->SetNumFaces(tris_.size() / 3);
    for (size_t f = 0; f < tris_.size() / 3; ++f) {
      draco::Mesh::Face face;
      for (int k = 0; k < 3; ++k) {
        if (tris_[3 * f + k] >= n) return Status::badInput(path + ": triangle " + std::to_string(f) + " refers to a missing point");
        face[k] = draco::PointIndex(tris_[3 * f + k]);
      }
      mesh->SetFace(draco::FaceIndex(uint32_t(f)), face);
    }
  }
  if (shift) {
    if (!pc->metadata()) pc->AddMetadata(std::make_unique<draco::GeometryMetadata>());
    pc->metadata()->AddEntryDoubleArray("scanatlas_origin", {origin[0], origin[1], origin[2]});
  }
  draco::Encoder enc;
  if (opt_.positionBits > 0) enc.SetAttributeQuantization(GA::POSITION, opt_.positionBits);
  if (all_.hasNormals() && opt_.normalBits > 0) enc.SetAttributeQuantization(GA::NORMAL, opt_.normalBits);
  enc.SetSpeedOptions(opt_.speed, opt_.speed);
  draco::EncoderBuffer out;
  const draco::Status s = mesh ? enc.EncodeMeshToBuffer(*mesh, &out) : enc.EncodePointCloudToBuffer(*pc, &out);
  if (!s.ok()) return Status::internal(path + ": Draco encoding failed: " + s.error_msg_string());
  SA_RETURN_IF_ERROR(writeFileAtomic(path, out.data(), out.size()));
  return uint64_t(out.size());
}

}  // namespace sa
