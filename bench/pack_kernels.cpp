// Google Benchmark of packing's per-point kernels (issue "Scale": the surface fit is most of
// packing a LAS without normals): the grid's k-nearest-neighbour pass and the whole fit
// (outliers, normals, moving-least-squares smoothing, orientation) on a patch of the synthetic
// survey of tools/gen_terrain (rolling ground, box buildings' roofs and walls, 3 cm noise).
// Items per second are points per second over every core TBB uses.
//   build/bench/pack_kernels [--benchmark_filter=...]
#include "preprocess/grid_knn.h"
#include "preprocess/normals.h"
#include "tools/terrain_scene.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace {

// n points of the survey within a square of 4.2 points a square metre (a fifth of the 20 M-point
// survey's density; 262144 points: 250 m x 250 m, about 25 buildings), relative to its corner.
// The points come in the order they were drawn: like a chunk of a file, not sorted in space.
const std::vector<double>& patch(size_t n) {
  static std::vector<double> pos;
  static size_t made = 0;
  if (made == n) return pos;
  static const sa::gen::Scene scene;
  std::mt19937_64 rng(11);
  pos.clear();
  const double side = std::min(1000.0, 250 * std::sqrt(double(n) / 262144)), x0 = (1000 - side) / 2, y0 = x0;
  while (pos.size() < 3 * n) {
    const sa::gen::Point p = scene.sample(rng);
    if (p.x < x0 || p.x >= x0 + side || p.y < y0 || p.y >= y0 + side) continue;
    pos.insert(pos.end(), {p.x - x0, p.y - y0, p.z - 100});
  }
  made = n;
  return pos;
}

void BM_GridKnnForEach(benchmark::State& state) {
  const std::vector<double>& pos = patch(size_t(state.range(0)));
  const size_t n = pos.size() / 3;
  const int k = int(state.range(1));
  const sa::Spacing sp = sa::estimateSpacing(pos.data(), n);
  const sa::GridKnn grid(pos.data(), n, sa::GridKnn::cellFor(sp.area, k));
  std::vector<double> sink(n);
  for (auto _ : state) {
    grid.forEach(k, [&](size_t i, const int*, const double* d2, int m) { sink[i] = d2[m - 1]; });
    benchmark::DoNotOptimize(sink.data());
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * int64_t(n));
}
BENCHMARK(BM_GridKnnForEach)->Args({262144, 9})->Args({262144, 24})->Args({2097152, 24})->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_FitSurface(benchmark::State& state) {
  const std::vector<double>& pos0 = patch(size_t(state.range(0)));
  const size_t n = pos0.size() / 3;
  sa::NormalOrientation orient;
  orient.sheetSide = Eigen::Vector3d::UnitZ();
  sa::SurfaceOptions so;
  so.estimateNormals = state.range(1) != 0;
  std::vector<double> pos;
  std::vector<float> nrm;
  std::vector<uint8_t> keep;
  std::vector<float> local(n);
  for (auto _ : state) {
    state.PauseTiming();
    pos = pos0;
    nrm.assign(3 * n, 0.f);
    if (!so.estimateNormals)
      for (size_t i = 0; i < n; ++i) nrm[3 * i + 2] = 1.f;  // a "file's normal": only its sign is used
    state.ResumeTiming();
    benchmark::DoNotOptimize(sa::fitSurface(pos.data(), n, orient, so, nrm.data(), keep, local.data()));
  }
  state.SetItemsProcessed(int64_t(state.iterations()) * int64_t(n));
}
// range(1): 1 estimates normals (a LAS), 0 takes the file's (a PLY with normals).
BENCHMARK(BM_FitSurface)->Args({262144, 1})->Args({262144, 0})->Args({2097152, 1})->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
