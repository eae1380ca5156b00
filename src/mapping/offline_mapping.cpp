#include "inekf_semantic_mapping/mapping/offline_mapping.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/kitti/raw_drive.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
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

// A sync drive's image is 5-15 ms after its scan; a frame the camera dropped leaves its scan
// without labels rather than with the next frame's (100 ms away).
constexpr std::int64_t kImageToScanMaxOffsetNs = 50'000'000;

// Poses at their stamps (the OXTS frames'), with the pose at any stamp between them.
class PoseTimeline {
 public:
  // Interpolating across a longer gap (frames the OXTS dropped) would bend a turn into a chord.
  static constexpr std::int64_t kMaxGapNs = 500'000'000;
  // A scan this close before the first pose or after the last takes that pose (a sync drive's
  // first scan is up to 20 ms before its first OXTS frame).
  static constexpr std::int64_t kEndToleranceNs = 50'000'000;

  // Stamps out of order (a timestamps.txt that goes back) are used in their sorted order.
  PoseTimeline(const std::vector<std::int64_t>& stamps_ns, std::vector<Eigen::Isometry3d> poses) {
    std::vector<std::size_t> order(stamps_ns.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return stamps_ns[a] < stamps_ns[b]; });
    for (const std::size_t i : order) {
      stamps_ns_.push_back(stamps_ns[i]);
      poses_.push_back(poses[i]);
    }
  }

  // Between the two poses around stamp_ns: the translation linearly, the rotation by slerp.
  // nullopt where no pose is near (beyond the ends, or inside a gap longer than kMaxGapNs).
  std::optional<Eigen::Isometry3d> poseAt(std::int64_t stamp_ns) const {
    if (stamps_ns_.empty()) return std::nullopt;
    const std::size_t after = static_cast<std::size_t>(
        std::lower_bound(stamps_ns_.begin(), stamps_ns_.end(), stamp_ns) - stamps_ns_.begin());
    if (after == 0) {
      if (stamps_ns_.front() - stamp_ns > kEndToleranceNs) return std::nullopt;
      return poses_.front();
    }
    if (after == stamps_ns_.size()) {
      if (stamp_ns - stamps_ns_.back() > kEndToleranceNs) return std::nullopt;
      return poses_.back();
    }
    const std::int64_t gap_ns = stamps_ns_[after] - stamps_ns_[after - 1];
    if (gap_ns > kMaxGapNs) return std::nullopt;
    const double alpha = static_cast<double>(stamp_ns - stamps_ns_[after - 1]) /
                         static_cast<double>(gap_ns);  // > 0: lower_bound put stamp_ns after it
    const Eigen::Isometry3d& from = poses_[after - 1];
    const Eigen::Isometry3d& to = poses_[after];
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = Eigen::Quaterniond(from.linear())
                        .slerp(alpha, Eigen::Quaterniond(to.linear()))
                        .toRotationMatrix();
    pose.translation() = (1.0 - alpha) * from.translation() + alpha * to.translation();
    return pose;
  }

 private:
  std::vector<std::int64_t> stamps_ns_;
  std::vector<Eigen::Isometry3d> poses_;
};

// The IMU's poses in time, for each scan to take the pose at its own stamp (the OXTS frame beside
// a sync drive's scan is up to 20 ms off it; an _extract drive's OXTS runs at 100 Hz): the OXTS
// solution at the OXTS stamps, or poses_path's lines at them (one per OXTS frame from the first,
// as inekf_offline writes them). A drive without oxts/ has only the file's lines, one per velodyne
// frame number.
PoseTimeline imuPoses(const kitti::RawDrive& raw, const std::string& poses_path) {
  const bool has_oxts = raw.hasOxts() && raw.oxts().size() > 0;
  if (poses_path.empty()) {
    if (!has_oxts) throw std::runtime_error(raw.driveDir() + ": no oxts/ frames and no poses file");
    std::vector<Eigen::Isometry3d> poses;
    const std::vector<kitti::OxtsFrame> oxts = raw.readOxts();
    const auto projection = kitti::MercatorProjection::atFirstFix(oxts.front().record);
    for (const kitti::OxtsFrame& frame : oxts) poses.push_back(projection.poseInMap(frame.record));
    return PoseTimeline(raw.oxts().stamps_ns, std::move(poses));
  }
  std::vector<Eigen::Isometry3d> poses = kitti::readKittiPoses(poses_path);
  std::vector<std::int64_t> stamps;
  if (has_oxts) {
    if (poses.size() > raw.oxts().size()) {
      throw std::runtime_error(poses_path + ": " + std::to_string(poses.size()) +
                               " poses for the " + std::to_string(raw.oxts().size()) +
                               " frames of " + raw.oxts().dir +
                               " (one per OXTS frame, as inekf_offline --output-kitti writes)");
    }
    stamps.assign(raw.oxts().stamps_ns.begin(), raw.oxts().stamps_ns.begin() + poses.size());
    return PoseTimeline(stamps, std::move(poses));
  }
  std::vector<Eigen::Isometry3d> placed;
  const kitti::SensorStream& velodyne = raw.velodyne();
  for (std::size_t i = 0; i < velodyne.size(); ++i) {
    if (velodyne.file_numbers[i] >= poses.size()) continue;
    stamps.push_back(velodyne.stamps_ns[i]);
    placed.push_back(poses[velodyne.file_numbers[i]]);
  }
  return PoseTimeline(stamps, std::move(placed));
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
    *progress << "[semantic_map_offline] read " << total_points << " points from " << scans.size()
              << " scans\n";
  }
}

void forEachRawDriveScan(const OfflineRawDrive& drive, const RawDriveScanVisitor& visit,
                         std::ostream* warnings) {
  // An empty map written with exit status 0 would look like a map.
  if (drive.max_scans == 0) throw std::invalid_argument("max_scans 0: no scan to map");
  const kitti::RawDrive raw(drive.drive_dir, drive.calib_dir);
  if (!raw.hasVelodyne()) throw std::runtime_error(drive.drive_dir + ": no velodyne_points/");
  raw.requireCalibrationFor(true, false, "--calib-dir", "");
  const kitti::SensorStream& velodyne = raw.velodyne();
  std::size_t frames = velodyne.size();
  // An empty drive would be written out as an empty map, with no word of why.
  if (frames == 0) throw std::runtime_error(drive.drive_dir + "/velodyne_points: no scans");
  if (drive.max_scans > 0) frames = std::min(frames, static_cast<std::size_t>(drive.max_scans));
  if (warnings) {
    for (const std::string& warning : raw.frameWarnings()) {
      *warnings << "[semantic_map_offline] warning: " << warning << "\n";
    }
  }
  const kitti::RawCalibration calibration = raw.readCalibration();
  const Eigen::Isometry3d T_imu_velo = calibration.T_velo_imu.inverse();
  const PoseTimeline timeline = imuPoses(raw, drive.poses_path);
  const std::string poses_source =
      drive.poses_path.empty() ? drive.drive_dir + "/oxts" : drive.poses_path;
  const kitti::SensorStream& images = raw.camera(drive.camera_index);
  const kitti::CameraProjection projection = calibration.projection(drive.camera_index);
  std::size_t visited = 0;
  for (std::size_t frame = 0; frame < frames; ++frame) {
    const std::int64_t stamp_ns = velodyne.stamps_ns[frame];
    const std::optional<Eigen::Isometry3d> T_map_imu_at_scan = timeline.poseAt(stamp_ns);
    if (!T_map_imu_at_scan) {
      if (warnings) {
        *warnings << "[semantic_map_offline] warning: " << velodyne.framePath(frame)
                  << ": no pose in " << poses_source << " at its stamp "
                  << kitti::formatKittiTimestamp(stamp_ns) << ": scan left out\n";
      }
      continue;
    }
    ++visited;
    kitti::VelodyneScan scan_data;
    {
      ScopedTimer timer("offline/read");
      scan_data = kitti::readVelodyneScan(velodyne.framePath(frame));
    }
    const Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(
        scan_data.xyzi.data(), 4, static_cast<Eigen::Index>(scan_data.size()));
    RawDriveScan scan{
        velodyne.fileStem(frame),        "",         frame, frames, buffer.topRows<3>(),
        *T_map_imu_at_scan * T_imu_velo, projection, ""};
    // The camera fires as the lidar faces forward (a sync drive's image is 5-15 ms after its
    // scan); an _extract drive's frames are numbered apart, so the image is found by its stamp.
    const std::ptrdiff_t image = images.nearestFrame(stamp_ns, kImageToScanMaxOffsetNs);
    if (image >= 0) {
      scan.image_stem = images.fileStem(static_cast<std::size_t>(image));
      scan.image_path = images.framePath(static_cast<std::size_t>(image));
    }
    try {
      visit(scan);
    } catch (const std::out_of_range& e) {
      // A scan far outside the map: its pose is wrong.
      throw std::runtime_error(poses_source + ": pose of velodyne frame " + scan.stem + ": " +
                               e.what());
    }
  }
  if (visited == 0) {
    throw std::runtime_error(drive.drive_dir + ": none of the " + std::to_string(frames) +
                             " scans has a pose in " + poses_source + " at its stamp");
  }
}

std::optional<GeodeticOrigin> rawDriveMapOrigin(const std::string& drive_dir,
                                                const std::string& calib_dir) {
  const kitti::RawDrive raw(drive_dir, calib_dir);
  if (!raw.hasOxts() || raw.oxts().size() == 0) return std::nullopt;
  const kitti::OxtsRecord first = kitti::readOxtsFile(raw.oxts().framePath(0));
  return GeodeticOrigin{first.lat, first.lon, first.alt};
}

void mapRawDrive(const OfflineRawDrive& drive, SemanticMappingSession* session,
                 const CameraLabelSource* camera_labels, std::ostream* progress) {
  // Saved with the map, so that a node resuming it checks that its own map frame is this one.
  if (const std::optional<GeodeticOrigin> origin =
          rawDriveMapOrigin(drive.drive_dir, drive.calib_dir)) {
    const std::string refusal = session->agreeOnGeodeticOrigin(*origin);
    if (!refusal.empty()) throw std::runtime_error(drive.drive_dir + ": " + refusal);
    if (progress) {
      std::ostringstream line;
      line.precision(10);
      line
          << "[semantic_map_offline] map frame: east-north-up at the drive's first OXTS frame (lat "
          << origin->lat_deg << ", lon " << origin->lon_deg << ", alt " << origin->alt_m
          << "), saved with the map\n";
      *progress << line.str();
    }
  }
  forEachRawDriveScan(
      drive,
      [&](const RawDriveScan& scan) {
        OwnedLabelImage image;
        std::string evidence = "no labels";
        if (camera_labels && scan.image_stem.empty()) {
          evidence = "no labels: no camera image within 50 ms of its stamp";
        }
        if (camera_labels && !scan.image_stem.empty() &&
            (*camera_labels)(scan.image_stem, &image)) {
          scan.camera.checkRectifiedImageSize(scan.image_path, image.width, image.height);
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
          *progress << "[semantic_map_offline] scan " << (scan.index + 1) << "/" << scan.count
                    << " (" << scan.points.cols() << " points, " << evidence << "), map "
                    << session->mapSizeText() << "\n";
        }
      },
      progress);
  finishRun(session, progress);
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
