// The SE(3) pose graph of the loop closure: the relative residual's Jacobians against central
// differences, an exact graph stays put, a loop pulls a drifted chain back onto the truth, and a
// false loop is defeated by the Cauchy kernel (and shows a large residual) where without a
// kernel it bends the chain; the marginal covariances equal the dense inverse of the Hessian
// (built here from numerical Jacobians) and grow linearly along an anchored random-walk chain.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <cmath>
#include <functional>
#include <random>
#include <vector>

#include "inekf_semantic_mapping/estimation/pose_graph.h"
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

TEST(PoseGraph, RelativeJacobiansMatchCentralDifferences) {
  const Pose3 a = makePose({0.1, -0.2, 1.3}, {3.0, -1.0, 0.5});
  const Pose3 b = makePose({-0.05, 0.1, 1.9}, {5.0, 2.0, 0.2});
  const Pose3 z = makePose({0.02, 0.01, 0.55}, {2.5, 1.5, -0.1});
  Matrix6d ja, jb;
  PoseGraph::relativeResidual(a, b, z, &ja, &jb);
  const double h = 1e-6;
  for (int i = 0; i < 6; ++i) {
    Vector6d d = Vector6d::Zero();
    d(i) = h;
    const Vector6d na = (PoseGraph::relativeResidual(PoseGraph::retract(a, d), b, z) -
                         PoseGraph::relativeResidual(PoseGraph::retract(a, -d), b, z)) /
                        (2 * h);
    const Vector6d nb = (PoseGraph::relativeResidual(a, PoseGraph::retract(b, d), z) -
                         PoseGraph::relativeResidual(a, PoseGraph::retract(b, -d), z)) /
                        (2 * h);
    EXPECT_LT((na - ja.col(i)).norm(), 1e-6) << "from, column " << i;
    EXPECT_LT((nb - jb.col(i)).norm(), 1e-6) << "to, column " << i;
  }
}

// A square-ish loop of 40 poses; odometry from the truth with a yaw bias (drift), GPS on the
// first 10 poses only, and a loop from the last pose to the first.
struct Scenario {
  std::vector<Pose3> truth, drifted;
  std::vector<Pose3> odometry;  // measured relative poses
};

Scenario makeScenario() {
  Scenario s;
  const int n = 40;
  for (int k = 0; k < n; ++k) {
    const double angle = 2 * M_PI * k / n;
    s.truth.push_back(
        makePose({0, 0, angle + M_PI / 2},
                 {20 * std::cos(angle), 20 * std::sin(angle), 0.1 * std::sin(angle)}));
  }
  s.drifted.push_back(s.truth[0]);
  for (int k = 0; k + 1 < n; ++k) {
    Pose3 rel = s.truth[k].inverse() * s.truth[k + 1];
    rel.rotation = rel.rotation * lie::expSO3({0, 0, 0.01});  // 0.57 deg per step
    s.odometry.push_back(rel);
    s.drifted.push_back(s.drifted.back() * rel);
  }
  return s;
}

PoseGraph makeGraph(const Scenario& s) {
  PoseGraph graph;
  for (const Pose3& p : s.drifted) graph.addNode(p);
  for (int k = 0; k + 1 < static_cast<int>(s.drifted.size()); ++k) {
    RelativePoseFactor f;
    f.from = k;
    f.to = k + 1;
    f.measurement = s.odometry[k];
    const double sm = 0.05, sr = 0.01;
    f.information = (Vector6d() << 1 / (sm * sm), 1 / (sm * sm), 1 / (sm * sm), 1 / (sr * sr),
                     1 / (sr * sr), 1 / (sr * sr))
                        .finished()
                        .asDiagonal();
    graph.addRelative(f);
  }
  for (int k = 0; k < 10; ++k) {
    PositionFactor f;
    f.node = k;
    f.position = s.truth[k].position;
    f.information = Eigen::Matrix3d::Identity() / (0.1 * 0.1);
    graph.addPosition(f);
  }
  return graph;
}

double worstError(const PoseGraph& graph, const Scenario& s) {
  double worst = 0;
  for (int k = 0; k < graph.numNodes(); ++k) {
    worst = std::max(worst, (graph.node(k).position - s.truth[k].position).norm());
  }
  return worst;
}

RelativePoseFactor loopFactor(const Scenario& s, const Pose3& measurement, RobustKernel kernel) {
  RelativePoseFactor f;
  f.from = 0;
  f.to = static_cast<int>(s.truth.size()) - 1;
  f.measurement = measurement;
  f.information = (Vector6d() << 100, 100, 100, 1e4, 1e4, 1e4).finished().asDiagonal();
  f.kernel = kernel;
  f.kernel_scale = 2.0;
  return f;
}

TEST(PoseGraph, ALoopPullsTheDriftedChainBack) {
  const Scenario s = makeScenario();
  PoseGraph without = makeGraph(s);
  without.optimize();
  const double drift = worstError(without, s);
  PoseGraph with = makeGraph(s);
  const int loop = with.addRelative(
      loopFactor(s, s.truth.front().inverse() * s.truth.back(), RobustKernel::kCauchy));
  const PoseGraphSummary summary = with.optimize();
  const double closed = worstError(with, s);
  std::printf("[ MEASURED ] worst position error without loop %.2f m, with %.2f m (%d iter)\n",
              drift, closed, summary.iterations);
  EXPECT_GT(drift, 5.0);
  EXPECT_LT(closed, 0.25 * drift);
  EXPECT_LT(with.relativeChi2(loop), 16.81);
  EXPECT_LT(summary.final_cost, summary.initial_cost);
}

TEST(PoseGraph, AFalseLoopIsDefeatedByTheCauchyKernel) {
  const Scenario s = makeScenario();
  PoseGraph reference = makeGraph(s);
  reference.addRelative(
      loopFactor(s, s.truth.front().inverse() * s.truth.back(), RobustKernel::kCauchy));
  reference.optimize();
  // A second, false loop between poses 5 and 25 (opposite sides of the circle) claiming they are
  // 1 m apart: a registration that matched the wrong place.
  const auto add_false = [&](PoseGraph* graph, RobustKernel kernel) {
    RelativePoseFactor f = loopFactor(s, makePose({0, 0, 0.1}, {1.0, 0, 0}), kernel);
    f.from = 5;
    f.to = 25;
    return graph->addRelative(f);
  };
  PoseGraph robust = makeGraph(s);
  robust.addRelative(
      loopFactor(s, s.truth.front().inverse() * s.truth.back(), RobustKernel::kCauchy));
  const int robust_false = add_false(&robust, RobustKernel::kCauchy);
  robust.optimize();
  PoseGraph plain = makeGraph(s);
  plain.addRelative(loopFactor(s, s.truth.front().inverse() * s.truth.back(), RobustKernel::kNone));
  add_false(&plain, RobustKernel::kNone);
  plain.optimize();
  std::printf(
      "[ MEASURED ] worst error: true loop only %.2f m, + false loop cauchy %.2f m, "
      "no kernel %.2f m; false loop chi2 %.0f\n",
      worstError(reference, s), worstError(robust, s), worstError(plain, s),
      robust.relativeChi2(robust_false));
  EXPECT_LT(worstError(robust, s), worstError(reference, s) + 0.5);
  EXPECT_GT(worstError(plain, s), 5.0);
  EXPECT_GT(robust.relativeChi2(robust_false), 1000.0);  // flagged by the residual check
}

TEST(PoseGraph, RejectsBadFactorsAndKernelNames) {
  PoseGraph graph;
  graph.addNode(Pose3());
  RelativePoseFactor f;
  f.to = 3;
  EXPECT_THROW(graph.addRelative(f), std::invalid_argument);
  EXPECT_THROW(robustKernelFromString("tukey"), std::invalid_argument);
  EXPECT_EQ(robustKernelFromString("huber"), RobustKernel::kHuber);
}

Matrix6d diagonalInformation(double sigma_m, double sigma_rad) {
  const double m = 1 / (sigma_m * sigma_m), r = 1 / (sigma_rad * sigma_rad);
  return (Vector6d() << m, m, m, r, r, r).finished().asDiagonal();
}

// The Gauss-Newton Hessian J^T W J of a graph at its poses, built independently of PoseGraph's
// own: each factor's whitened residual (IRLS weight held at its value at the poses) is
// differentiated numerically along every node's retraction.
struct DenseFactor {
  std::vector<int> nodes;
  std::function<Eigen::VectorXd(const std::vector<Pose3>&)> whitened;
};

Eigen::MatrixXd numericalHessian(const std::vector<Pose3>& poses,
                                 const std::vector<DenseFactor>& factors) {
  const int n = static_cast<int>(poses.size());
  Eigen::MatrixXd h = Eigen::MatrixXd::Zero(6 * n, 6 * n);
  const double step = 1e-6;
  for (const DenseFactor& factor : factors) {
    const int m = static_cast<int>(factor.whitened(poses).size());
    Eigen::MatrixXd j = Eigen::MatrixXd::Zero(m, 6 * n);
    for (int node : factor.nodes) {
      for (int i = 0; i < 6; ++i) {
        Vector6d d = Vector6d::Zero();
        d(i) = step;
        std::vector<Pose3> plus = poses, minus = poses;
        plus[node] = PoseGraph::retract(poses[node], d);
        minus[node] = PoseGraph::retract(poses[node], -d);
        j.col(6 * node + i) = (factor.whitened(plus) - factor.whitened(minus)) / (2 * step);
      }
    }
    h += j.transpose() * j;
  }
  return h;
}

// Five poses around a bend: odometry, GPS on three, a weak prior on the first, a Cauchy loop
// from the last to the first that disagrees with the odometry (so its IRLS weight at the
// solution is well below 1) and a wildly wrong loop switched off.
TEST(PoseGraphMarginals, EqualTheDenseInverseOfTheHessian) {
  std::vector<Pose3> truth;
  for (int k = 0; k < 5; ++k) {
    truth.push_back(makePose({0.02 * k, -0.01 * k, 0.4 * k}, {3.0 * k, 1.0 * k * k, 0.1 * k}));
  }
  PoseGraph graph;
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 1.0);
  const auto jitter = [&](const Pose3& pose, double m, double r) {
    return PoseGraph::retract(pose, (Vector6d() << m * noise(rng), m * noise(rng), m * noise(rng),
                                     r * noise(rng), r * noise(rng), r * noise(rng))
                                        .finished());
  };
  for (const Pose3& pose : truth) graph.addNode(jitter(pose, 0.5, 0.05));
  std::vector<DenseFactor> dense;
  const auto whiten = [](const Eigen::MatrixXd& information) {
    return Eigen::MatrixXd(Eigen::LLT<Eigen::MatrixXd>(information).matrixU());
  };
  for (int k = 0; k + 1 < 5; ++k) {
    RelativePoseFactor f;
    f.from = k;
    f.to = k + 1;
    f.measurement = jitter(truth[k].inverse() * truth[k + 1], 0.05, 0.01);
    f.information = diagonalInformation(0.05, 0.01);
    f.information(0, 4) = f.information(4, 0) = 50.0;  // a correlated one
    graph.addRelative(f);
  }
  RelativePoseFactor loop;
  loop.from = 4;
  loop.to = 0;
  loop.measurement = truth[4].inverse() * truth[0] * makePose({0, 0, 0.02}, {0.3, -0.2, 0});
  loop.information = diagonalInformation(0.1, 0.01);
  loop.kernel = RobustKernel::kCauchy;
  loop.kernel_scale = 1.0;
  const int loop_index = graph.addRelative(loop);
  RelativePoseFactor wrong = loop;
  wrong.from = 1;
  wrong.to = 3;
  wrong.measurement = makePose({0, 0, 1.0}, {10, 0, 0});
  const int wrong_index = graph.addRelative(wrong);
  graph.setRelativeActive(wrong_index, false);
  for (int k : {0, 2, 3}) {
    PositionFactor f;
    f.node = k;
    f.position = truth[k].position + Eigen::Vector3d(0.2, -0.1, 0.3);
    f.information = Eigen::Vector3d(1.0, 2.0, 0.25).asDiagonal();
    graph.addPosition(f);
  }
  PosePriorFactor prior;
  prior.node = 0;
  prior.pose = jitter(truth[0], 1.0, 0.1);
  prior.information = diagonalInformation(3.0, 0.2);
  graph.addPrior(prior);
  graph.optimize();

  for (int index = 0; index < graph.numRelatives(); ++index) {
    const RelativePoseFactor& f = graph.relative(index);
    if (!f.active) continue;
    const double weight = robustWeight(f.kernel, f.kernel_scale, graph.relativeChi2(index));
    if (index == loop_index) {
      std::printf("[ MEASURED ] the loop's IRLS weight at the solution: %.3f\n", weight);
      EXPECT_LT(weight, 0.9);  // the kernel matters in this Hessian
    }
    const Eigen::MatrixXd u = whiten(weight * f.information);
    dense.push_back({{f.from, f.to}, [f, u](const std::vector<Pose3>& x) -> Eigen::VectorXd {
                       return u * PoseGraph::relativeResidual(x[f.from], x[f.to], f.measurement);
                     }});
  }
  for (int k : {0, 2, 3}) {
    const Eigen::Vector3d z = truth[k].position + Eigen::Vector3d(0.2, -0.1, 0.3);
    const Eigen::MatrixXd u = whiten(Eigen::Vector3d(1.0, 2.0, 0.25).asDiagonal().toDenseMatrix());
    dense.push_back({{k}, [k, z, u](const std::vector<Pose3>& x) -> Eigen::VectorXd {
                       return u * (x[k].position - z);
                     }});
  }
  {
    const Eigen::MatrixXd u = whiten(prior.information);
    dense.push_back({{0}, [prior, u](const std::vector<Pose3>& x) -> Eigen::VectorXd {
                       Vector6d r;
                       r.head<3>() = x[0].position - prior.pose.position;
                       r.tail<3>() = lie::logSO3(prior.pose.rotation.transpose() * x[0].rotation);
                       return u * r;
                     }});
  }
  std::vector<Pose3> solution;
  for (int k = 0; k < graph.numNodes(); ++k) solution.push_back(graph.node(k));
  const Eigen::MatrixXd inverse = numericalHessian(solution, dense).inverse();

  const std::vector<Matrix6d> all = graph.marginalCovariances();
  ASSERT_EQ(all.size(), 5u);
  for (int k = 0; k < 5; ++k) {
    const Matrix6d expected = inverse.block<6, 6>(6 * k, 6 * k);
    EXPECT_LT((all[k] - expected).norm(), 1e-5 * expected.norm()) << "node " << k << "\n"
                                                                  << all[k] << "\nexpected\n"
                                                                  << expected;
    EXPECT_LT((all[k] - all[k].transpose()).norm(), 1e-12 * all[k].norm());
  }
  // A chosen subset, in the order asked for.
  const std::vector<Matrix6d> some = graph.marginalCovariances({3, 1});
  ASSERT_EQ(some.size(), 2u);
  EXPECT_EQ(some[0], all[3]);
  EXPECT_EQ(some[1], all[1]);
  EXPECT_THROW(graph.marginalCovariances({5}), std::invalid_argument);
}

// A random walk anchored at one end: every node at the origin with the identity rotation, the
// odometry measuring "no motion" with a full covariance C, a prior P0 on node 0. The Jacobians
// are then -I and I, and node k's marginal is exactly P0 + k C. (Its speed on 2000 nodes:
// bench_inekf BM_PoseGraphMarginals.)
TEST(PoseGraphMarginals, GrowLinearlyAlongAnAnchoredChain) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 1.0);
  Matrix6d a;
  for (int i = 0; i < 36; ++i) a(i / 6, i % 6) = noise(rng);
  const Matrix6d odometry = 0.01 * (a * a.transpose() + Matrix6d::Identity());
  const Matrix6d anchor =
      (Vector6d() << 0.04, 0.09, 0.01, 1e-4, 4e-4, 1e-4).finished().asDiagonal();
  const int nodes = 600;
  PoseGraph graph;
  for (int k = 0; k < nodes; ++k) graph.addNode(Pose3());
  for (int k = 0; k + 1 < nodes; ++k) {
    RelativePoseFactor f;
    f.from = k;
    f.to = k + 1;
    f.information = odometry.inverse();
    graph.addRelative(f);
  }
  PosePriorFactor prior;
  prior.information = anchor.inverse();
  graph.addPrior(prior);
  const std::vector<Matrix6d> marginals = graph.marginalCovariances();
  ASSERT_EQ(static_cast<int>(marginals.size()), nodes);
  for (int k : {0, 1, 2, 10, 300, nodes - 1}) {
    const Matrix6d expected = anchor + k * odometry;
    EXPECT_LT((marginals[k] - expected).norm(), 1e-8 * expected.norm())
        << "node " << k << "\n"
        << marginals[k] << "\nexpected\n"
        << expected;
  }
}

// Without the prior nothing fixes where the chain is: the Hessian is singular.
TEST(PoseGraphMarginals, AnUnanchoredGraphIsAClearError) {
  PoseGraph graph;
  for (int k = 0; k < 4; ++k) graph.addNode(makePose({0, 0, 0.1 * k}, {1.0 * k, 0, 0}));
  for (int k = 0; k + 1 < 4; ++k) {
    RelativePoseFactor f;
    f.from = k;
    f.to = k + 1;
    f.measurement = graph.node(k).inverse() * graph.node(k + 1);
    f.information = diagonalInformation(0.1, 0.01);
    graph.addRelative(f);
  }
  try {
    graph.marginalCovariances();
    ADD_FAILURE() << "no error for an unanchored graph";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("cannot be factored"), std::string::npos)
        << error.what();
  }
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
