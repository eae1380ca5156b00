// Scan insertion speed: SemanticOcTree::insertLabeledScan (batched: endpoints grouped per
// voxel, free voxels collected in a key set, every voxel updated once, class evidence included)
// and HashedVoxelGrid::insertLabeledScan (hashed 8^3 blocks, per-scan stamps, DDA from
// the endpoint back, early ray termination) against plain octomap::OcTree::insertPointCloud on
// the same real HDL-64 scans, 0.2 m resolution, 50 m max range, each insertion into a fresh map.
// Uses the first 12 scans of the real KITTI raw drive 2011_09_26_0013 in ../shared
// (ISM_SHARED_DIR overrides), else the 2 KITTI object scans, else a synthetic 120k-point scan.
// Counters: points per scan, map nodes, bytes per node and MB per million nodes (octrees); known
// voxels, ray visits, misses and MB (grid). At the end: every benchmark's time per scan as a
// ratio of octomap's insertPointCloud (discretize 0) in the same run.
#include <benchmark/benchmark.h>
#include <octomap/OcTree.h>
#include <time.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <random>
#include <string>

#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/mapping/hashed_voxel_grid.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace {

using inekf_semantic_mapping::mapping::ClassSet;
using inekf_semantic_mapping::mapping::FusionModel;
using inekf_semantic_mapping::mapping::HashedVoxelGrid;
using inekf_semantic_mapping::mapping::HashedVoxelGridOptions;
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
  const std::string drive =
      shared + "/data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync/velodyne_points/data/";
  for (int frame = 0; frame < 12; ++frame) {
    char name[32];
    std::snprintf(name, sizeof(name), "%010d.bin", frame);
    if (std::filesystem::exists(drive + name)) {
      raw.push_back(inekf_semantic_mapping::kitti::readVelodyneBin(drive + name).xyzi);
    }
  }
  if (raw.empty()) {
    for (const char* name : {"000000.bin", "000001.bin"}) {
      const std::string path = shared + "/data/kitti_object/training/velodyne/" + name;
      if (std::filesystem::exists(path)) {
        raw.push_back(inekf_semantic_mapping::kitti::readVelodyneBin(path).xyzi);
      }
    }
  }
  std::cerr << "bench_semantic_octree: " << raw.size() << " real scans\n";
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

// Time per scan of every benchmark (name with its arguments): wall and this thread's CPU time
// (the fair one on a shared machine; for the 2-thread octree the other thread's CPU is missing,
// so its CPU ratio flatters it), for the ratios at the end.
struct ScanTimes {
  double wall_ms;
  double cpu_ms;
};
std::map<std::string, ScanTimes>& msPerScan() {
  static std::map<std::string, ScanTimes> times;
  return times;
}
double threadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}
class ScanClock {
 public:
  explicit ScanClock(std::string name) : name_(std::move(name)) {}
  void start() {
    begin_ = std::chrono::steady_clock::now();
    cpu_begin_ = threadCpuSeconds();
  }
  void stop() {
    total_s_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - begin_).count();
    cpu_s_ += threadCpuSeconds() - cpu_begin_;
    ++scans_;
  }
  ~ScanClock() {
    if (scans_ > 0) {
      msPerScan()[name_] = {1e3 * total_s_ / static_cast<double>(scans_),
                            1e3 * cpu_s_ / static_cast<double>(scans_)};
    }
  }

 private:
  std::string name_;
  std::chrono::steady_clock::time_point begin_;
  double total_s_ = 0;
  double cpu_begin_ = 0;
  double cpu_s_ = 0;
  std::size_t scans_ = 0;
};

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
  ScanClock clock(std::string("octomap insertPointCloud discretize=") + (discretize ? "1" : "0"));
  std::size_t k = 0;
  for (auto _ : state) {
    const BenchScan& scan = scans()[k++ % scans().size()];
    octomap::OcTree tree(kResolution);
    clock.start();
    tree.insertPointCloud(scan.octomap_cloud, octomap::point3d(0, 0, 0), kMaxRange, false,
                          discretize);
    clock.stop();
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
  ScanClock clock("SemanticOcTree insertLabeledScan threads=" + std::to_string(threads));
  for (auto _ : state) {
    const BenchScan& scan = scans()[k++ % scans().size()];
    SemanticOcTree tree(kResolution, ClassSet::cityscapes(), FusionModel());
    tree.setRayCastingThreads(threads);
    clock.start();
    tree.insertLabeledScan(scan.labeled, kMaxRange);
    clock.stop();
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

HashedVoxelGridOptions gridOptions(int early_termination) {
  HashedVoxelGridOptions options;
  options.resolution_m = kResolution;
  options.early_termination_voxels = early_termination;
  return options;
}

void reportGrid(benchmark::State& state, const HashedVoxelGrid& grid, std::size_t points) {
  state.counters["points"] = static_cast<double>(points);
  state.counters["known_voxels"] = static_cast<double>(grid.knownVoxels());
  state.counters["ray_visits"] = static_cast<double>(grid.lastRayVisits());
  state.counters["misses"] = static_cast<double>(grid.lastMisses());
  state.counters["MB"] = static_cast<double>(grid.memoryUsage()) / 1e6;
}

// The grid path, each scan into a fresh grid (the octree benchmarks' setting). Arg: early ray
// termination (0: off).
void BM_HashedGridInsertLabeledScan(benchmark::State& state) {
  const int early = static_cast<int>(state.range(0));
  const ClassSet classes = ClassSet::cityscapes();
  ScanClock clock("HashedVoxelGrid insertLabeledScan early_termination=" + std::to_string(early));
  std::size_t k = 0;
  for (auto _ : state) {
    const BenchScan& scan = scans()[k++ % scans().size()];
    HashedVoxelGrid grid(gridOptions(early));
    clock.start();
    grid.insertLabeledScan(scan.labeled, kMaxRange, classes);
    clock.stop();
    benchmark::DoNotOptimize(grid.blockCount());
    if (k == 1) reportGrid(state, grid, scan.octomap_cloud.size());
  }
}
BENCHMARK(BM_HashedGridInsertLabeledScan)
    ->ArgName("early_termination")
    ->Arg(0)
    ->Arg(10)
    ->Arg(20)
    ->Unit(benchmark::kMillisecond);

// The grid path plus the conversion of the scan's blocks into a SemanticOcTree (what a save or
// a publish after every scan would cost).
void BM_HashedGridInsertAndSyncTree(benchmark::State& state) {
  const int early = static_cast<int>(state.range(0));
  const ClassSet classes = ClassSet::cityscapes();
  ScanClock clock("HashedVoxelGrid insert + syncTo(tree) early_termination=" +
                  std::to_string(early));
  std::size_t k = 0;
  for (auto _ : state) {
    const BenchScan& scan = scans()[k++ % scans().size()];
    HashedVoxelGrid grid(gridOptions(early));
    SemanticOcTree tree(kResolution, classes, FusionModel());
    clock.start();
    grid.insertLabeledScan(scan.labeled, kMaxRange, classes);
    grid.syncTo(&tree);
    clock.stop();
    benchmark::DoNotOptimize(tree.size());
    if (k == 1) reportMemory(state, tree, scan.octomap_cloud.size());
  }
}
BENCHMARK(BM_HashedGridInsertAndSyncTree)
    ->ArgName("early_termination")
    ->Arg(0)
    ->Arg(10)
    ->Arg(20)
    ->Unit(benchmark::kMillisecond);

// Steady state: a scan into a grid that already holds the other scans.
void BM_HashedGridInsertIntoExistingMap(benchmark::State& state) {
  const int early = static_cast<int>(state.range(0));
  const ClassSet classes = ClassSet::cityscapes();
  HashedVoxelGrid grid(gridOptions(early));
  for (const BenchScan& scan : scans()) grid.insertLabeledScan(scan.labeled, kMaxRange, classes);
  std::size_t k = 0;
  for (auto _ : state) {
    grid.insertLabeledScan(scans()[k++ % scans().size()].labeled, kMaxRange, classes);
  }
  reportGrid(state, grid, scans()[0].octomap_cloud.size());
}
BENCHMARK(BM_HashedGridInsertIntoExistingMap)
    ->ArgName("early_termination")
    ->Arg(0)
    ->Arg(10)
    ->Arg(20)
    ->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  const auto& times = msPerScan();
  const auto reference = times.find("octomap insertPointCloud discretize=0");
  if (reference != times.end()) {
    std::printf(
        "\nTime per scan (insertion only, fresh map) vs octomap insertPointCloud in this run "
        "(wall %.1f ms, thread CPU %.1f ms):\n",
        reference->second.wall_ms, reference->second.cpu_ms);
    std::printf("  %-62s %9s %7s %9s %7s\n", "", "wall ms", "ratio", "CPU ms", "ratio");
    for (const auto& [name, t] : times) {
      std::printf("  %-62s %9.2f %6.3fx %9.2f %6.3fx\n", name.c_str(), t.wall_ms,
                  t.wall_ms / reference->second.wall_ms, t.cpu_ms,
                  t.cpu_ms / reference->second.cpu_ms);
    }
  }
  return 0;
}
