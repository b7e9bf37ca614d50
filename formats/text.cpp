#include "formats/text.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <map>

#include "common/fileio.h"

namespace sa {
namespace {

std::vector<std::string> split(const std::string& line, char delim) {
  std::vector<std::string> out;
  if (delim == ' ') {
    size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
      const size_t b = i;
      while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
      if (i > b) out.push_back(line.substr(b, i - b));
    }
  } else {
    size_t b = 0;
    for (size_t i = 0; i <= line.size(); ++i)
      if (i == line.size() || line[i] == delim) {
        std::string f = line.substr(b, i - b);
        f.erase(0, f.find_first_not_of(" \t"));
        f.erase(f.find_last_not_of(" \t") + 1);
        out.push_back(f);
        b = i + 1;
      }
  }
  return out;
}

bool number(const std::string& s, double& v) {
  const char* b = s.data();
  const char* e = b + s.size();
  if (b != e && *b == '+') ++b;
  auto [p, ec] = std::from_chars(b, e, v);
  return ec == std::errc() && p == e && b != e;
}

int roleOf(std::string n) {
  std::transform(n.begin(), n.end(), n.begin(), [](unsigned char c) { return std::tolower(c); });
  static const std::map<std::string, int> names = {
      {"x", 0}, {"y", 1}, {"z", 2}, {"nx", 3}, {"ny", 4}, {"nz", 5}, {"r", 6}, {"red", 6}, {"g", 7}, {"green", 7},
      {"b", 8}, {"blue", 8}, {"i", 9}, {"intensity", 9}, {"c", 10}, {"class", 10}, {"classification", 10},
      {"confidence", 11}, {"_", -1}, {"-", -1}};
  auto it = names.find(n);
  return it == names.end() ? -2 : it->second;
}

}  // namespace

Result<TextLayout> readTextLayout(const std::string& path, const std::string& columns) {
  BufferedReader in;
  SA_RETURN_IF_ERROR(in.open(path));
  TextLayout L;
  std::string line, first, header;
  bool decided = false, countChecked = false;
  while (in.readLine(line)) {
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#' || line[0] == '/') continue;
    if (!decided) {
      // Before the first point line: an optional PTS count line, an optional header line.
      const auto words = split(line, ' ');
      double v;
      if (!countChecked) {
        countChecked = true;
        if (words.size() == 1 && number(words[0], v) && v == std::floor(v)) continue;
      }
      const char d = line.find(',') != std::string::npos ? ',' : line.find(';') != std::string::npos ? ';' : ' ';
      L.delimiter = d;
      const auto f = split(line, L.delimiter);
      if (!f.empty() && !number(f[0], v) && header.empty()) {
        header = line;
        continue;
      }
      first = line;
      decided = true;
    }
    ++L.dataLines;
  }
  if (L.dataLines == 0) return Status::badInput(path + ": no point lines");
  std::vector<std::string> names;
  if (!columns.empty()) {
    names = split(columns, ',');
  } else if (!header.empty()) {
    names = split(header, L.delimiter);
  } else {
    const size_t n = split(first, L.delimiter).size();
    static const std::map<size_t, std::string> defaults = {{3, "x,y,z"},         {4, "x,y,z,i"},
                                                            {6, "x,y,z,r,g,b"},   {7, "x,y,z,i,r,g,b"},
                                                            {9, "x,y,z,r,g,b,nx,ny,nz"}};
    auto it = defaults.find(n);
    if (it == defaults.end())
      return Status::badInput(path + ": " + std::to_string(n) +
                              " columns and no header line: say what they are with --columns (e.g. x,y,z,_,r,g,b)");
    names = split(it->second, ',');
  }
  bool seen[kTextRoles] = {};
  for (const auto& n : names) {
    const int r = roleOf(n);
    if (r == -2) {
      if (!header.empty() && columns.empty()) {
        L.roles.push_back(-1);  // unknown header names are skipped columns
        continue;
      }
      return Status::badInput(path + ": unknown column name '" + n +
                              "' (x,y,z,nx,ny,nz,r,g,b,i,c,confidence or _ to skip)");
    }
    if (r >= 0) seen[r] = true;
    L.roles.push_back(r);
  }
  if (!(seen[0] && seen[1] && seen[2])) return Status::badInput(path + ": the columns must include x, y and z");
  L.hasNormals = seen[3] && seen[4] && seen[5];
  L.hasColors = seen[6] && seen[7] && seen[8];
  L.hasIntensity = seen[9];
  L.hasClassification = seen[10];
  L.hasConfidence = seen[11];
  return L;
}

Status readText(const std::string& path, const TextLayout& L, size_t batchPoints, BatchSink& sink) {
  BufferedReader in;
  SA_RETURN_IF_ERROR(in.open(path));
  std::string line;
  uint64_t lineNo = 0, done = 0;
  PointBatch b;
  bool headerSkipped = false;
  auto flush = [&]() -> Status {
    if (b.size() == 0) return Status::ok();
    Status s = sink.onPoints(b);
    done += b.size();
    b.clear();
    b.firstIndex = done;
    return s;
  };
  double v[kTextRoles];
  while (in.readLine(line)) {
    ++lineNo;
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#' || line[0] == '/') continue;
    const auto f = split(line, L.delimiter);
    double x;
    if (!headerSkipped) {
      headerSkipped = true;
      if (f.size() == 1 && number(f[0], x)) continue;  // PTS count
      if (!f.empty() && !number(f[0], x)) continue;     // header
    }
    if (f.size() < L.roles.size())
      return Status::badInput(path + ":" + std::to_string(lineNo) + ": expected " + std::to_string(L.roles.size()) +
                              " columns, found " + std::to_string(f.size()));
    std::fill(v, v + kTextRoles, 0.0);
    for (size_t c = 0; c < L.roles.size(); ++c) {
      if (L.roles[c] < 0) continue;
      if (!number(f[c], v[L.roles[c]])) {
        if (f[c] == "nan" || f[c] == "NaN") v[L.roles[c]] = NAN;
        else
          return Status::badInput(path + ":" + std::to_string(lineNo) + ": column " + std::to_string(c + 1) +
                                  ": expected a number, found '" + f[c].substr(0, 40) + "'");
      }
    }
    b.x.push_back(v[0]);
    b.y.push_back(v[1]);
    b.z.push_back(v[2]);
    if (L.hasNormals) {
      b.nx.push_back(float(v[3]));
      b.ny.push_back(float(v[4]));
      b.nz.push_back(float(v[5]));
    }
    if (L.hasColors) {
      // Colours as 0-255; 0-1 floats are scaled.
      const double s = (v[6] <= 1 && v[7] <= 1 && v[8] <= 1 && (v[6] != std::floor(v[6]) || v[7] != std::floor(v[7]))) ? 255 : 1;
      b.r.push_back(uint8_t(std::clamp(v[6] * s, 0.0, 255.0)));
      b.g.push_back(uint8_t(std::clamp(v[7] * s, 0.0, 255.0)));
      b.b.push_back(uint8_t(std::clamp(v[8] * s, 0.0, 255.0)));
    }
    if (L.hasIntensity) b.intensity.push_back(float(v[9]));
    if (L.hasClassification) b.classification.push_back(uint8_t(std::clamp(v[10], 0.0, 255.0)));
    if (L.hasConfidence) b.confidence.push_back(float(v[11]));
    if (b.size() >= batchPoints) SA_RETURN_IF_ERROR(flush());
  }
  return flush();
}

}  // namespace sa
