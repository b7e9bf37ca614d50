#include "viewer/source_points.h"

#include <cmath>

#include "formats/source.h"
#include "modes/pack_sources.h"
#include "viewer/renderer.h"

namespace sa {
namespace {

class ToFloats : public BatchSink {
 public:
  ToFloats(const double origin[3], SourcePoints& out) : out_(out) { std::copy(origin, origin + 3, o_); }
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) {
      if (!std::isfinite(b.x[i]) || !std::isfinite(b.y[i]) || !std::isfinite(b.z[i])) continue;
      out_.xyz.push_back(float(b.x[i] - o_[0]));
      out_.xyz.push_back(float(b.y[i] - o_[1]));
      out_.xyz.push_back(float(b.z[i] - o_[2]));
      const bool c = b.hasColors();
      out_.rgba.push_back(c ? b.r[i] : 255);
      out_.rgba.push_back(c ? b.g[i] : 255);
      out_.rgba.push_back(c ? b.b[i] : 255);
      out_.rgba.push_back(255);
    }
    return Status::ok();
  }

 private:
  double o_[3];
  SourcePoints& out_;
};

}  // namespace

Status loadSourcePoints(const PackReader& pack, SourcePoints& out) {
  auto input = openPackSources(pack, "the points baseline reads the sources");
  if (!input) return input.status();
  out.xyz.clear();
  out.rgba.clear();
  out.xyz.reserve(input->pointCount() * 3);
  out.rgba.reserve(input->pointCount() * 4);
  ToFloats sink(pack.meta().origin, out);
  return input->stream(sink, false);
}

Status uploadSourcePoints(const PackReader& pack, Renderer& renderer) {
  SourcePoints pts;
  SA_RETURN_IF_ERROR(loadSourcePoints(pack, pts));
  return renderer.setPoints(pts.xyz, pts.rgba, pack.meta().sampleSpacing);
}

}  // namespace sa
