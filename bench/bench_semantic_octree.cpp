// Scan insertion speed: SemanticOcTree::insertLabeledScan (batched: endpoints grouped per
// voxel, free voxels collected in a key set, every voxel updated once, class evidence included)
// against plain octomap::OcTree::insertPointCloud on the same real HDL-64 scans, 0.2 m
// resolution, 50 m max range, each insertion into a fresh map. Uses the KITTI object scans in
// ../shared (ISM_SHARED_DIR overrides); without them, a synthetic 120k-point scan.
// Counters: points per scan, map nodes, bytes per node and MB per million nodes.
#include <benchmark/benchmark.h>
#include <octomap/OcTree.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <random>

#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace {

using inekf_semantic_mapping::mapping::ClassSet;
using inekf_semantic_mapping::mapping::FusionModel;
using inekf_semantic_mapping::mapping::LabeledScan;
using inekf_semantic_mapping::mapping::SemanticOcTree;

constexpr double kResolution = 0.2;
constexpr double kMaxRange = 50.0;

struct BenchScan {
  octomap::Pointcloud octomap_cloud;
  LabeledScan labeled;
};

// Height-and-range classes: enough label variety that pruning and evidence work as on real data.
std::uint32_t plausibleLabel(float x, float y, float z) {
  if (z < -1.4f) return 7;                 // road
  if (std::hypot(x, y) > 20.f) return 11;  // building
  return z > 0.5f ? 21 : 26;               // vegetation / car
}

std::vector<BenchScan> loadScans() {
  const char* env = std::getenv("ISM_SHARED_DIR");
  const std::string shared = env && *env ? env : ISM_SHARED_DIR_DEFAULT;
  std::vector<std::vector<float>> raw;
  for (const char* name : {"000000.bin", "000001.bin"}) {
    const std::string path = shared + "/data/kitti_object/training/velodyne/" + name;
    if (std::filesystem::exists(path)) {
      raw.push_back(inekf_semantic_mapping::kitti::readVelodyneBin(path).xyzi);
    }
  }
  if (raw.empty()) {
    std::cerr << "*** bench_semantic_octree: no KITTI scans in " << shared
              << "/data/kitti_object/training/velodyne: using a synthetic 120k-point scan\n";
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::vector<float> xyzi;
    for (int i = 0; i < 120000; ++i) {
      const float azimuth = 2.f * static_cast<float>(M_PI) * unit(rng);
      const float elevation = -0.43f + 0.48f * unit(rng);
      // Ground at -1.73 m below the sensor, walls at 5..60 m.
      float range = 5.f + 55.f * unit(rng);
      if (elevation < 0) range = std::min(range, 1.73f / -std::sin(elevation));
      xyzi.insert(xyzi.end(), {range * std::cos(elevation) * std::cos(azimuth),
                               range * std::cos(elevation) * std::sin(azimuth),
                               range * std::sin(elevation), 0.f});
    }
    raw.push_back(std::move(xyzi));
  }
  std::vector<BenchScan> scans;
  for (const auto& xyzi : raw) {
    BenchScan scan;
    const std::size_t n = xyzi.size() / 4;
    scan.labeled.points_map.resize(3, static_cast<Eigen::Index>(n));
    for (std::size_t i = 0; i < n; ++i) {
      const float x = xyzi[4 * i], y = xyzi[4 * i + 1], z = xyzi[4 * i + 2];
      scan.octomap_cloud.push_back(x, y, z);
      scan.labeled.points_map.col(static_cast<Eigen::Index>(i)) << x, y, z;
      scan.labeled.label_ids.push_back(plausibleLabel(x, y, z));
    }
    scans.push_back(std::move(scan));
  }
  return scans;
}

const std::vector<BenchScan>& scans() {
  static const std::vector<BenchScan> loaded = loadScans();
  return loaded;
}

template <typename Tree>
void reportMemory(benchmark::State& state, const Tree& tree, std::size_t points) {
  state.counters["points"] = static_cast<double>(points);
  state.counters["nodes"] = static_cast<double>(tree.size());
  state.counters["bytes_per_node"] = static_cast<double>(tree.memoryUsageNode());
  state.counters["MB_per_Mnodes"] =
      static_cast<double>(tree.memoryUsage()) / static_cast<double>(tree.size());
}

void BM_OctomapInsertPointCloud(benchmark::State& state) {
  const bool discretize = state.range(0) != 0;
  std::size_t k = 0;
  for (auto _ : state) {
    const BenchScan& scan = scans()[k++ % scans().size()];
    octomap::OcTree tree(kResolution);
    tree.insertPointCloud(scan.octomap_cloud, octomap::point3d(0, 0, 0), kMaxRange, false,
                          discretize);
    benchmark::DoNotOptimize(tree.size());
    if (k == 1) reportMemory(state, tree, scan.octomap_cloud.size());
  }
}
BENCHMARK(BM_OctomapInsertPointCloud)
    ->ArgName("discretize")
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond);

void BM_SemanticInsertLabeledScan(benchmark::State& state) {
  std::size_t k = 0;
  const int threads = static_cast<int>(state.range(0));
  for (auto _ : state) {
    const BenchScan& scan = scans()[k++ % scans().size()];
    SemanticOcTree tree(kResolution, ClassSet::cityscapes(), FusionModel());
    tree.setRayCastingThreads(threads);
    tree.insertLabeledScan(scan.labeled, kMaxRange);
    benchmark::DoNotOptimize(tree.size());
    if (k == 1) reportMemory(state, tree, scan.octomap_cloud.size());
  }
}
BENCHMARK(BM_SemanticInsertLabeledScan)
    ->ArgName("threads")
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond);

// Steady state: a scan inserted into a map that already holds the other scans.
void BM_SemanticInsertIntoExistingMap(benchmark::State& state) {
  SemanticOcTree tree(kResolution, ClassSet::cityscapes(), FusionModel());
  for (const BenchScan& scan : scans()) tree.insertLabeledScan(scan.labeled, kMaxRange);
  std::size_t k = 0;
  for (auto _ : state) {
    tree.insertLabeledScan(scans()[k++ % scans().size()].labeled, kMaxRange);
  }
  reportMemory(state, tree, scans()[0].octomap_cloud.size());
}
BENCHMARK(BM_SemanticInsertIntoExistingMap)->Unit(benchmark::kMillisecond);

void BM_OctomapInsertIntoExistingMap(benchmark::State& state) {
  octomap::OcTree tree(kResolution);
  for (const BenchScan& scan : scans()) {
    tree.insertPointCloud(scan.octomap_cloud, octomap::point3d(0, 0, 0), kMaxRange);
  }
  std::size_t k = 0;
  for (auto _ : state) {
    tree.insertPointCloud(scans()[k++ % scans().size()].octomap_cloud, octomap::point3d(0, 0, 0),
                          kMaxRange);
  }
  reportMemory(state, tree, scans()[0].octomap_cloud.size());
}
BENCHMARK(BM_OctomapInsertIntoExistingMap)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
