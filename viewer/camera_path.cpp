#include "viewer/camera_path.h"

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "common/fileio.h"

namespace sa {
namespace {

Result<Eigen::Vector3d> vec3(const nlohmann::json& j, const std::string& where) {
  if (!j.is_array() || j.size() != 3) return Status::badInput(where + ": expected an array of 3 numbers");
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) {
    if (!j[size_t(i)].is_number()) return Status::badInput(where + ": expected an array of 3 numbers");
    v[i] = j[size_t(i)].get<double>();
  }
  if (!v.allFinite()) return Status::badInput(where + ": not finite");
  return v;
}

}  // namespace

Result<std::vector<Camera>> readCameraPath(const std::string& path, int width, int height) {
  auto size = fileSize(path);
  if (!size) return size.status();
  if (*size > (64u << 20)) return Status::badInput(path + ": camera path larger than 64 MiB");
  std::ifstream in(path);
  nlohmann::json doc;
  try {
    in >> doc;
  } catch (const nlohmann::json::parse_error& e) {
    return Status::badInput(path + ": not valid JSON at byte " + std::to_string(e.byte) + ": " + e.what());
  }
  const nlohmann::json* list = &doc;
  if (doc.is_object() && doc.contains("cameras")) list = &doc["cameras"];
  if (!list->is_array() || list->empty())
    return Status::badInput(path + ": expected {\"cameras\": [...]} or an array of cameras");
  std::vector<Camera> cams;
  for (size_t i = 0; i < list->size(); ++i) {
    const nlohmann::json& c = (*list)[i];
    const std::string where = path + ": camera " + std::to_string(i);
    if (!c.is_object() || !c.contains("eye") || !c.contains("target"))
      return Status::badInput(where + ": needs \"eye\" and \"target\"");
    Camera cam;
    cam.width = width;
    cam.height = height;
    auto eye = vec3(c["eye"], where + " eye");
    if (!eye) return eye.status();
    auto target = vec3(c["target"], where + " target");
    if (!target) return target.status();
    cam.eye = *eye;
    cam.target = *target;
    if (c.contains("up")) {
      auto up = vec3(c["up"], where + " up");
      if (!up) return up.status();
      cam.up = *up;
    }
    if (c.contains("fov")) {
      if (!c["fov"].is_number()) return Status::badInput(where + ": fov must be a number");
      cam.fovDeg = c["fov"].get<double>();
    }
    Status s = cam.validate();
    if (!s) return Status::badInput(where + ": " + s.message());
    cams.push_back(cam);
  }
  return cams;
}

Status writeCameraPath(const std::string& path, const std::vector<Camera>& cams) {
  nlohmann::json list = nlohmann::json::array();
  for (const Camera& c : cams) {
    list.push_back({{"eye", {c.eye.x(), c.eye.y(), c.eye.z()}},
                    {"target", {c.target.x(), c.target.y(), c.target.z()}},
                    {"up", {c.up.x(), c.up.y(), c.up.z()}},
                    {"fov", c.fovDeg}});
  }
  const std::string text = nlohmann::json{{"cameras", list}}.dump(2) + "\n";
  return writeFileAtomic(path, text.data(), text.size());
}

}  // namespace sa
