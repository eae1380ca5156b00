// The camera a label image was taken with, and a view of the label image itself: what the
// mapping session needs to give lidar points the classes of the pixels they fall on.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>

namespace inekf_semantic_mapping {
namespace mapping {

// A rectified camera: pixel ~ P [R_rect (T_camera_sensor x); 1] in a width x height image.
struct CameraModel {
  Eigen::Matrix<double, 3, 4> P = Eigen::Matrix<double, 3, 4>::Zero();
  Eigen::Matrix3d R_rect = Eigen::Matrix3d::Identity();
  Eigen::Isometry3d T_camera_sensor = Eigen::Isometry3d::Identity();
  int width = 0;
  int height = 0;
};

// A row-major 8-bit label image (label ids of the config's class set), not owned.
struct LabelImageView {
  const std::uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  std::size_t step = 0;  // bytes per row
};

}  // namespace mapping
}  // namespace inekf_semantic_mapping
