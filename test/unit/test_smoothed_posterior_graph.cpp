// The loop closure's back end (estimation/smoothed_posterior_graph.h) on a linear-Gaussian
// Markov chain whose joint covariance is known in closed form: without loops the posterior is
// the smoothed run itself (states and covariances of every frame, keyframes or not); with a loop
// the solution is stationary for the exact cost (dense prior over the keyframes plus the loop,
// its Jacobian by central differences), every other frame's mean is the dense Gaussian
// regression on the keyframes, and every frame's covariance is the dense Laplace posterior
// (prior information plus J^T W J) carried to the new estimate. Bad inputs are clear errors.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>
#include <vector>

#include "inekf_semantic_mapping/estimation/smoothed_posterior_graph.h"
#include "inekf_semantic_mapping/estimation/smoother.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

using Vector15d = Eigen::Matrix<double, 15, 1>;
constexpr int kFrames = 40;
constexpr int kFirstEstimated = 2;

// d[dp (map), dphi (body)] / d xi of the pose of `state` exp(xi), by central differences: the
// pose-covariance convention of the run ([position error in the map frame, R_true = R Exp(dphi)]).
Eigen::Matrix<double, 6, 15> poseMap(const NavState& state, const Vector15d& xi) {
  const NavState at = applyLeftInvariant(state, xi);
  Eigen::Matrix<double, 6, 15> e;
  for (int c = 0; c < 15; ++c) {
    const double h = 1e-6;
    const NavState plus = applyLeftInvariant(state, xi + h * Vector15d::Unit(c));
    const NavState minus = applyLeftInvariant(state, xi - h * Vector15d::Unit(c));
    e.block<3, 1>(0, c) = (plus.position_map - minus.position_map) / (2 * h);
    e.block<3, 1>(3, c) = (lie::logSO3(at.rotation.transpose() * plus.rotation) -
                           lie::logSO3(at.rotation.transpose() * minus.rotation)) /
                          (2 * h);
  }
  return e;
}

// xi_k+1 = F_k xi_k + w_k from frame kFirstEstimated on, with errors of a plausible size per
// component (rad, m/s, m, rad/s, m/s^2); P_k and the gains G_k = P_k F_k^T P_k+1^-1 (so that
// Cov(xi_a, xi_b) = G_a ... G_b-1 P_b); `joint` the dense covariance of all estimated frames.
struct ChainRun {
  OxtsRunResult run;
  Eigen::MatrixXd joint;
};

ChainRun makeChainRun() {
  std::mt19937 rng(11);
  std::normal_distribution<double> normal(0.0, 1.0);
  Vector15d scale;
  scale << 0.01, 0.01, 0.02, 0.1, 0.1, 0.1, 1.0, 1.0, 2.0, 1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2;
  const Matrix15d s = scale.asDiagonal();
  ChainRun chain;
  OxtsRunResult& run = chain.run;
  run.smoothed = true;
  run.first_estimated_frame = kFirstEstimated;
  run.states.resize(kFrames);
  run.smoothed_covariances.resize(kFrames);
  run.smoother_gains.assign(kFrames, Matrix15d::Zero());
  run.pose_covariances.resize(kFrames);
  std::vector<Matrix15d> transitions(kFrames, Matrix15d::Identity());
  for (int k = kFirstEstimated; k < kFrames; ++k) {
    NavState& state = run.states[k];
    state.stamp_s = 0.1 * k;
    state.rotation = lie::expSO3(Eigen::Vector3d(0.01, -0.02, 0.03 * k));
    state.velocity_map = Eigen::Vector3d(10.0, 0.3 * k, 0.1);
    state.position_map = Eigen::Vector3d(1.0 * k, 0.05 * k * k, 0.2);
    state.gyro_bias = Eigen::Vector3d(1e-4, 0, 0);
    if (k == kFirstEstimated) {
      run.smoothed_covariances[k] = s * s;
      continue;
    }
    Matrix15d m;
    for (int i = 0; i < 225; ++i) m.data()[i] = normal(rng) / 15.0;
    transitions[k - 1] = Matrix15d::Identity() + s * m * s.inverse();
    const Matrix15d& f = transitions[k - 1];
    const Matrix15d& previous = run.smoothed_covariances[k - 1];
    run.smoothed_covariances[k] = f * previous * f.transpose() + 0.01 * s * s;
    run.smoothed_covariances[k] =
        0.5 * (run.smoothed_covariances[k] + run.smoothed_covariances[k].transpose().eval());
    run.smoother_gains[k - 1] = previous * f.transpose() * run.smoothed_covariances[k].inverse();
  }
  for (int k = 0; k < kFirstEstimated; ++k) {
    run.states[k] = run.states[kFirstEstimated];
    run.smoothed_covariances[k] = run.smoothed_covariances[kFirstEstimated];
  }
  for (int k = 0; k < kFrames; ++k) {
    // At the estimate itself: dp = R rho, dphi = phi.
    Eigen::Matrix<double, 6, 15> e = Eigen::Matrix<double, 6, 15>::Zero();
    e.block<3, 3>(0, 6) = run.states[k].rotation;
    e.block<3, 3>(3, 0) = Eigen::Matrix3d::Identity();
    run.pose_covariances[k] = e * run.smoothed_covariances[k] * e.transpose();
  }
  const int n = kFrames - kFirstEstimated;
  chain.joint.resize(15 * n, 15 * n);
  for (int j = 0; j < n; ++j) {
    Matrix15d product = Matrix15d::Identity();  // F_k-1 ... F_j
    for (int k = j; k < n; ++k) {
      if (k > j) product = transitions[kFirstEstimated + k - 1] * product;
      const Matrix15d cross = run.smoothed_covariances[kFirstEstimated + j] * product.transpose();
      chain.joint.block<15, 15>(15 * j, 15 * k) = cross;
      chain.joint.block<15, 15>(15 * k, 15 * j) = cross.transpose();
    }
  }
  return chain;
}

// Keyframes from frame 5 to 34: frames before the first and after the last are covered too.
std::vector<int> keyframes() { return {5, 8, 9, 13, 20, 27, 31, 34}; }

TEST(SmoothedPosteriorGraph, WithoutLoopsThePosteriorIsTheSmoothedRun) {
  const ChainRun chain = makeChainRun();
  SmoothedPosteriorGraph graph(chain.run, keyframes());
  EXPECT_NEAR(graph.optimize().final_cost, 0.0, 1e-20);
  std::vector<NavState> states;
  std::vector<PoseCovariance> covariances;
  graph.posterior(&states, &covariances);
  ASSERT_EQ(states.size(), chain.run.states.size());
  for (int k = 0; k < kFrames; ++k) {
    EXPECT_LT((states[k].position_map - chain.run.states[k].position_map).norm(), 1e-12) << k;
    EXPECT_LT((covariances[k] - chain.run.pose_covariances[k]).norm(),
              1e-8 * chain.run.pose_covariances[k].norm())
        << "frame " << k;
  }
}

TEST(SmoothedPosteriorGraph, ALoopGivesTheDenseGaussianPosterior) {
  const ChainRun chain = makeChainRun();
  const OxtsRunResult& run = chain.run;
  const std::vector<int> keys = keyframes();
  SmoothedPosteriorGraph graph(run, keys);
  // A loop from keyframe 1 to 6 that disagrees with the smoothed relative pose by 0.5 m and
  // 1.1 deg, tight enough to move both ends well beyond their own sigmas.
  RelativePoseFactor loop;
  loop.from = 1;
  loop.to = 6;
  loop.measurement = poseOf(run.states[keys[1]]).inverse() * poseOf(run.states[keys[6]]);
  loop.measurement.position += Eigen::Vector3d(0.5, -0.2, 0.1);
  loop.measurement.rotation = loop.measurement.rotation * lie::expSO3({0.0, 0.005, 0.02});
  Vector6d sigmas;
  sigmas << 0.05, 0.05, 0.05, 0.002, 0.002, 0.002;
  loop.information = sigmas.cwiseAbs2().cwiseInverse().asDiagonal();
  graph.addLoop(loop);
  const double before = graph.loopChi2(0);
  graph.optimize();
  EXPECT_LT(graph.loopChi2(0), 0.05 * before);
  std::vector<NavState> states;
  std::vector<PoseCovariance> covariances;
  graph.posterior(&states, &covariances);

  const int n = kFrames - kFirstEstimated;
  Eigen::VectorXd xi(15 * n);
  for (int k = kFirstEstimated; k < kFrames; ++k) {
    xi.segment<15>(15 * (k - kFirstEstimated)) = leftInvariantDifference(run.states[k], states[k]);
  }
  const int m = static_cast<int>(keys.size());
  std::vector<int> rows;  // the keyframes' rows in the joint
  for (int key : keys) {
    for (int i = 0; i < 15; ++i) rows.push_back(15 * (key - kFirstEstimated) + i);
  }
  Eigen::MatrixXd key_cov(15 * m, 15 * m), all_key(15 * n, 15 * m);
  Eigen::VectorXd xi_keys(15 * m);
  for (int r = 0; r < 15 * m; ++r) {
    xi_keys(r) = xi(rows[r]);
    for (int c = 0; c < 15 * m; ++c) key_cov(r, c) = chain.joint(rows[r], rows[c]);
    for (int a = 0; a < 15 * n; ++a) all_key(a, r) = chain.joint(a, rows[r]);
  }

  // The loop's residual as a function of the keyframes' xi, its Jacobian by central differences.
  const auto residual = [&](const Eigen::VectorXd& x) -> Vector6d {
    const Pose3 from = poseOf(applyLeftInvariant(run.states[keys[1]], x.segment<15>(15)));
    const Pose3 to = poseOf(applyLeftInvariant(run.states[keys[6]], x.segment<15>(15 * 6)));
    return relativePoseResidual(from, to, loop.measurement);
  };
  Eigen::MatrixXd jacobian(6, 15 * m);
  for (int c = 0; c < 15 * m; ++c) {
    const double h = 1e-6;
    Eigen::VectorXd plus = xi_keys, minus = xi_keys;
    plus(c) += h;
    minus(c) -= h;
    jacobian.col(c) = (residual(plus) - residual(minus)) / (2 * h);
  }
  const Eigen::MatrixXd w = loop.information;
  // Stationary for 1/2 xi^T Sigma^-1 xi + 1/2 r^T W r.
  const Eigen::VectorXd prior_gradient = key_cov.ldlt().solve(xi_keys);
  const Eigen::VectorXd loop_gradient = jacobian.transpose() * w * residual(xi_keys);
  EXPECT_GT(xi_keys.segment<3>(15 + 6).norm(), 0.05);  // the loop moved keyframe 1
  EXPECT_LT((prior_gradient + loop_gradient).norm(), 1e-5 * loop_gradient.norm());

  // Every frame's mean: the regression on the keyframes.
  const Eigen::VectorXd expected_xi = all_key * key_cov.ldlt().solve(xi_keys);
  EXPECT_LT((expected_xi - xi).norm(), 1e-6 * xi.norm());

  // Every frame's covariance: the Laplace posterior (Sigma^-1 + J^T W J)^-1 over all frames,
  // carried to the new estimate.
  Eigen::MatrixXd jacobian_all = Eigen::MatrixXd::Zero(6, 15 * n);
  for (int c = 0; c < 15 * m; ++c) jacobian_all.col(rows[c]) = jacobian.col(c);
  const Eigen::MatrixXd posterior =
      (chain.joint.inverse() + jacobian_all.transpose() * w * jacobian_all).inverse();
  double worst = 0.0;
  for (int k = kFirstEstimated; k < kFrames; ++k) {
    const int i = 15 * (k - kFirstEstimated);
    const Eigen::Matrix<double, 6, 15> e = poseMap(run.states[k], xi.segment<15>(i));
    const Matrix6d expected = e * posterior.block<15, 15>(i, i) * e.transpose();
    worst = std::max(worst, (covariances[k] - expected).norm() / expected.norm());
    // The loop shrinks the covariance of the frames it binds.
    if (k == keys[1]) {
      EXPECT_LT(covariances[k].trace(), 0.9 * run.pose_covariances[k].trace());
    }
  }
  EXPECT_LT(worst, 1e-5);
}

TEST(SmoothedPosteriorGraph, BadInputsAreClearErrors) {
  const ChainRun chain = makeChainRun();
  EXPECT_THROW(SmoothedPosteriorGraph(chain.run, {}), std::invalid_argument);
  EXPECT_THROW(SmoothedPosteriorGraph(chain.run, {5, 5}), std::invalid_argument);
  EXPECT_THROW(SmoothedPosteriorGraph(chain.run, {1, 5}), std::invalid_argument);  // not estimated
  EXPECT_THROW(SmoothedPosteriorGraph(chain.run, {5, kFrames}), std::invalid_argument);
  OxtsRunResult unsmoothed = chain.run;
  unsmoothed.smoothed = false;
  EXPECT_THROW(SmoothedPosteriorGraph(unsmoothed, {5}), std::invalid_argument);
  SmoothedPosteriorGraph graph(chain.run, keyframes());
  RelativePoseFactor loop;
  loop.from = 0;
  loop.to = 8;  // 8 keyframes: indices 0..7
  EXPECT_THROW(graph.addLoop(loop), std::invalid_argument);
  loop.to = 1;
  loop.information(0, 0) = std::nan("");
  EXPECT_THROW(graph.addLoop(loop), std::invalid_argument);
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
