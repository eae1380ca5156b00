#include "inekf_semantic_mapping/mapping/map_label_images.h"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/perception/projection.h"

namespace inekf_semantic_mapping {
namespace mapping {

OwnedLabelImage mapLabelImage(const SemanticOcTree& tree, const Eigen::Matrix3Xf& points_sensor,
                              const Eigen::Isometry3d& T_map_sensor, const CameraModel& camera,
                              const MapLabelImageOptions& options, MapLabelImageStats* stats) {
  if (camera.width <= 0 || camera.height <= 0) {
    throw std::invalid_argument("mapLabelImage: camera image size " + std::to_string(camera.width) +
                                "x" + std::to_string(camera.height) + " is not positive");
  }
  if (options.none_label > 255) {
    throw std::invalid_argument("mapLabelImage: none_label " + std::to_string(options.none_label) +
                                " does not fit an 8-bit label image");
  }
  const perception::PointProjector projector(camera.P, camera.R_rect, camera.T_camera_sensor,
                                             camera.width, camera.height);
  perception::ProjectedPoints projected;
  projector.project(points_sensor, &projected);

  // The map's class at every point in view; points the camera cannot see take none.
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> labels(projected.size(), kNone);
  const Eigen::Matrix3Xf points_map = (T_map_sensor.cast<float>() * points_sensor).eval();
  const int num_classes = static_cast<int>(tree.classSet().size());
  MapLabelImageStats local;
  for (std::size_t i = 0; i < projected.size(); ++i) {
    if (!projected.valid[i]) continue;
    ++local.points_in_view;
    const Eigen::Vector3f& p = points_map.col(static_cast<Eigen::Index>(i));
    const SemanticOcTreeNode* node = tree.search(p.x(), p.y(), p.z());
    if (!node || !tree.isNodeOccupied(node)) continue;
    const ClassIndex index = node->mostLikelyClass();
    if (index == kNoClass || static_cast<int>(index) >= num_classes) continue;
    if (options.min_class_probability > 0.0 &&
        node->classProbability(index, tree.fusionModel(), num_classes) <
            options.min_class_probability) {
      continue;
    }
    labels[i] = tree.classSet().info(index).label_id;
  }
  std::size_t hidden = 0;
  perception::rejectOccludedPoints(projected, camera.width, camera.height,
                                   perception::OcclusionOptions(), kNone, &labels, &hidden);
  local.hidden = hidden;

  for (std::uint32_t& label : labels) {
    if (label > 255) label = kNone;  // an 8-bit image cannot hold it
  }
  std::vector<std::uint32_t> pixels;
  local.labelled = perception::rasterizePointLabels(projected, labels, camera.width, camera.height,
                                                    kNone, options.none_label, &pixels);
  OwnedLabelImage image;
  image.width = camera.width;
  image.height = camera.height;
  image.pixels.resize(pixels.size());
  std::transform(pixels.begin(), pixels.end(), image.pixels.begin(),
                 [](std::uint32_t label) { return static_cast<std::uint8_t>(label); });
  if (stats) *stats = local;
  return image;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
