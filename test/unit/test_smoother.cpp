// The Rauch-Tung-Striebel smoother on the left-invariant error: the group difference and its
// inverse, no information no change, and on Monte-Carlo runs of a noisy simulated drive with GPS:
// smaller errors than the filter's everywhere and a consistent covariance (NEES in its band).
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "inekf_semantic_mapping/estimation/error_dynamics.h"
#include "inekf_semantic_mapping/estimation/smoother.h"
#include "inekf_semantic_mapping/lie/so3.h"
#include "simulated_drive.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

using Vector15d = Eigen::Matrix<double, 15, 1>;
using test_drive::someState;

// The forward record of one run of the left-invariant filter, and the truth at each epoch.
struct RecordedRun {
  std::vector<ForwardEpoch> epochs;
  std::vector<NavState> truth;
};

RecordedRun recordRun(const test_drive::SimulatedDrive& drive, const test_drive::RunNoise& noise,
                      std::mt19937* rng) {
  RecordedRun run;
  test_drive::simulateNoisyRun(
      FilterType::kLeftInvariant, drive, noise, rng, [&](const test_drive::RunStep& step) {
        ForwardEpoch epoch;
        if (!run.epochs.empty()) {
          const NavState& previous = run.epochs.back().filtered;
          epoch.has_step = true;
          epoch.predicted = step.predicted;
          epoch.predicted_covariance = step.predicted_covariance;
          epoch.transition =
              leftErrorTransition(step.measured.angular_velocity - previous.gyro_bias,
                                  step.measured.specific_force - previous.accel_bias,
                                  step.predicted.stamp_s - previous.stamp_s);
        }
        epoch.filtered = step.filter->state();
        epoch.filtered_covariance = step.filter->covariance();
        run.epochs.push_back(epoch);
        run.truth.push_back(step.truth);
      });
  return run;
}

TEST(Smoother, LeftInvariantDifferenceInvertsApply) {
  const NavState a = someState();
  Vector15d xi;
  xi << 0.3, -0.1, 0.2, 1.0, -2.0, 0.5, 3.0, 4.0, -1.0, 1e-3, -2e-3, 3e-3, 0.01, 0.02, -0.03;
  const NavState b = applyLeftInvariant(a, xi);
  EXPECT_LT((leftInvariantDifference(a, b) - xi).norm(), 1e-9);
  // b = a exp(xi): the error of the estimate a against the "truth" b, as the filter defines it.
  EXPECT_LT((b.rotation - a.rotation * lie::expSO3(xi.head<3>())).norm(), 1e-12);
}

// Without measurements the future says nothing about the past: the smoothed run is the filtered.
TEST(Smoother, WithoutFixesTheSmoothedRunIsTheFilteredOne) {
  const test_drive::SimulatedDrive drive = test_drive::simulateDrive(60, 0.1);
  test_drive::RunNoise noise;
  noise.fix_every = 1000;  // none
  std::mt19937 rng(3);
  const RecordedRun run = recordRun(drive, noise, &rng);
  const std::vector<SmoothedEpoch> smoothed = smoothLeftInvariant(run.epochs);
  ASSERT_EQ(smoothed.size(), run.epochs.size());
  for (std::size_t k = 0; k < smoothed.size(); ++k) {
    EXPECT_LT((smoothed[k].state.position_map - run.epochs[k].filtered.position_map).norm(), 1e-6)
        << k;
    EXPECT_LT((smoothed[k].covariance - run.epochs[k].filtered_covariance).norm(),
              1e-6 * run.epochs[k].filtered_covariance.norm())
        << k;
  }
}

// A break in the chain (has_step false) splits the run: the epoch before it keeps its filtered
// estimate, since nothing links it to what follows.
TEST(Smoother, ABrokenChainRestartsTheSegment) {
  const test_drive::SimulatedDrive drive = test_drive::simulateDrive(60, 0.1);
  std::mt19937 rng(5);
  RecordedRun run = recordRun(drive, test_drive::RunNoise(), &rng);
  run.epochs[30].has_step = false;
  const std::vector<SmoothedEpoch> smoothed = smoothLeftInvariant(run.epochs);
  EXPECT_LT((smoothed[29].state.position_map - run.epochs[29].filtered.position_map).norm(), 1e-12);
  EXPECT_GT((smoothed[20].state.position_map - run.epochs[20].filtered.position_map).norm(), 1e-6);
}

// 25 runs of 200 steps, a fix every 10: position errors well below the filter's, rotation errors
// not above them (GPS positions say little about attitude: measured 0.97 of the filter's), and
// the smoothed covariance consistent with them (6-dof pose NEES in the 95 % band of the
// run average, [4.68, 7.45]).
TEST(Smoother, SmoothedErrorsAreSmallerAndConsistent) {
  const test_drive::SimulatedDrive drive = test_drive::simulateDrive(200, 0.1);
  std::mt19937 rng(42);
  const test_drive::RunNoise noise;
  const std::unique_ptr<NavigationFilter> reporter =
      makeFilter(FilterType::kLeftInvariant, noise.imu);
  double filtered_position = 0.0, smoothed_position = 0.0;
  double filtered_rotation = 0.0, smoothed_rotation = 0.0, nees = 0.0;
  int count = 0;
  for (int r = 0; r < 25; ++r) {
    const RecordedRun run = recordRun(drive, noise, &rng);
    const std::vector<SmoothedEpoch> smoothed = smoothLeftInvariant(run.epochs);
    for (std::size_t k = 10; k < smoothed.size(); ++k) {
      const NavState& truth = run.truth[k];
      const NavState& f = run.epochs[k].filtered;
      const NavState& s = smoothed[k].state;
      filtered_position += (f.position_map - truth.position_map).squaredNorm();
      smoothed_position += (s.position_map - truth.position_map).squaredNorm();
      filtered_rotation += lie::logSO3(f.rotation.transpose() * truth.rotation).squaredNorm();
      const Eigen::Vector3d rotation_error = lie::logSO3(s.rotation.transpose() * truth.rotation);
      smoothed_rotation += rotation_error.squaredNorm();
      Eigen::Matrix<double, 6, 1> pose_error;
      pose_error << truth.position_map - s.position_map, rotation_error;
      reporter->initialize(s, smoothed[k].covariance);
      nees += pose_error.dot(reporter->poseCovariance().ldlt().solve(pose_error));
      ++count;
    }
  }
  const double position_ratio = std::sqrt(smoothed_position / filtered_position);
  const double rotation_ratio = std::sqrt(smoothed_rotation / filtered_rotation);
  nees /= count;
  std::printf(
      "[ MEASURED ] smoothed / filtered RMS error: position %.2f, rotation %.2f; "
      "smoothed pose NEES %.2f (6 dof)\n",
      position_ratio, rotation_ratio, nees);
  EXPECT_LT(position_ratio, 0.8);
  EXPECT_LT(rotation_ratio, 1.0);
  EXPECT_GT(nees, 4.68);
  EXPECT_LT(nees, 7.45);
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
