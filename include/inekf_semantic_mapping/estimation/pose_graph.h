// A small pose graph on SE(3) solved by Levenberg-Marquardt with Eigen's sparse Cholesky (no
// Ceres): the back end of the loop closure (estimation/loop_closure.h). ROS-free, Eigen only.
//
// Nodes are poses T = (R, p) (body -> map). The update of a node is decoupled: R <- R Exp(dphi)
// (body-frame small angle), p <- p + dp (map frame); the tangent order is [dp, dphi].
//
// Factors (residual order [position (3), rotation (3)], their information in that order):
//  - relative (odometry, loop): r = [R_i^T (p_j - p_i) - t_ij ; Log(R_ij^T R_i^T R_j)] for the
//    measured pose of j in i's frame (R_ij, t_ij): the relative translation in i's frame, the
//    relative rotation error as a small angle on the measured one's right;
//  - position (GPS): r = p_i - z;
//  - pose prior: r = [p_i - p0 ; Log(R0^T R_i)].
// Relative factors may carry a robust kernel on their squared Mahalanobis distance s = r^T W r
// (c = kernel_scale, in sigmas): Huber rho(s) = s (s <= c^2), 2 c sqrt(s) - c^2 beyond;
// Cauchy rho(s) = c^2 log(1 + s / c^2). Solved by iteratively reweighted Gauss-Newton inside LM,
// with graduated kernel scales (see PoseGraphOptions).
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <string>
#include <vector>

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

struct PositionFactor {
  int node = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Matrix3d information = Eigen::Matrix3d::Identity();
};

struct PosePriorFactor {
  int node = 0;
  Pose3 pose;
  Matrix6d information = Matrix6d::Identity();
};

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

class PoseGraph {
 public:
  int addNode(const Pose3& pose);
  int addRelative(const RelativePoseFactor& factor);  // returns its index
  void addPosition(const PositionFactor& factor);
  void addPrior(const PosePriorFactor& factor);
  // Throws std::invalid_argument for an unknown node, a non-finite value or a factor whose
  // information is not symmetric positive semi-definite in its diagonal.

  void setRelativeActive(int index, bool active) { relatives_.at(index).active = active; }

  // Levenberg-Marquardt from the current poses. Throws std::runtime_error when the normal
  // equations cannot be factored (an unconstrained graph: give it a prior or GPS factors).
  PoseGraphSummary optimize(const PoseGraphOptions& options = PoseGraphOptions());

  // Marginal covariances of the nodes at the current poses (after optimize(): at the solution):
  // the 6x6 diagonal blocks of the inverse of the Gauss-Newton Hessian J^T W J, in the nodes'
  // tangent order [dp (map frame), dphi (body frame, R_true = R Exp(dphi))]. Robust factors
  // enter with their IRLS weight at the current residual (the configured kernel scale), inactive
  // factors not at all. One sparse LDL^T factorization and the selected inverse on its pattern
  // (Takahashi's recursion): no dense inverse, cost independent of how many nodes are asked
  // for. `nodes` empty: every node, in order. Throws std::invalid_argument for an unknown node
  // and std::runtime_error when the Hessian cannot be factored (a pivot not clearly positive: an
  // unanchored graph or a direction no factor observes).
  std::vector<Matrix6d> marginalCovariances(const std::vector<int>& nodes = {}) const;

  int numNodes() const { return static_cast<int>(nodes_.size()); }
  const Pose3& node(int index) const { return nodes_.at(index); }
  const RelativePoseFactor& relative(int index) const { return relatives_.at(index); }
  int numRelatives() const { return static_cast<int>(relatives_.size()); }

  // The residual of relative factor `index` at the current poses, and its squared Mahalanobis
  // distance r^T W r (without kernel).
  Vector6d relativeResidual(int index) const;
  double relativeChi2(int index) const;

  // The residual of a relative measurement and its Jacobians with respect to the two nodes'
  // updates [dp, dphi] (exposed for the test of the derivatives).
  static Vector6d relativeResidual(const Pose3& from, const Pose3& to, const Pose3& measurement,
                                   Matrix6d* jacobian_from = nullptr,
                                   Matrix6d* jacobian_to = nullptr);
  // The node update: R Exp(dphi), p + dp.
  static Pose3 retract(const Pose3& pose, const Vector6d& delta);

 private:
  double cost(const std::vector<Pose3>& nodes, double kernel_multiplier) const;
  PoseGraphSummary solve(const PoseGraphOptions& options, double kernel_multiplier);
  // The reweighted Gauss-Newton normal equations H dx = -g at the current poses (every node's
  // diagonal block stored, so the pattern depends on the graph only). gradient may be null.
  void normalEquations(double kernel_multiplier, Eigen::SparseMatrix<double>* hessian,
                       Eigen::VectorXd* gradient) const;

  std::vector<Pose3> nodes_;
  std::vector<RelativePoseFactor> relatives_;
  std::vector<PositionFactor> positions_;
  std::vector<PosePriorFactor> priors_;
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
