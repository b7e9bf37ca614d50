// Grooves as JSON (everything, editable, read back by --grooves) and CSV (one row per groove).
#include <cmath>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/fileio.h"
#include "grooves/grooves.h"

namespace sa {
namespace {

using nlohmann::json;

constexpr const char* kFormat = "scanatlas-grooves";
constexpr int kVersion = 1;

Result<Groove> parseGroove(const json& j, const std::string& where) {
  Groove g;
  if (!j.is_object()) return Status::badInput(where + ": expected an object");
  auto num = [&](const char* key, double dflt, bool required, double& out) -> Status {
    if (!j.contains(key)) {
      if (required) return Status::badInput(where + ": missing \"" + key + "\"");
      out = dflt;
      return Status::ok();
    }
    if (!j[key].is_number() || !std::isfinite(j[key].get<double>()))
      return Status::badInput(where + ": \"" + key + "\" must be a finite number");
    out = j[key].get<double>();
    return Status::ok();
  };
  Status s = num("width", 0, true, g.width);
  if (s) s = num("depth", 0, false, g.depth);
  if (s) s = num("confidence", 1, false, g.confidence);
  if (!s) return s;
  if (g.width <= 0 || g.depth < 0) return Status::badInput(where + ": width must be > 0 and depth >= 0");
  g.shape = j.contains("shape") && j["shape"].is_string() ? j["shape"].get<std::string>() : "given";
  if (g.shape != "V" && g.shape != "U" && g.shape != "gap" && g.shape != "given")
    return Status::badInput(where + ": shape must be V, U, gap or given");
  if (!j.contains("polyline") || !j["polyline"].is_array() || j["polyline"].size() < 2)
    return Status::badInput(where + ": \"polyline\" must be an array of at least 2 [x, y, z] points");
  for (size_t k = 0; k < j["polyline"].size(); ++k) {
    const json& p = j["polyline"][k];
    if (!p.is_array() || p.size() != 3 || !p[0].is_number() || !p[1].is_number() || !p[2].is_number())
      return Status::badInput(where + ": polyline point " + std::to_string(k) + " is not [x, y, z]");
    const Eigen::Vector3d q(p[0].get<double>(), p[1].get<double>(), p[2].get<double>());
    if (!q.allFinite()) return Status::badInput(where + ": polyline point " + std::to_string(k) + " is not finite");
    g.line.push_back(q);
  }
  for (size_t k = 0; k + 1 < g.line.size(); ++k) g.length += (g.line[k + 1] - g.line[k]).norm();
  if (j.contains("profile") && j["profile"].is_array())
    for (const json& p : j["profile"])
      if (p.is_array() && p.size() == 2 && p[0].is_number() && p[1].is_number())
        g.profile.push_back({p[0].get<float>(), p[1].get<float>()});
  return g;
}

}  // namespace

std::string groovesJsonText(const GrooveSet& set) {
  json j;
  j["format"] = kFormat;
  j["version"] = kVersion;
  j["spacing"] = set.spacing;
  j["noise"] = set.noise;
  j["regions"] = set.regions;
  j["skipped_regions"] = set.skippedRegions;
  j["grooves"] = json::array();
  for (size_t i = 0; i < set.grooves.size(); ++i) {
    const Groove& g = set.grooves[i];
    json o;
    o["id"] = i;
    o["shape"] = g.shape;
    o["width"] = g.width;
    o["width_uncertainty"] = set.spacing;
    if (g.shape == "gap") o["depth"] = nullptr;  // no points inside: not measured
    else o["depth"] = g.depth;
    o["length"] = g.length;
    o["confidence"] = g.confidence;
    o["polyline"] = json::array();
    for (const Eigen::Vector3d& p : g.line) o["polyline"].push_back({p.x(), p.y(), p.z()});
    o["profile"] = json::array();
    for (const auto& [x, h] : g.profile) o["profile"].push_back({x, h});
    j["grooves"].push_back(o);
  }
  return j.dump(1) + "\n";
}

Status writeGroovesJson(const GrooveSet& set, const std::string& path) {
  const std::string text = groovesJsonText(set);
  return writeFileAtomic(path, text.data(), text.size());
}

Status writeGroovesCsv(const GrooveSet& set, const std::string& path) {
  std::ostringstream o;
  o.precision(9);
  o << "id,shape,width,width_uncertainty,depth,length,confidence,points,polyline\n";
  for (size_t i = 0; i < set.grooves.size(); ++i) {
    const Groove& g = set.grooves[i];
    o << i << ',' << g.shape << ',' << g.width << ',' << set.spacing << ',';
    if (g.shape != "gap") o << g.depth;
    o << ',' << g.length << ',' << g.confidence << ',' << g.line.size() << ",\"";
    for (size_t k = 0; k < g.line.size(); ++k)
      o << (k ? ";" : "") << g.line[k].x() << ' ' << g.line[k].y() << ' ' << g.line[k].z();
    o << "\"\n";
  }
  const std::string text = o.str();
  return writeFileAtomic(path, text.data(), text.size());
}

Result<GrooveSet> readGroovesJson(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return Status::badInput(path + ": cannot open");
  std::stringstream text;
  text << f.rdbuf();
  return parseGroovesJson(text.str(), path);
}

Result<GrooveSet> parseGroovesJson(const std::string& text, const std::string& path) {
  json j = json::parse(text, nullptr, false);
  if (j.is_discarded()) return Status::badInput(path + ": not valid JSON");
  if (!j.is_object() || !j.contains("grooves") || !j["grooves"].is_array())
    return Status::badInput(path + ": expected an object with a \"grooves\" array");
  if (j.contains("version") && (!j["version"].is_number_integer() || j["version"].get<int>() > kVersion))
    return Status::badInput(path + ": grooves version " + j["version"].dump() + " is newer than this scanatlas reads (" +
                            std::to_string(kVersion) + ")");
  GrooveSet set;
  if (j.contains("spacing") && j["spacing"].is_number()) set.spacing = j["spacing"].get<double>();
  if (j.contains("noise") && j["noise"].is_number()) set.noise = j["noise"].get<double>();
  for (size_t i = 0; i < j["grooves"].size(); ++i) {
    Result<Groove> g = parseGroove(j["grooves"][i], path + ": groove " + std::to_string(i));
    if (!g) return g.status();
    set.grooves.push_back(std::move(*g));
  }
  return set;
}

}  // namespace sa
