#include "window/script.h"

#include <fstream>
#include <map>
#include <sstream>

#include "common/fileio.h"
#include "viewer/image_io.h"

namespace sa {
namespace {

struct Spec {
  size_t numbers;  // at least this many numbers
  std::vector<std::string> firstWord;  // when not empty: the first argument is one of these
  bool file = false;                   // the first argument is an output image
};

const std::map<std::string, Spec>& specs() {
  static const std::map<std::string, Spec> s = {
      {"quit", {0, {}}},       {"size", {2, {}}},       {"camera", {6, {}}},    {"orbit", {2, {}}},
      {"pan", {2, {}}},        {"zoom", {3, {}}},       {"frame", {0, {}}},     {"top", {0, {}}},
      {"front", {0, {}}},      {"side", {0, {}}},       {"pick", {2, {}}},      {"distance", {0, {}}},
      {"polyline", {0, {}}},   {"height", {0, {}}},     {"clear", {0, {}}},
      {"clip", {0, {"box", "plane", "off"}}},
      {"shading", {0, {"lambert", "normals", "height", "color"}}},
      {"edl", {0, {"on", "off"}}},                      {"boxes", {0, {"on", "off"}}},
      {"iterations", {1, {}}}, {"screenshot", {0, {}, true}}, {"windowshot", {0, {}, true}},
      {"bookmark", {0, {}}},   {"wait", {1, {}}},       {"groove", {1, {}}}};
  return s;
}

}  // namespace

Result<ScriptCommand> parseScriptLine(const std::string& text) {
  ScriptCommand c;
  std::istringstream is(text);
  std::string name;
  if (!(is >> name) || name[0] == '#') return c;
  for (std::string w; is >> w;) {
    c.words.push_back(w);
    char* end = nullptr;
    const double x = std::strtod(w.c_str(), &end);
    if (end && end != w.c_str() && *end == '\0') c.numbers.push_back(x);
  }
  auto it = specs().find(name);
  if (it == specs().end()) return Status::badInput("unknown command '" + name + "' (scanatlas view --help lists them)");
  const Spec& sp = it->second;
  if (c.numbers.size() < sp.numbers)
    return Status::badInput("'" + text + "': " + name + " needs " + std::to_string(sp.numbers) + " numbers");
  if (!sp.firstWord.empty()) {
    bool ok = !c.words.empty();
    for (size_t i = 0; ok && i < sp.firstWord.size(); ++i)
      if (c.words[0] == sp.firstWord[i]) break;
      else if (i + 1 == sp.firstWord.size()) ok = false;
    if (!ok) {
      std::string choices;
      for (const auto& w : sp.firstWord) choices += (choices.empty() ? "" : "|") + w;
      return Status::badInput("'" + text + "': " + name + " takes " + choices);
    }
    if (name == "clip" && c.words[0] != "off" && c.numbers.size() < 6)
      return Status::badInput("'" + text + "': clip " + c.words[0] + " needs 6 numbers");
  }
  if (sp.file) {
    if (c.words.empty()) return Status::badInput("'" + text + "': " + name + " needs a file name");
    SA_RETURN_IF_ERROR(checkImageExtension(c.words[0]));
  }
  c.name = name;
  return c;
}

Result<std::vector<ScriptCommand>> loadScript(const std::string& path, const std::vector<std::string>& inputs) {
  std::ifstream in(path);
  if (!in) return Status::badInput(path + ": cannot open the script");
  std::vector<ScriptCommand> out;
  size_t n = 0;
  for (std::string l; std::getline(in, l);) {
    ++n;
    auto c = parseScriptLine(l);
    if (!c) return Status::badInput(path + ":" + std::to_string(n) + ": " + c.status().message());
    if (c->name.empty()) continue;
    if (specs().at(c->name).file) {
      Status s = checkNotAnInput(c->words[0], inputs, c->name);
      if (!s) return Status::badInput(path + ":" + std::to_string(n) + ": " + s.message());
    }
    c->line = n;
    out.push_back(*c);
  }
  return out;
}

}  // namespace sa
