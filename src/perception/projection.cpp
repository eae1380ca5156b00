#include "inekf_semantic_mapping/perception/projection.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace inekf_semantic_mapping {
namespace perception {

std::size_t ProjectedPoints::validCount() const {
  return static_cast<std::size_t>(std::count(valid.begin(), valid.end(), std::uint8_t{1}));
}

PointProjector::PointProjector(const Eigen::Matrix<double, 3, 4>& P_rect,
                               const Eigen::Matrix3d& R_rect, const Eigen::Isometry3d& T_cam0_velo,
                               int width, int height, double min_depth_m)
    : width_(width), height_(height), min_depth_m_(static_cast<float>(min_depth_m)) {
  if (width <= 0 || height <= 0) {
    throw std::invalid_argument("PointProjector: image size must be positive, got " +
                                std::to_string(width) + "x" + std::to_string(height));
  }
  Eigen::Matrix4d rectified_from_velo = Eigen::Matrix4d::Identity();
  rectified_from_velo.topLeftCorner<3, 3>() = R_rect * T_cam0_velo.linear();
  rectified_from_velo.topRightCorner<3, 1>() = R_rect * T_cam0_velo.translation();
  velo_to_pixel_ = P_rect * rectified_from_velo;
  if (!velo_to_pixel_.allFinite()) {
    throw std::invalid_argument("PointProjector: calibration contains non-finite values");
  }
  velo_to_pixel_f_ = velo_to_pixel_.cast<float>();
}

void PointProjector::project(const PointMatrixRef& points, ProjectedPoints* out) const {
  const Eigen::Index n = points.cols();
  // One 3x3 * 3xN product plus the translation column: homogeneous pixels of all points.
  const Eigen::Matrix3Xf homogeneous =
      (velo_to_pixel_f_.leftCols<3>() * points).colwise() + velo_to_pixel_f_.col(3);
  out->depth = homogeneous.row(2).transpose();
  out->u = (homogeneous.row(0).array() / homogeneous.row(2).array()).transpose();
  out->v = (homogeneous.row(1).array() / homogeneous.row(2).array()).transpose();
  out->valid.resize(static_cast<std::size_t>(n));
  const float width = static_cast<float>(width_);
  const float height = static_cast<float>(height_);
  for (Eigen::Index i = 0; i < n; ++i) {
    const float u = out->u[i];
    const float v = out->v[i];
    out->valid[i] = out->depth[i] > min_depth_m_ && u >= 0.f && u < width && v >= 0.f &&
                    v < height;  // NaN compares false: never valid
  }
}

void labelPointsFromImage(const ProjectedPoints& projected, const std::uint8_t* label_image,
                          int width, int height, std::size_t row_stride_bytes,
                          std::uint32_t unknown_label, std::vector<std::uint32_t>* labels) {
  const std::size_t n = projected.size();
  labels->assign(n, unknown_label);
  for (std::size_t i = 0; i < n; ++i) {
    if (!projected.valid[i]) continue;
    const int col = std::min(static_cast<int>(std::lround(projected.u[i])), width - 1);
    const int row = std::min(static_cast<int>(std::lround(projected.v[i])), height - 1);
    (*labels)[i] = label_image[static_cast<std::size_t>(row) * row_stride_bytes + col];
  }
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
