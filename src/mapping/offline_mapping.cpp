#include "inekf_semantic_mapping/mapping/offline_mapping.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace inekf_semantic_mapping {
namespace mapping {

std::vector<Eigen::Isometry3d> readOdometryPoses(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open poses file");
  std::vector<Eigen::Isometry3d> poses;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    std::istringstream values(line);
    Eigen::Matrix<double, 3, 4> pose;
    for (int i = 0; i < 12; ++i) {
      if (!(values >> pose(i / 4, i % 4))) {
        throw std::runtime_error(path + ":" + std::to_string(line_number) +
                                 ": expected 12 numbers (3x4 row-major pose), got " +
                                 std::to_string(i));
      }
    }
    if (!pose.allFinite()) {
      throw std::runtime_error(path + ":" + std::to_string(line_number) + ": non-finite pose");
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.matrix().topRows<3>() = pose;
    poses.push_back(T);
  }
  return poses;
}

std::unique_ptr<SemanticOcTree> buildSemanticMapFromSequence(const OfflineMappingOptions& options,
                                                             std::ostream* progress) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(options.scans_dir)) {
    throw std::runtime_error(options.scans_dir + ": scans directory not found");
  }
  std::vector<fs::path> scan_paths;
  for (const auto& entry : fs::directory_iterator(options.scans_dir)) {
    if (entry.path().extension() == ".bin") scan_paths.push_back(entry.path());
  }
  std::sort(scan_paths.begin(), scan_paths.end());
  if (scan_paths.empty()) throw std::runtime_error(options.scans_dir + ": no .bin scans");
  if (options.max_scans >= 0 && scan_paths.size() > static_cast<std::size_t>(options.max_scans)) {
    scan_paths.resize(static_cast<std::size_t>(options.max_scans));
  }

  const std::vector<Eigen::Isometry3d> poses = readOdometryPoses(options.poses_path);
  const Eigen::Isometry3d T_cam0_velo =
      kitti::readObjectCalibration(options.calib_path).Tr_velo_to_cam;
  const Eigen::Isometry3d T_velo_cam0 = T_cam0_velo.inverse();

  auto tree =
      std::make_unique<SemanticOcTree>(options.resolution_m, options.classes, options.fusion);
  tree->setProbHit(options.prob_hit);
  tree->setProbMiss(options.prob_miss);
  tree->setGrazingRayTruncation(options.grazing_truncation_voxels);
  LabeledScan scan;
  scan.unknown_label_id = options.ignored_label_id;
  std::size_t total_points = 0;
  for (std::size_t n = 0; n < scan_paths.size(); ++n) {
    const fs::path& scan_path = scan_paths[n];
    const std::string stem = scan_path.stem().string();
    std::size_t frame = 0;
    try {
      frame = std::stoul(stem);
    } catch (const std::exception&) {
      throw std::runtime_error(scan_path.string() + ": scan name is not a frame number");
    }
    if (frame >= poses.size()) {
      throw std::runtime_error(options.poses_path + ": no pose for scan " + scan_path.string() +
                               " (" + std::to_string(poses.size()) + " poses)");
    }
    kitti::VelodyneScan velodyne;
    std::vector<std::uint32_t> raw_labels;
    {
      ScopedTimer timer("offline/read");
      velodyne = kitti::readVelodyneBin(scan_path.string());
      const std::string label_path = (fs::path(options.labels_dir) / (stem + ".label")).string();
      raw_labels = kitti::readLabelFile(label_path);
      if (raw_labels.size() != velodyne.size()) {
        throw std::runtime_error(label_path + ": " + std::to_string(raw_labels.size()) +
                                 " labels for " + std::to_string(velodyne.size()) + " points in " +
                                 scan_path.string());
      }
    }
    {
      ScopedTimer timer("offline/transform");
      const Eigen::Isometry3d T_w_velo = T_velo_cam0 * poses[frame] * T_cam0_velo;
      const Eigen::Matrix3f rotation = T_w_velo.linear().cast<float>();
      const Eigen::Vector3f translation = T_w_velo.translation().cast<float>();
      Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(
          velodyne.xyzi.data(), 4, static_cast<Eigen::Index>(velodyne.size()));
      scan.points_map = (rotation * buffer.topRows<3>()).colwise() + translation;
      scan.sensor_origin_map = translation;
      scan.label_ids.resize(raw_labels.size());
      for (std::size_t i = 0; i < raw_labels.size(); ++i) {
        const std::uint32_t label = kitti::semanticClass(raw_labels[i]);
        scan.label_ids[i] = label;
        if (label != options.ignored_label_id) {
          // Ids the configured set does not know get their own class (grey for display).
          tree->mutableClassSet().addLabel(label);
        }
      }
    }
    {
      ScopedTimer timer("offline/insert");
      tree->insertLabeledScan(scan, options.max_range_m);
    }
    total_points += velodyne.size();
    if (progress) {
      *progress << "[semantic_map_offline] scan " << (n + 1) << "/" << scan_paths.size() << " ("
                << scan_path.filename().string() << ", " << velodyne.size() << " points), map "
                << tree->size() << " nodes\n";
    }
  }
  {
    ScopedTimer timer("offline/update_inner");
    tree->updateInnerOccupancy();
  }
  if (progress) {
    *progress << "[semantic_map_offline] inserted " << total_points << " points from "
              << scan_paths.size() << " scans\n";
  }
  return tree;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
