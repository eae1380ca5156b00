// Speed of the navigation filters: one propagate and one position correction per filter, and a
// whole KITTI drive through the Localizer (2011_09_30_drive_0028, 5177 frames, when ../shared is
// there; else a 4500-step synthetic drive).
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>

#include "inekf_semantic_mapping/estimation/oxts_run.h"
#include "inekf_semantic_mapping/estimation/smoothed_posterior_graph.h"

namespace estimation = inekf_semantic_mapping::estimation;
namespace kitti = inekf_semantic_mapping::kitti;

namespace {

estimation::FilterType filterOf(const benchmark::State& state) {
  return static_cast<estimation::FilterType>(state.range(0));
}

std::unique_ptr<estimation::NavigationFilter> readyFilter(estimation::FilterType type) {
  auto filter = estimation::makeFilter(type, estimation::ImuNoise());
  estimation::NavState s;
  s.velocity_map = Eigen::Vector3d(8, 1, 0);
  s.position_map = Eigen::Vector3d(300, -120, 4);
  filter->initialize(s, estimation::ErrorCovariance::Identity() * 0.01);
  return filter;
}

void BM_Propagate(benchmark::State& state) {
  auto filter = readyFilter(filterOf(state));
  estimation::ImuSample sample;
  sample.angular_velocity = Eigen::Vector3d(0.01, -0.02, 0.2);
  sample.specific_force = Eigen::Vector3d(0.5, 0.3, 9.8);
  for (auto _ : state) {
    filter->propagate(sample, 0.1);
    benchmark::DoNotOptimize(filter->state());
  }
  state.SetLabel(estimation::toString(filterOf(state)));
}
BENCHMARK(BM_Propagate)->Arg(0)->Arg(1)->Arg(2);

void BM_CorrectPosition(benchmark::State& state) {
  auto filter = readyFilter(filterOf(state));
  estimation::PositionFix fix;
  fix.position_map = filter->state().position_map + Eigen::Vector3d(0.3, -0.2, 0.1);
  fix.covariance_map = Eigen::Matrix3d::Identity();
  // Repeated fixes: the state converges on the fix, the work per update stays the same.
  for (auto _ : state) {
    benchmark::DoNotOptimize(filter->correctPosition(fix, 1e9));
  }
  state.SetLabel(estimation::toString(filterOf(state)));
}
BENCHMARK(BM_CorrectPosition)->Arg(0)->Arg(1)->Arg(2);

std::vector<kitti::OxtsFrame> benchmarkDrive() {
  const char* shared = std::getenv("ISM_SHARED_DIR");
  const std::string dir = std::string(shared && *shared ? shared : "../shared") +
                          "/data/kitti_raw/2011_09_30/2011_09_30_drive_0028_sync/oxts";
  if (std::filesystem::exists(dir)) return kitti::readOxtsFolder(dir);
  // Synthetic stand-in: a steady curve at 10 m/s, 4500 frames.
  std::vector<kitti::OxtsFrame> frames(4500);
  for (std::size_t k = 0; k < frames.size(); ++k) {
    frames[k].stamp_ns = static_cast<std::int64_t>(k) * 100000000;
    kitti::OxtsRecord& r = frames[k].record;
    r.lat = 49.0 + 1e-6 * k;
    r.lon = 8.4 + 1e-6 * k;
    r.alt = 110.0;
    r.yaw = 0.01 * k;
    r.az = 9.81;
    r.wz = 0.1;
    r.posmode = 5;
  }
  return frames;
}

void BM_WholeDriveThroughLocalizer(benchmark::State& state) {
  static const std::vector<kitti::OxtsFrame> frames = benchmarkDrive();
  estimation::OxtsRunOptions options;
  options.config.localizer.filter_type = filterOf(state);
  options.gps = estimation::protocolGps();
  for (auto _ : state) {
    benchmark::DoNotOptimize(estimation::runLocalizerOnOxts(frames, options));
  }
  state.SetLabel(estimation::toString(filterOf(state)) + ", " + std::to_string(frames.size()) +
                 " frames");
}
BENCHMARK(BM_WholeDriveThroughLocalizer)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// The same run with the Rauch-Tung-Striebel pass (inekf_offline --smooth): filter + smoother.
void BM_WholeDriveFilteredAndSmoothed(benchmark::State& state) {
  static const std::vector<kitti::OxtsFrame> frames = benchmarkDrive();
  estimation::OxtsRunOptions options;
  options.gps = estimation::protocolGps();
  options.smooth = true;
  for (auto _ : state) {
    benchmark::DoNotOptimize(estimation::runLocalizerOnOxts(frames, options));
  }
  state.SetLabel("left + RTS, " + std::to_string(frames.size()) + " frames");
}
BENCHMARK(BM_WholeDriveFilteredAndSmoothed)->Unit(benchmark::kMillisecond);

// The loop closure's back end on the smoothed drive (estimation/smoothed_posterior_graph.h):
// keyframes every N frames (20 is about 2 m at the drive's speed), loops between the first
// keyframes and those half the drive later, each measuring the smoothed relative pose moved by
// 0.3 m; optimize from the smoothed run, then the posterior states and covariances of every frame.
void BM_SmoothedPosteriorGraph(benchmark::State& state) {
  static const estimation::OxtsRunResult run = [] {
    estimation::OxtsRunOptions options;
    options.gps = estimation::protocolGps();
    options.smooth = true;
    return estimation::runLocalizerOnOxts(benchmarkDrive(), options);
  }();
  const int spacing = static_cast<int>(state.range(0));
  std::vector<int> keyframes;
  for (int k = run.first_estimated_frame; k < static_cast<int>(run.states.size()); k += spacing) {
    keyframes.push_back(k);
  }
  const int nodes = static_cast<int>(keyframes.size());
  std::vector<estimation::NavState> states;
  std::vector<estimation::PoseCovariance> covariances;
  int iterations = 0;
  for (auto _ : state) {
    estimation::SmoothedPosteriorGraph graph(run, keyframes);
    for (int n = 0; n < 20; ++n) {
      estimation::RelativePoseFactor loop;
      loop.from = n;
      loop.to = n + nodes / 2;
      const auto pose = [&](int node) { return estimation::poseOf(run.states[keyframes[node]]); };
      loop.measurement = pose(loop.from).inverse() * pose(loop.to);
      loop.measurement.position.x() += 0.3;
      loop.information = 100.0 * estimation::Matrix6d::Identity();
      loop.kernel = estimation::RobustKernel::kCauchy;
      loop.kernel_scale = 2.0;
      graph.addLoop(loop);
    }
    iterations = graph.optimize().iterations;
    graph.posterior(&states, &covariances);
    benchmark::DoNotOptimize(covariances.data());
  }
  state.SetLabel(std::to_string(nodes) + " keyframes, 20 loops, " +
                 std::to_string(run.states.size()) + " frames, " + std::to_string(iterations) +
                 " LM iterations");
}
BENCHMARK(BM_SmoothedPosteriorGraph)->Arg(20)->Arg(5)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
