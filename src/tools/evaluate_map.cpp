// evaluate_map: scores a saved semantic map against labelled lidar scans with the package's one
// map metric (evaluation::mapLabelAt): every labelled point, placed in the map with the pose of
// its frame, takes the most likely class of its voxel; accuracy and IoU per class over the
// covered points, mIoU over the scored classes present in the truth, coverage = covered /
// scored points. The synthetic drives carry such scans (ground_truth/velodyne_labels); the demo
// and the e2e tests score their maps with this tool, evaluate_semantics scores SemanticKITTI maps
// with the same function.
//
// Scored are the points in the camera's view, as on SemanticKITTI (the map holds what the camera
// labels): a map whose scans went in without labels covers fewer of them.
//
//   evaluate_map --map MAP.ot --drive DRIVE_DIR [--poses POSES.txt [--frames FRAMES.txt]]
//       [--labels DIR] [--camera 2 | --all-points] [--scan-step 2] [--max-range M] [--json FILE]

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <unordered_set>
#include <vector>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/evaluation/semantic_evaluation.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/perception/projection.h"
#include "inekf_semantic_mapping/perception/semantickitti_to_cityscapes.h"

namespace fs = std::filesystem;
namespace ism = inekf_semantic_mapping;
using ism::common::UsageError;

namespace {

constexpr char kUsage[] =
    "usage: evaluate_map --map MAP.ot --drive DRIVE_DIR [--poses POSES.txt [--frames FRAMES.txt]]\n"
    "                    [--labels DIR] [--camera 2 | --all-points] [--scan-step 2]\n"
    "                    [--max-range M] [--json FILE]\n"
    "  --map        a semantic map saved as .ot (semantic_map_offline, ~save_map)\n"
    "  --drive      a KITTI raw drive folder with velodyne_points/data/%010d.bin; its date\n"
    "               folder holds calib_imu_to_velo.txt\n"
    "  --labels     labels per scan, %010d.label (Cityscapes labelIds in the lower 16 bits);\n"
    "               default DRIVE/ground_truth/velodyne_labels (synthetic drives)\n"
    "  --poses      T_map_imu per frame, KITTI 12 numbers per line; default\n"
    "               DRIVE/ground_truth/poses_imu_map.txt. Score a map built with estimated poses\n"
    "               with those poses, so that the score is of the semantics alone\n"
    "  --frames     the frame index of each line of --poses (one integer per line); default\n"
    "               0, 1, 2, ... (frames without a pose, e.g. before the filter started, left "
    "out)\n"
    "  --camera     score the points in this camera's rectified image (calib_cam_to_cam.txt of\n"
    "               the date folder; default 2, the left colour camera)\n"
    "  --all-points score every labelled point (the whole lidar sweep)\n"
    "  --scan-step  score every n-th frame (default 2)\n"
    "  --max-range  only points within M metres of the lidar (default: all)\n"
    "  --json       also write the result there (atomically)\n"
    "The last line printed is `RESULT <json>`.";

std::vector<int> readFrameIndices(const std::string& path, std::size_t expected) {
  std::ifstream in(path);
  if (!in) throw ism::kitti::KittiFormatError(path, "cannot open");
  std::vector<int> frames;
  std::string line;
  for (int line_number = 1; std::getline(in, line); ++line_number) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    std::istringstream fields(line);
    long frame = -1;
    std::string rest;
    if (!(fields >> frame) || frame < 0 || frame > 100000000 || (fields >> rest)) {
      throw ism::kitti::KittiFormatError(path, line_number,
                                         "expected one frame index >= 0, got '" + line + "'");
    }
    frames.push_back(static_cast<int>(frame));
  }
  if (frames.size() != expected) {
    throw ism::kitti::KittiFormatError(path, std::to_string(frames.size()) + " frame indices for " +
                                                 std::to_string(expected) + " poses");
  }
  return frames;
}

// Truth of one point: its Cityscapes labelId when the package scores that class, else ignored.
std::uint8_t scoredTruth(std::uint32_t raw_label) {
  const std::uint16_t label = ism::kitti::semanticClass(raw_label);
  for (std::uint8_t scored : ism::perception::kScoredCityscapesLabels) {
    if (label == scored) return scored;
  }
  return ism::perception::kIgnoredLabel;
}

// SemanticKITTI's ids (40 road, 50 building, ...) read as labelIds scored nothing, or the wrong
// class where they overlap (20: other-vehicle against Cityscapes' traffic sign), with exit status
// 0.
void checkCityscapesLabelIds(const std::vector<std::uint32_t>& labels, const std::string& path) {
  constexpr std::uint16_t kLastCityscapesLabelId = 33;
  for (std::size_t p = 0; p < labels.size(); ++p) {
    const std::uint16_t label = ism::kitti::semanticClass(labels[p]);
    if (label > kLastCityscapesLabelId) {
      throw ism::kitti::KittiFormatError(
          path, "point " + std::to_string(p) + " has label " + std::to_string(label) +
                    ", not a Cityscapes labelId (0-33): SemanticKITTI's own ids? --labels takes "
                    "Cityscapes labelIds per point (generate_synthetic_drive writes them); a "
                    "SemanticKITTI sequence is scored by evaluate_semantics");
    }
  }
}

int run(const ism::common::CommandLine& cli) {
  // Normalised: its parent is the date folder (the calibration), also for "DRIVE/" and ".".
  fs::path drive_path = fs::absolute(cli.require("--drive")).lexically_normal();
  if (!drive_path.has_filename()) drive_path = drive_path.parent_path();
  const std::string drive = drive_path.string();
  const std::string map_path = cli.require("--map");
  const std::string labels_dir =
      cli.get("--labels", (fs::path(drive) / "ground_truth" / "velodyne_labels").string());
  const std::string poses_path =
      cli.get("--poses", (fs::path(drive) / "ground_truth" / "poses_imu_map.txt").string());
  const int scan_step = cli.getInt("--scan-step", 2);
  if (scan_step < 1) throw UsageError("--scan-step must be >= 1");
  const double max_range = cli.getDouble("--max-range", 0.0);
  if (max_range < 0) throw UsageError("--max-range must be >= 0 (0: every point)");
  if (cli.has("--json")) {  // before the run
    ism::common::checkOutputPath(cli.get("--json"));
    ism::common::checkOutputsAreNotInputs({cli.get("--json")},
                                          {drive, map_path, labels_dir, poses_path});
  }

  const std::unique_ptr<ism::mapping::SemanticOcTree> tree =
      ism::mapping::loadSemanticOcTree(map_path);
  const std::vector<Eigen::Isometry3d> poses = ism::kitti::readKittiPoses(poses_path);
  std::vector<int> frames(poses.size());
  for (std::size_t i = 0; i < frames.size(); ++i) frames[i] = static_cast<int>(i);
  if (cli.has("--frames")) frames = readFrameIndices(cli.get("--frames"), poses.size());
  const ism::kitti::RawCalibration calibration =
      ism::kitti::readRawCalibration(fs::path(drive).parent_path().string());
  const Eigen::Isometry3d T_imu_velo = calibration.T_velo_imu.inverse();
  const bool all_points = cli.has("--all-points");
  if (all_points && cli.has("--camera"))
    throw UsageError("--camera and --all-points exclude each other");
  ism::kitti::CameraProjection camera;
  if (!all_points) {
    camera = calibration.projection(cli.getInt("--camera", 2));
    if (camera.width <= 0 || camera.height <= 0) {
      throw UsageError(
          "camera " + std::to_string(cli.getInt("--camera", 2)) +
          " has no rectified image size (S_rect) in the calibration: use --all-points");
    }
  }
  const auto inCameraView = [&](const Eigen::Vector3f& point_velo) {
    if (all_points) return true;
    const Eigen::Vector3d h = camera.projectHomogeneous(point_velo.cast<double>());
    if (!(h.z() > 0)) return false;
    // The mapping's own rule: pixel k covers [k - 0.5, k + 0.5).
    return ism::perception::pixelInImage(static_cast<float>(h.x() / h.z()),
                                         static_cast<float>(h.y() / h.z()), camera.width,
                                         camera.height);
  };

  ism::evaluation::PointLabelScore score;
  std::unordered_set<octomap::OcTreeKey, octomap::OcTreeKey::KeyHash> voxels_hit;
  int scans = 0;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    if (frames[i] % scan_step != 0) continue;
    char name[32];
    std::snprintf(name, sizeof(name), "%010d", frames[i]);
    const fs::path scan_path =
        fs::path(drive) / "velodyne_points" / "data" / (name + std::string(".bin"));
    const fs::path label_path = fs::path(labels_dir) / (name + std::string(".label"));
    if (!fs::exists(scan_path) || !fs::exists(label_path)) continue;
    const ism::kitti::VelodyneScan scan = ism::kitti::readVelodyneBin(scan_path.string());
    const std::vector<std::uint32_t> labels = ism::kitti::readLabelFile(label_path.string());
    if (labels.size() != scan.size()) {
      throw ism::kitti::KittiFormatError(label_path.string(),
                                         std::to_string(labels.size()) + " labels for " +
                                             std::to_string(scan.size()) + " points of " +
                                             scan_path.string());
    }
    checkCityscapesLabelIds(labels, label_path.string());
    const Eigen::Isometry3f T_map_velo = (poses[i] * T_imu_velo).cast<float>();
    for (std::size_t p = 0; p < scan.size(); ++p) {
      const Eigen::Vector3f point(scan.point(p)[0], scan.point(p)[1], scan.point(p)[2]);
      if (max_range > 0 && point.norm() > max_range) continue;
      if (!inCameraView(point)) continue;
      const std::uint8_t truth = scoredTruth(labels[p]);
      if (truth == ism::perception::kIgnoredLabel) continue;
      const Eigen::Vector3f point_map = T_map_velo * point;
      const std::uint32_t predicted = ism::evaluation::mapLabelAt(*tree, point_map);
      score.add(truth, predicted);
      if (predicted != ism::cityscapes::kUnlabeled) {
        voxels_hit.insert(tree->coordToKey(point_map.x(), point_map.y(), point_map.z()));
      }
    }
    ++scans;
  }
  if (scans == 0) {
    throw std::runtime_error("no frame of " + poses_path + " has both a scan in " + drive +
                             "/velodyne_points/data and labels in " + labels_dir);
  }
  if (score.scored() == 0) {
    throw std::runtime_error("no labelled point of the " + std::to_string(scans) + " scans in " +
                             labels_dir +
                             " is of a scored class in the camera's view: nothing "
                             "to score");
  }
  tree->updateInnerOccupancy();
  const std::size_t map_voxels = ism::mapping::countOccupiedFinestVoxels(*tree);
  std::printf("%s: %d scans, %llu scored points, coverage %.3f, accuracy %.3f, mIoU %.3f\n",
              map_path.c_str(), scans, static_cast<unsigned long long>(score.scored()),
              score.coverage(), score.accuracy(), score.meanIoU());
  std::printf("occupied voxels %zu, of them holding a covered point %zu\n", map_voxels,
              voxels_hit.size());
  std::ostringstream json;
  const std::string point_json = score.toJson();
  json << point_json.substr(0, point_json.size() - 1) << ",\"scans\":" << scans
       << ",\"map_voxels\":" << map_voxels << ",\"map_voxels_hit\":" << voxels_hit.size()
       << ",\"resolution_m\":" << tree->getResolution() << "}";
  if (cli.has("--json")) {
    ism::common::writeStreamAtomically(cli.get("--json"),
                                       [&](std::ostream& out) { out << json.str() << "\n"; });
  }
  std::printf("RESULT %s\n", json.str().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return ism::common::runCli("evaluate_map", kUsage, [&] {
    const ism::common::CommandLine cli(argc, argv,
                                       {"--map", "--drive", "--labels", "--poses", "--frames",
                                        "--scan-step", "--max-range", "--json", "--camera"},
                                       {"--all-points"});
    if (cli.helpRequested()) return ism::common::printUsage(kUsage);
    return run(cli);
  });
}
