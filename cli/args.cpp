#include "cli/args.h"

#include <charconv>
#include <cmath>
#include <sstream>

namespace sa {

Status Args::parse(int argc, char** argv, const std::set<std::string>& valueOptions,
                   const std::set<std::string>& flagNames, const std::map<std::string, std::string>& aliases) {
  bool onlyPositionals = false;
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    if (onlyPositionals || a.size() < 2 || a[0] != '-' || (a.size() > 1 && (std::isdigit(static_cast<unsigned char>(a[1])) || a[1] == '.'))) {
      positionals_.push_back(a);
      continue;
    }
    if (a == "--") {
      onlyPositionals = true;
      continue;
    }
    std::string name = a[1] == '-' ? a.substr(2) : a.substr(1);
    std::string value;
    bool hasValue = false;
    const size_t eq = name.find('=');
    if (eq != std::string::npos) {
      value = name.substr(eq + 1);
      name = name.substr(0, eq);
      hasValue = true;
    }
    if (auto al = aliases.find(name); al != aliases.end()) name = al->second;
    if (valueOptions.count(name)) {
      if (!hasValue) {
        if (i + 1 >= argc) return Status::badInput("option --" + name + " needs a value");
        value = argv[++i];
      }
      values_[name] = value;
    } else if (flagNames.count(name)) {
      if (hasValue) return Status::badInput("option --" + name + " takes no value");
      flags_.insert(name);
    } else {
      return Status::badInput("unknown option '" + a + "' (see --help)");
    }
  }
  return Status::ok();
}

std::string Args::get(const std::string& name, const std::string& def) const {
  auto it = values_.find(name);
  return it == values_.end() ? def : it->second;
}

Result<double> parseNumber(const std::string& opt, const std::string& text) {
  double v = 0;
  const char* b = text.data();
  const char* e = b + text.size();
  if (b != e && *b == '+') ++b;
  auto [p, ec] = std::from_chars(b, e, v);
  if (ec != std::errc() || p != e || !std::isfinite(v))
    return Status::badInput("--" + opt + ": '" + text + "' is not a finite number");
  return v;
}

Result<int64_t> parseInt(const std::string& opt, const std::string& text, int64_t lo, int64_t hi) {
  int64_t v = 0;
  auto [p, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || p != text.data() + text.size())
    return Status::badInput("--" + opt + ": '" + text + "' is not an integer");
  if (v < lo || v > hi)
    return Status::badInput("--" + opt + ": " + text + " is outside " + std::to_string(lo) + ".." + std::to_string(hi));
  return v;
}

Result<uint64_t> parseSize(const std::string& opt, const std::string& text) {
  if (text.empty()) return Status::badInput("--" + opt + ": empty size");
  std::string num = text;
  double mult = 1;
  std::string suf;
  while (!num.empty() && std::isalpha(static_cast<unsigned char>(num.back()))) {
    suf.insert(suf.begin(), static_cast<char>(std::toupper(static_cast<unsigned char>(num.back()))));
    num.pop_back();
  }
  if (suf == "" || suf == "B") mult = 1;
  else if (suf == "K" || suf == "KI" || suf == "KIB" || suf == "KB") mult = 1024.0;
  else if (suf == "M" || suf == "MI" || suf == "MIB" || suf == "MB") mult = 1024.0 * 1024;
  else if (suf == "G" || suf == "GI" || suf == "GIB" || suf == "GB") mult = 1024.0 * 1024 * 1024;
  else if (suf == "T" || suf == "TI" || suf == "TIB" || suf == "TB") mult = 1024.0 * 1024 * 1024 * 1024;
  else return Status::badInput("--" + opt + ": unknown size suffix '" + suf + "' (use K, M, G or T)");
  auto v = parseNumber(opt, num);
  if (!v) return v.status();
  if (*v <= 0) return Status::badInput("--" + opt + ": size must be positive");
  const double bytes = *v * mult;
  if (bytes > 1e18) return Status::badInput("--" + opt + ": size too large");
  return static_cast<uint64_t>(bytes);
}

Result<Eigen::Vector3d> parseVec3(const std::string& opt, const std::string& text) {
  Eigen::Vector3d v;
  std::string rest = text;
  for (int i = 0; i < 3; ++i) {
    const size_t c = rest.find(',');
    if ((i < 2) != (c != std::string::npos))
      return Status::badInput("--" + opt + ": expected three numbers x,y,z, got '" + text + "'");
    auto n = parseNumber(opt, i < 2 ? rest.substr(0, c) : rest);
    if (!n) return n.status();
    v[i] = *n;
    if (i < 2) rest = rest.substr(c + 1);
  }
  return v;
}

Status parseWxH(const std::string& opt, const std::string& text, int& w, int& h) {
  const size_t x = text.find_first_of("xX");
  if (x == std::string::npos) return Status::badInput("--" + opt + ": expected WIDTHxHEIGHT, got '" + text + "'");
  auto a = parseInt(opt, text.substr(0, x), 1, 16384);
  if (!a) return a.status();
  auto b = parseInt(opt, text.substr(x + 1), 1, 16384);
  if (!b) return b.status();
  w = static_cast<int>(*a);
  h = static_cast<int>(*b);
  return Status::ok();
}

}  // namespace sa
