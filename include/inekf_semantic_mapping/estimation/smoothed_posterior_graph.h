// The loop closure's back end (estimation/loop_closure.h): loop factors added to the smoothed
// run's own posterior, instead of to a pose graph that re-derives it from odometry and GPS
// factors.
//
// The RTS smoother's result is a Gaussian over all epochs' 15-dim left-invariant errors
// xi_k (X_k = X_k|N exp(xi_k), biases additive) that is a Markov chain: marginals P_k|N and
// Cov(xi_a, xi_b) = G_a ... G_b-1 P_b|N for a <= b (estimation/smoother.h). A subsequence of a
// Markov chain is one too, so over the keyframes k_0 < k_1 < ... the prior
//   p(xi_0) prod_n p(xi_n+1 | xi_n),  p(xi_n+1 | xi_n) = N(A_n xi_n, Q_n),
//   A_n = C_n^T P_n^-1,  Q_n = P_n+1 - A_n C_n,  C_n = Cov(xi_n, xi_n+1),
// has a block-tridiagonal information matrix. It holds everything the smoother knew (IMU, GPS,
// the land-vehicle constraint, gravity on the tilt, velocity and bias correlations) exactly once:
// a pose graph of smoothed relative poses plus GPS factors counts the fixes twice and treats the
// chain's errors as independent between keyframes (its marginals were about 2x overconfident in
// variance on drive 0018 with oracle loops). Loop factors act on the keyframes' poses
// T_n(xi_n) = pose of X_n|N exp(xi_n); the cost
//   1/2 xi^T Lambda xi + 1/2 sum_loops rho(r^T W r)
// is minimized by Levenberg-Marquardt with graduated robust kernels (PoseGraphOptions), in the
// fixed chart xi (the prior stays exactly quadratic; the loops' Jacobians take SE_2(3)'s right
// Jacobian). Without loops the posterior is the smoothed run itself.
//
// Every frame's posterior follows from its keyframes: loops touch keyframes only, so a frame k
// between keyframes a and b is conditionally independent of them given (xi_a, xi_b), and
//   E[xi_k] = K [xi_a; xi_b],  Cov = P_k - K S_k^T + K Sigma_ab K^T,  K = S_k Pi_ab^-1,
// with S_k = [Cov(xi_k, xi_a), Cov(xi_k, xi_b)] and Pi_ab the prior, Sigma_ab the posterior
// joint covariance of the two keyframes (the selected inverse of the Hessian holds it). So the
// velocities and biases move with the poses, and the covariance is the posterior's, not a blend.
// ROS-free, Eigen only.
#pragma once

#include <vector>

#include "inekf_semantic_mapping/estimation/oxts_run.h"
#include "inekf_semantic_mapping/estimation/pose_graph.h"

namespace inekf_semantic_mapping {
namespace estimation {

// Cov(xi_a, xi_b) of frames a <= b under a smoothed run: G_a ... G_b-1 P_b|N.
Matrix15d smoothedCrossCovariance(const OxtsRunResult& run, int a, int b);

class SmoothedPosteriorGraph {
 public:
  // `run` must be smoothed (its covariances and gains) and outlive the graph; `keyframes` its
  // frames, strictly ascending, from run.first_estimated_frame on, at least one. Throws
  // std::invalid_argument otherwise, std::runtime_error when a smoothed covariance is not
  // positive definite.
  SmoothedPosteriorGraph(const OxtsRunResult& run, std::vector<int> keyframes);

  int numKeyframes() const { return static_cast<int>(keyframes_.size()); }
  // A loop between keyframes from < to (indices into keyframes): the measured pose of `to` in
  // `from`'s frame, residual as relativePoseResidual. Returns its index.
  int addLoop(const RelativePoseFactor& factor);
  void setLoopActive(int index, bool active) { loops_.at(index).active = active; }
  const RelativePoseFactor& loop(int index) const { return loops_.at(index); }
  int numLoops() const { return static_cast<int>(loops_.size()); }

  // Levenberg-Marquardt from the smoothed run (xi = 0) or the last solution.
  PoseGraphSummary optimize(const PoseGraphOptions& options = PoseGraphOptions());
  // Back to the smoothed run (xi = 0).
  void reset();

  // The squared Mahalanobis distance r^T W r of a loop at the current solution (no kernel).
  double loopChi2(int index) const;
  Pose3 keyframePose(int n) const;

  // The posterior of every frame of the run at the current solution: the states (all 15
  // components) and the pose covariances in OxtsRunResult::pose_covariances' convention
  // ([position error in the map frame, body-frame rotation error]). Frames before the first
  // keyframe and after the last are conditioned on the nearest keyframe alone, frames before
  // run.first_estimated_frame repeat that frame (as the run does). Throws std::runtime_error when
  // the Hessian cannot be factored or a covariance is not finite.
  void posterior(std::vector<NavState>* states, std::vector<PoseCovariance>* covariances) const;

 private:
  using Vector15d = Eigen::Matrix<double, 15, 1>;
  Vector15d xiOf(const Eigen::VectorXd& xi, int n) const { return xi.segment<15>(15 * n); }
  Pose3 pose(int n, const Eigen::VectorXd& xi) const;
  double cost(const Eigen::VectorXd& xi, double kernel_multiplier) const;
  void normalEquations(const Eigen::VectorXd& xi, double kernel_multiplier,
                       Eigen::SparseMatrix<double>* hessian, Eigen::VectorXd* gradient) const;
  PoseGraphSummary solve(const PoseGraphOptions& options, double kernel_multiplier);

  const OxtsRunResult& run_;
  std::vector<int> keyframes_;
  Eigen::SparseMatrix<double> prior_information_;  // Lambda, 15 per keyframe
  std::vector<RelativePoseFactor> loops_;
  Eigen::VectorXd xi_;
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
