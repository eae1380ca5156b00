#include "inekf_semantic_mapping/estimation/pose_graph.h"

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

using Triplets = std::vector<Eigen::Triplet<double>>;

void checkNode(int node, int count, const char* what) {
  if (node < 0 || node >= count) {
    throw std::invalid_argument(std::string("PoseGraph: ") + what + " names node " +
                                std::to_string(node) + " of " + std::to_string(count));
  }
}

template <typename Matrix>
void checkInformation(const Matrix& information, const char* what) {
  if (!information.allFinite() ||
      (information - information.transpose()).norm() > 1e-6 * (1.0 + information.norm()) ||
      information.diagonal().minCoeff() < 0.0) {
    throw std::invalid_argument(std::string("PoseGraph: the information of a ") + what +
                                " factor is not finite and symmetric with a non-negative diagonal");
  }
}

// Adds J_a^T W J_b into the 6x6 block (a, b) of the Hessian (zeros too: the sparsity pattern
// then depends on the graph only, never on the values).
void addBlock(Triplets* triplets, int row_node, int col_node, const Matrix6d& block) {
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) {
      triplets->emplace_back(6 * row_node + r, 6 * col_node + c, block(r, c));
    }
  }
}

}  // namespace

Pose3 Pose3::inverse() const {
  Pose3 result;
  result.rotation = rotation.transpose();
  result.position = -(result.rotation * position);
  return result;
}

Pose3 Pose3::operator*(const Pose3& other) const {
  Pose3 result;
  result.rotation = rotation * other.rotation;
  result.position = rotation * other.position + position;
  return result;
}

RobustKernel robustKernelFromString(const std::string& text) {
  if (text == "none") return RobustKernel::kNone;
  if (text == "huber") return RobustKernel::kHuber;
  if (text == "cauchy") return RobustKernel::kCauchy;
  throw std::invalid_argument("unknown robust kernel '" + text +
                              "' (expected none, huber or cauchy)");
}

std::string toString(RobustKernel kernel) {
  switch (kernel) {
    case RobustKernel::kHuber:
      return "huber";
    case RobustKernel::kCauchy:
      return "cauchy";
    case RobustKernel::kNone:
      break;
  }
  return "none";
}

double robustCost(RobustKernel kernel, double scale, double squared) {
  const double c2 = scale * scale;
  switch (kernel) {
    case RobustKernel::kHuber:
      return squared <= c2 ? squared : 2.0 * scale * std::sqrt(squared) - c2;
    case RobustKernel::kCauchy:
      return c2 * std::log1p(squared / c2);
    case RobustKernel::kNone:
      break;
  }
  return squared;
}

double robustWeight(RobustKernel kernel, double scale, double squared) {
  const double c2 = scale * scale;
  switch (kernel) {
    case RobustKernel::kHuber:
      return squared <= c2 ? 1.0 : scale / std::sqrt(squared);
    case RobustKernel::kCauchy:
      return 1.0 / (1.0 + squared / c2);
    case RobustKernel::kNone:
      break;
  }
  return 1.0;
}

int PoseGraph::addNode(const Pose3& pose) {
  if (!pose.rotation.allFinite() || !pose.position.allFinite()) {
    throw std::invalid_argument("PoseGraph: a node pose is not finite");
  }
  nodes_.push_back(pose);
  return numNodes() - 1;
}

int PoseGraph::addRelative(const RelativePoseFactor& factor) {
  checkNode(factor.from, numNodes(), "a relative factor");
  checkNode(factor.to, numNodes(), "a relative factor");
  checkInformation(factor.information, "relative");
  if (!factor.measurement.rotation.allFinite() || !factor.measurement.position.allFinite() ||
      !(factor.kernel_scale > 0.0)) {
    throw std::invalid_argument(
        "PoseGraph: a relative factor's measurement or kernel scale is bad");
  }
  relatives_.push_back(factor);
  return numRelatives() - 1;
}

void PoseGraph::addPosition(const PositionFactor& factor) {
  checkNode(factor.node, numNodes(), "a position factor");
  checkInformation(factor.information, "position");
  if (!factor.position.allFinite()) {
    throw std::invalid_argument("PoseGraph: a position factor's position is not finite");
  }
  positions_.push_back(factor);
}

void PoseGraph::addPrior(const PosePriorFactor& factor) {
  checkNode(factor.node, numNodes(), "a prior factor");
  checkInformation(factor.information, "prior");
  priors_.push_back(factor);
}

Vector6d PoseGraph::relativeResidual(const Pose3& from, const Pose3& to, const Pose3& measurement,
                                     Matrix6d* jacobian_from, Matrix6d* jacobian_to) {
  const Eigen::Vector3d d = to.position - from.position;
  const Eigen::Vector3d local = from.rotation.transpose() * d;
  const Eigen::Matrix3d error =
      measurement.rotation.transpose() * from.rotation.transpose() * to.rotation;
  Vector6d r;
  r.head<3>() = local - measurement.position;
  r.tail<3>() = lie::logSO3(error);
  if (jacobian_from || jacobian_to) {
    const Eigen::Matrix3d jr_inv = lie::rightJacobianInverseSO3(r.tail<3>());
    if (jacobian_from) {
      jacobian_from->setZero();
      jacobian_from->block<3, 3>(0, 0) = -from.rotation.transpose();
      jacobian_from->block<3, 3>(0, 3) = lie::hat(local);
      jacobian_from->block<3, 3>(3, 3) = -jr_inv * to.rotation.transpose() * from.rotation;
    }
    if (jacobian_to) {
      jacobian_to->setZero();
      jacobian_to->block<3, 3>(0, 0) = from.rotation.transpose();
      jacobian_to->block<3, 3>(3, 3) = jr_inv;
    }
  }
  return r;
}

Pose3 PoseGraph::retract(const Pose3& pose, const Vector6d& delta) {
  Pose3 result;
  result.rotation = lie::normalizeRotation(pose.rotation * lie::expSO3(delta.tail<3>()));
  result.position = pose.position + delta.head<3>();
  return result;
}

Vector6d PoseGraph::relativeResidual(int index) const {
  const RelativePoseFactor& f = relatives_.at(index);
  return relativeResidual(nodes_[f.from], nodes_[f.to], f.measurement);
}

double PoseGraph::relativeChi2(int index) const {
  const Vector6d r = relativeResidual(index);
  return r.dot(relatives_.at(index).information * r);
}

double PoseGraph::cost(const std::vector<Pose3>& nodes, double kernel_multiplier) const {
  double total = 0.0;
  for (const RelativePoseFactor& f : relatives_) {
    if (!f.active) continue;
    const Vector6d r = relativeResidual(nodes[f.from], nodes[f.to], f.measurement);
    total += robustCost(f.kernel, kernel_multiplier * f.kernel_scale, r.dot(f.information * r));
  }
  for (const PositionFactor& f : positions_) {
    const Eigen::Vector3d r = nodes[f.node].position - f.position;
    total += r.dot(f.information * r);
  }
  for (const PosePriorFactor& f : priors_) {
    Vector6d r;
    r.head<3>() = nodes[f.node].position - f.pose.position;
    r.tail<3>() = lie::logSO3(f.pose.rotation.transpose() * nodes[f.node].rotation);
    total += r.dot(f.information * r);
  }
  return 0.5 * total;
}

PoseGraphSummary PoseGraph::optimize(const PoseGraphOptions& options) {
  PoseGraphSummary summary;
  summary.initial_cost = summary.final_cost = cost(nodes_, 1.0);
  if (numNodes() == 0) {
    summary.converged = true;
    return summary;
  }
  // Graduated kernels: start with every robust factor inside its quadratic region, then shrink
  // the scales to the configured ones.
  double multiplier = 1.0;
  if (options.graduated_factor > 1.0) {
    for (const RelativePoseFactor& f : relatives_) {
      if (!f.active || f.kernel == RobustKernel::kNone) continue;
      const Vector6d r = relativeResidual(nodes_[f.from], nodes_[f.to], f.measurement);
      multiplier = std::max(multiplier, std::sqrt(r.dot(f.information * r)) / f.kernel_scale);
    }
    multiplier = std::min(multiplier, options.graduated_max_multiplier);
  }
  while (true) {
    const PoseGraphSummary stage = solve(options, multiplier);
    summary.iterations += stage.iterations;
    summary.converged = stage.converged;
    if (multiplier <= 1.0) break;
    multiplier = std::max(1.0, multiplier / options.graduated_factor);
  }
  summary.final_cost = cost(nodes_, 1.0);
  return summary;
}

void PoseGraph::normalEquations(double kernel_multiplier, Eigen::SparseMatrix<double>* hessian,
                                Eigen::VectorXd* gradient_out) const {
  const int n = numNodes();
  // Normal equations H dx = -g of the (reweighted) linearization at the current poses.
  Triplets triplets;
  triplets.reserve(static_cast<std::size_t>(relatives_.size()) * 144 + 36 * n);
  Eigen::VectorXd gradient = Eigen::VectorXd::Zero(6 * n);
  for (const RelativePoseFactor& f : relatives_) {
    if (!f.active) continue;
    Matrix6d ja, jb;
    const Vector6d r = relativeResidual(nodes_[f.from], nodes_[f.to], f.measurement, &ja, &jb);
    const double w =
        robustWeight(f.kernel, kernel_multiplier * f.kernel_scale, r.dot(f.information * r));
    const Matrix6d wi = w * f.information;
    addBlock(&triplets, f.from, f.from, ja.transpose() * wi * ja);
    addBlock(&triplets, f.to, f.to, jb.transpose() * wi * jb);
    addBlock(&triplets, f.from, f.to, ja.transpose() * wi * jb);
    addBlock(&triplets, f.to, f.from, jb.transpose() * wi * ja);
    gradient.segment<6>(6 * f.from) += ja.transpose() * wi * r;
    gradient.segment<6>(6 * f.to) += jb.transpose() * wi * r;
  }
  for (const PositionFactor& f : positions_) {
    Matrix6d block = Matrix6d::Zero();
    block.topLeftCorner<3, 3>() = f.information;
    addBlock(&triplets, f.node, f.node, block);
    gradient.segment<3>(6 * f.node) += f.information * (nodes_[f.node].position - f.position);
  }
  for (const PosePriorFactor& f : priors_) {
    Vector6d r;
    r.head<3>() = nodes_[f.node].position - f.pose.position;
    r.tail<3>() = lie::logSO3(f.pose.rotation.transpose() * nodes_[f.node].rotation);
    Matrix6d j = Matrix6d::Identity();
    j.bottomRightCorner<3, 3>() = lie::rightJacobianInverseSO3(r.tail<3>());
    addBlock(&triplets, f.node, f.node, j.transpose() * f.information * j);
    gradient.segment<6>(6 * f.node) += j.transpose() * f.information * r;
  }
  for (int i = 0; i < n; ++i) addBlock(&triplets, i, i, Matrix6d::Zero());  // every diagonal
  hessian->resize(6 * n, 6 * n);
  hessian->setFromTriplets(triplets.begin(), triplets.end());
  if (gradient_out) *gradient_out = std::move(gradient);
}

std::vector<Matrix6d> PoseGraph::marginalCovariances(const std::vector<int>& nodes) const {
  std::vector<int> wanted = nodes;
  if (wanted.empty()) {
    for (int i = 0; i < numNodes(); ++i) wanted.push_back(i);
  }
  for (int node : wanted) checkNode(node, numNodes(), "a marginal covariance request");
  if (wanted.empty()) return {};

  // The Hessian at the current poses with the kernels at their configured scales (the IRLS
  // weights of the solution optimize() converged to).
  Eigen::SparseMatrix<double> hessian;
  normalEquations(1.0, &hessian, nullptr);
  const int size = static_cast<int>(hessian.rows());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(hessian);
  // P H P^T = L D L^T. Eigen only reports an exactly zero pivot; a pivot that is not clearly
  // positive against the diagonal it came from is a direction the factors do not observe (the
  // inverse would be rounding noise, or negative).
  const auto fail = [](const std::string& why) {
    return std::runtime_error(
        "PoseGraph: the Hessian cannot be factored for the marginal covariances (" + why +
        "; is the graph anchored, is every direction of every node observed?)");
  };
  if (solver.info() != Eigen::Success) throw fail("zero pivot");
  const Eigen::VectorXd d = solver.vectorD();
  const auto& indices = solver.permutationP().indices();
  Eigen::VectorXd permuted_diagonal(size);
  for (int i = 0; i < size; ++i) permuted_diagonal(indices(i)) = hessian.coeff(i, i);
  constexpr double kRelativePivot = 1e-12;
  for (int i = 0; i < size; ++i) {
    if (!std::isfinite(d(i)) || !(d(i) > kRelativePivot * permuted_diagonal(i))) {
      throw fail("pivot " + std::to_string(d(i)) + " for a diagonal of " +
                 std::to_string(permuted_diagonal(i)));
    }
  }

  // Takahashi's recursion for Z = (L D L^T)^-1 on the pattern of L (the strictly lower part as
  // stored by Eigen, each column's rows ascending), columns from the last to the first:
  //   Z(j, i) = -sum_{k in S_i} L(k, i) Z(k, j)  for j in S_i,
  //   Z(i, i) = 1 / d_i - sum_{k in S_i} L(k, i) Z(k, i),
  // with S_i the rows of column i below the diagonal. S_i is a clique of the filled graph, so
  // every Z(k, j) needed is on the pattern and already computed. Cost: sum |S_i|^2 log |S_i|.
  const auto& l = solver.matrixL().nestedExpression();
  const int* outer = l.outerIndexPtr();
  const int* rows = l.innerIndexPtr();
  const double* values = l.valuePtr();
  std::vector<double> z_lower(static_cast<std::size_t>(outer[size]), 0.0);
  std::vector<double> z_diagonal(size, 0.0);
  const auto z = [&](int r, int c) -> double {
    if (r == c) return z_diagonal[r];
    if (r < c) std::swap(r, c);
    const int* begin = rows + outer[c];
    const int* end = rows + outer[c + 1];
    const int* found = std::lower_bound(begin, end, r);
    if (found == end || *found != r) {
      throw std::logic_error("PoseGraph: the selected inverse left its pattern");
    }
    return z_lower[found - rows];
  };
  for (int i = size - 1; i >= 0; --i) {
    const int begin = outer[i], end = outer[i + 1];
    double diagonal = 1.0 / d(i);
    for (int p = begin; p < end; ++p) {
      const int j = rows[p];
      double sum = 0.0;
      for (int q = begin; q < end; ++q) sum += values[q] * z(rows[q], j);
      z_lower[p] = -sum;
      diagonal -= values[p] * z_lower[p];
    }
    z_diagonal[i] = diagonal;
  }

  // H^-1 (a, b) = Z(P a, P b).
  std::vector<Matrix6d> marginals;
  marginals.reserve(wanted.size());
  for (int node : wanted) {
    Matrix6d block;
    for (int r = 0; r < 6; ++r) {
      for (int c = 0; c <= r; ++c) {
        block(r, c) = block(c, r) = z(indices(6 * node + r), indices(6 * node + c));
      }
    }
    if (!block.allFinite() || !(block.diagonal().minCoeff() > 0.0)) {
      throw fail("a marginal covariance is not finite and positive");
    }
    marginals.push_back(block);
  }
  return marginals;
}

PoseGraphSummary PoseGraph::solve(const PoseGraphOptions& options, double kernel_multiplier) {
  PoseGraphSummary summary;
  const int n = numNodes();
  double lambda = options.initial_lambda;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver;
  bool pattern_known = false;
  double current = cost(nodes_, kernel_multiplier);
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    summary.iterations = iteration + 1;
    Eigen::SparseMatrix<double> hessian;
    Eigen::VectorXd gradient;
    normalEquations(kernel_multiplier, &hessian, &gradient);
    const Eigen::VectorXd diagonal = hessian.diagonal().cwiseMax(1e-9);
    if (!pattern_known) {  // the pattern stays: the same factors, all blocks stored
      solver.analyzePattern(hessian);
      pattern_known = true;
    }
    // LM: raise the damping until a step lowers the cost.
    bool improved = false;
    for (int attempt = 0; attempt < 12 && !improved; ++attempt) {
      Eigen::SparseMatrix<double> damped = hessian;
      for (int i = 0; i < 6 * n; ++i) damped.coeffRef(i, i) += lambda * diagonal(i);
      solver.factorize(damped);
      if (solver.info() != Eigen::Success) {
        throw std::runtime_error(
            "PoseGraph: the normal equations are singular (is the graph anchored?)");
      }
      const Eigen::VectorXd step = solver.solve(-gradient);
      std::vector<Pose3> candidate(nodes_);
      for (int i = 0; i < n; ++i) candidate[i] = retract(nodes_[i], step.segment<6>(6 * i));
      const double next = cost(candidate, kernel_multiplier);
      if (std::isfinite(next) && next < current) {
        const double decrease = current - next;
        nodes_ = std::move(candidate);
        current = next;
        lambda = std::max(lambda * 0.2, 1e-12);
        improved = true;
        if (decrease <= options.relative_cost_tolerance * (1.0 + current)) {
          summary.converged = true;
        }
      } else {
        lambda *= 10.0;
      }
    }
    if (!improved) summary.converged = true;  // no step lowers the cost: a minimum
    if (summary.converged) break;
  }
  summary.final_cost = current;
  return summary;
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
