// Scan-to-scan registration of KITTI lidar scans for the loop closure (estimation/loop_closure.h),
// with PCL's Generalized-ICP (or point-to-point ICP) on voxel-downsampled clouds. The PCL headers
// stay in the .cpp.
#pragma once

#include <Eigen/Geometry>
#include <functional>
#include <memory>
#include <string>

#include "inekf_semantic_mapping/estimation/loop_closure.h"

namespace inekf_semantic_mapping {
namespace common {
class YamlReader;
}
namespace registration {

// Coarse to fine: point-to-point ICP on a coarse voxel grid with a wide and then a narrower
// correspondence distance (a drifted estimate can be metres off), then the fine stage.
struct IcpOptions {
  double coarse_voxel_m = 1.0;
  double coarse_max_correspondence_m = 8.0;  // first coarse pass; the second uses a third of it
  int coarse_iterations = 20;                // per coarse pass; 0: no coarse stage
  bool generalized = true;            // fine stage: GICP (plane-to-plane); false: point-to-point
  double voxel_m = 0.5;               // voxel grid leaf of both clouds
  double min_range_m = 2.0;           // points nearer than this (the car) are dropped
  double max_range_m = 60.0;          // and those farther (sparse)
  double max_correspondence_m = 2.0;  // pairs farther apart are not matched
  int max_iterations = 30;
  double fitness_max_distance_m = 1.0;  // the fitness counts matched points within this

  void read(common::YamlReader* reader);  // keys under "registration."
  void validate() const;                  // throws std::invalid_argument naming the field
};

// Registers the scans of OXTS frames, reading each scan once (readVelodyneScan: .bin or .txt)
// from scan_path(frame) and keeping its downsampled cloud. Reading errors throw
// kitti::KittiFormatError naming the file. Copies share the cache.
class IcpScanMatcher {
 public:
  IcpScanMatcher(std::function<std::string(int)> scan_path, IcpOptions options);

  estimation::ScanRegistrationResult operator()(int target_frame, int source_frame,
                                                const Eigen::Isometry3d& guess) const;

  int scansRead() const;

 private:
  struct Impl;
  std::shared_ptr<Impl> impl_;
};

}  // namespace registration
}  // namespace inekf_semantic_mapping
