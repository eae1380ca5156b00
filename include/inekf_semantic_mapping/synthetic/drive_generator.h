// Writes a synthetic drive in the KITTI raw layout, with its ground truth:
//
//   OUT/<date>/calib_{cam_to_cam,imu_to_velo,velo_to_cam}.txt
//   OUT/<date>/<date>_drive_<nnnn>_sync/
//       oxts/{data/%010d.txt, timestamps.txt, dataformat.txt}            10 Hz, 30 fields
//       velodyne_points/{data/%010d.bin, timestamps{,_start,_end}.txt}    10 Hz HDL-64E
//       image_02/{data/%010d.png, timestamps.txt}                         rectified colour
//       ground_truth/poses_imu_map.txt       T_map_imu per OXTS frame (KITTI 12 numbers)
//       ground_truth/velodyne_labels/%010d.label   SemanticKITTI, lower 16 bits = labelId
//       ground_truth/image_02_labels/%010d.png     8-bit Cityscapes labelIds (sky = 23)
//       ground_truth/world.txt               the surfaces (SyntheticWorld::load)
//       ground_truth/poses_velodyne_map.txt  T_map_velo at each sweep time (velodyne stamps)
//       ground_truth/poses_image_02_map.txt  T_map_camera (rectified camera-2 optical frame,
//                                            kitti::CameraProjection::T_rectified_camera_velo)
//                                            at each image time
//   OUT/<date>/<date>_drive_<nnnn>_extract/
//       oxts/{data/%010d.txt, timestamps.txt, dataformat.txt}            100 Hz
//       ground_truth/poses_imu_map.txt       T_map_imu per 100 Hz OXTS frame
//
// Timing, as KITTI: the OXTS unit samples at 100 Hz (_extract); each lidar sweep's centre time
// gets about 0.1 s (+-jitter) after the previous one, the camera is triggered by the lidar
// (camera_delay_s after the sweep centre, default 0), and the _sync OXTS frame is the 100 Hz sample
// nearest to the sweep (the same text line as in _extract). Positions, velocities and attitude in
// OXTS are the truth (the RT3003's RTK solution); accelerations and angular rates carry the IMU
// noise model. The map frame is the devkit Mercator frame at the first _sync fix, which is the
// route's start. Earth rotation is not modelled (gyros measure only the body rate).
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "inekf_semantic_mapping/synthetic/sensors.h"

namespace inekf_semantic_mapping {
namespace synthetic {

struct DriveOptions {
  std::string output_dir;
  std::uint64_t seed = 1;
  double duration_s = 30.0;
  std::string date = "2011_09_26";  // YYYY_MM_DD
  int drive_number = 1;
  bool write_lidar = true;
  bool write_images = true;
  LidarModel lidar;
  int image_width = 1242, image_height = 375;
  double camera_rate_hz = 10.0;  // <= 10: every n-th lidar sweep triggers the camera
  // Exposure time minus sweep centre time. KITTI triggers the camera when the lidar faces
  // forward, i.e. at the sweep's centre stamp; a non-zero delay makes the static calibration
  // projection of a scan into its image wrong by the motion in between.
  double camera_delay_s = 0.0;
  ImuNoiseModel imu_noise;
  int threads = 2;
  // Geodetic position of the map origin (the first fix), Karlsruhe by default.
  double origin_lat_deg = 49.0112128, origin_lon_deg = 8.4163, origin_alt_m = 112.5;
  // Called after each lidar scan or image is written (done of total, the long part of the run),
  // from one thread at a time; may be empty.
  std::function<void(std::size_t done, std::size_t total)> on_progress;
};

struct DriveSummary {
  std::string date_dir, sync_dir, extract_dir;
  int oxts_frames = 0, extract_frames = 0, scans = 0, images = 0;
  std::size_t lidar_points = 0;
  double loop_length_m = 0, distance_m = 0;
  double wall_seconds = 0;
};

// Throws std::invalid_argument for bad options, std::runtime_error for I/O errors.
DriveSummary generateSyntheticDrive(const DriveOptions& options);
// Throws std::invalid_argument naming the option (as the command line spells it) that is out of
// range; generateSyntheticDrive calls it first.
void validateDriveOptions(const DriveOptions& options);

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
