#include "inekf_semantic_mapping/perception/projection.h"

#include <algorithm>
#include <cmath>
#include <limits>
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
  for (Eigen::Index i = 0; i < n; ++i) {
    out->valid[i] =  // NaN compares false: never valid
        out->depth[i] > min_depth_m_ && pixelInImage(out->u[i], out->v[i], width_, height_);
  }
}

void labelPointsFromImage(const ProjectedPoints& projected, const std::uint8_t* label_image,
                          int width, int height, std::size_t row_stride_bytes,
                          std::uint32_t unknown_label, std::vector<std::uint32_t>* labels) {
  const std::size_t n = projected.size();
  labels->assign(n, unknown_label);
  for (std::size_t i = 0; i < n; ++i) {
    if (!projected.valid[i]) continue;
    const int col = std::min(static_cast<int>(nearestPixel(projected.u[i])), width - 1);
    const int row = std::min(static_cast<int>(nearestPixel(projected.v[i])), height - 1);
    (*labels)[i] = label_image[static_cast<std::size_t>(row) * row_stride_bytes + col];
  }
}

std::size_t rasterizePointLabels(const ProjectedPoints& projected,
                                 const std::vector<std::uint32_t>& labels, int width, int height,
                                 std::uint32_t skip_label, std::uint32_t none_label,
                                 std::vector<std::uint32_t>* image) {
  if (labels.size() != projected.size()) {
    throw std::invalid_argument("rasterizePointLabels: " + std::to_string(labels.size()) +
                                " labels for " + std::to_string(projected.size()) + " points");
  }
  if (width <= 0 || height <= 0) {
    throw std::invalid_argument("rasterizePointLabels: image size " + std::to_string(width) + "x" +
                                std::to_string(height) + " is not positive");
  }
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  image->assign(pixels, none_label);
  std::vector<float> nearest(pixels, std::numeric_limits<float>::infinity());
  std::size_t written = 0;
  for (std::size_t i = 0; i < projected.size(); ++i) {
    if (!projected.valid[i] || labels[i] == skip_label) continue;
    const int col = std::min(static_cast<int>(nearestPixel(projected.u[i])), width - 1);
    const int row = std::min(static_cast<int>(nearestPixel(projected.v[i])), height - 1);
    const std::size_t pixel = static_cast<std::size_t>(row) * width + col;
    if (!(projected.depth[i] < nearest[pixel])) continue;
    if (nearest[pixel] == std::numeric_limits<float>::infinity()) ++written;
    nearest[pixel] = projected.depth[i];
    (*image)[pixel] = labels[i];
  }
  return written;
}

void rejectOccludedPoints(const ProjectedPoints& projected, int width, int height,
                          const OcclusionOptions& options, std::uint32_t unknown_label,
                          std::vector<std::uint32_t>* labels, std::size_t* rejected) {
  if (rejected) *rejected = 0;
  if (labels->size() != projected.size()) {
    throw std::invalid_argument("rejectOccludedPoints: " + std::to_string(labels->size()) +
                                " labels for " + std::to_string(projected.size()) + " points");
  }
  if (width <= 0 || height <= 0 || options.cell_width_px <= 0 || options.cell_height_px <= 0 ||
      options.window_radius_x < 0 || options.window_up < 0 || options.window_down < 0 ||
      !(options.relative_margin >= 0.f) || !(options.absolute_margin_m >= 0.f)) {
    throw std::invalid_argument(
        "rejectOccludedPoints: image size and cell size must be > 0, window and margins >= 0");
  }
  const int grid_width = (width + options.cell_width_px - 1) / options.cell_width_px;
  const int grid_height = (height + options.cell_height_px - 1) / options.cell_height_px;
  const float kFar = std::numeric_limits<float>::infinity();
  std::vector<float> nearest(static_cast<std::size_t>(grid_width) * grid_height, kFar);
  const auto cellOf = [&](std::size_t i) {
    const int col = std::clamp(
        static_cast<int>(nearestPixel(projected.u[i])) / options.cell_width_px, 0, grid_width - 1);
    const int row =
        std::clamp(static_cast<int>(nearestPixel(projected.v[i])) / options.cell_height_px, 0,
                   grid_height - 1);
    return static_cast<std::size_t>(row) * grid_width + col;
  };
  const std::size_t n = projected.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (!projected.valid[i]) continue;
    float& cell = nearest[cellOf(i)];
    cell = std::min(cell, projected.depth[i]);
  }
  // Window minimum, separable: along rows, then along columns.
  const int rx = options.window_radius_x;
  const int up = options.window_up;
  const int down = options.window_down;
  std::vector<float> row_min(nearest.size(), kFar);
  for (int y = 0; y < grid_height; ++y) {
    for (int x = 0; x < grid_width; ++x) {
      float m = kFar;
      for (int dx = std::max(0, x - rx); dx <= std::min(grid_width - 1, x + rx); ++dx)
        m = std::min(m, nearest[static_cast<std::size_t>(y) * grid_width + dx]);
      row_min[static_cast<std::size_t>(y) * grid_width + x] = m;
    }
  }
  std::vector<float>& local_min = nearest;  // reused: nearest is not needed any more
  for (int y = 0; y < grid_height; ++y) {
    for (int x = 0; x < grid_width; ++x) {
      float m = kFar;
      for (int dy = std::max(0, y - up); dy <= std::min(grid_height - 1, y + down); ++dy)
        m = std::min(m, row_min[static_cast<std::size_t>(dy) * grid_width + x]);
      local_min[static_cast<std::size_t>(y) * grid_width + x] = m;
    }
  }
  std::size_t changed = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!projected.valid[i]) continue;
    const float limit =
        local_min[cellOf(i)] * (1.f + options.relative_margin) + options.absolute_margin_m;
    if (projected.depth[i] > limit) {
      if ((*labels)[i] != unknown_label) ++changed;
      (*labels)[i] = unknown_label;
    }
  }
  if (rejected) *rejected = changed;
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
