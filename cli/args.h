// Command-line parsing shared by the subcommands: `--opt value` and `--opt=value` (values may
// start with '-', e.g. --eye=-0.1,0.2,0.3 or --eye -0.1,0.2,0.3), flags, positionals, sizes
// with suffixes (512K, 16M, 1G: binary multiples), vectors "x,y,z" and "WxH".
#pragma once
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/error.h"

namespace sa {

class Args {
 public:
  // valueOptions: names (without --) that take a value; flags: names that do not.
  // Short aliases map e.g. "o" -> "output".
  Status parse(int argc, char** argv, const std::set<std::string>& valueOptions, const std::set<std::string>& flags,
               const std::map<std::string, std::string>& aliases = {});
  bool has(const std::string& name) const { return values_.count(name) || flags_.count(name); }
  bool flag(const std::string& name) const { return flags_.count(name) > 0; }
  std::string get(const std::string& name, const std::string& def = "") const;
  const std::vector<std::string>& positionals() const { return positionals_; }

 private:
  std::map<std::string, std::string> values_;
  std::set<std::string> flags_;
  std::vector<std::string> positionals_;
};

Result<uint64_t> parseSize(const std::string& opt, const std::string& text);
Result<double> parseNumber(const std::string& opt, const std::string& text);
Result<int64_t> parseInt(const std::string& opt, const std::string& text, int64_t lo, int64_t hi);
Result<Eigen::Vector3d> parseVec3(const std::string& opt, const std::string& text);
Status parseWxH(const std::string& opt, const std::string& text, int& w, int& h);

}  // namespace sa
