// A KITTI raw drive folder: <date>/<date>_drive_<nnnn>_sync/ (10 Hz, synchronized) or
// _extract/ (100 Hz OXTS, unsynchronized), with whatever sensors it has.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/sensor_stream.h"

namespace inekf_semantic_mapping {
namespace kitti {

class RawDrive {
 public:
  static constexpr int kNumCameras = 4;

  // Opens the drive: finds the sensors and reads their timestamps (readSensorStream: a frame
  // with a blank line or without its file is left out and named in frameWarnings()). calib_dir
  // empty: the drive's parent folder (the date folder). Missing calibration is allowed (also in
  // an explicit calib_dir): hasCalibration() is then false and missingParts() says so.
  explicit RawDrive(const std::string& drive_dir, const std::string& calib_dir = "");

  const std::string& driveDir() const { return drive_dir_; }
  bool isExtract() const { return is_extract_; }  // the folder name ends in _extract

  const SensorStream& oxts() const { return oxts_; }
  const SensorStream& velodyne() const { return velodyne_; }
  const SensorStream& camera(int index) const;  // image_00 .. image_03

  bool hasOxts() const { return oxts_.present; }
  bool hasVelodyne() const { return velodyne_.present; }
  bool hasCamera(int index) const { return camera(index).present; }

  // Reads every OXTS frame (stamps from oxts/timestamps.txt). Throws if there is no oxts/.
  std::vector<OxtsFrame> readOxts() const;

  // The folder with calib_*.txt, or "" when none was found.
  const std::string& calibrationDir() const { return calibration_dir_; }
  bool hasCalibration() const { return !calibration_dir_.empty(); }
  RawCalibration readCalibration() const;  // throws when !hasCalibration()
  // Throws KittiFormatError when the lidar (velodyne) or the colour left camera (camera) is to be
  // used and present but the calibration is not: its scans or images could not be placed (a bag
  // with clouds and no imu_link -> velo_link maps nothing). The message names the folder searched,
  // `calib_option` (how the tool is given the date folder) and `leave_out` (how it leaves them
  // out; "": it cannot). kitti2bag, kitti_player and semantic_map_offline refuse alike.
  void requireCalibrationFor(bool velodyne, bool camera, const std::string& calib_option,
                             const std::string& leave_out) const;

  // Human-readable names of what is absent ("velodyne_points", "image_02", "oxts (no frames in
  // DIR)", "calibration (no calib_*.txt in DIR)"), for one warning that tells the user what will
  // not be published.
  std::vector<std::string> missingParts() const;
  // Why hasCalibration() is false ("no calib_*.txt in DIR", "calib_velo_to_cam.txt missing in
  // DIR"); "" when it is true.
  std::string calibrationProblem() const;
  // Every present sensor's frames left out (SensorStream::warnings), for one warning each.
  std::vector<std::string> frameWarnings() const;
  // Every present sensor's timestamps.txt steps that go back or jump ahead by more than a second
  // (timestampWarnings): played or converted in stamp order, such frames land out of place.
  std::vector<std::string> stampWarnings() const;

  // Earliest stamp over all present sensors (0 if none).
  std::int64_t firstStampNs() const;

 private:
  std::string drive_dir_;
  bool is_extract_ = false;
  SensorStream oxts_, velodyne_;
  SensorStream cameras_[kNumCameras];
  std::string calibration_dir_;
  std::string calibration_search_dir_;
};

}  // namespace kitti
}  // namespace inekf_semantic_mapping
