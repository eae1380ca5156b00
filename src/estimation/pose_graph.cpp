#include "inekf_semantic_mapping/estimation/pose_graph.h"

#include <cmath>
#include <stdexcept>

#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {

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

Pose3 poseOf(const NavState& state) {
  Pose3 pose;
  pose.rotation = state.rotation;
  pose.position = state.position_map;
  return pose;
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

Vector6d relativePoseResidual(const Pose3& from, const Pose3& to, const Pose3& measurement,
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

}  // namespace estimation
}  // namespace inekf_semantic_mapping
