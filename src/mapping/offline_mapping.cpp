#include "inekf_semantic_mapping/mapping/offline_mapping.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/raw_drive.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"

namespace inekf_semantic_mapping {
namespace mapping {

namespace fs = std::filesystem;

namespace {

// The end of an offline run: the map moves from the insertion grid into the tree (one copy of it
// in memory for the save that follows), inner nodes refreshed.
void finishRun(SemanticMappingSession* session, std::ostream* progress) {
  if (const HashedVoxelGrid* grid = session->grid(); grid && !session->gridReleased() && progress) {
    *progress << "[semantic_map_offline] insertion grid: " << grid->blockCount() << " blocks, "
              << grid->knownVoxels() << " known voxels, " << grid->occupiedVoxels() << " occupied, "
              << grid->memoryUsage() / 1e6 << " MB in memory\n";
  }
  SemanticOcTree& tree = session->treeReleasingGrid();
  ScopedTimer timer("offline/update_inner");
  tree.updateInnerOccupancy();
}

}  // namespace

std::vector<ScanFile> listScanFiles(const std::string& scans_dir, int max_scans) {
  if (!fs::is_directory(scans_dir)) {
    throw std::runtime_error(scans_dir + ": scans directory not found");
  }
  if (max_scans == 0) throw std::invalid_argument("max_scans 0: no scan to map");
  std::vector<ScanFile> scans;
  for (const auto& entry : fs::directory_iterator(scans_dir)) {
    if (entry.path().extension() != ".bin") continue;
    const std::string stem = entry.path().stem().string();
    // The whole name, digits only: "000001_copy.bin" was mapped as frame 1 a second time.
    // Leading zeros are any number (KITTI raw names have 10 digits, odometry ones 6).
    const bool digits_only = !stem.empty() && std::all_of(stem.begin(), stem.end(), [](char c) {
      return std::isdigit(static_cast<unsigned char>(c));
    });
    const std::size_t first_digit = std::min(stem.find_first_not_of('0'), stem.size() - 1);
    if (!digits_only || stem.size() - first_digit > 9) {
      throw std::runtime_error(entry.path().string() + ": scan name is not a frame number");
    }
    scans.push_back({entry.path().string(), static_cast<std::size_t>(std::stoul(stem))});
  }
  if (scans.empty()) throw std::runtime_error(scans_dir + ": no .bin scans");
  // By frame number, not by name: "10.bin" sorts before "2.bin".
  std::sort(scans.begin(), scans.end(),
            [](const ScanFile& a, const ScanFile& b) { return a.frame < b.frame; });
  for (std::size_t i = 1; i < scans.size(); ++i) {
    if (scans[i].frame == scans[i - 1].frame) {
      throw std::runtime_error(scans[i - 1].path + " and " + scans[i].path + " are both frame " +
                               std::to_string(scans[i].frame));
    }
  }
  if (max_scans > 0 && scans.size() > static_cast<std::size_t>(max_scans)) {
    scans.resize(static_cast<std::size_t>(max_scans));
  }
  return scans;
}

CameraModel odometryColorCamera(const std::string& calib_path, int width, int height) {
  const kitti::ObjectCalibration calib = kitti::readObjectCalibration(calib_path);
  CameraModel camera;
  camera.P = calib.P[2];
  camera.R_rect = Eigen::Matrix3d::Identity();  // odometry Tr maps into rectified cam0
  camera.T_camera_sensor = calib.Tr_velo_to_cam;
  camera.width = width;
  camera.height = height;
  return camera;
}

void mapSequence(const OfflineSequence& sequence, SemanticMappingSession* session,
                 const CameraLabelSource* camera_labels, std::ostream* progress) {
  const std::vector<ScanFile> scans = listScanFiles(sequence.scans_dir, sequence.max_scans);
  const std::vector<Eigen::Isometry3d> poses = kitti::readKittiPoses(sequence.poses_path);
  const Eigen::Isometry3d T_cam0_velo =
      kitti::readObjectCalibration(sequence.calib_path).Tr_velo_to_cam;
  const Eigen::Isometry3d T_velo_cam0 = T_cam0_velo.inverse();

  std::size_t total_points = 0;
  for (std::size_t n = 0; n < scans.size(); ++n) {
    const fs::path scan_path(scans[n].path);
    const std::string stem = scan_path.stem().string();
    const std::size_t frame = scans[n].frame;
    if (frame >= poses.size()) {
      throw std::runtime_error(sequence.poses_path + ": no pose for scan " + scan_path.string() +
                               " (" + std::to_string(poses.size()) + " poses)");
    }
    kitti::VelodyneScan velodyne;
    {
      ScopedTimer timer("offline/read");
      velodyne = kitti::readVelodyneBin(scan_path.string());
    }
    const Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(
        velodyne.xyzi.data(), 4, static_cast<Eigen::Index>(velodyne.size()));
    const Eigen::Matrix3Xf points = buffer.topRows<3>();
    const Eigen::Isometry3d T_w_velo = T_velo_cam0 * poses[frame] * T_cam0_velo;
    std::string evidence = "no labels";
    try {
      if (!sequence.labels_dir.empty()) {
        const std::string label_path = (fs::path(sequence.labels_dir) / (stem + ".label")).string();
        std::vector<std::uint32_t> labels = kitti::readLabelFile(label_path);
        if (labels.size() != velodyne.size()) {
          throw std::runtime_error(label_path + ": " + std::to_string(labels.size()) +
                                   " labels for " + std::to_string(velodyne.size()) +
                                   " points in " + scan_path.string());
        }
        for (std::uint32_t& label : labels) label = kitti::semanticClass(label);
        try {
          session->insertScanWithPointLabels(points, T_w_velo, labels, sequence.ignored_label_id);
        } catch (const std::length_error& e) {
          // More distinct label ids than the map holds classes: not a SemanticKITTI .label file.
          throw std::runtime_error(label_path + ": " + e.what());
        }
        evidence = "point labels";
      } else if (camera_labels) {
        OwnedLabelImage image;
        if ((*camera_labels)(stem, &image)) {
          const LabelImageView view{image.pixels.data(), image.width, image.height,
                                    static_cast<std::size_t>(image.width)};
          const CameraModel camera =
              odometryColorCamera(sequence.calib_path, image.width, image.height);
          session->insertScan(points, T_w_velo, &view, &camera);
          evidence = "camera labels";
        } else {
          session->insertScan(points, T_w_velo);
          evidence = "no label image";
        }
      } else {
        session->insertScan(points, T_w_velo);
      }
    } catch (const std::out_of_range& e) {
      // A scan far outside the map: its pose (or the calibration) is wrong.
      throw std::runtime_error(sequence.poses_path + ": pose of frame " + stem + ": " + e.what());
    }
    if (sequence.on_scan_inserted) sequence.on_scan_inserted(T_w_velo);
    total_points += velodyne.size();
    if (progress) {
      *progress << "[semantic_map_offline] scan " << (n + 1) << "/" << scans.size() << " ("
                << scan_path.filename().string() << ", " << velodyne.size() << " points, "
                << evidence << "), map " << session->mapSizeText() << "\n";
    }
  }
  finishRun(session, progress);
  if (progress) {
    *progress << "[semantic_map_offline] inserted " << total_points << " points from "
              << scans.size() << " scans\n";
  }
}

void forEachRawDriveScan(const OfflineRawDrive& drive, const RawDriveScanVisitor& visit) {
  // An empty map written with exit status 0 would look like a map.
  if (drive.max_scans == 0) throw std::invalid_argument("max_scans 0: no scan to map");
  const kitti::RawDrive raw(drive.drive_dir, drive.calib_dir);
  if (!raw.hasVelodyne()) throw std::runtime_error(drive.drive_dir + ": no velodyne_points/");
  if (!raw.hasCalibration()) {
    throw std::runtime_error(drive.drive_dir + ": no calibration (calib_*.txt) found");
  }
  const kitti::RawCalibration calibration = raw.readCalibration();
  const Eigen::Isometry3d T_imu_velo = calibration.T_velo_imu.inverse();
  std::vector<Eigen::Isometry3d> T_map_imu;
  if (!drive.poses_path.empty()) {
    T_map_imu = kitti::readKittiPoses(drive.poses_path);
  } else {
    const std::vector<kitti::OxtsFrame> oxts = raw.readOxts();
    if (oxts.empty()) throw std::runtime_error(drive.drive_dir + ": oxts/ has no frames");
    const auto projection = kitti::MercatorProjection::atFirstFix(oxts.front().record);
    for (const kitti::OxtsFrame& frame : oxts) {
      T_map_imu.push_back(projection.poseInMap(frame.record));
    }
  }
  std::size_t frames = raw.velodyne().size();
  // An empty drive would be written out as an empty map, with no word of why.
  if (frames == 0) throw std::runtime_error(drive.drive_dir + "/velodyne_points: no scans");
  if (drive.max_scans > 0) frames = std::min(frames, static_cast<std::size_t>(drive.max_scans));
  const std::string poses_source =
      drive.poses_path.empty() ? drive.drive_dir + "/oxts" : drive.poses_path;
  if (frames > T_map_imu.size()) {
    throw std::runtime_error(poses_source + ": " + std::to_string(T_map_imu.size()) +
                             " poses for " + std::to_string(frames) + " velodyne frames");
  }
  const kitti::CameraProjection projection = calibration.projection(drive.camera_index);
  for (std::size_t frame = 0; frame < frames; ++frame) {
    kitti::VelodyneScan velodyne;
    {
      ScopedTimer timer("offline/read");
      velodyne = kitti::readVelodyneBin(raw.velodyne().framePath(frame));
    }
    const Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(
        velodyne.xyzi.data(), 4, static_cast<Eigen::Index>(velodyne.size()));
    char stem[24];
    std::snprintf(stem, sizeof(stem), "%010zu", frame);
    RawDriveScan scan{stem,      frame, frames, buffer.topRows<3>(), T_map_imu[frame] * T_imu_velo,
                      projection};
    try {
      visit(scan);
    } catch (const std::out_of_range& e) {
      // A scan far outside the map: its pose is wrong.
      throw std::runtime_error(poses_source + ": pose of frame " + stem + ": " + e.what());
    }
  }
}

void mapRawDrive(const OfflineRawDrive& drive, SemanticMappingSession* session,
                 const CameraLabelSource* camera_labels, std::ostream* progress) {
  forEachRawDriveScan(drive, [&](const RawDriveScan& scan) {
    OwnedLabelImage image;
    std::string evidence = "no labels";
    if (camera_labels && (*camera_labels)(scan.stem, &image)) {
      const LabelImageView view{image.pixels.data(), image.width, image.height,
                                static_cast<std::size_t>(image.width)};
      const CameraModel camera{scan.camera.P_rect, scan.camera.R_rect, scan.camera.T_cam0_velo,
                               image.width, image.height};
      session->insertScan(scan.points, scan.T_map_velo, &view, &camera);
      evidence = "camera labels";
    } else {
      session->insertScan(scan.points, scan.T_map_velo);
    }
    if (drive.on_scan_inserted) drive.on_scan_inserted(scan.T_map_velo);
    if (progress) {
      *progress << "[semantic_map_offline] scan " << (scan.index + 1) << "/" << scan.count << " ("
                << scan.points.cols() << " points, " << evidence << "), map "
                << session->mapSizeText() << "\n";
    }
  });
  finishRun(session, progress);
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
