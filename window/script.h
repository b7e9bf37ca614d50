// `scanatlas view --script`: the session script, parsed and checked whole before the window
// opens (a typo on line 40 is reported at once, not after 39 frames of a session).
#pragma once
#include <string>
#include <vector>

#include "common/error.h"

namespace sa {

struct ScriptCommand {
  std::string name;                // "camera", "pick", ...; empty for blank and comment lines
  std::vector<double> numbers;     // the numeric arguments, in order
  std::vector<std::string> words;  // every argument, as written
  size_t line = 0;                 // 1-based
};

// One line: the command must exist and have its arguments (see kViewerScriptHelp).
Result<ScriptCommand> parseScriptLine(const std::string& text);

// The whole file; errors name the file and the line. Blank and comment lines are dropped.
// Files the script writes (screenshot, windowshot) must be images and none of `inputs`.
Result<std::vector<ScriptCommand>> loadScript(const std::string& path, const std::vector<std::string>& inputs);

}  // namespace sa
