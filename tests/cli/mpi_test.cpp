// Cluster packing: `mpirun -np N scanatlas pack` makes the pack one process makes, byte for
// byte (--reproducible), on real scans: a LAS survey without normals, Stanford range scans and
// a mesh, each in more chunks than ranks. Failures reach every rank and leave nothing behind.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "../common/test_util.h"
#include "atlas/pack_file.h"
#include "atlas/verify.h"

namespace sa {
namespace {

std::string mpirun(int ranks) {
  // Root in a container: OpenMPI asks for consent; shared-memory transport only, without the
  // cross-process copies (CMA) that containers forbid.
  std::string cmd = "mpirun -np " + std::to_string(ranks) + " --oversubscribe --mca btl self,vader "
                    "--mca btl_vader_single_copy_mechanism none";
  if (geteuid() == 0) cmd += " --allow-run-as-root";
  return cmd + " ";
}

std::string readAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

int sh(const std::string& cmd) {
  const int st = std::system(cmd.c_str());
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

struct PackRun {
  int code;
  std::string bytes, log;
};

// The same command line (so the same NOTE) every time: the output path is fixed, the result
// copied away.
PackRun pack(const std::string& launcher, const std::string& args, const test::TempDir& d) {
  const std::string out = d.file("out.hfa"), log = d.file("log.txt");
  std::filesystem::remove(out);
  const int code = sh(launcher + SA_BINARY + " pack " + args + " -o " + out + " --reproducible --force > " + log + " 2>&1");
  return {code, readAll(out), readAll(log)};
}

size_t count(const std::string& s, const std::string& what) {
  size_t n = 0;
  for (size_t at = s.find(what); at != std::string::npos; at = s.find(what, at + 1)) ++n;
  return n;
}

void expectSameOverRanks(const std::string& args, const test::TempDir& d) {
  const PackRun one = pack("", args, d);
  ASSERT_EQ(one.code, 0) << one.log;
  ASSERT_FALSE(one.bytes.empty());
  {
    PackReader r;
    ASSERT_TRUE(r.open(d.file("out.hfa")).isOk());
    EXPECT_TRUE(verifyPack(r).problems.empty());
    EXPECT_GE(r.meta().chunkCount, 5u) << "more chunks than ranks are needed to exercise the split";
    for (double s : r.meta().seconds) EXPECT_EQ(s, 0.0) << "--reproducible keeps timings out of the pack";
  }
  FILE* info = popen((std::string(SA_BINARY) + " info " + d.file("out.hfa")).c_str(), "r");
  std::string text(1 << 16, '\0');
  text.resize(std::fread(text.data(), 1, text.size(), info));
  pclose(info);
  EXPECT_NE(text.find("not recorded (packed with --reproducible)"), std::string::npos) << text;
  const PackRun again = pack("", args, d);
  EXPECT_TRUE(again.bytes == one.bytes) << "one process, twice: not the same bytes";
  for (int ranks : {2, 4}) {
    const PackRun many = pack(mpirun(ranks), args, d);
    ASSERT_EQ(many.code, 0) << many.log;
    EXPECT_TRUE(many.bytes == one.bytes) << ranks << " ranks: not the single process's pack (" << many.bytes.size()
                                         << " vs " << one.bytes.size() << " bytes)";
    EXPECT_EQ(count(many.log, "packed "), 1u) << "only rank 0 reports:\n" << many.log;
    EXPECT_NE(many.log.find("over " + std::to_string(ranks) + " MPI ranks"), std::string::npos) << many.log;
  }
}

TEST(Mpi, LasSurveyWithoutNormalsIsTheSamePackOnTwoAndFourRanks) {
  test::TempDir d;
  expectSameOverRanks(test::sharedData("lidar/lone-star.las") + " --mem-budget 16M", d);
  // Cells whose surface-like samples reach past the pack's spacing: their reach travels with
  // the cells between ranks, and auto's choice from every chunk's spacings is the same on each.
  expectSameOverRanks(test::sharedData("lidar/lone-star.las") + " --mem-budget 16M --sparse-reach auto", d);
}

TEST(Mpi, RangeScansAndAMeshAreTheSamePackOnTwoAndFourRanks) {
  test::TempDir d;
  expectSameOverRanks(test::sharedData("stanford_bunny/scans/bun.conf") + " --mem-budget 16M", d);
  expectSameOverRanks(test::sharedData("stanford_dragon/reconstruction/dragon_vrip.ply") + " --mem-budget 16M", d);
}

TEST(Mpi, AFailingInputFailsEveryRankWithOneMessageAndNoOutput) {
  test::TempDir d;
  {
    std::ofstream bad(d.file("bad.ply"), std::ios::binary);
    bad << "ply\nformat binary_little_endian 1.0\nelement vertex 1000000\nproperty float x\nproperty float y\n"
           "property float z\nend_header\n" << std::string(1200, '\1');
  }
  const PackRun r = pack(mpirun(2), d.file("bad.ply"), d);
  EXPECT_NE(r.code, 0);
  EXPECT_EQ(count(r.log, "scanatlas: error:"), 1u) << r.log;
  EXPECT_NE(r.log.find("bad.ply"), std::string::npos) << r.log;
  for (const auto& e : std::filesystem::directory_iterator(d.path()))
    EXPECT_TRUE(e.path().filename() == "bad.ply" || e.path().filename() == "log.txt") << "left behind: " << e.path();
}

TEST(Mpi, SrunWithoutAnMpiPluginIsRefused) {
  test::TempDir d;
  const PackRun r = pack("SLURM_PROCID=0 SLURM_NTASKS=2 ", test::sharedData("lidar/autzen_trim.las"), d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.log.find("srun --mpi=pmix"), std::string::npos) << r.log;
  EXPECT_TRUE(r.bytes.empty());
}

}  // namespace
}  // namespace sa
