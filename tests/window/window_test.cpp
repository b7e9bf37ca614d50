// The window path for real: `scanatlas view --script` under xvfb-run (Mesa), checked against
// the headless renderer and against known geometry.
#include <gtest/gtest.h>
#include <cstdlib>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "../common/test_util.h"
#include "grooves/grooves.h"
#include "preprocess/pipeline.h"
#include "viewer/camera.h"
#include "viewer/image_io.h"

namespace sa {
namespace {

int run(const std::string& args, std::string* out = nullptr) {
  const std::string cmd = args + " 2>&1";
  std::FILE* p = popen(cmd.c_str(), "r");
  std::string text;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0) text.append(buf, n);
  const int status = pclose(p);
  // view() prints the viewer's own exit status: xvfb-run's can differ from it when its cleanup
  // races another instance (it exits 5 when it cannot remove its temporary folder).
  const size_t mark = text.rfind("[sa-exit ");
  if (mark != std::string::npos) {
    const int code = std::atoi(text.c_str() + mark + 9);
    text.erase(mark);
    if (out) *out = text;
    return code;
  }
  if (out) *out = text;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// The viewer under a virtual X server; its exit status follows as "[sa-exit N]" (read by run()).
std::string view(const std::string& args) {
  return "xvfb-run -a -s '-screen 0 1280x1024x24' sh -c '" + std::string(SA_BINARY) + " view " + args +
         "; echo \"[sa-exit $?]\"'";
}

class Window : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_EQ(run("command -v xvfb-run >/dev/null"), 0) << "xvfb-run is needed (apt-get install xvfb)"; }
  test::TempDir dir_;
};

TEST_F(Window, ScreenshotMatchesTheHeadlessRender) {
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(20000, 1.0, Eigen::Vector3d(3, 2, 1), pts, nrm);
  test::writePointsPly(dir_.file("s.ply"), pts, &nrm);
  auto in = InputSet::open({dir_.file("s.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, dir_.file("s.hfa"), PackOptions{}, nullptr, sum).isOk());
  test::writeText(dir_.file("session.txt"),
                  "size 200 150\ncamera 3.5 3.1 4.2 3 2 1 0 1 0 40\nwait 2\nscreenshot " + dir_.file("win.png") + "\nquit\n");
  std::string out;
  ASSERT_EQ(run(view(dir_.file("s.hfa") + " --script " + dir_.file("session.txt")), &out), 0) << out;
  ASSERT_EQ(run(std::string(SA_BINARY) + " render " + dir_.file("s.hfa") +
                " --eye 3.5,3.1,4.2 --target 3,2,1 --up 0,1,0 --fov 40 --size 200x150 -q -o " + dir_.file("head.png"), &out), 0) << out;
  auto a = readPng(dir_.file("win.png"));
  auto b = readPng(dir_.file("head.png"));
  ASSERT_TRUE(a.isOk() && b.isOk());
  ASSERT_EQ(a->width, 200);
  ASSERT_EQ(a->height, 150);
  ASSERT_EQ(b->width, 200);
  size_t same = 0, object = 0;
  for (size_t i = 0; i < a->rgba.size(); i += 4) {
    int d = 0;
    for (int k = 0; k < 3; ++k) d = std::max(d, std::abs(int(a->rgba[i + k]) - int(b->rgba[i + k])));
    same += d <= 2;
    object += b->rgba[i] > 60;
  }
  const size_t px = a->rgba.size() / 4;
  std::printf("window vs headless: %zu of %zu pixels within 2/255 (%zu object pixels)\n", same, px, object);
  EXPECT_GT(object, px / 10);
  EXPECT_GE(double(same), 0.99 * double(px));
}

// A 2 m x 2 m surface with millimetre detail at georeferenced coordinates: picks land within
// 1 mm of the true surface, and the measured distance is within 0.5% of the truth.
TEST_F(Window, PickAndMeasureAgainstKnownGeometryAtGeoreferencedOffset) {
  const Eigen::Vector3d off(5e5, 5e6, 1e2);
  auto h = [](double x, double y) { return 0.002 * std::sin(2 * M_PI * x / 0.25) * std::cos(2 * M_PI * y / 0.3); };
  std::vector<Eigen::Vector3d> pts, nrm;
  const int n = 400;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double x = -1 + 2.0 * i / (n - 1), y = -1 + 2.0 * j / (n - 1);
      pts.push_back(off + Eigen::Vector3d(x, y, h(x, y)));
      const double hx = 0.002 * 2 * M_PI / 0.25 * std::cos(2 * M_PI * x / 0.25) * std::cos(2 * M_PI * y / 0.3);
      const double hy = -0.002 * 2 * M_PI / 0.3 * std::sin(2 * M_PI * x / 0.25) * std::sin(2 * M_PI * y / 0.3);
      nrm.push_back(Eigen::Vector3d(-hx, -hy, 1).normalized());
    }
  test::writePointsPly(dir_.file("g.ply"), pts, &nrm);
  auto in = InputSet::open({dir_.file("g.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, dir_.file("g.hfa"), PackOptions{}, nullptr, sum).isOk());
  Camera cam;
  cam.eye = off + Eigen::Vector3d(0.2, -0.9, 1.4);
  cam.target = off + Eigen::Vector3d(0.1, 0.05, 0);
  cam.up = Eigen::Vector3d::UnitZ();
  cam.width = 320;
  cam.height = 240;
  char line[512];
  std::snprintf(line, sizeof(line), "size 320 240\ncamera %.10f %.10f %.10f %.10f %.10f %.10f 0 0 1 40\nwait 2\n",
                cam.eye.x(), cam.eye.y(), cam.eye.z(), cam.target.x(), cam.target.y(), cam.target.z());
  const int picks[3][2] = {{40, 60}, {280, 190}, {170, 30}};
  std::string script = line;
  for (auto& p : picks) script += "pick " + std::to_string(p[0]) + " " + std::to_string(p[1]) + "\n";
  script += "distance\npolyline\nquit\n";
  test::writeText(dir_.file("m.txt"), script);
  std::string out;
  ASSERT_EQ(run(view(dir_.file("g.hfa") + " --script " + dir_.file("m.txt") + " --measurements " + dir_.file("m.csv")), &out), 0) << out;
  // True surface points: each pixel centre's ray intersected with the analytic surface.
  std::vector<Eigen::Vector3d> truth;
  for (auto& p : picks) {
    const Eigen::Vector3d d = cam.rayDirection(p[0] + 0.5, p[1] + 0.5);
    auto g = [&](double t) {
      const Eigen::Vector3d q = cam.eye + d * t - off;
      return q.z() - h(q.x(), q.y());
    };
    double lo = 0.5, hi = 4.0;
    ASSERT_GT(g(lo), 0);
    ASSERT_LT(g(hi), 0);
    for (int k = 0; k < 200; ++k) {
      const double m = 0.5 * (lo + hi);
      (g(m) > 0 ? lo : hi) = m;
    }
    truth.push_back(cam.eye + d * lo);
  }
  std::ifstream csv(dir_.file("m.csv"));
  std::vector<Eigen::Vector3d> got;
  double distance = -1, polyline = -1;
  for (std::string l; std::getline(csv, l);) {
    std::istringstream is(l);
    std::string kind, a, b, c, e;
    std::getline(is, kind, ',');
    if (kind == "pick") {
      std::getline(is, a, ',');
      std::getline(is, b, ',');
      std::getline(is, c, ',');
      std::getline(is, e, ',');
      got.emplace_back(std::stod(b), std::stod(c), std::stod(e));
    } else if (kind == "distance") {
      std::getline(is, a, ',');
      std::getline(is, b, ',');
      std::getline(is, c, ',');
      distance = std::stod(c);
    } else if (kind == "polyline") {
      std::getline(is, a, ',');
      std::getline(is, b, ',');
      polyline = std::stod(b);
    }
  }
  ASSERT_EQ(got.size(), 3u) << out;
  double worst = 0;
  for (size_t i = 0; i < 3; ++i) worst = std::max(worst, (got[i] - truth[i]).norm());
  const double trueDist = (truth[2] - truth[1]).norm();
  const double truePoly = (truth[1] - truth[0]).norm() + (truth[2] - truth[1]).norm();
  std::printf("picks at (5e5, 5e6, 1e2): worst error %.3f mm; distance %.6f vs %.6f m (%.4f%%); polyline %.6f vs %.6f m\n",
              worst * 1e3, distance, trueDist, 100 * std::abs(distance - trueDist) / trueDist, polyline, truePoly);
  EXPECT_LE(worst, 1e-3);
  EXPECT_LE(std::abs(distance - trueDist), 0.005 * trueDist);
  EXPECT_LE(std::abs(polyline - truePoly), 0.005 * truePoly);
}

// --grooves: the list's "groove N" flies there (a pick at the window's centre lands on the
// groove's middle), and a groove number past the list is a clear script error.
TEST_F(Window, GrooveListFliesToTheGroove) {
  const SyntheticScan scan = makeGrooveScan(200, 1, 0.1, acceptanceGrooves(200, 1, 0.1), 3);
  {
    std::ofstream o(dir_.file("wall.ply"), std::ios::binary);
    o << "ply\nformat binary_little_endian 1.0\nelement vertex " << scan.pos.size() / 3
      << "\nproperty double x\nproperty double y\nproperty double z\nend_header\n";
    o.write(reinterpret_cast<const char*>(scan.pos.data()), std::streamsize(scan.pos.size() * sizeof(double)));
  }
  const std::string sa = SA_BINARY;
  ASSERT_EQ(run(sa + " pack " + dir_.file("wall.ply") + " -o " + dir_.file("wall.hfa") + " --quiet"), 0);
  ASSERT_EQ(run(sa + " grooves " + dir_.file("wall.ply") + " --json " + dir_.file("g.json") + " --quiet"), 0);
  Result<GrooveSet> gs = readGroovesJson(dir_.file("g.json"));
  ASSERT_TRUE(gs.isOk());
  ASSERT_GE(gs->grooves.size(), 2u);
  test::writeText(dir_.file("fly.txt"), "size 400 300\ngroove 1\npick 200 150\nquit\n");
  std::string out;
  ASSERT_EQ(run(view(dir_.file("wall.hfa") + " --grooves " + dir_.file("g.json") + " --script " + dir_.file("fly.txt") +
                     " --measurements " + dir_.file("fly.csv")), &out), 0) << out;
  std::ifstream csv(dir_.file("fly.csv"));
  Eigen::Vector3d centre(NAN, NAN, NAN), pick(NAN, NAN, NAN);
  for (std::string l; std::getline(csv, l);) {
    std::vector<std::string> f;
    std::istringstream is(l);
    for (std::string x; std::getline(is, x, ',');) f.push_back(x);
    if (f[0] == "groove" && f.size() == 9) centre = Eigen::Vector3d(std::stod(f[6]), std::stod(f[7]), std::stod(f[8]));
    if (f[0] == "pick" && f.size() == 5) pick = Eigen::Vector3d(std::stod(f[2]), std::stod(f[3]), std::stod(f[4]));
  }
  ASSERT_TRUE(centre.allFinite()) << out;
  ASSERT_TRUE(pick.allFinite()) << out;
  const Groove& g = gs->grooves[1];
  std::printf("groove 1 (%s, width %.2f, length %.1f): centre %.3f %.3f %.3f, picked %.3f %.3f %.3f\n", g.shape.c_str(),
              g.width, g.length, centre.x(), centre.y(), centre.z(), pick.x(), pick.y(), pick.z());
  // The centre lies on the rim; the pick hits the groove's floor or wall near it.
  EXPECT_LE((pick - centre).norm(), g.width + g.depth + 1.0);
  test::writeText(dir_.file("past.txt"), "groove 99\nquit\n");
  EXPECT_EQ(run(view(dir_.file("wall.hfa") + " --grooves " + dir_.file("g.json") + " --script " + dir_.file("past.txt")), &out), 2);
  EXPECT_NE(out.find("groove 99"), std::string::npos) << out;
  test::writeText(dir_.file("bad.json"), "[1, 2]");
  EXPECT_EQ(run(view(dir_.file("wall.hfa") + " --grooves " + dir_.file("bad.json")), &out), 2);
  EXPECT_NE(out.find("bad.json"), std::string::npos) << out;
}

TEST_F(Window, BadPackAndBadScriptGiveClearErrors) {
  test::writeText(dir_.file("bad.hfa"), "this is not a pack, but it is long enough to have a header.........");
  std::string out;
  EXPECT_EQ(run(view(dir_.file("bad.hfa")), &out), 2);
  EXPECT_NE(out.find("not a ScanAtlas pack"), std::string::npos) << out;
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(2000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  test::writePointsPly(dir_.file("s.ply"), pts, &nrm);
  test::writeText(dir_.file("bad.txt"), "frobnicate 1 2\n");
  // A scan instead of a pack: packed into a cache beside it, then the script fails cleanly.
  EXPECT_EQ(run(view(dir_.file("s.ply") + " --script " + dir_.file("bad.txt")), &out), 2);
  EXPECT_NE(out.find("unknown command"), std::string::npos) << out;
  EXPECT_TRUE(std::ifstream(dir_.file("s.hfa")).good());
  // The whole script is checked before the window opens: a typo on line 3 stops the session
  // before line 1's screenshot is taken, and the error names the line.
  test::writeText(dir_.file("typo.txt"), "screenshot " + dir_.file("first.png") + "\nframe\npick 10\nquit\n");
  EXPECT_EQ(run(view(dir_.file("s.hfa") + " --script " + dir_.file("typo.txt")), &out), 2);
  EXPECT_NE(out.find("typo.txt:3:"), std::string::npos) << out;
  EXPECT_FALSE(std::ifstream(dir_.file("first.png")).good());
  EXPECT_EQ(out.find("first frame"), std::string::npos) << out;
  // A script screenshot over the pack is refused, as is an unknown image type.
  test::writeText(dir_.file("over.txt"), "screenshot " + dir_.file("s.hfa") + "\nquit\n");
  EXPECT_EQ(run(view(dir_.file("s.hfa") + " --script " + dir_.file("over.txt")), &out), 2);
  EXPECT_NE(out.find("unknown image type"), std::string::npos) << out;
  test::writeText(dir_.file("over.txt"), "windowshot " + dir_.file("s.png") + "\nquit\n");
  EXPECT_EQ(run(view(dir_.file("s.hfa") + " --script " + dir_.file("over.txt") + " --measurements " + dir_.file("s.ply")), &out), 2);
  EXPECT_NE(out.find("refusing to overwrite"), std::string::npos) << out;
}

}  // namespace
}  // namespace sa
