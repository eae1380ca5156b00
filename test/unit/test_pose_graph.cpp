// The SE(3) pose graph of the loop closure: the relative residual's Jacobians against central
// differences, an exact graph stays put, a loop pulls a drifted chain back onto the truth, and a
// false loop is defeated by the Cauchy kernel (and shows a large residual) where without a
// kernel it bends the chain.
#include <gtest/gtest.h>

#include <cmath>
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

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
