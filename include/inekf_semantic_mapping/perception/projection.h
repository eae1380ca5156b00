// Lidar-to-camera projection (KITTI convention): pixel ~ P_rect * [R_rect * (T_cam0_velo * x); 1].
// Vectorized over all points with Eigen (one matrix product, no per-point allocation). Eigen only:
// the calibration itself is read by the kitti library.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

namespace inekf_semantic_mapping {
namespace perception {

// 3 x N points with any column stride (e.g. the x y z rows of a 4 x N x y z intensity buffer).
using PointMatrixRef = Eigen::Ref<const Eigen::Matrix3Xf, 0, Eigen::OuterStride<>>;

struct ProjectedPoints {
  Eigen::VectorXf u;      // pixel column (OpenCV convention: pixel centers at integers)
  Eigen::VectorXf v;      // pixel row
  Eigen::VectorXf depth;  // metres along the optical axis of the projection's camera
  // 1 where the point is in front of the camera (depth > min depth) and 0 <= u < width,
  // 0 <= v < height; 0 otherwise.
  std::vector<std::uint8_t> valid;
  std::size_t size() const { return valid.size(); }
  std::size_t validCount() const;
};

class PointProjector {
 public:
  // pixel = P_rect * [R_rect * (T_cam0_velo * x); 1], the image is width x height pixels.
  PointProjector(const Eigen::Matrix<double, 3, 4>& P_rect, const Eigen::Matrix3d& R_rect,
                 const Eigen::Isometry3d& T_cam0_velo, int width, int height,
                 double min_depth_m = 0.1);

  // Projects N points (sensor frame); `out` is resized (reusing its storage).
  void project(const PointMatrixRef& points, ProjectedPoints* out) const;

  // The combined 3 x 4 matrix P_rect * [R_rect T_cam0_velo]: homogeneous pixel of a point.
  const Eigen::Matrix<double, 3, 4>& velodyneToPixel() const { return velo_to_pixel_; }
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  Eigen::Matrix<double, 3, 4> velo_to_pixel_;
  Eigen::Matrix<float, 3, 4> velo_to_pixel_f_;
  int width_;
  int height_;
  float min_depth_m_;
};

// Looks up each valid point's pixel (nearest pixel center) in a row-major 8-bit label image of
// the projector's size; invalid points get `unknown_label`. `labels` is resized to N.
void labelPointsFromImage(const ProjectedPoints& projected, const std::uint8_t* label_image,
                          int width, int height, std::size_t row_stride_bytes,
                          std::uint32_t unknown_label, std::vector<std::uint32_t>* labels);

}  // namespace perception
}  // namespace inekf_semantic_mapping
