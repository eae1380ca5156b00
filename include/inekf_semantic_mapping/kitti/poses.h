// KITTI odometry pose files: one pose per line, the 12 numbers of the row-major 3x4 [R | t]
// (odometry ground truth, inekf_offline's --output-kitti, the synthetic drives' ground truth).
// The one reader and the one writer of the format in the package.
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace kitti {

// Throws KittiFormatError naming the file (and line) when it cannot be opened, a line has other
// than 12 numbers, a number is not finite, or the 3x3 part is not a rotation (within 1e-3).
// Blank lines are skipped.
std::vector<Eigen::Isometry3d> readKittiPoses(const std::string& path);

// One line of the format, newline included, with 13 significant digits (1e-12 relative: a pose
// read back is the pose written, to far below a millimetre at any KITTI distance).
std::string kittiPoseLine(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation);
inline std::string kittiPoseLine(const Eigen::Isometry3d& pose) {
  return kittiPoseLine(pose.linear(), pose.translation());
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
