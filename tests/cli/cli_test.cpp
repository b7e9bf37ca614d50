// The scanatlas binary end to end: exit codes, --json outputs of pack / info / bench / eval.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <map>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "../common/pack_damage.h"
#include "../common/test_util.h"
#include "grooves/grooves.h"

namespace sa {
namespace {

struct CmdResult {
  int code;
  std::string out;
  std::string err;  // only from runErr
};

// A little-endian single-channel PFM's values (row order as stored); empty if unreadable.
std::vector<float> readPfmForTest(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string magic;
  int w = 0, h = 0;
  double scale = 0;
  in >> magic >> w >> h >> scale;
  in.get();
  if (magic != "Pf" || w <= 0 || h <= 0 || scale >= 0) return {};
  std::vector<float> v(size_t(w) * h);
  if (!in.read(reinterpret_cast<char*>(v.data()), std::streamsize(v.size() * 4))) return {};
  return v;
}

size_t fileSize(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  return in ? size_t(in.tellg()) : 0;
}

CmdResult run(const std::string& args) {
  const std::string cmd = std::string(SA_BINARY) + " " + args + " 2>/dev/null";
  std::FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out, {}};
}

// As run, also capturing stderr (into a file beside the binary's temp dir).
CmdResult runErr(const std::string& args, const std::string& errFile) {
  const std::string cmd = std::string(SA_BINARY) + " " + args + " 2>" + errFile;
  std::FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int status = pclose(p);
  std::ifstream e(errFile);
  std::string err((std::istreambuf_iterator<char>(e)), std::istreambuf_iterator<char>());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out, err};
}

// An icosphere mesh PLY (subdivided 4 times): a closed reference surface.
void writeIcosphere(const std::string& path) {
  const double t = (1 + std::sqrt(5.0)) / 2;
  std::vector<Eigen::Vector3d> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                    {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<std::array<int, 3>> f = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                                       {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
                                       {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
  for (auto& p : v) p.normalize();
  for (int s = 0; s < 4; ++s) {
    std::vector<std::array<int, 3>> g;
    std::map<std::pair<int, int>, int> mid;
    auto m = [&](int a, int b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[size_t(a)] + v[size_t(b)]).normalized());
      return mid[key] = int(v.size()) - 1;
    };
    for (auto& tri : f) {
      const int a = m(tri[0], tri[1]), b = m(tri[1], tri[2]), c = m(tri[2], tri[0]);
      g.push_back({tri[0], a, c});
      g.push_back({tri[1], b, a});
      g.push_back({tri[2], c, b});
      g.push_back({a, b, c});
    }
    f = g;
  }
  std::ofstream o(path);
  o << "ply\nformat ascii 1.0\nelement vertex " << v.size() << "\nproperty double x\nproperty double y\nproperty double z\n"
    << "element face " << f.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
  o.precision(17);
  for (auto& p : v) o << p.x() << " " << p.y() << " " << p.z() << "\n";
  for (auto& tri : f) o << "3 " << tri[0] << " " << tri[1] << " " << tri[2] << "\n";
}

TEST(Cli, ExitCodesAndErrors) {
  test::TempDir d;
  EXPECT_EQ(run("").code, 2);
  EXPECT_EQ(run("--help").code, 0);
  EXPECT_EQ(run("frobnicate").code, 2);
  EXPECT_EQ(run("pack --bogus").code, 2);
  EXPECT_EQ(run("pack " + d.file("missing.ply") + " -o " + d.file("x.hfa")).code, 2);
  EXPECT_EQ(run("info " + d.file("missing.hfa")).code, 2);
  test::writeText(d.file("junk.hfa"), "not a pack at all, just text that is long enough for a header....");
  EXPECT_EQ(run("render " + d.file("junk.hfa") + " -o " + d.file("x.png")).code, 2);
  for (const char* c : {"pack", "render", "info", "bench", "eval"}) EXPECT_EQ(run(std::string(c) + " --help").code, 0) << c;
}

TEST(Cli, PackInfoBenchEvalJson) {
  test::TempDir d;
  writeIcosphere(d.file("ico.ply"));
  CmdResult p = run("pack " + d.file("ico.ply") + " -o " + d.file("ico.hfa") + " --json");
  ASSERT_EQ(p.code, 0) << p.out;
  auto pj = nlohmann::json::parse(p.out);
  EXPECT_EQ(pj["triangles"].get<int>(), 5120);
  EXPECT_TRUE(pj["from_triangles"].get<bool>());
  EXPECT_FALSE(pj["up_to_date"].get<bool>());
  // Per-phase CPU seconds beside the wall seconds: a phase keeps at most every core busy, and
  // the whole run's CPU time holds every phase's.
  const double cores = pj["cores"].get<double>();
  double phases = 0;
  for (const char* ph : {"count", "distribute", "octree", "heightmaps", "write"}) {
    const double cpu = pj["cpu_seconds"][ph].get<double>(), wall = pj["seconds"][ph].get<double>();
    EXPECT_GE(cpu, 0) << ph;
    EXPECT_LE(cpu, wall * cores + 0.02) << ph;  // getrusage ticks: a few ms
    phases += cpu;
  }
  EXPECT_GE(pj["cpu_seconds"]["total"].get<double>() + 0.02, phases);
  EXPECT_TRUE(nlohmann::json::parse(run("pack " + d.file("ico.ply") + " -o " + d.file("ico.hfa") + " --json").out)["up_to_date"].get<bool>());
  auto info = nlohmann::json::parse(run("info " + d.file("ico.hfa") + " --json").out);
  EXPECT_EQ(info["cells"].get<int>(), pj["cells"].get<int>());

  CmdResult b = run("bench " + d.file("ico.hfa") + " --orbit 4 --size 64x64 --warmup 1 --frames 4 --mode parallax,points "
              "--iterations 4,12 --compare-skips --json --csv " + d.file("b.csv"));
  ASSERT_EQ(b.code, 0) << b.out;
  auto bj = nlohmann::json::parse(b.out);
  ASSERT_EQ(bj["configs"].size(), 2u + 1u + 6u + 1u);  // 2 parallax, points, 6 skip comparisons, auto
  EXPECT_EQ(bj["configs"].back()["mode"], "auto");
  EXPECT_EQ(bj["configs"].back()["skips"], "all+auto-slices");
  for (const auto& c : bj["configs"]) {
    EXPECT_GT(c["cpu_ms"]["median"].get<double>(), 0) << c.dump();
    EXPECT_GE(c["cpu_ms"]["p99"].get<double>(), c["cpu_ms"]["median"].get<double>());
    EXPECT_GT(c["fragments"].get<double>(), 0) << c.dump();
  }
  std::ifstream csv(d.file("b.csv"));
  size_t lines = 0;
  for (std::string l; std::getline(csv, l);) ++lines;
  EXPECT_EQ(lines, 1u + 10u * 4u);  // header + frames

  // --interleave: the same configurations and counts, their frames taken in turn (the CSV's
  // config column cycles), so a drift of the machine's speed falls on each alike.
  CmdResult il = run("bench " + d.file("ico.hfa") + " --orbit 4 --size 64x64 --warmup 1 --frames 4 --mode parallax,points "
                     "--iterations 4,12 --interleave --json --csv " + d.file("il.csv"));
  ASSERT_EQ(il.code, 0) << il.out;
  auto ij = nlohmann::json::parse(il.out);
  ASSERT_EQ(ij["configs"].size(), 3u);
  for (size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(ij["configs"][k]["mode"], bj["configs"][k]["mode"]);
    EXPECT_EQ(ij["configs"][k]["fragments"].get<double>(), bj["configs"][k]["fragments"].get<double>()) << k;
  }
  std::ifstream icsv(d.file("il.csv"));
  std::vector<std::string> order;
  for (std::string l; std::getline(icsv, l);) order.push_back(l.substr(0, l.find(',')));
  ASSERT_EQ(order.size(), 1u + 4u * 3u);
  for (size_t i = 1; i < order.size(); ++i) EXPECT_EQ(order[i], std::to_string((i - 1) % 3)) << i;

  CmdResult e = run("eval " + d.file("ico.hfa") + " --reference " + d.file("ico.ply") +
              " --orbit 3 --size 96x96 --mode parallax,points --iterations 12 --json");
  ASSERT_EQ(e.code, 0) << e.out;
  auto ej = nlohmann::json::parse(e.out);
  ASSERT_EQ(ej["configs"].size(), 2u);
  const auto& par = ej["configs"][0];
  EXPECT_EQ(par["mode"], "parallax");
  EXPECT_GE(par["iou"].get<double>(), 0.99);
  EXPECT_LE(par["depth_median"].get<double>(), 1e-4);
  EXPECT_LE(par["normal_median_deg"].get<double>(), 3.0);
  // Shading normals come from the height gradient, the reference uses flat facet normals.
  EXPECT_GE(par["psnr"].get<double>(), 27.0);
  EXPECT_TRUE(ej["configs"][1]["normal_median_deg"].is_null());  // points: no normals
  EXPECT_EQ(par["interior_holes"].get<int>(), 0);
  EXPECT_TRUE(par["far"].is_null());  // only with --far (or without a reference)
  // Pixels covered by one image alone: the views' counts add up to the configuration's, interior
  // holes are reference pixels the render lacks, and the points baseline differs most.
  for (const auto& c : ej["configs"]) {
    size_t render = 0, reference = 0;
    for (const auto& v : c["per_view"]) {
      render += v["only_render"].get<size_t>();
      reference += v["only_reference"].get<size_t>();
      EXPECT_LE(v["interior_holes"].get<size_t>(), v["only_reference"].get<size_t>()) << c.dump();
    }
    EXPECT_EQ(render, c["only_render"].get<size_t>());
    EXPECT_EQ(reference, c["only_reference"].get<size_t>());
  }
  EXPECT_LT(par["only_render"].get<size_t>() + par["only_reference"].get<size_t>(),
            ej["configs"][1]["only_render"].get<size_t>() + ej["configs"][1]["only_reference"].get<size_t>());

  // The reference in every mesh format pack reads: the same mesh as OBJ and as Draco gives the
  // same figures; --far adds the reference-free measure; without --reference it is the measure.
  {
    std::ifstream in(d.file("ico.ply"));
    std::ofstream obj(d.file("ico.obj"));
    obj.precision(17);
    std::string line;
    size_t nv = 0, nf = 0;
    while (std::getline(in, line) && line != "end_header") {
      if (line.rfind("element vertex", 0) == 0) nv = std::stoul(line.substr(15));
      if (line.rfind("element face", 0) == 0) nf = std::stoul(line.substr(13));
    }
    for (size_t i = 0; i < nv && std::getline(in, line); ++i) obj << "v " << line << "\n";
    for (size_t i = 0; i < nf && std::getline(in, line); ++i) {
      std::istringstream f(line);
      int k, a, b, c;
      f >> k >> a >> b >> c;
      obj << "f " << a + 1 << " " << b + 1 << " " << c + 1 << "\n";
    }
  }
  ASSERT_EQ(run("convert " + d.file("ico.ply") + " -o " + d.file("ico.drc") + " --quantization 0 -q").code, 0);
  for (const char* ref : {"ico.obj", "ico.drc"}) {
    CmdResult r = run("eval " + d.file("ico.hfa") + " --reference " + d.file(ref) + " --orbit 3 --size 96x96 --iterations 12 --far --json");
    ASSERT_EQ(r.code, 0) << ref << r.out;
    const auto c = nlohmann::json::parse(r.out)["configs"][0];
    EXPECT_NEAR(c["iou"].get<double>(), par["iou"].get<double>(), 1e-9) << ref;
    EXPECT_NEAR(c["depth_median"].get<double>(), par["depth_median"].get<double>(), 1e-9) << ref;
    EXPECT_FALSE(c["far"].is_null());
    EXPECT_LE(c["far"]["beyond3"].get<double>(), 0.001) << ref;
    // In local spacings (never narrower than the pack's) no pixel is farther than in the pack's.
    EXPECT_GE(c["far"]["beyond3_local"].get<double>(), 0.0) << ref;
    EXPECT_LE(c["far"]["beyond3_local"].get<double>(), c["far"]["beyond3"].get<double>()) << ref;
  }
  // --images: the files hold what was measured. Pixels only the render covers (finite in its depth,
  // infinite in the reference's) are the JSON's only_render; normal errors exist where both cover.
  {
    CmdResult r = run("eval " + d.file("ico.hfa") + " --reference " + d.file("ico.ply") +
                      " --orbit 2 --size 96x96 --mode parallax --iterations 12 --json --images " + d.file("imgs"));
    ASSERT_EQ(r.code, 0) << r.out;
    const auto c = nlohmann::json::parse(r.out)["configs"][0];
    for (int v = 0; v < 2; ++v) {
      const std::string stem = d.file("imgs/parallax-12_" + std::to_string(v));
      const std::vector<float> test = readPfmForTest(stem + ".pfm"), ref = readPfmForTest(d.file("imgs/reference_" + std::to_string(v) + ".pfm"));
      const std::vector<float> nerr = readPfmForTest(stem + "_normal_error.pfm");
      ASSERT_EQ(test.size(), size_t(96 * 96));
      ASSERT_EQ(ref.size(), test.size());
      ASSERT_EQ(nerr.size(), test.size());
      size_t onlyRender = 0, onlyRef = 0, both = 0, withNormal = 0;
      for (size_t i = 0; i < test.size(); ++i) {
        onlyRender += std::isfinite(test[i]) && !std::isfinite(ref[i]);
        onlyRef += !std::isfinite(test[i]) && std::isfinite(ref[i]);
        both += std::isfinite(test[i]) && std::isfinite(ref[i]);
        withNormal += std::isfinite(nerr[i]);
      }
      EXPECT_EQ(onlyRender, c["per_view"][v]["only_render"].get<size_t>());
      EXPECT_EQ(onlyRef, c["per_view"][v]["only_reference"].get<size_t>());
      EXPECT_GT(both, 1000u);
      EXPECT_EQ(withNormal, both);
      for (const std::string& f : {stem + ".png", stem + "_error.png", d.file("imgs/reference_" + std::to_string(v) + ".png")})
        EXPECT_GT(fileSize(f), 100u) << f;
    }
    EXPECT_EQ(run("eval " + d.file("ico.hfa") + " --orbit 1 --size 32x32 -q --images " + d.file("ico.ply")).code, 2);
  }
  auto fj = nlohmann::json::parse(run("eval " + d.file("ico.hfa") + " --orbit 2 --size 64x64 --json").out);
  EXPECT_TRUE(fj["reference"].is_null());
  EXPECT_GT(fj["configs"][0]["far"]["pixels"].get<int>(), 500);
  EXPECT_EQ(fj["configs"][0]["per_view"].size(), 2u);
}

}  // namespace
}  // namespace sa

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <thread>

#include "atlas/pack_file.h"
#include "atlas/verify.h"

extern char** environ;

namespace sa {
namespace {

// kill -9 at several moments of a pack: never a file that looks like a pack unless it is a
// complete one; the next pack removes what the killed one left (chunk files, partial output).
// The mode framework from the command line: pack --modes bakes the exact mode's section, bake adds
// it to a pack that lacks it (atomically, to the same or another file), info lists it, bench draws it
// and reports its bytes, bake time and node counters; a pack without it draws parallax and says so.
TEST(Cli, ModesBakeInfoBenchAndFallback) {
  test::TempDir d;
  writeIcosphere(d.file("ico.ply"));
  ASSERT_EQ(run("pack " + d.file("ico.ply") + " -o " + d.file("plain.hfa") + " -q").code, 0);
  CmdResult fb = runErr("bench " + d.file("plain.hfa") + " --orbit 2 --size 64x64 --warmup 0 --frames 2 --mode exact --json",
                        d.file("err.txt"));
  ASSERT_EQ(fb.code, 0) << fb.out;
  EXPECT_NE(fb.err.find("has no XMAX section"), std::string::npos) << fb.err;
  EXPECT_EQ(nlohmann::json::parse(fb.out)["configs"][0]["drawn_mode"].get<std::string>(), "parallax");
  auto plain = nlohmann::json::parse(run("info " + d.file("plain.hfa") + " --json").out);
  bool exactListed = false;
  for (const auto& m : plain["modes"])
    if (m["mode"] == "exact") exactListed = !m["present"].get<bool>();
  EXPECT_TRUE(exactListed);

  EXPECT_EQ(run("bake " + d.file("plain.hfa") + " --mode bogus").code, 2);
  EXPECT_EQ(run("bake " + d.file("missing.hfa") + " --mode exact").code, 2);
  EXPECT_EQ(run("bake " + d.file("plain.hfa")).code, 2);  // --mode is required
  ASSERT_EQ(run("bake " + d.file("plain.hfa") + " --mode exact -o " + d.file("baked.hfa")).code, 0);
  EXPECT_EQ(run("verify " + d.file("baked.hfa")).code, 0);
  auto baked = nlohmann::json::parse(run("info " + d.file("baked.hfa") + " --json").out);
  for (const auto& m : baked["modes"])
    if (m["mode"] == "exact") {
      EXPECT_TRUE(m["present"].get<bool>());
      EXPECT_GT(m["bytes"].get<double>(), 0);
    }
  // The input is untouched; baking in place twice is a no-op the second time.
  EXPECT_EQ(nlohmann::json::parse(run("info " + d.file("plain.hfa") + " --json").out)["bytes"], plain["bytes"]);
  ASSERT_EQ(run("bake " + d.file("plain.hfa") + " --mode exact").code, 0);
  CmdResult again = runErr("bake " + d.file("plain.hfa") + " --mode exact", d.file("err.txt"));
  EXPECT_EQ(again.code, 0);
  EXPECT_NE(again.err.find("already baked"), std::string::npos) << again.err;

  ASSERT_EQ(run("pack " + d.file("ico.ply") + " -o " + d.file("modes.hfa") + " --modes exact,parallax -q").code, 0);
  CmdResult b = run("bench " + d.file("modes.hfa") + " --orbit 2 --size 64x64 --warmup 0 --frames 2 --mode parallax,exact --json");
  ASSERT_EQ(b.code, 0) << b.out;
  auto bj = nlohmann::json::parse(b.out);
  ASSERT_EQ(bj["configs"].size(), 2u);
  const auto& ex = bj["configs"][1];
  EXPECT_EQ(ex["drawn_mode"].get<std::string>(), "exact");
  EXPECT_GT(ex["mode_disk_bytes"].get<double>(), 0);
  EXPECT_GT(ex["mode_gpu_bytes"].get<double>(), 0);
  EXPECT_GT(ex["work"]["rays"].get<double>(), 0);
  EXPECT_EQ(ex["work"]["unit"].get<std::string>(), "nodes");
  EXPECT_EQ(ex["work"]["capped"].get<int>(), 0);
  EXPECT_EQ(run("pack " + d.file("ico.ply") + " -o " + d.file("x.hfa") + " --modes frobnicate").code, 2);

  // gdm builds from the pack's sources: gone sources are a clear error and the pack is untouched.
  ASSERT_EQ(run("pack " + d.file("ico.ply") + " -o " + d.file("g.hfa") + " --max-depth 0 -q").code, 0);  // one forced cell
  const auto before = nlohmann::json::parse(run("info " + d.file("g.hfa") + " --json").out)["bytes"];
  std::filesystem::rename(d.file("ico.ply"), d.file("moved.ply"));
  CmdResult gone = runErr("bake " + d.file("g.hfa") + " --mode gdm", d.file("err.txt"));
  EXPECT_EQ(gone.code, 2);
  EXPECT_NE(gone.err.find("is gone"), std::string::npos) << gone.err;
  EXPECT_EQ(nlohmann::json::parse(run("info " + d.file("g.hfa") + " --json").out)["bytes"], before);
  std::filesystem::rename(d.file("moved.ply"), d.file("ico.ply"));
  ASSERT_EQ(run("bake " + d.file("g.hfa") + " --mode gdm -q").code, 0);
  auto gj = nlohmann::json::parse(run("info " + d.file("g.hfa") + " --json").out);
  for (const auto& m : gj["modes"])
    if (m["mode"] == "gdm" || m["mode"] == "exact") {
      EXPECT_TRUE(m["present"].get<bool>()) << m.dump();
    }
  EXPECT_EQ(run("verify " + d.file("g.hfa")).code, 0);
  // --gdm-elsewhere parallax: gdm's height-field cells march, so its rows follow --iterations.
  CmdResult ge = run("bench " + d.file("g.hfa") +
                     " --orbit 1 --size 64x64 --warmup 0 --frames 1 --mode gdm --iterations 8,16 --gdm-elsewhere parallax --json");
  ASSERT_EQ(ge.code, 0) << ge.err;
  auto gc = nlohmann::json::parse(ge.out)["configs"];
  ASSERT_EQ(gc.size(), 2u);
  EXPECT_EQ(gc[1]["iterations"].get<int>(), 16);
  EXPECT_EQ(gc[1]["gdm_elsewhere"].get<std::string>(), "parallax");
  CmdResult bad = runErr("render " + d.file("g.hfa") + " -o " + d.file("r.png") + " --gdm-elsewhere bogus", d.file("err2.txt"));
  EXPECT_EQ(bad.code, 2);
  EXPECT_NE(bad.err.find("--gdm-elsewhere"), std::string::npos) << bad.err;
  EXPECT_FALSE(std::filesystem::exists(d.file("r.png")));
}

TEST(Cli, KilledPackLeavesNoHalfWrittenPackAndIsCleanedUpNextTime) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(2000000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  test::writePointsPly(d.file("big.ply"), pts, &nrm);
  const std::string out = d.file("big.hfa");
  for (int delayMs : {150, 600, 1400}) {
    std::filesystem::remove(out);
    std::string bin = SA_BINARY, cmd = "pack", in = d.file("big.ply"), o = "-o", q = "-q", mem = "--mem-budget", m = "64M";
    char* argv[] = {bin.data(), cmd.data(), in.data(), o.data(), const_cast<char*>(out.c_str()), mem.data(), m.data(), q.data(), nullptr};
    pid_t pid;
    ASSERT_EQ(posix_spawn(&pid, SA_BINARY, nullptr, nullptr, argv, environ), 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(delayMs));
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    size_t leftovers = 0;
    for (const auto& e : std::filesystem::directory_iterator(d.path())) {
      const std::string name = e.path().filename().string();
      if (name == "big.ply") continue;
      if (name == "big.hfa") {  // only if the kill came after the rename: then it is complete
        PackReader r;
        ASSERT_TRUE(r.open(out).isOk()) << "killed at " << delayMs << " ms: big.hfa exists but does not open";
        EXPECT_TRUE(verifyPack(r).problems.empty());
        continue;
      }
      ++leftovers;
      // A temporary that opens as a pack must be a complete one: killed between writing the
      // header (written last, after every section) and the rename.
      PackReader r;
      if (e.is_regular_file() && r.open(e.path().string()).isOk()) {
        EXPECT_TRUE(verifyPack(r).problems.empty()) << name << " is a half-written pack";
      }
    }
    std::printf("killed after %d ms (%s): %zu temporary entries left\n", delayMs,
                WIFSIGNALED(status) ? "by the signal" : "had finished", leftovers);
  }
  // A complete run cleans up every leftover.
  std::filesystem::remove(out);
  ASSERT_EQ(std::system((std::string(SA_BINARY) + " pack " + d.file("big.ply") + " -o " + out + " --mem-budget 64M -q").c_str()), 0);
  for (const auto& e : std::filesystem::directory_iterator(d.path())) {
    const std::string name = e.path().filename().string();
    EXPECT_TRUE(name == "big.ply" || name == "big.hfa") << "left behind: " << name;
  }
  PackReader r;
  ASSERT_TRUE(r.open(out).isOk());
  EXPECT_TRUE(verifyPack(r).problems.empty());
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

bool anyTemporary(const std::string& dir) {
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp-") != std::string::npos) return true;
  return false;
}

// convert and info on the real files of every format, mixed inputs in one pack, and the exit
// codes and cleanup of failed conversions.
TEST(Cli, ConvertInfoAndMixedPackOnRealFiles) {
  test::TempDir d;
  const std::string las = test::sharedData("lidar/autzen_trim.las");
  const std::string pcd = test::sharedData("pcd/table_scene_mug_stereo_textured.pcd");
  auto pi = nlohmann::json::parse(run("info " + pcd + " --json").out)["inputs"][0];
  EXPECT_EQ(pi["points"].get<int>(), 209280);
  EXPECT_EQ(pi["invalid_entries"].get<int>(), 97920);
  EXPECT_EQ(pi["attributes"].get<std::string>(), "colors");
  auto li = nlohmann::json::parse(run("info " + las + " --json").out)["inputs"][0];
  EXPECT_EQ(li["classes"]["1"].get<int>(), 83893);
  EXPECT_EQ(li["classes"]["2"].get<int>(), 26107);

  // LAS -> binary PLY keeps doubles and the attributes exactly.
  CmdResult c = run("convert " + las + " -o " + d.file("a.ply") + " --json");
  ASSERT_EQ(c.code, 0) << c.out;
  EXPECT_EQ(nlohmann::json::parse(c.out)["points"].get<int>(), 110000);
  auto ai = nlohmann::json::parse(run("info " + d.file("a.ply") + " --json").out)["inputs"][0];
  EXPECT_EQ(ai["attributes"].get<std::string>(), "colors,intensity,classification");
  EXPECT_EQ(ai["classes"]["2"].get<int>(), 26107);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(ai["bounds_min"][k].get<double>(), li["bounds_min"][k].get<double>());
    EXPECT_EQ(ai["bounds_max"][k].get<double>(), li["bounds_max"][k].get<double>());
  }
  // LAS -> Draco at two quantizations: fewer bits, smaller file.
  auto q11 = nlohmann::json::parse(run("convert " + las + " -o " + d.file("a11.drc") + " --quantization 11 --json").out);
  auto q16 = nlohmann::json::parse(run("convert " + las + " -o " + d.file("a16.drc") + " --json").out);
  EXPECT_TRUE(q16["origin_shifted"].get<bool>());
  EXPECT_LT(q11["bytes"].get<int>(), q16["bytes"].get<int>());
  // PCD -> text -> pack; and PCD + Draco + text mixed in one pack.
  ASSERT_EQ(run("convert " + pcd + " -o " + d.file("m.xyz") + " -q").code, 0);
  ASSERT_EQ(run("convert " + pcd + " -o " + d.file("m.drc") + " -q").code, 0);
  CmdResult mix = run("pack " + pcd + " " + d.file("m.drc") + " " + d.file("m.xyz") + " -o " + d.file("mix.hfa") + " --json");
  ASSERT_EQ(mix.code, 0) << mix.out;
  EXPECT_EQ(nlohmann::json::parse(mix.out)["points"].get<int>(), 3 * 209280);
  EXPECT_EQ(run("verify " + d.file("mix.hfa")).code, 0);
  // bench --stream: the window's start (tiles decoded in the background), then the timed frames.
  CmdResult sb = run("bench " + d.file("mix.hfa") + " --stream --orbit 2 --size 64x64 --warmup 0 --frames 2 --json");
  ASSERT_EQ(sb.code, 0) << sb.out;
  auto sj = nlohmann::json::parse(sb.out);
  EXPECT_GT(sj["stream"]["tiles"].get<int>(), 0);
  EXPECT_GT(sj["stream"]["tiles_resident"].get<int>(), 0);
  EXPECT_LE(sj["stream"]["tiles_resident"].get<int>(), sj["stream"]["tiles"].get<int>());
  EXPECT_GE(sj["stream"]["frames_to_complete"].get<int>(), 1);
  EXPECT_LE(sj["stream"]["first_frame_ms"].get<double>(), sj["stream"]["view_complete_ms"].get<double>());
  EXPECT_EQ(sj["configs"].size(), 1u);
  // --gpu-budget: render settles within it, bench reports the cache per configuration.
  CmdResult gr = runErr("render " + d.file("mix.hfa") + " --gpu-budget 16M --size 64x64 -o " + d.file("g.png"), d.file("g.err"));
  ASSERT_EQ(gr.code, 0) << gr.err;
  EXPECT_NE(gr.err.find("--gpu-budget: settled after"), std::string::npos) << gr.err;
  EXPECT_TRUE(std::filesystem::exists(d.file("g.png")));
  EXPECT_EQ(run("render " + d.file("mix.hfa") + " --gpu-budget 1M -o " + d.file("h.png")).code, 2);
  EXPECT_FALSE(std::filesystem::exists(d.file("h.png")));
  CmdResult gb = run("bench " + d.file("mix.hfa") + " --gpu-budget 16M --orbit 2 --size 64x64 --warmup 0 --frames 2 --json --budget-error");
  ASSERT_EQ(gb.code, 0) << gb.out;
  auto gj = nlohmann::json::parse(gb.out);
  EXPECT_EQ(gj["gpu_budget"].get<uint64_t>(), uint64_t(16) << 20);
  EXPECT_LE(gj["configs"][0]["budget"]["resident_bytes"].get<double>(), double(uint64_t(16) << 20));
  // --budget-error: each settled view against the unlimited render (the pack fits: nearly the same).
  EXPECT_EQ(gj["budget_error"]["views"].get<int>(), 2);
  EXPECT_GT(gj["budget_error"]["iou_min"].get<double>(), 0.8);
  EXPECT_LE(gj["budget_error"]["iou_min"].get<double>(), gj["budget_error"]["iou_mean"].get<double>());
  EXPECT_LE(gj["budget_error"]["depth_median_texels_max"].get<double>(), 1.0);
  EXPECT_EQ(run("bench " + d.file("mix.hfa") + " --budget-error --orbit 1 --frames 1").code, 2) << "needs --gpu-budget";
  // Without --gpu-budget a pack whose pages outgrow a quarter of the memory streams under a
  // default budget (SCANATLAS_MEMORY stands in for the RAM); 'off' uploads everything.
  setenv("SCANATLAS_MEMORY", "40M", 1);
  CmdResult db = runErr("bench " + d.file("mix.hfa") + " --orbit 1 --size 64x64 --warmup 0 --frames 1 --json", d.file("db.err"));
  setenv("SCANATLAS_MEMORY", "lots", 1);
  const int badMemory = run("render " + d.file("mix.hfa") + " -o " + d.file("m.png")).code;
  unsetenv("SCANATLAS_MEMORY");
  ASSERT_EQ(db.code, 0) << db.err;
  EXPECT_NE(db.err.find("tiles stream under a GPU budget of 16 MiB"), std::string::npos) << db.err;
  auto dj = nlohmann::json::parse(db.out);
  EXPECT_EQ(dj["gpu_budget"].get<uint64_t>(), uint64_t(16) << 20);
  EXPECT_TRUE(dj["gpu_budget_default"].get<bool>());
  EXPECT_EQ(badMemory, 2);
  EXPECT_FALSE(std::filesystem::exists(d.file("m.png")));
  CmdResult ob = run("bench " + d.file("mix.hfa") + " --gpu-budget off --orbit 1 --size 64x64 --warmup 0 --frames 1 --json");
  ASSERT_EQ(ob.code, 0) << ob.out;
  EXPECT_FALSE(nlohmann::json::parse(ob.out).contains("gpu_budget"));

  // Failures: exit 2 with no output file and no temporary left behind.
  EXPECT_EQ(run("convert " + las + " -o " + d.file("x.las")).code, 2);  // no LAS writer
  EXPECT_EQ(run("convert " + d.file("missing.ply") + " -o " + d.file("x.ply")).code, 2);
  EXPECT_EQ(run("convert " + test::sharedData("lidar/lone-star.laz") + " -o " + d.file("x.ply")).code, 2);
  EXPECT_EQ(run("convert " + las + " -o " + d.file("x.drc") + " --quantization 31").code, 2);
  EXPECT_EQ(run("convert " + d.file("a.ply") + " -o " + d.file("a.ply")).code, 2);
  EXPECT_EQ(run("convert --help").code, 0);
  EXPECT_EQ(run("info --help").code, 0);
  // A PLY whose body ends early: the error comes mid-stream, after output has begun.
  {
    std::ifstream in(d.file("a.ply"), std::ios::binary);
    std::vector<char> all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    all.resize(all.size() - 1000);
    test::writeBytes(d.file("cut.ply"), all);
  }
  EXPECT_EQ(run("convert " + d.file("cut.ply") + " -o " + d.file("cut.xyz")).code, 2);
  EXPECT_FALSE(std::filesystem::exists(d.file("cut.xyz")));
  EXPECT_FALSE(anyTemporary(d.path()));
  // A hostile PCD header through the CLI.
  test::writeText(d.file("huge.pcd"), "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1000000000\nPOINTS 1000000000\nDATA binary\n");
  EXPECT_EQ(run("info " + d.file("huge.pcd")).code, 2);
  EXPECT_EQ(run("pack " + d.file("huge.pcd") + " -o " + d.file("h.hfa")).code, 2);
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

std::string bytesOf(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// A command whose output is one of its inputs (the same file, through a symbolic or a hard link
// too) refuses with exit 2 and changes nothing; image outputs are PNG or JPEG by extension.
// `scanatlas grooves` on a generated scan with known grooves: JSON and CSV written, the grooves
// there, and clear errors for bad options.
// A synthetic groove scan's points as a binary PLY.
void writeScanPly(const std::string& path, const SyntheticScan& scan) {
  std::ofstream o(path, std::ios::binary);
  o << "ply\nformat binary_little_endian 1.0\nelement vertex " << scan.pos.size() / 3
    << "\nproperty double x\nproperty double y\nproperty double z\nend_header\n";
  o.write(reinterpret_cast<const char*>(scan.pos.data()), std::streamsize(scan.pos.size() * sizeof(double)));
}

TEST(Cli, GroovesExportJsonAndCsv) {
  test::TempDir d;
  const SyntheticScan scan = makeGrooveScan(200, 1, 0.1, acceptanceGrooves(200, 1, 0.1), 3);
  writeScanPly(d.file("wall.ply"), scan);
  const std::string in = d.file("wall.ply");
  CmdResult r = run("grooves " + in + " --json " + d.file("g.json") + " --csv " + d.file("g.csv") + " --quiet");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("grooves,"), std::string::npos) << r.out;
  std::ifstream jf(d.file("g.json"));
  const nlohmann::json j = nlohmann::json::parse(jf);
  EXPECT_EQ(j["format"], "scanatlas-grooves");
  ASSERT_GE(j["grooves"].size(), 8u);  // half-size plane: the ten grooves, the shallowest may be missed
  for (const auto& g : j["grooves"]) {
    EXPECT_GE(g["polyline"].size(), 2u);
    EXPECT_GT(g["width"].get<double>(), 0);
    EXPECT_EQ(g["width_uncertainty"].get<double>(), j["spacing"].get<double>());
  }
  std::ifstream cf(d.file("g.csv"));
  std::string header;
  std::getline(cf, header);
  EXPECT_EQ(header, "id,shape,width,width_uncertainty,depth,length,confidence,points,polyline");
  size_t rows = 0;
  for (std::string line; std::getline(cf, line);) ++rows;
  EXPECT_EQ(rows, j["grooves"].size());
  // On a pack: the same grooves, from the file it was made from.
  ASSERT_EQ(run("pack " + in + " -o " + d.file("wall.hfa")).code, 0);
  ASSERT_EQ(run("grooves " + d.file("wall.hfa") + " --json " + d.file("p.json") + " --quiet").code, 0);
  std::ifstream pf(d.file("p.json"));
  EXPECT_EQ(nlohmann::json::parse(pf)["grooves"].size(), j["grooves"].size());
  // Given (hand-drawn) grooves measured: the first detected line with a placeholder width.
  {
    nlohmann::json given;
    given["grooves"] = nlohmann::json::array();
    given["grooves"].push_back({{"width", 1}, {"polyline", j["grooves"][0]["polyline"]}});
    test::writeText(d.file("given.json"), given.dump());
    ASSERT_EQ(run("grooves " + in + " --grooves " + d.file("given.json") + " --json " + d.file("m.json") + " --quiet").code, 0);
    std::ifstream mf(d.file("m.json"));
    const nlohmann::json m = nlohmann::json::parse(mf);
    ASSERT_EQ(m["grooves"].size(), 1u);
    EXPECT_NEAR(m["grooves"][0]["width"].get<double>(), j["grooves"][0]["width"].get<double>(), 0.5);
    test::writeText(d.file("bad.json"), "{\"grooves\": [{\"polyline\": []}]}");
    const CmdResult bad = runErr("grooves " + in + " --grooves " + d.file("bad.json"), d.file("err2.txt"));
    EXPECT_EQ(bad.code, 2);
    EXPECT_NE(bad.err.find("bad.json"), std::string::npos) << bad.err;
  }
  EXPECT_EQ(run("grooves --help").code, 0);
  EXPECT_EQ(run("grooves").code, 2);
  EXPECT_EQ(run("grooves " + d.file("missing.ply")).code, 2);
  EXPECT_EQ(run("grooves " + in + " --min-width 9 --max-width 8").code, 2);
  EXPECT_EQ(run("grooves " + in + " --threshold -1").code, 2);
  const CmdResult same = runErr("grooves " + in + " --json " + in, d.file("err.txt"));
  EXPECT_EQ(same.code, 2);
  EXPECT_NE(same.err.find("--json"), std::string::npos) << same.err;
}

// The grooves mode through the binary: pack --modes grooves detects and stores them, info lists
// the section, render draws them (the image differs from parallax's), bench counts the pixels
// the carved cast drew, pack --grooves FILE takes given ones, bad files fail cleanly with nothing
// written.
TEST(Cli, GroovesModePackBakeRender) {
  test::TempDir d;
  const SyntheticScan scan = makeGrooveScan(160, 1, 0.1, acceptanceGrooves(160, 1, 0.1), 5);
  writeScanPly(d.file("wall.ply"), scan);
  const std::string in = d.file("wall.ply"), pack = d.file("wall.hfa");
  const CmdResult p = runErr("pack " + in + " -o " + pack + " --modes grooves", d.file("err.txt"));
  ASSERT_EQ(p.code, 0) << p.err;
  EXPECT_NE(p.err.find("grooves: section GROO"), std::string::npos) << p.err;
  const CmdResult info = run("info " + pack);
  EXPECT_NE(info.out.find("grooves   section GROO"), std::string::npos) << info.out;
  const std::string a = d.file("g.png"), b = d.file("p.png");
  ASSERT_EQ(run("render " + pack + " --orbit 1 --size 128x128 --mode grooves -o " + a).code, 0);
  ASSERT_EQ(run("render " + pack + " --orbit 1 --size 128x128 --mode parallax -o " + b).code, 0);
  EXPECT_NE(bytesOf(a), bytesOf(b));
  // bench --json: the pixels the first pass left to the carved cast, every one with a slot.
  const CmdResult bj = run("bench " + pack + " --orbit 2 --size 128x128 --warmup 0 --frames 2 --mode parallax,grooves --json");
  ASSERT_EQ(bj.code, 0) << bj.err;
  const auto bc = nlohmann::json::parse(bj.out)["configs"];
  ASSERT_EQ(bc.size(), 2u);
  EXPECT_FALSE(bc[0].contains("grooves"));
  EXPECT_GT(bc[1]["grooves"]["deferred_per_frame"].get<double>(), 0.0) << bc[1].dump();
  EXPECT_EQ(bc[1]["grooves"]["unslotted_per_frame"].get<double>(), 0.0) << bc[1].dump();
  // Given grooves: an export, edited (one groove kept), taken as it is.
  ASSERT_EQ(run("grooves " + in + " --json " + d.file("all.json") + " --quiet").code, 0);
  nlohmann::json j = nlohmann::json::parse(bytesOf(d.file("all.json")));
  ASSERT_GE(j["grooves"].size(), 2u);
  j["grooves"] = nlohmann::json::array({j["grooves"][0]});
  test::writeText(d.file("one.json"), j.dump());
  const CmdResult g = runErr("pack " + in + " -o " + pack + " --grooves " + d.file("one.json"), d.file("err3.txt"));
  ASSERT_EQ(g.code, 0) << g.err;
  EXPECT_NE(g.err.find("1 grooves (1 given with their profiles"), std::string::npos) << g.err;
  // Bad input: a missing file, a broken one; the pack is left as it was.
  const std::string before = bytesOf(pack);
  EXPECT_EQ(run("pack " + in + " -o " + pack + " --grooves " + d.file("missing.json")).code, 2);
  test::writeText(d.file("bad.json"), "{\"grooves\": [{\"width\": 2}]}");
  const CmdResult bad = runErr("bake " + pack + " --mode grooves --grooves " + d.file("bad.json"), d.file("err4.txt"));
  EXPECT_EQ(bad.code, 2);
  EXPECT_NE(bad.err.find("bad.json"), std::string::npos) << bad.err;
  EXPECT_EQ(bytesOf(pack), before);
}

TEST(Cli, OutputsNeverOverwriteInputs) {
  test::TempDir d;
  const std::string scan = d.file("scan.ply");
  writeIcosphere(scan);
  const std::string original = bytesOf(scan);
  std::filesystem::create_symlink(scan, d.file("link.ply"));
  std::filesystem::create_hard_link(scan, d.file("hard.ply"));
  EXPECT_EQ(run("pack " + scan + " -o " + scan).code, 2);
  EXPECT_EQ(run("pack " + scan + " -o " + d.file("link.ply")).code, 2);
  EXPECT_EQ(run("pack " + d.file("link.ply") + " -o " + d.file("hard.ply")).code, 2);
  EXPECT_EQ(run("convert " + scan + " -o " + d.file("hard.ply")).code, 2);
  EXPECT_EQ(bytesOf(scan), original);

  ASSERT_EQ(run("pack " + scan + " -o " + d.file("scan.hfa") + " -q").code, 0);
  const std::string pack = bytesOf(d.file("scan.hfa"));
  EXPECT_EQ(run("render " + d.file("scan.hfa") + " -o " + d.file("scan.hfa") + " --size 32x32").code, 2);  // not an image type
  EXPECT_EQ(run("render " + d.file("scan.hfa") + " -o " + d.file("a.png") + " --depth-out " + d.file("scan.ply") +
                " --size 32x32").code, 2);
  // eval and bench read the pack's sources (far measure, points baseline): not an output either.
  EXPECT_EQ(run("eval " + d.file("scan.hfa") + " --orbit 1 --size 32x32 --csv " + scan).code, 2);
  EXPECT_EQ(run("eval " + d.file("scan.hfa") + " --orbit 1 --size 32x32 --csv " + d.file("scan.hfa")).code, 2);
  EXPECT_EQ(run("bench " + d.file("scan.hfa") + " --orbit 1 --size 32x32 --frames 1 --csv " + d.file("link.ply")).code, 2);
  EXPECT_EQ(bytesOf(scan), original);
  EXPECT_EQ(bytesOf(d.file("scan.hfa")), pack);

  // Images: .jpg is JPEG, .png is PNG, anything else is refused before rendering.
  EXPECT_EQ(run("render " + d.file("scan.hfa") + " -o " + d.file("v.bmp") + " --size 32x32").code, 2);
  EXPECT_FALSE(std::filesystem::exists(d.file("v.bmp")));
  ASSERT_EQ(run("render " + d.file("scan.hfa") + " -o " + d.file("v.jpg") + " --size 32x32 -q").code, 0);
  ASSERT_EQ(run("render " + d.file("scan.hfa") + " -o " + d.file("v.png") + " --size 32x32 -q").code, 0);
  const std::string jpg = bytesOf(d.file("v.jpg")), png = bytesOf(d.file("v.png"));
  ASSERT_GE(jpg.size(), 3u);
  EXPECT_EQ(jpg.substr(0, 3), std::string("\xFF\xD8\xFF"));
  EXPECT_EQ(png.substr(1, 3), "PNG");
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

// A texel cap that coarsens the data's resolution is said at pack time and by info afterwards
// (text and JSON), naming the cap; without a cap info says the detail is full.
// The precision options: recorded in the pack, reported by info (text and JSON); --lossless
// keeps more bytes; contradictory or out-of-range options are errors that write nothing.
TEST(Cli, PrecisionOptionsAreRecordedAndReported) {
  test::TempDir d;
  const std::string scans = test::sharedData("stanford_bunny/scans/bun.conf");
  ASSERT_EQ(run("pack " + scans + " -o " + d.file("d.hfa") + " -q").code, 0);
  ASSERT_EQ(run("pack " + scans + " -o " + d.file("l.hfa") + " -q --lossless").code, 0);
  ASSERT_EQ(run("pack " + scans + " -o " + d.file("c.hfa") + " -q --height-step 0.25 --normal-tolerance 0").code, 0);
  EXPECT_NE(run("info " + d.file("d.hfa")).out.find("precision heights in steps of at most 0.0625 texel, normals within 1.5 degree"),
            std::string::npos) << run("info " + d.file("d.hfa")).out;
  EXPECT_NE(run("info " + d.file("l.hfa")).out.find("precision lossless"), std::string::npos);
  auto dj = nlohmann::json::parse(run("info " + d.file("d.hfa") + " --json").out);
  auto lj = nlohmann::json::parse(run("info " + d.file("l.hfa") + " --json").out);
  auto cj = nlohmann::json::parse(run("info " + d.file("c.hfa") + " --json").out);
  EXPECT_DOUBLE_EQ(dj["precision"]["height_step"].get<double>(), 0.0625);
  EXPECT_DOUBLE_EQ(lj["precision"]["normal_tolerance"].get<double>(), 0);
  EXPECT_DOUBLE_EQ(cj["precision"]["height_step"].get<double>(), 0.25);
  EXPECT_DOUBLE_EQ(cj["precision"]["normal_tolerance"].get<double>(), 0);
  const double bd = dj["bytes_per_point"].get<double>(), bl = lj["bytes_per_point"].get<double>();
  std::printf("bunny scans: %.2f bytes a point by default, %.2f lossless\n", bd, bl);
  EXPECT_LT(bd, 0.8 * bl);
  for (const std::string bad : {"--lossless --normal-tolerance 1", "--height-step 2", "--normal-tolerance -1",
                                "--colour-tolerance 300"}) {
    CmdResult r = runErr("pack " + scans + " -o " + d.file("bad.hfa") + " " + bad, d.file("err.txt"));
    EXPECT_EQ(r.code, 2) << bad;
    EXPECT_NE(r.err.find(bad.substr(bad.rfind("--"), bad.find(' ', bad.rfind("--")) - bad.rfind("--"))), std::string::npos)
        << bad << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(d.file("bad.hfa"))) << bad;
  }
}

// `pack IN -o OUT FLAGS --json`'s summary; null when the pack failed.
nlohmann::json packSummary(const std::string& in, const std::string& out, const std::string& flags) {
  const CmdResult r = run("pack " + in + " -o " + out + " " + flags + " --json");
  EXPECT_EQ(r.code, 0) << in << " " << flags;
  return r.code == 0 ? nlohmann::json::parse(r.out) : nlohmann::json();
}

// Compressed pages are coded while the tiles are made: the temporaries are the chunks and the
// coded tiles (about the pack's size, not the raw atlas), reported, and gone afterwards. A point
// input that fits one chunk keeps it in memory: no chunk file.
TEST(Cli, PackReportsItsTemporariesAndLeavesNone) {
  test::TempDir d;
  const std::string las = test::sharedData("lidar/autzen_trim.las");
  const nlohmann::json zj = packSummary(las, d.file("z.hfa"), ""), rj = packSummary(las, d.file("raw.hfa"), "--raw-pages");
  const nlohmann::json cj = packSummary(las, d.file("c.hfa"), "--mem-budget 16M");  // 69905 points a chunk
  ASSERT_FALSE(zj.is_null() || rj.is_null() || cj.is_null());
  const double coded = zj["scratch_coded_bytes"].get<double>(), bytes = zj["bytes"].get<double>();
  std::printf("autzen: chunks %.0f bytes (in memory), %.0f in %d chunks; coded tiles %.0f, pack %.0f\n",
              zj["scratch_bytes"].get<double>(), cj["scratch_bytes"].get<double>(), cj["chunks"].get<int>(), coded, bytes);
  EXPECT_GT(coded, 0.5 * bytes);
  EXPECT_LT(coded, bytes);
  EXPECT_EQ(rj["scratch_coded_bytes"].get<double>(), 0) << "raw pages are written in place";
  EXPECT_EQ(zj["chunks"].get<int>(), 1);
  EXPECT_EQ(zj["chunks_in_memory"].get<int>(), 1);
  EXPECT_EQ(zj["scratch_bytes"].get<double>(), 0) << "one chunk, held in memory";
  EXPECT_GT(cj["chunks"].get<int>(), 1);
  EXPECT_EQ(cj["chunks_in_memory"].get<int>(), 0);
  EXPECT_GT(cj["scratch_bytes"].get<double>(), 0) << "chunks in files";
  EXPECT_FALSE(anyTemporary(d.path()));
  EXPECT_EQ(run("verify " + d.file("z.hfa")).code, 0);
  EXPECT_EQ(run("verify " + d.file("c.hfa")).code, 0);
}

// --zstd-level changes how hard the tiles are compressed, not what they hold: the default (6)
// is smaller than 1 and draws the same image; a level out of range is refused, nothing written.
TEST(Cli, ZstdLevelChangesTheBytesNotThePages) {
  test::TempDir d;
  const std::string las = test::sharedData("lidar/autzen_trim.las");
  const nlohmann::json fast = packSummary(las, d.file("fast.hfa"), "--zstd-level 1 --reproducible");
  const nlohmann::json dflt = packSummary(las, d.file("dflt.hfa"), "--reproducible");
  ASSERT_FALSE(fast.is_null() || dflt.is_null());
  const double fastBytes = fast["bytes"].get<double>(), dfltBytes = dflt["bytes"].get<double>();
  std::printf("autzen: %.0f bytes at --zstd-level 1, %.0f at the default\n", fastBytes, dfltBytes);
  EXPECT_LT(dfltBytes, fastBytes);
  EXPECT_EQ(run("verify " + d.file("fast.hfa")).code, 0);
  EXPECT_EQ(run("verify " + d.file("dflt.hfa")).code, 0);
  ASSERT_EQ(run("render " + d.file("fast.hfa") + " --orbit 1 --size 128x128 -o " + d.file("f.png")).code, 0);
  ASSERT_EQ(run("render " + d.file("dflt.hfa") + " --orbit 1 --size 128x128 -o " + d.file("d.png")).code, 0);
  EXPECT_EQ(bytesOf(d.file("f.png")), bytesOf(d.file("d.png")));
  for (const char* bad : {"0", "20", "2.5", "fast"}) {
    const CmdResult r = runErr("pack " + las + " -o " + d.file("bad.hfa") + " --zstd-level " + bad, d.file("err.txt"));
    EXPECT_EQ(r.code, 2) << bad;
    EXPECT_NE(r.err.find("--zstd-level"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(d.file("bad.hfa"))) << bad;
  }
}

// autzen's river returns lie over 3 sample spacings apart: the pack says they show as specks and
// names --sparse-reach auto with the reach it would choose; with it the warning goes, the summary
// and 'info' say what it chose, the pack differs, and a default pack of the same input is not
// taken as up to date. A number given is reported as given; a mesh, or a file with normals under
// --no-smooth, gets a warning that it does nothing; bad values are refused, nothing written.
TEST(Cli, SparseReachIsSuggestedChangesThePackAndIsChecked) {
  test::TempDir d;
  const std::string las = test::sharedData("lidar/autzen_trim.las");
  CmdResult dflt = runErr("pack " + las + " -o " + d.file("a.hfa"), d.file("err.txt"));
  ASSERT_EQ(dflt.code, 0) << dflt.err;
  const size_t hint = dflt.err.find("--sparse-reach auto (here ");
  ASSERT_NE(hint, std::string::npos) << dflt.err;
  const double suggested = std::atof(dflt.err.c_str() + hint + 26);
  EXPECT_GT(suggested, 3.0);
  EXPECT_LE(suggested, 16.0);
  CmdResult reach = runErr("pack " + las + " -o " + d.file("a.hfa") + " --sparse-reach auto", d.file("err.txt"));
  ASSERT_EQ(reach.code, 0) << reach.err;
  EXPECT_EQ(reach.err.find("up to date"), std::string::npos) << reach.err;
  EXPECT_EQ(reach.err.find("scattered specks"), std::string::npos) << reach.err;
  const size_t said = reach.err.find("sparse reach ");
  ASSERT_NE(said, std::string::npos) << reach.err;
  EXPECT_NEAR(std::atof(reach.err.c_str() + said + 13), suggested, 0.051) << reach.err;
  EXPECT_NE(reach.err.find("(auto: the median spacing"), std::string::npos) << reach.err;
  const CmdResult info = run("info " + d.file("a.hfa"));
  EXPECT_NE(info.out.find("sample spacings (--sparse-reach auto)"), std::string::npos) << info.out;
  EXPECT_NE(run("info " + d.file("a.hfa") + " --json").out.find("\"sparse_reach\": {\"reach\": "), std::string::npos);
  ASSERT_EQ(run("pack " + las + " -o " + d.file("b.hfa") + " -q").code, 0);
  EXPECT_NE(bytesOf(d.file("a.hfa")), bytesOf(d.file("b.hfa")));
  EXPECT_EQ(run("info " + d.file("b.hfa")).out.find("sparse "), std::string::npos);
  EXPECT_NE(run("info " + d.file("b.hfa") + " --json").out.find("\"sparse_reach\": null"), std::string::npos);
  EXPECT_EQ(run("verify " + d.file("a.hfa")).code, 0);
  const CmdResult six = runErr("pack " + las + " -o " + d.file("c.hfa") + " --sparse-reach 6", d.file("err.txt"));
  ASSERT_EQ(six.code, 0) << six.err;
  EXPECT_NE(six.err.find("sparse reach 6 ("), std::string::npos) << six.err;
  EXPECT_NE(run("info " + d.file("c.hfa")).out.find("up to 6 sample spacings (--sparse-reach 6)"), std::string::npos);
  // Where it can do nothing, it says so: a mesh, and a file with normals under --no-smooth.
  const CmdResult mesh = runErr("pack " + test::sharedData("stanford_bunny/reconstruction/bun_zipper_res4.ply") + " -o " +
                                    d.file("m.hfa") + " --sparse-reach auto", d.file("err.txt"));
  ASSERT_EQ(mesh.code, 0) << mesh.err;
  EXPECT_NE(mesh.err.find("--sparse-reach does nothing here: mesh faces"), std::string::npos) << mesh.err;
  EXPECT_EQ(run("info " + d.file("m.hfa")).out.find("sparse "), std::string::npos);
  std::string plane = "ply\nformat ascii 1.0\nelement vertex 2500\nproperty float x\nproperty float y\nproperty float z\n"
                      "property float nx\nproperty float ny\nproperty float nz\nend_header\n";
  for (int i = 0; i < 2500; ++i) plane += std::to_string(i % 50) + " " + std::to_string(i / 50) + " 0 0 0 1\n";
  test::writeText(d.file("plane.ply"), plane);
  const CmdResult rough = runErr("pack " + d.file("plane.ply") + " -o " + d.file("n.hfa") + " --no-smooth --sparse-reach 6",
                                 d.file("err.txt"));
  ASSERT_EQ(rough.code, 0) << rough.err;
  EXPECT_NE(rough.err.find("--no-smooth skips on files with normals"), std::string::npos) << rough.err;
  for (const char* bad : {"1", "16.5", "wide", "Auto"}) {
    const CmdResult r = runErr("pack " + las + " -o " + d.file("bad.hfa") + " --sparse-reach " + bad, d.file("err.txt"));
    EXPECT_EQ(r.code, 2) << bad;
    EXPECT_NE(r.err.find("--sparse-reach must be 'auto' or"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(d.file("bad.hfa"))) << bad;
  }
}

TEST(Cli, InfoSaysWhenATexelCapLoweredTheResolution) {
  test::TempDir d;
  const std::string bunny = test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply");
  CmdResult capped = runErr("pack " + bunny + " -o " + d.file("capped.hfa") + " --texels 64K", d.file("err.txt"));
  ASSERT_EQ(capped.code, 0) << capped.err;
  EXPECT_NE((capped.out + capped.err).find("detail is lost"), std::string::npos) << capped.out << capped.err;
  CmdResult info = run("info " + d.file("capped.hfa"));
  EXPECT_NE(info.out.find("detail    LOST"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("--texels 65536"), std::string::npos) << info.out;
  auto j = nlohmann::json::parse(run("info " + d.file("capped.hfa") + " --json").out);
  EXPECT_EQ(j["texel_capped_by"].get<std::string>(), "--texels 65536");
  EXPECT_GT(j["texel_size"].get<double>(), 1.5 * j["texel_wanted"].get<double>());

  ASSERT_EQ(run("pack " + bunny + " -o " + d.file("full.hfa") + " -q").code, 0);
  EXPECT_NE(run("info " + d.file("full.hfa")).out.find("detail    full"), std::string::npos);
  auto f = nlohmann::json::parse(run("info " + d.file("full.hfa") + " --json").out);
  EXPECT_TRUE(f["texel_capped_by"].is_null());
  EXPECT_DOUBLE_EQ(f["texel_size"].get<double>(), f["texel_wanted"].get<double>());
}


// render without --gpu-budget decodes the tiles its views draw, before it writes any image: a
// close-up of autzen is the same image from a pack with a damaged tile it does not draw, and a
// view that draws that tile fails, naming the file and the cell, and writes no image at all.
TEST(Cli, RenderDecodesTheTilesItsViewsDrawBeforeWritingAny) {
  test::TempDir d;
  ASSERT_EQ(run("pack " + test::sharedData("lidar/autzen_trim.las") + " -o " + d.file("a.hfa") + " -q").code, 0);
  PackReader pack;
  ASSERT_TRUE(pack.open(d.file("a.hfa"), PageLoad::kNone).isOk());
  const PackMeta& m = pack.meta();
  const double dx = m.boundsMax[0] - m.boundsMin[0];
  // A cell wholly in the far half along x (cell frames are relative to the pack origin).
  uint32_t far = UINT32_MAX;
  for (uint32_t i = 0; i < pack.cells().size() && far == UINT32_MAX; ++i) {
    const CellRecord& c = pack.cells()[i];
    double lowX = c.origin[0];
    for (const double* axis : {c.u, c.v, c.w}) {
      const int k = axis == c.u ? 0 : axis == c.v ? 2 : 4;
      lowX += std::min(axis[0] * c.box[k], axis[0] * c.box[k + 1]);
    }
    if (lowX > m.boundsMin[0] + 0.6 * dx && c.tileW > 2) far = i;
  }
  ASSERT_NE(far, UINT32_MAX);
  ASSERT_TRUE(test::damageHeightTile(d.file("a.hfa"), far, d.file("bad.hfa")));
  // Straight down onto the near end along x, from a tenth of the extent above it.
  const double x = m.origin[0] + m.boundsMin[0] + 0.1 * dx, y = m.origin[1] + (m.boundsMin[1] + m.boundsMax[1]) / 2;
  const double z = m.origin[2] + (m.boundsMin[2] + m.boundsMax[2]) / 2;
  char view[256];
  std::snprintf(view, sizeof view, " --eye %.3f,%.3f,%.3f --target %.3f,%.3f,%.3f --up 0,1,0 --size 96x96 -q", x, y,
                z + 0.1 * dx, x, y, z);
  CmdResult good = run("render " + d.file("a.hfa") + " -o " + d.file("good.png") + view + " --json");
  ASSERT_EQ(good.code, 0) << good.out;
  auto j = nlohmann::json::parse(good.out);
  EXPECT_EQ(j["tiles"].get<uint32_t>(), pack.cells().size());
  EXPECT_GT(j["tiles_decoded"].get<uint32_t>(), 0u);
  EXPECT_LT(j["tiles_decoded"].get<uint32_t>(), pack.cells().size() / 4) << "a close-up decodes what it draws";
  CmdResult close = runErr("render " + d.file("bad.hfa") + " -o " + d.file("close.png") + view, d.file("close.err"));
  ASSERT_EQ(close.code, 0) << close.err;
  auto bytes = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };
  EXPECT_EQ(bytes(d.file("close.png")), bytes(d.file("good.png")));
  CmdResult orbit = runErr("render " + d.file("bad.hfa") + " -o " + d.file("o.png") + " --orbit 2 --size 64x64", d.file("o.err"));
  EXPECT_EQ(orbit.code, 2);
  EXPECT_NE(orbit.err.find(d.file("bad.hfa")), std::string::npos) << orbit.err;
  EXPECT_NE(orbit.err.find("tile of cell " + std::to_string(far)), std::string::npos) << orbit.err;
  EXPECT_FALSE(std::filesystem::exists(d.file("o_0.png")));
  EXPECT_FALSE(std::filesystem::exists(d.file("o_1.png")));
}

}  // namespace
}  // namespace sa
