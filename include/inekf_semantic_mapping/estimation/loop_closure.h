// Loop closure on top of the smoothed InEKF run (issue 15 item 2): revisits found by the
// smoothed estimate and its uncertainty, confirmed by registering the two lidar scans, and a
// pose graph over keyframes (estimation/pose_graph.h) whose correction is carried back onto
// every frame. ROS-free and PCL-free: the scan registration is a function given by the caller
// (registration/icp_registration.h wraps PCL's GICP).
//
// The graph, over keyframes (every keyframe_spacing_m driven, a frame with a scan):
//  - odometry: the smoothed relative pose of consecutive keyframes a < b, with the smoother's
//    covariance of the relative left-invariant error e = xi_b - Ad(T_ab^-1) xi_a, from the
//    marginals and the RTS cross-covariance Cov(xi_a, xi_b) = G_a ... G_b-1 P_b|N. (This
//    covariance already holds some of the GPS information, which the GPS factors add again: a
//    mild overconfidence of the chain where GPS is dense, none inside an outage.)
//  - GPS: each fix the filter used, at the keyframe nearest in time within half a keyframe
//    interval, with its own covariance (the fix is moved along the smoothed trajectory to the
//    keyframe's time first);
//  - loops: the registered relative pose with a fixed covariance (loop_sigma_*) and a robust
//    kernel;
//  - tilt: roll and pitch of every keyframe with their smoothed marginal covariance (gravity
//    makes them observable to the filter; relative factors and GPS alone do not);
//  - a weak pose prior on the first keyframe (anchor for a graph without fixes).
// Each loop candidate goes through: the search (estimated distance <= search_radius_m +
// search_sigmas * the distance's sigma, time gap >= min_time_gap_s, driven gap >=
// min_travel_gap_m), the registration (converged, fitness <= max_fitness_m2), the consistency
// gate (squared Mahalanobis distance of measured vs estimated relative pose under the
// smoothed relative covariance plus the loop's <= gate_chi2), the optimization with the robust
// kernel, and the residual check after it (chi2 <= outlier_chi2, else removed and the graph
// solved again). Every candidate is logged with its fate and reason. Without an accepted loop
// the result is the smoothed run unchanged (the graph would only count the fixes twice).
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
  // Floors of the odometry covariance (a smoothed chain can be nearly exact where GPS is dense).
  double odometry_floor_sigma_m = 0.005;
  double odometry_floor_sigma_deg = 0.005;
  int max_iterations = 50;
  int max_outlier_rounds = 5;
  // Roll/pitch priors at the keyframes from the smoothed covariance (gravity observes the tilt;
  // without them loops tilt the outage's trajectory: measured rotation RMSE 1.29 -> 1.49 deg).
  bool tilt_priors = true;

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
  // R_est Exp(delta), rad); Euclidean, symmetric positive semi-definite. At a keyframe: the
  // smoother's covariance updated with the information the accepted loops add to the pose graph,
  // (P_smoothed^-1 + Sigma_with_loops^-1 - Sigma_without_loops^-1)^-1, from the graph's marginals
  // (PoseGraph::marginalCovariances, whose node tangent [dp map, dphi body] is that convention)
  // with and without the loop factors at the solution; why not the graph's marginal alone: see
  // closeLoops. Between two keyframes a and b: each keyframe's covariance carried
  // to the frame with the smoother's covariance of the relative pose (keyframe -> frame),
  // blended with the weights of the pose interpolation (1 - alpha from a, alpha from b); before
  // the first and after the last keyframe from the nearest one alone. See closeLoops. Without an
  // accepted loop: the smoothed run's pose_covariances unchanged.
  std::vector<PoseCovariance> pose_covariances;
  std::vector<int> keyframes;  // their frames
  std::vector<LoopRecord> loops;
  int accepted = 0, rejected = 0;
  int gps_factors = 0;
  PoseGraphSummary summary;
  double seconds_registration = 0.0, seconds_optimization = 0.0;
  double seconds_covariance = 0.0;  // the marginals and the per-frame covariances
};

// The keyframes' covariance: the graph's own marginal would be the estimator's Laplace
// covariance, but the graph counts the fixes twice (module comment): without loops its position
// sigma is about half the smoother's (drive 0018: 0.44 vs 0.86 m mean at the keyframes) where
// the estimate is no better, and with oracle loops on that drive its position NEES against the
// OXTS truth is 12 (3 if consistent). The smoother's covariance plus the loops' information
// keeps the smoother's calibration away from the loops and is exactly it without loops
// (measured NEES 6 on 0018, 2.2 in the synthetic outage).
// Why the blend between keyframes: the keyframe covariance carried forward from a (or backward
// from b) is the covariance of "keyframe pose composed with the smoothed relative pose", each
// a defensible estimate of the frame's uncertainty that ignores the other keyframe's
// constraint (to first order not smaller than the exact one); the convex blend keeps that,
// stays positive semi-definite, equals the keyframe's covariance at the keyframes and is
// continuous in time, like the interpolated pose correction. Keyframes are <=
// keyframe_spacing_m / keyframe_max_interval_s apart, so the relative part is small.
//
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
