// The SE(3) pieces of the loop closure's graph (estimation/smoothed_posterior_graph.h): poses,
// the relative-pose factor of a loop with its robust kernel, and the Levenberg-Marquardt options.
// ROS-free, Eigen only.
//
// A relative factor's residual, for the measured pose (R_ij, t_ij) of node j in node i's frame:
//   r = [R_i^T (p_j - p_i) - t_ij ; Log(R_ij^T R_i^T R_j)]
// (the relative translation in i's frame, the relative rotation error as a small angle on the
// measured one's right), with its information in that order. A robust kernel acts on the squared
// Mahalanobis distance s = r^T W r (c = kernel_scale, in sigmas): Huber rho(s) = s (s <= c^2),
// 2 c sqrt(s) - c^2 beyond; Cauchy rho(s) = c^2 log(1 + s / c^2); solved by iteratively
// reweighted Gauss-Newton inside LM with graduated scales (PoseGraphOptions).
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <string>

#include "inekf_semantic_mapping/estimation/types.h"

namespace inekf_semantic_mapping {
namespace estimation {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

struct Pose3 {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // body -> map
  Eigen::Vector3d position = Eigen::Vector3d::Zero();      // map frame

  Pose3 inverse() const;
  Pose3 operator*(const Pose3& other) const;
};
// The pose part of a navigation state.
Pose3 poseOf(const NavState& state);

enum class RobustKernel { kNone, kHuber, kCauchy };
// "none" | "huber" | "cauchy"; throws std::invalid_argument naming the text otherwise.
RobustKernel robustKernelFromString(const std::string& text);
std::string toString(RobustKernel kernel);
// rho(s) and its derivative (the IRLS weight) for a squared Mahalanobis distance s.
double robustCost(RobustKernel kernel, double scale, double squared);
double robustWeight(RobustKernel kernel, double scale, double squared);

struct RelativePoseFactor {
  int from = 0, to = 0;
  Pose3 measurement;  // pose of `to` in the frame of `from`
  Matrix6d information = Matrix6d::Identity();
  RobustKernel kernel = RobustKernel::kNone;
  double kernel_scale = 1.0;  // sigmas
  bool active = true;
};

// The residual of a relative measurement and its Jacobians with respect to updates of the two
// poses in the order [dp, dphi]: R Exp(dphi), p + dp (map-frame translation, body-frame angle).
Vector6d relativePoseResidual(const Pose3& from, const Pose3& to, const Pose3& measurement,
                              Matrix6d* jacobian_from = nullptr, Matrix6d* jacobian_to = nullptr);

struct PoseGraphOptions {
  int max_iterations = 50;
  double initial_lambda = 1e-4;  // LM damping, relative to the Hessian's diagonal
  double relative_cost_tolerance = 1e-10;
  // Graduated robust kernels: the kernels' scales start multiplied so that every robust factor
  // is inside its quadratic region at the initial poses (at most graduated_max_multiplier) and
  // shrink by graduated_factor per stage to the configured ones; each stage is solved by LM.
  // A true loop far from the drifted start is then not written off as an outlier, and a false
  // one loses its weight as the scales shrink. <= 1: no graduation.
  double graduated_factor = 2.0;
  double graduated_max_multiplier = 1e3;
};

struct PoseGraphSummary {
  int iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;  // 0.5 sum of (robustified) squared residuals
  bool converged = false;
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
