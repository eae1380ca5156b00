// Fixed-interval smoothing of a left-invariant EKF run: a Rauch-Tung-Striebel backward pass on
// the invariant error (Barrau & Bonnabel's left error eta = X_est^-1 X_true = exp(xi), biases
// additive), with the filter's own discrete transition. The covariances stay in the Lie algebra
// of the estimate they belong to: the correction of step k+1 is the group difference
// log(X_pred^-1 X_smooth), carried back through the gain and applied with exp on the group, so
// no information matrix is ever formed or inverted in a Euclidean chart.
//
//   G_k    = P_k|k Phi_k^T P_k+1|k^-1
//   xi_k   = G_k log(X_k+1|k^-1 X_k+1|N)         (15-dim: SE_2(3) log, bias differences)
//   X_k|N  = X_k|k exp(xi_k),  b_k|N = b_k|k + xi_k(bias)
//   P_k|N  = P_k|k + G_k (P_k+1|N - P_k+1|k) G_k^T
//
// First order like the filter; exact for a linear system. ROS-free.
#pragma once

#include <vector>

#include "inekf_semantic_mapping/estimation/error_dynamics.h"
#include "inekf_semantic_mapping/estimation/types.h"

namespace inekf_semantic_mapping {
namespace estimation {

// One epoch of the forward run, all covariances in left-invariant error coordinates.
struct ForwardEpoch {
  NavState filtered;  // X_k|k: after the IMU step to k and any fix at k
  Matrix15d filtered_covariance = Matrix15d::Identity();
  // The step from epoch k-1: X_k|k-1 and P_k|k-1 (the filter after the IMU step, before the
  // fixes) and Phi_k-1. false for the first epoch and where the chain breaks (a reset): the
  // smoother then treats the epoch as the end of one segment and the start of the next.
  bool has_step = false;
  NavState predicted;
  Matrix15d predicted_covariance = Matrix15d::Identity();
  Matrix15d transition = Matrix15d::Identity();
};

struct SmoothedEpoch {
  NavState state;
  Matrix15d covariance;
  // G_k, linking this epoch to the next (zero where a segment ends): the smoothed
  // cross-covariance is Cov(xi_k, xi_k+1 | N) = G_k P_k+1|N, and over a lag
  // Cov(xi_k, xi_k+m | N) = G_k ... G_k+m-1 P_k+m|N (relative-pose covariances, loop closure).
  Matrix15d gain = Matrix15d::Zero();
};

// Throws std::invalid_argument when a predicted covariance is not positive definite (a broken
// forward record). The result has one entry per epoch.
std::vector<SmoothedEpoch> smoothLeftInvariant(const std::vector<ForwardEpoch>& epochs);

// The 15-dim left-invariant difference xi with b = a exp(xi) (biases: b - a).
Eigen::Matrix<double, 15, 1> leftInvariantDifference(const NavState& a, const NavState& b);
// a exp(xi), biases a + xi(bias).
NavState applyLeftInvariant(const NavState& a, const Eigen::Matrix<double, 15, 1>& xi);

}  // namespace estimation
}  // namespace inekf_semantic_mapping
