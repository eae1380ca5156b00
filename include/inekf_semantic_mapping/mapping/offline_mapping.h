// Mapping a scan sequence on disk (SemanticKITTI layout) through a SemanticMappingSession: the
// core of semantic_map_offline, ROS-free.
//
//   scans_dir/NNNNNN.bin      velodyne scans (float32 x y z reflectance)
//   labels_dir/NNNNNN.label   uint32 per point, class id in the lower 16 bits (optional)
//   poses.txt                 one 3x4 row-major pose per line: cam0 of scan i in cam0 of scan 0
//   calib.txt                 odometry calibration: P2 (left colour camera), Tr = velodyne -> cam0
// The map is built in the velodyne frame of the first scan: T_w_velo_i = inv(Tr) P_i Tr.
// Class evidence comes from the per-point labels, or from camera label images (a callback that
// the caller fills, e.g. by segmenting image_2/NNNNNN.png), or not at all.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

namespace inekf_semantic_mapping {
namespace mapping {

struct OfflineSequence {
  std::string scans_dir;
  std::string labels_dir;  // per-point labels; empty: none
  std::string poses_path;
  std::string calib_path;
  int max_scans = -1;                  // < 0: all (0 is refused)
  std::uint32_t ignored_label_id = 0;  // per-point label "unlabeled": occupancy only
  // Called after each scan went in, with its lidar pose (e.g. the grids' GroundTrace).
  std::function<void(const Eigen::Isometry3d& T_map_velo)> on_scan_inserted;
};

// A label image owned by the caller's callback (row-major, width bytes per row).
struct OwnedLabelImage {
  std::vector<std::uint8_t> pixels;
  int width = 0;
  int height = 0;
};
// Fills `out` with the label image of the scan named `stem` (e.g. "000042"); false: none.
using CameraLabelSource = std::function<bool(const std::string& stem, OwnedLabelImage* out)>;

struct ScanFile {
  std::string path;
  std::size_t frame = 0;  // the number its name is
};
// The scans of a sequence directory in frame order (NNNNNN.bin, the name a number), at most
// max_scans (< 0: all; 0 is refused). Throws on a name that is not a number and on two files of
// one frame (1.bin and 000001.bin).
std::vector<ScanFile> listScanFiles(const std::string& scans_dir, int max_scans);

// The left colour camera (P2) of an odometry calib.txt, for images of width x height.
CameraModel odometryColorCamera(const std::string& calib_path, int width, int height);

// A KITTI raw drive folder: <date>/<date>_drive_NNNN_sync with velodyne_points/, oxts/ and
// image_0N/, calibration in the date folder (or calib_dir).
struct OfflineRawDrive {
  std::string drive_dir;
  std::string calib_dir;   // "" = the drive's date folder
  std::string poses_path;  // IMU poses in the map frame, one 3x4 per OXTS frame from the first
                           // (inekf_offline --output-kitti; without oxts/: per velodyne frame
                           // number); "" = the OXTS RTK/INS solution
  int camera_index = 2;
  int max_scans = -1;  // < 0: all (0 is refused)
  // Called after each scan went in, with its lidar pose (e.g. the grids' GroundTrace).
  std::function<void(const Eigen::Isometry3d& T_map_velo)> on_scan_inserted;
};

// The geodetic origin of a raw drive's map frame: east-north-up at its first OXTS frame, where
// both pose sources put it (the OXTS solution, and inekf_offline for the poses it writes). None
// for a drive without oxts/ (its poses file's frame is not known).
std::optional<GeodeticOrigin> rawDriveMapOrigin(const std::string& drive_dir,
                                                const std::string& calib_dir = "");

// One velodyne frame of a raw drive, as mapRawDrive inserts it.
struct RawDriveScan {
  std::string stem;        // its file's 10-digit number (velodyne_points/data/<stem>.bin)
  std::string image_stem;  // the camera image at its stamp (image_0N/data/<image_stem>.png), or
                           // "" when the camera has none within 50 ms
  std::size_t index = 0;   // 0-based, of `count` visited
  std::size_t count = 0;
  Eigen::Matrix3Xf points;  // velodyne frame
  Eigen::Isometry3d T_map_velo;
  kitti::CameraProjection camera;  // the drive's camera_index
  std::string image_path;          // the image of image_stem, or ""
};
using RawDriveScanVisitor = std::function<void(const RawDriveScan& scan)>;

// Visits every velodyne frame of the drive in order (at most max_scans; .bin or an _extract
// drive's .txt) with its pose T_map_velo = T_map_imu * inv(T_velo_imu), T_map_imu at the scan's
// stamp (interpolated between the OXTS frames around it). A scan more than 50 ms outside the OXTS
// frames' span, or in a gap of more than 0.5 s between two of them, is left out with a warning,
// as are the frames the drive lacks (RawDrive::frameWarnings); warnings go to `warnings` when
// given. Throws on missing inputs (the message names the folder or file) and when no scan has a
// pose; an std::out_of_range from `visit` becomes an error naming the frame's pose.
void forEachRawDriveScan(const OfflineRawDrive& drive, const RawDriveScanVisitor& visit,
                         std::ostream* warnings = nullptr);

// Inserts every velodyne frame of the drive (forEachRawDriveScan) with camera labels from
// `camera_labels` (stem: the scan's image_stem) when given; warnings and progress go to
// `progress`. Map frame: the devkit's Mercator frame at the first fix; its geodetic origin
// (rawDriveMapOrigin) goes into the session's map, which saves it.
void mapRawDrive(const OfflineRawDrive& drive, SemanticMappingSession* session,
                 const CameraLabelSource* camera_labels, std::ostream* progress);

// Inserts the scans in frame order into `session` (per-point labels if labels_dir is set, else
// camera labels if `camera_labels` is given, else occupancy only); progress lines go to
// `progress` (may be null). Throws on missing or malformed inputs (the message names the file).
// Both end with the map in the session's tree alone (SemanticMappingSession::treeReleasingGrid,
// inner nodes refreshed), ready to save; the insertion grid's figures go to `progress` first.
void mapSequence(const OfflineSequence& sequence, SemanticMappingSession* session,
                 const CameraLabelSource* camera_labels, std::ostream* progress);

}  // namespace mapping
}  // namespace inekf_semantic_mapping
