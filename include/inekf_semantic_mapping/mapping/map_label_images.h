// The fused map's classes seen from a frame's camera: label images for training the camera on
// frames nobody labelled. The map holds many views of each voxel and the lidar's geometry
// checks, so its classes at a frame's lidar points are better labels for that frame's image
// than the network's own labels of it.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>

#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace inekf_semantic_mapping {
namespace mapping {

struct MapLabelImageOptions {
  std::uint32_t none_label = 0;  // written where no labelled point lands (Cityscapes: unlabeled)
  // A voxel whose most likely class has a posterior below this labels nothing (0: any class).
  double min_class_probability = 0.0;
};

struct MapLabelImageStats {
  std::size_t points_in_view = 0;  // lidar points projected into the image, in front of it
  std::size_t hidden = 0;          // of those, hidden from the camera (the occlusion test)
  std::size_t labelled = 0;        // pixels that took a class
};

// Each lidar point of the frame (points_sensor, 3 x N, at T_map_sensor) takes the most likely
// class of its voxel in `tree` (none where the voxel is missing, free, classless or its class's
// posterior under the tree's fusion model is below min_class_probability) and writes it at its
// pixel of `camera`, unless the camera cannot see it (perception::rejectOccludedPoints, the
// session's occlusion test); the nearest point wins a pixel. Returns a camera.width x camera.height
// label image of the tree's class set.
OwnedLabelImage mapLabelImage(const SemanticOcTree& tree, const Eigen::Matrix3Xf& points_sensor,
                              const Eigen::Isometry3d& T_map_sensor, const CameraModel& camera,
                              const MapLabelImageOptions& options,
                              MapLabelImageStats* stats = nullptr);

}  // namespace mapping
}  // namespace inekf_semantic_mapping
