// The pieces of the loop closure's graph: the relative-pose residual's Jacobians against central
// differences, the robust kernels (the IRLS weight is the cost's derivative), and the selected
// inverse (Takahashi) against the dense inverse of a block-sparse matrix shaped like the graph's
// Hessian, and its clear error for a singular one.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/SparseCore>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/estimation/pose_graph.h"
#include "inekf_semantic_mapping/estimation/selected_inverse.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

Pose3 makePose(const Eigen::Vector3d& phi, const Eigen::Vector3d& p) {
  Pose3 pose;
  pose.rotation = lie::expSO3(phi);
  pose.position = p;
  return pose;
}

// The update the Jacobians are taken for: R Exp(dphi), p + dp.
Pose3 retract(const Pose3& pose, const Vector6d& delta) {
  Pose3 result;
  result.rotation = pose.rotation * lie::expSO3(delta.tail<3>());
  result.position = pose.position + delta.head<3>();
  return result;
}

TEST(RelativePose, JacobiansMatchCentralDifferences) {
  const Pose3 a = makePose({0.1, -0.2, 1.3}, {3.0, -1.0, 0.5});
  const Pose3 b = makePose({-0.05, 0.1, 1.9}, {5.0, 2.0, 0.2});
  const Pose3 z = makePose({0.02, 0.01, 0.55}, {2.5, 1.5, -0.1});
  Matrix6d ja, jb;
  relativePoseResidual(a, b, z, &ja, &jb);
  const double h = 1e-6;
  for (int i = 0; i < 6; ++i) {
    Vector6d d = Vector6d::Zero();
    d(i) = h;
    const Vector6d na =
        (relativePoseResidual(retract(a, d), b, z) - relativePoseResidual(retract(a, -d), b, z)) /
        (2 * h);
    const Vector6d nb =
        (relativePoseResidual(a, retract(b, d), z) - relativePoseResidual(a, retract(b, -d), z)) /
        (2 * h);
    EXPECT_LT((na - ja.col(i)).norm(), 1e-6) << "from, column " << i;
    EXPECT_LT((nb - jb.col(i)).norm(), 1e-6) << "to, column " << i;
  }
  // The exact measurement leaves no residual.
  EXPECT_LT(relativePoseResidual(a, b, a.inverse() * b).norm(), 1e-12);
}

// IRLS is right only if the weight is d rho / d s: checked by differences for both kernels, on
// both sides of Huber's corner.
TEST(RobustKernels, WeightIsTheCostsDerivativeAndNamesParse) {
  for (RobustKernel kernel : {RobustKernel::kNone, RobustKernel::kHuber, RobustKernel::kCauchy}) {
    for (double s : {0.5, 3.0, 50.0}) {
      const double h = 1e-6;
      const double numeric =
          (robustCost(kernel, 2.0, s + h) - robustCost(kernel, 2.0, s - h)) / (2 * h);
      EXPECT_NEAR(robustWeight(kernel, 2.0, s), numeric, 1e-6) << toString(kernel) << " " << s;
    }
    EXPECT_EQ(robustKernelFromString(toString(kernel)), kernel);
  }
  EXPECT_LT(robustCost(RobustKernel::kCauchy, 2.0, 1e4), 0.01 * 1e4);  // an outlier counts little
  EXPECT_THROW(robustKernelFromString("tukey"), std::invalid_argument);
}

// A block-tridiagonal chain of 6x6 blocks plus two far "loop" blocks, symmetric positive definite.
Eigen::SparseMatrix<double> chainWithLoops(int nodes, std::mt19937* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  const int n = 6 * nodes;
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(n, n);
  const auto couple = [&](int a, int b, double strength) {
    Eigen::MatrixXd j(6, n);
    j.setZero();
    for (int r = 0; r < 6; ++r) {
      for (int c = 0; c < 6; ++c) {
        j(r, 6 * a + c) = normal(*rng);
        j(r, 6 * b + c) = normal(*rng);
      }
    }
    dense += strength * j.transpose() * j;
  };
  for (int k = 0; k + 1 < nodes; ++k) couple(k, k + 1, 4.0);
  couple(0, nodes - 1, 50.0);
  couple(2, nodes - 3, 0.5);
  dense += 0.01 * Eigen::MatrixXd::Identity(n, n);
  return dense.sparseView();
}

TEST(SelectedInverse, EqualsTheDenseInverseOnThePattern) {
  std::mt19937 rng(7);
  const Eigen::SparseMatrix<double> matrix = chainWithLoops(12, &rng);
  const Eigen::MatrixXd dense_inverse = Eigen::MatrixXd(matrix).inverse();
  const SelectedInverse inverse(matrix, "test");
  double worst = 0.0;
  int checked = 0;
  for (int col = 0; col < matrix.outerSize(); ++col) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(matrix, col); it; ++it) {
      worst = std::max(
          worst, std::abs(inverse(static_cast<int>(it.row()), col) - dense_inverse(it.row(), col)));
      ++checked;
    }
  }
  EXPECT_GT(checked, 12 * 36 * 3);
  EXPECT_LT(worst, 1e-9 * dense_inverse.cwiseAbs().maxCoeff());
  const Eigen::MatrixXd block = inverse.block(0, 66, 6, 6);  // the first and the last node
  EXPECT_LT((block - dense_inverse.block(0, 66, 6, 6)).norm(), 1e-9 * block.norm());
}

// A direction nothing observes (a node without any factor): a clear error naming the owner.
TEST(SelectedInverse, ASingularMatrixIsAClearError) {
  std::mt19937 rng(3);
  Eigen::MatrixXd dense = Eigen::MatrixXd(chainWithLoops(4, &rng));
  dense.row(7).setZero();
  dense.col(7).setZero();
  try {
    SelectedInverse inverse(Eigen::SparseMatrix<double>(dense.sparseView()), "TheOwner");
    FAIL() << "no error for a singular matrix";
  } catch (const std::runtime_error& error) {
    const std::string what = error.what();
    EXPECT_NE(what.find("TheOwner"), std::string::npos) << what;
    EXPECT_NE(what.find("cannot be factored"), std::string::npos) << what;
  }
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
