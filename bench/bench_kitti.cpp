// KITTI I/O speed: what kitti_player must do per frame at 10 Hz (x rate) and what kitti2bag
// does per drive. Real data from ../shared (ISM_SHARED_DIR overrides); without it the file
// benchmarks are skipped with a message, the in-memory ones use a synthetic 120k-point scan.
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/ros/kitti_conversions.h"

namespace {

namespace kitti = inekf_semantic_mapping::kitti;
namespace conv = inekf_semantic_mapping::ros_conversions;

std::string sharedPath(const std::string& relative) {
  const char* dir = std::getenv("ISM_SHARED_DIR");
  return std::string(dir && *dir ? dir : ISM_SHARED_DIR_DEFAULT) + "/" + relative;
}

const std::string kScan = "data/kitti_object/training/velodyne/000000.bin";
const std::string kOxtsDir = "data/kitti_raw/2011_09_26/2011_09_26_drive_0009_sync/oxts";

// 64 rings x 1800 azimuth steps swept counter-clockwise, as the HDL-64E writes them.
kitti::VelodyneScan syntheticScan() {
  kitti::VelodyneScan scan;
  std::mt19937 random(1);
  std::uniform_real_distribution<float> range(3.0f, 60.0f);
  for (int ring = 0; ring < 64; ++ring) {
    const double elevation = (2.0 - 0.42 * ring) * M_PI / 180.0;
    for (int k = 0; k < 1800; ++k) {
      const double azimuth = (0.1 + 0.2 * k) * M_PI / 180.0;
      const float r = range(random);
      scan.xyzi.insert(scan.xyzi.end(),
                       {static_cast<float>(r * std::cos(elevation) * std::cos(azimuth)),
                        static_cast<float>(r * std::cos(elevation) * std::sin(azimuth)),
                        static_cast<float>(r * std::sin(elevation)), 0.5f});
    }
  }
  return scan;
}

kitti::VelodyneScan benchmarkScan() {
  return std::filesystem::exists(sharedPath(kScan)) ? kitti::readVelodyneBin(sharedPath(kScan))
                                                    : syntheticScan();
}

void BM_ReadVelodyneBin(benchmark::State& state) {
  if (!std::filesystem::exists(sharedPath(kScan))) {
    state.SkipWithError("shared data not found (../shared/data/kitti_object)");
    return;
  }
  for (auto _ : state) benchmark::DoNotOptimize(kitti::readVelodyneBin(sharedPath(kScan)));
  state.counters["points"] = static_cast<double>(kitti::readVelodyneBin(sharedPath(kScan)).size());
}
BENCHMARK(BM_ReadVelodyneBin)->Unit(benchmark::kMillisecond);

void BM_ComputeRings(benchmark::State& state) {
  const kitti::VelodyneScan scan = benchmarkScan();
  for (auto _ : state) benchmark::DoNotOptimize(kitti::computeRings(scan));
  state.counters["points"] = static_cast<double>(scan.size());
}
BENCHMARK(BM_ComputeRings)->Unit(benchmark::kMillisecond);

void BM_ToPointCloudMessage(benchmark::State& state) {
  const kitti::VelodyneScan scan = benchmarkScan();
  for (auto _ : state) benchmark::DoNotOptimize(conv::toPointCloudMessage(scan, ros::Time(1, 0)));
  state.counters["points"] = static_cast<double>(scan.size());
}
BENCHMARK(BM_ToPointCloudMessage)->Unit(benchmark::kMillisecond);

void BM_ReadOxtsFolder(benchmark::State& state) {
  if (!std::filesystem::exists(sharedPath(kOxtsDir))) {
    state.SkipWithError("shared data not found (../shared/data/kitti_raw)");
    return;
  }
  std::size_t frames = 0;
  for (auto _ : state) {
    const auto oxts = kitti::readOxtsFolder(sharedPath(kOxtsDir));
    frames = oxts.size();
    benchmark::DoNotOptimize(oxts.data());
  }
  state.counters["frames"] = static_cast<double>(frames);
}
BENCHMARK(BM_ReadOxtsFolder)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
