// Lidar-to-camera projection (KITTI convention): pixel ~ P_rect * [R_rect * (T_cam0_velo * x); 1].
// Vectorized over all points with Eigen (one matrix product, no per-point allocation). Eigen only:
// the calibration itself is read by the kitti library.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <vector>

namespace inekf_semantic_mapping {
namespace perception {

// 3 x N points with any column stride (e.g. the x y z rows of a 4 x N x y z intensity buffer).
using PointMatrixRef = Eigen::Ref<const Eigen::Matrix3Xf, 0, Eigen::OuterStride<>>;

// The pixel a coordinate falls in: pixel centres at integers (OpenCV's convention), so pixel k
// covers [k - 0.5, k + 0.5). NaN stays NaN (it compares false with any bound).
inline float nearestPixel(float coordinate) { return std::floor(coordinate + 0.5f); }

// Whether (u, v)'s pixel is in a width x height image: -0.5 <= u < width - 0.5, the same for v.
// False for NaN.
inline bool pixelInImage(float u, float v, int width, int height) {
  const float col = nearestPixel(u), row = nearestPixel(v);
  return col >= 0.f && col < static_cast<float>(width) && row >= 0.f &&
         row < static_cast<float>(height);
}

struct ProjectedPoints {
  Eigen::VectorXf u;      // pixel column (OpenCV convention: pixel centers at integers)
  Eigen::VectorXf v;      // pixel row
  Eigen::VectorXf depth;  // metres along the optical axis of the projection's camera
  // 1 where the point is in front of the camera (depth > min depth) and its pixel
  // (nearestPixel of u and v) is in the image: -0.5 <= u < width - 0.5, the same for v; 0
  // otherwise.
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

// The inverse of labelPointsFromImage: each valid point whose label is not skip_label writes
// its label at its pixel (the nearest pixel center, as labelPointsFromImage reads it) of a
// row-major width x height image, and the nearest such point (smallest depth) wins a pixel.
// `image` is resized to width * height and filled with none_label first. Returns the number of
// pixels that took a label. Throws std::invalid_argument when labels and points differ in number
// or the size is not positive.
std::size_t rasterizePointLabels(const ProjectedPoints& projected,
                                 const std::vector<std::uint32_t>& labels, int width, int height,
                                 std::uint32_t skip_label, std::uint32_t none_label,
                                 std::vector<std::uint32_t>* image);

// Lidar-camera parallax: the lidar sits elsewhere than the camera, so it measures surfaces the
// camera does not see (behind a pole, past a car's edge...), which then project onto the pixels
// of what hides them and would take its label. A depth buffer of the projected scan finds them:
// the nearest depth per cell of cell_width_px x cell_height_px pixels, the minimum of that over
// a window of cells (window_radius_x to each side, window_up rows of cells above and
// window_down below the point's cell); a point farther than
// local_min * (1 + relative_margin) + absolute_margin_m is taken as hidden from the camera.
// The window reaches up rather than down: down an image column a road comes nearer with every
// pixel, so a window reaching down would hide far road behind near road, while along a row and
// upwards the road only recedes.
struct OcclusionOptions {
  int cell_width_px = 4;
  int cell_height_px = 1;
  int window_radius_x = 2;  // cells
  int window_up = 6;        // cells
  int window_down = 0;      // cells
  float relative_margin = 0.1f;
  float absolute_margin_m = 0.3f;
};

// Sets labels[i] = unknown_label for the valid points of `projected` (projected into a width x
// height image) that the depth buffer finds hidden; `labels` holds one label per point (e.g.
// from labelPointsFromImage). rejected (optional): how many labels it changed from another
// value to unknown_label. Throws std::invalid_argument for sizes that do not match or options
// out of range.
void rejectOccludedPoints(const ProjectedPoints& projected, int width, int height,
                          const OcclusionOptions& options, std::uint32_t unknown_label,
                          std::vector<std::uint32_t>* labels, std::size_t* rejected = nullptr);

}  // namespace perception
}  // namespace inekf_semantic_mapping
