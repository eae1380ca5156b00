// Speed of the synthetic drive generator's parts: one HDL-64E sweep (~133k rays), one
// 1242x375 camera frame (466k rays) on 1 and 2 threads, one 100 Hz IMU sample.
// Run: $ISM_BIN/bench_synthetic (items/s = rays/s for the ray casting benchmarks).
#include <benchmark/benchmark.h>

#include "inekf_semantic_mapping/synthetic/route.h"
#include "inekf_semantic_mapping/synthetic/sensors.h"
#include "inekf_semantic_mapping/synthetic/world.h"

namespace {
using namespace inekf_semantic_mapping::synthetic;

const SyntheticWorld& world() {
  static const SyntheticWorld town = SyntheticWorld::generateTown(1);
  return town;
}

// A pose on the route a few seconds in (in the street, looking along it), raised to the
// sensor height.
Eigen::Isometry3d sensorPose(double height_above_imu) {
  const VehicleState state = SyntheticRoute::forWorld(world()).poseAt(6.0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = state.rotation;
  T.translation() = state.position + state.rotation * Eigen::Vector3d(0, 0, height_above_imu);
  return T;
}

void BM_LidarSweep(benchmark::State& state) {
  const Eigen::Isometry3d T_map_velo = sensorPose(0.8);
  const LidarModel model;
  std::size_t points = 0;
  for (auto _ : state) {
    const LidarScan scan = simulateLidarScan(world(), T_map_velo, model, 1);
    points = scan.size();
    benchmark::DoNotOptimize(scan.xyzi.data());
  }
  state.SetItemsProcessed(state.iterations() * model.columns() * model.beams);
  state.counters["points"] = static_cast<double>(points);
}
BENCHMARK(BM_LidarSweep)->Unit(benchmark::kMillisecond);

void BM_CameraFrame(benchmark::State& state) {
  Eigen::Isometry3d T_map_camera = sensorPose(0.7);
  Eigen::Matrix3d R_imu_camera;  // optical frame: x right, y down, z forward
  R_imu_camera << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  T_map_camera.linear() = T_map_camera.linear() * R_imu_camera;
  Eigen::Matrix3d K;
  K << 721.5377, 0, 609.5593, 0, 721.5377, 172.854, 0, 0, 1;
  const int threads = static_cast<int>(state.range(0));
  for (auto _ : state) {
    const RenderedImage image = renderCamera(world(), T_map_camera, K, 1242, 375, {}, threads);
    benchmark::DoNotOptimize(image.bgr.data());
  }
  state.SetItemsProcessed(state.iterations() * 1242 * 375);
}
BENCHMARK(BM_CameraFrame)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ImuSample(benchmark::State& state) {
  const SyntheticRoute route = SyntheticRoute::forWorld(world());
  double t = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(route.stateAt(t));
    t += 0.01;
  }
}
BENCHMARK(BM_ImuSample);

void BM_GenerateTown(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(SyntheticWorld::generateTown(2));
}
BENCHMARK(BM_GenerateTown)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
