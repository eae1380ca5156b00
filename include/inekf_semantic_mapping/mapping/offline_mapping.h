// Building a semantic map from a labeled scan sequence on disk (SemanticKITTI layout): the core
// of semantic_map_offline, ROS-free.
//
//   scans_dir/NNNNNN.bin      velodyne scans (float32 x y z reflectance)
//   labels_dir/NNNNNN.label   uint32 per point, class id in the lower 16 bits
//   poses.txt                 one 3x4 row-major pose per line: cam0 of scan i in cam0 of scan 0
//   calib.txt                 odometry calibration, `Tr:` = velodyne -> cam0
// The map is built in the velodyne frame of the first scan: T_w_velo_i = inv(Tr) P_i Tr.
#pragma once

#include <Eigen/Geometry>
#include <iosfwd>
#include <memory>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/mapping/semantic_classes.h"

namespace inekf_semantic_mapping {
namespace mapping {

class SemanticOcTree;

struct OfflineMappingOptions {
  std::string scans_dir;
  std::string labels_dir;
  std::string poses_path;
  std::string calib_path;
  double resolution_m = 0.2;
  double max_range_m = 50.0;
  double prob_hit = 0.7;  // occupancy sensor model (octomap's defaults)
  double prob_miss = 0.4;
  double grazing_truncation_voxels = 1.0;  // SemanticOcTree::setGrazingRayTruncation
  FusionModel fusion;
  int max_scans = -1;  // < 0: all
  // Known classes (palette, names); ids outside it are added as they appear (grey).
  ClassSet classes = ClassSet::semanticKitti();
  std::uint32_t ignored_label_id = 0;  // "unlabeled": occupancy only, no class evidence
};

// KITTI odometry poses file. Throws std::runtime_error naming file:line on a malformed line.
std::vector<Eigen::Isometry3d> readOdometryPoses(const std::string& path);

// Inserts the scans in file-name order; progress lines go to `progress` (may be null). Throws
// on missing/malformed inputs (the message names the file), e.g. a label file whose size does
// not match its scan or a scan without a pose.
std::unique_ptr<SemanticOcTree> buildSemanticMapFromSequence(const OfflineMappingOptions& options,
                                                             std::ostream* progress);

}  // namespace mapping
}  // namespace inekf_semantic_mapping
