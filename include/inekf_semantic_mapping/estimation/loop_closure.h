// Loop closure on top of the smoothed InEKF run: revisits found by the
// smoothed estimate and its uncertainty, confirmed by registering the two lidar scans, and
// loop factors between keyframes whose posterior is carried back onto every frame. ROS-free and
// PCL-free: the scan registration is a function given by the caller
// (registration/icp_registration.h wraps PCL's GICP).
//
// The back end (estimation/smoothed_posterior_graph.h): the loop factors are added to the
// smoothed run's own posterior over the keyframes' 15-dim states (a Markov chain: block-
// tridiagonal information from the smoother's marginals and gains), which already holds the IMU,
// the fixes, the land-vehicle constraint and gravity's hold on the tilt exactly once. A loop
// factor is the registered relative pose with a fixed covariance (loop_sigma_*) and a robust
// kernel. The posterior is then carried to every frame (states and covariances) by the same
// chain.
//
// Each loop candidate goes through: the search (estimated distance <= search_radius_m +
// search_sigmas * the distance's sigma, time gap >= min_time_gap_s, driven gap >=
// min_travel_gap_m), the registration (converged, fitness <= max_fitness_m2), the consistency
// gate (squared Mahalanobis distance of measured vs estimated relative pose under the
// smoothed relative covariance plus the loop's <= gate_chi2), the optimization with the robust
// kernel, and the residual check after it (chi2 <= outlier_chi2, else removed and the graph
// solved again). Every candidate is logged with its fate and reason. Without an accepted loop
// the result is the smoothed run unchanged.
#pragma once

#include <Eigen/Geometry>
#include <functional>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/estimation/oxts_run.h"
#include "inekf_semantic_mapping/estimation/pose_graph.h"

namespace inekf_semantic_mapping {
namespace common {
class YamlReader;
}
namespace estimation {

struct LoopClosureOptions {
  // Keyframes: a frame becomes one after keyframe_spacing_m driven (estimated path) or
  // keyframe_max_interval_s since the previous one.
  double keyframe_spacing_m = 2.0;
  double keyframe_max_interval_s = 2.0;
  // Candidate search.
  double min_time_gap_s = 10.0;
  double min_travel_gap_m = 30.0;
  double search_radius_m = 5.0;
  double search_sigmas = 3.0;
  double max_search_radius_m = 30.0;
  double query_spacing_m = 4.0;  // driven distance between two loop queries
  // Registration acceptance and the loop factor.
  double max_fitness_m2 = 0.2;  // mean squared distance of the matched points
  double loop_sigma_m = 0.1;
  double loop_sigma_deg = 0.5;
  double gate_chi2 = 22.46;     // 6 dof, 99.9 %
  double outlier_chi2 = 16.81;  // 6 dof, 99 %: residual of a loop after the optimization
  RobustKernel kernel = RobustKernel::kCauchy;
  double kernel_scale = 2.0;  // sigmas
  int max_iterations = 50;
  int max_outlier_rounds = 5;

  // Reads the keys under "loop_closure." (see config/loop_closure.yaml); the caller rejects
  // unknown keys. Values out of range fail naming the key.
  void read(common::YamlReader* reader);
  void validate() const;  // throws std::invalid_argument naming the bad field
};

struct ScanRegistrationResult {
  bool converged = false;
  double fitness_m2 = 0.0;  // mean squared distance of the matched points
  // The source scan's sensor pose in the target scan's sensor frame (p_target = T p_source).
  Eigen::Isometry3d target_from_source = Eigen::Isometry3d::Identity();
};
// Registers the scan of OXTS frame `source` onto that of frame `target`, starting from `guess`
// (target_from_source). Throws (naming the file) when a scan cannot be read.
using ScanRegistration = std::function<ScanRegistrationResult(int target_frame, int source_frame,
                                                              const Eigen::Isometry3d& guess)>;

struct LoopRecord {
  int query_frame = 0, match_frame = 0;  // later and earlier frame
  double time_gap_s = 0.0;
  double distance_m = 0.0;        // estimated distance between the two (smoothed)
  double distance_sigma_m = 0.0;  // its 1-sigma
  bool registered = false;
  double fitness_m2 = 0.0;
  double correction_m = 0.0;    // translation of measured vs estimated relative pose
  double correction_deg = 0.0;  // rotation of the same
  double chi2_estimate = 0.0;   // gate: against the smoothed relative pose
  double chi2_final = 0.0;      // after the optimization
  bool accepted = false;
  std::string reason;  // "accepted" or why not
};

struct LoopClosureResult {
  std::vector<NavState> states;  // one per frame: the loop-closed estimate
  // One per frame: the loop-closed pose covariance, in the convention of
  // OxtsRunResult::pose_covariances (NavigationFilter::poseCovariance): position error in the
  // map frame (m) first, then the rotation error as a body-frame small angle (R_true =
  // R_est Exp(delta), rad); Euclidean, symmetric positive semi-definite. The posterior's
  // (SmoothedPosteriorGraph::posterior); without an accepted loop the smoothed run's unchanged.
  std::vector<PoseCovariance> pose_covariances;
  std::vector<int> keyframes;  // their frames
  std::vector<LoopRecord> loops;
  int accepted = 0, rejected = 0;
  PoseGraphSummary summary;
  double seconds_registration = 0.0, seconds_optimization = 0.0;
  double seconds_covariance = 0.0;  // the marginals and the per-frame covariances
};

// frame_has_scan: one per frame (empty: every frame has one). T_imu_sensor: the scanner's pose
// in the IMU frame. Needs a smoothed run (run.smoothed, with its covariances and gains); throws
// std::invalid_argument otherwise.
LoopClosureResult closeLoops(const OxtsRunResult& run, const std::vector<bool>& frame_has_scan,
                             const Eigen::Isometry3d& T_imu_sensor,
                             const ScanRegistration& registration,
                             const LoopClosureOptions& options);

// One line per loop for a log or a CSV (header first).
std::string loopCsvHeader();
std::string loopCsvLine(const LoopRecord& loop);

}  // namespace estimation
}  // namespace inekf_semantic_mapping
