#include "inekf_semantic_mapping/estimation/smoother.h"

#include <Eigen/Cholesky>
#include <stdexcept>
#include <string>

#include "inekf_semantic_mapping/lie/se23.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

using Vector15d = Eigen::Matrix<double, 15, 1>;

lie::ExtendedPose extendedPose(const NavState& state) {
  lie::ExtendedPose pose;
  pose.rotation = state.rotation;
  pose.velocity = state.velocity_map;
  pose.position = state.position_map;
  return pose;
}

}  // namespace

Vector15d leftInvariantDifference(const NavState& a, const NavState& b) {
  Vector15d xi;
  xi.head<9>() = lie::logSE23(extendedPose(a).inverse() * extendedPose(b));
  xi.segment<3>(9) = b.gyro_bias - a.gyro_bias;
  xi.segment<3>(12) = b.accel_bias - a.accel_bias;
  return xi;
}

NavState applyLeftInvariant(const NavState& a, const Vector15d& xi) {
  const lie::ExtendedPose pose = extendedPose(a) * lie::expSE23(xi.head<9>());
  NavState result = a;
  result.rotation = lie::normalizeRotation(pose.rotation);
  result.velocity_map = pose.velocity;
  result.position_map = pose.position;
  result.gyro_bias = a.gyro_bias + xi.segment<3>(9);
  result.accel_bias = a.accel_bias + xi.segment<3>(12);
  return result;
}

std::vector<SmoothedEpoch> smoothLeftInvariant(const std::vector<ForwardEpoch>& epochs) {
  std::vector<SmoothedEpoch> smoothed(epochs.size());
  if (epochs.empty()) return smoothed;
  const std::size_t last = epochs.size() - 1;
  smoothed[last] = {epochs[last].filtered, epochs[last].filtered_covariance};
  for (std::size_t k = last; k-- > 0;) {
    const ForwardEpoch& now = epochs[k];
    const ForwardEpoch& next = epochs[k + 1];
    if (!next.has_step) {  // a segment ends at k: its filtered estimate is its smoothed one
      smoothed[k] = {now.filtered, now.filtered_covariance};
      continue;
    }
    // G^T = P_k+1|k^-1 Phi P_k|k (P symmetric), by Cholesky: no explicit inverse.
    const Eigen::LLT<Matrix15d> predicted(next.predicted_covariance);
    if (predicted.info() != Eigen::Success) {
      throw std::invalid_argument("smoothLeftInvariant: the predicted covariance of epoch " +
                                  std::to_string(k + 1) + " is not positive definite");
    }
    const Matrix15d gain = predicted.solve(next.transition * now.filtered_covariance).transpose();
    const Vector15d correction =
        gain * leftInvariantDifference(next.predicted, smoothed[k + 1].state);
    SmoothedEpoch& out = smoothed[k];
    out.state = applyLeftInvariant(now.filtered, correction);
    out.covariance =
        now.filtered_covariance +
        gain * (smoothed[k + 1].covariance - next.predicted_covariance) * gain.transpose();
    out.covariance = 0.5 * (out.covariance + out.covariance.transpose());
    out.gain = gain;
    if (!out.state.rotation.allFinite() || !out.state.position_map.allFinite() ||
        !out.covariance.allFinite()) {
      out = {now.filtered, now.filtered_covariance, Matrix15d::Zero()};  // never let a NaN out
    }
  }
  return smoothed;
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
