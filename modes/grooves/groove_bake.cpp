#include "modes/grooves/groove_bake.h"

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "formats/source.h"
#include "modes/grooves/groove_cast.h"
#include "modes/pack_sources.h"

namespace sa::grooves {
namespace {

struct PointSink : BatchSink {
  std::vector<double> pos;
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) pos.insert(pos.end(), {b.x[i], b.y[i], b.z[i]});
    return Status::ok();
  }
};

// The pack's source points (world coordinates); mesh: whether the source is one mesh.
Status sourcePoints(const PackReader& pack, std::vector<double>& pos, bool& mesh) {
  auto input = openPackSources(pack, "grooves are found in the raw points");
  if (!input) return input.status();
  PointSink sink;
  SA_RETURN_IF_ERROR(input->stream(sink, false));
  mesh = input->hasTriangles();
  pos = std::move(sink.pos);
  if (pos.size() < 3 * 64) return Status::badInput(pack.path() + ": its sources hold fewer than 64 points");
  return Status::ok();
}

bool measured(const Groove& g) { return g.shape != "gap" && (g.depth > 0 || g.profile.size() >= 3); }

}  // namespace

Result<GrooveSet> groovesForPack(const PackReader& pack, const BakeRequest& req, std::string& how) {
  GrooveOptions opt;
  opt.progress = req.progress;
  std::vector<double> pos;
  bool mesh = false;
  if (!req.groovesFile.empty()) {
    Result<GrooveSet> given = readGroovesJson(req.groovesFile);
    if (!given) return given.status();
    GrooveSet keep = *given, todo = *given;
    keep.grooves.clear();
    todo.grooves.clear();
    for (const Groove& g : given->grooves) (measured(g) ? keep : todo).grooves.push_back(g);
    how = std::to_string(keep.grooves.size()) + " given with their profiles";
    if (!todo.grooves.empty()) {
      SA_RETURN_IF_ERROR(sourcePoints(pack, pos, mesh));
      GrooveSet m = measureGrooves(pos.data(), pos.size() / 3, todo, opt);
      how += ", " + std::to_string(m.grooves.size() - m.unmeasured) + " measured in the points";
      if (m.unmeasured) how += " (" + std::to_string(m.unmeasured) + " with too few points beside them kept as given)";
      keep.grooves.insert(keep.grooves.end(), m.grooves.begin(), m.grooves.end());
      if (keep.spacing == 0) keep.spacing = m.spacing;
      if (keep.noise == 0) keep.noise = m.noise;
    }
    how += " from " + req.groovesFile;
    return keep;
  }
  SA_RETURN_IF_ERROR(sourcePoints(pack, pos, mesh));
  if (mesh) opt.gaps = false;  // a mesh's triangles cover the strips between its vertices
  GrooveSet set = detectGrooves(pos.data(), pos.size() / 3, opt);
  how = "detected in the sources";
  return set;
}

Result<ExtraSection> bakeSection(const PackReader& pack, const BakeRequest& req, std::string& summary) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string how;
  Result<GrooveSet> set = groovesForPack(pack, req, how);
  if (!set) return set.status();
  gcast::Model m = gcast::buildModel(pack, *set);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ExtraSection s = gcast::makeSection(pack, m, groovesJsonText(*set), seconds);
  size_t pieces = 0, bins = 0, used = 0, entries = 0, most = 0;
  for (const auto& c : m.cells) {
    pieces += c.pieces.size();
    bins += c.bins.size();
    for (const auto& b : c.bins) {
      used += !b.empty();
      entries += b.size();
      most = std::max(most, b.size());
    }
  }
  char line[512];
  std::snprintf(line, sizeof(line),
                "grooves: section GROO, %.1f KiB, %zu grooves (%s), %u drawn, %u not drawn (gaps of unknown depth, or on no "
                "cell's surface); %zu pieces in %zu cells (%zu of %zu bins hold pieces, %.1f on average, at most %zu), in %.2f s",
                double(s.bytes.size()) / 1024, set->grooves.size(), how.c_str(), m.drawn, m.skipped, pieces,
                m.cells.size(), used, bins, used ? double(entries) / double(used) : 0.0, most, seconds);
  summary = line;
  return s;
}

Result<GrooveSet> packGrooves(const PackReader& pack) {
  auto v = gcast::readSection(pack);
  if (!v) return v.status();
  if (!v->present) return GrooveSet{};
  return parseGroovesJson(v->json, pack.path() + " (section GROO)");
}

}  // namespace sa::grooves
