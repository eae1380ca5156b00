// KITTI raw data -> ROS messages, shared by kitti_player and kitti2bag so that a live replay and
// a bag carry the same messages with the same stamps and frames (names from ros/names.h).
//
// Frames and the tf chain on /tf_static:
//   base_link -> imu_link            identity (the OXTS unit is the body)
//   imu_link  -> velo_link           T_imu_velo = inverse(T_velo_imu)   (calib_imu_to_velo.txt)
//   velo_link -> camera_<name>       T_velo_cami = inverse(Translation(b_i) R_rect_00 T_cam0_velo)
// camera_<name> is the RECTIFIED optical frame of camera i: origin at camera i's optical centre,
// axes of rectified cam0 (x right, y down, z forward); b_i = K_rect^-1 * P_rect_i.col(3).
// Its camera_info has K = P_rect_i(0:3,0:3), R = I, D = 0 and P = [K | 0]: the baseline is in
// the tf, so P * x_camera_frame reproduces the devkit pixel P_rect_i * R_rect_00 * T_cam0_velo x.
#pragma once

#include <geometry_msgs/TransformStamped.h>
#include <geometry_msgs/TwistStamped.h>
#include <nav_msgs/Odometry.h>
#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>
#include <sensor_msgs/PointCloud2.h>

#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/gps_degradation.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/raw_drive.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

// ROS time holds unsigned 32-bit seconds: 1970-01-01 to 2106-02-07. toRosTime throws
// std::out_of_range naming the stamp (as a date) outside that; checkTimelineFitsRosTime names the
// drive's timestamps files, for the tools that load a whole timeline first.
bool fitsRosTime(std::int64_t stamp_ns);
ros::Time toRosTime(std::int64_t stamp_ns);
void checkTimelineFitsRosTime(const std::string& drive_dir, std::int64_t first_stamp_ns,
                              std::int64_t last_stamp_ns);

// Nominal 1-sigma figures of the OXTS RT3003 (datasheet), used as diagonal covariances.
struct OxtsImuNoise {
  double roll_pitch_rad = 0.03 * M_PI / 180.0;
  double yaw_rad = 0.1 * M_PI / 180.0;
  double gyro_rad_s = 0.1 * M_PI / 180.0;  // bias-dominated: ~0.1 deg/s
  double accel_m_s2 = 0.05;
};

// Imu: body-frame specific force ax ay az and rates wx wy wz (NOT the levelled af.. / wf..),
// orientation of imu_link in map from Rz(yaw) Ry(pitch) Rx(roll), frame imu_link.
sensor_msgs::Imu toImuMessage(const kitti::OxtsRecord& record, const ros::Time& stamp,
                              const OxtsImuNoise& noise = OxtsImuNoise());

// NavSatFix status from the OXTS position mode: posmode <= 0 or numsats < 4 -> STATUS_NO_FIX,
// 1..3 (search/Doppler/SPS) -> STATUS_FIX, 4 (differential) -> STATUS_SBAS_FIX,
// >= 5 (RTK float/integer) -> STATUS_GBAS_FIX.
std::int8_t navSatStatusFromOxts(const kitti::OxtsRecord& record);

// A fix from GpsDegrader: its (noisy) position, diagonal known covariance from its sigmas.
// No fix (nullopt): the record's own lat/lon/alt with STATUS_NO_FIX and unknown covariance,
// what a receiver reports while it has no solution.
sensor_msgs::NavSatFix toNavSatFixMessage(const kitti::OxtsRecord& record,
                                          const std::optional<kitti::GeodeticFix>& fix,
                                          const ros::Time& stamp);

// East/north/up velocity (ve, vn, vu) in the map frame.
geometry_msgs::TwistStamped toGpsVelocityMessage(const kitti::OxtsRecord& record,
                                                 const ros::Time& stamp);

// Ground-truth pose map -> base_link from the devkit Mercator; twist in base_link (body
// velocity R^T (ve, vn, vu), body rates wx wy wz). For evaluation only, never on /tf.
nav_msgs::Odometry toGroundTruthMessage(const kitti::OxtsRecord& record,
                                        const kitti::MercatorProjection& projection,
                                        const ros::Time& stamp);

// PointCloud2 with float32 x y z intensity and uint16 ring (computeRings), frame velo_link.
sensor_msgs::PointCloud2 toPointCloudMessage(const kitti::VelodyneScan& scan,
                                             const ros::Time& stamp);

sensor_msgs::CameraInfo toCameraInfoMessage(const kitti::CameraProjection& projection,
                                            const std::string& frame_id, const ros::Time& stamp);

// Reads a png with cv::imread -> bgr8 (color cameras) or mono8 (gray cameras). Throws
// kitti::KittiFormatError naming the file when it cannot be read.
sensor_msgs::Image readImageMessage(const std::string& png_path, bool color,
                                    const std::string& frame_id, const ros::Time& stamp);

// The camera frame names of ros/names.h by KITTI camera index 0..3.
const char* cameraFrameId(int camera_index);

// The /tf_static transforms of the chain documented above; without calibration only
// base_link -> imu_link.
std::vector<geometry_msgs::TransformStamped> staticTransforms(
    const std::optional<kitti::RawCalibration>& calibration, const ros::Time& stamp);

geometry_msgs::TransformStamped toTransformMessage(const Eigen::Isometry3d& T_parent_child,
                                                   const std::string& parent,
                                                   const std::string& child,
                                                   const ros::Time& stamp);

// What one OXTS frame produces. gps_fix is absent on frames the degradation rate drops.
struct OxtsMessages {
  sensor_msgs::Imu imu;
  std::optional<sensor_msgs::NavSatFix> gps_fix;
  geometry_msgs::TwistStamped gps_velocity;
  nav_msgs::Odometry ground_truth;
};

// Everything kitti_player and kitti2bag need from one drive: the OXTS frames, the calibration,
// the map projection (first OXTS fix of the whole drive, so offsets do not move the map) and
// the GPS degrader. oxtsMessages must be called in frame order (the noise stream is
// sequential); restart() rewinds the noise for a loop.
class DriveMessageFactory {
 public:
  DriveMessageFactory(const kitti::RawDrive& drive, kitti::GpsDegradationOptions gps_options);

  const kitti::RawDrive& drive() const { return drive_; }
  bool hasCalibration() const { return calibration_.has_value(); }
  const std::optional<kitti::RawCalibration>& calibration() const { return calibration_; }
  const std::vector<kitti::OxtsFrame>& oxtsFrames() const { return oxts_frames_; }

  void restart();
  OxtsMessages oxtsMessages(std::size_t frame);
  sensor_msgs::PointCloud2 velodyneMessage(std::size_t frame) const;
  // Requires calibration for camera_info; throws std::logic_error otherwise.
  std::pair<sensor_msgs::Image, sensor_msgs::CameraInfo> cameraMessages(int camera_index,
                                                                        std::size_t frame) const;
  // Throws KittiFormatError when the camera's first readable image is not of the calibration's
  // rectified size (another day's calibration: every image would be refused); an image that
  // does not read is left to its own frame.
  void checkCameraImageSize(int camera_index) const;
  std::vector<geometry_msgs::TransformStamped> staticTransformMessages(
      const ros::Time& stamp) const;

 private:
  const kitti::RawDrive& drive_;
  kitti::GpsDegradationOptions gps_options_;
  std::unique_ptr<kitti::GpsDegrader> degrader_;
  std::vector<kitti::OxtsFrame> oxts_frames_;
  std::optional<kitti::RawCalibration> calibration_;
  std::optional<kitti::MercatorProjection> projection_;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
