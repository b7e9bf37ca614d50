#pragma once
#include <string>

#include "common/error.h"

namespace sa {
// Each subcommand returns its exit code: 0 ok, 2 bad input or usage, 1 internal failure.
int cmdPack(int argc, char** argv);
int cmdRender(int argc, char** argv);
int cmdInfo(int argc, char** argv);
int cmdBench(int argc, char** argv);
int cmdEval(int argc, char** argv);
int cmdView(int argc, char** argv);
int cmdVerify(int argc, char** argv);
int cmdConvert(int argc, char** argv);
int cmdBake(int argc, char** argv);
int cmdGrooves(int argc, char** argv);
int reportError(const Status& s);
std::string jsonEscape(const std::string& s);
}  // namespace sa
